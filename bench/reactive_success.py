"""Acceptance figures of the first agents with Θ-hat, per scenario: success, median handover time,
median release force, median and max peak contact force, drops before release and releases that
were not caused by the receiver's pull.

Scenarios (seeded, 50 walkers each by default):

* ``dynamic ID`` / ``dynamic OOD``: ``DynamicHandover-v0`` with the reactive agent
  (:class:`agents.reactive.ReactiveAgent`), scripted ID walkers (seeds 0..n-1) and OOD walkers
  (wander / pause, seeds 10000..).
* ``static ID``: ``StaticHandover-v0`` with the static baseline (:class:`agents.static.StaticAgent`:
  deliver to the detected hand), the same ID walkers stopping in the predefined area. Its
  handover time is reported without and with the 2 s stabilisation delay (paper Sec. V-C).

Handover time is measured as in the paper's user study: from when the receiver leaves the start
point to the gripper release (paper: dynamic 3.2 s, static 6.9 s, delay excluded).

A release counts as "without a pull" if it happened before the receiver grasped the object, at
the same control tick as the grasp, or at a wrist force not above f_r.

Usage: ``python bench/reactive_success.py [--quick] [--n 50] [--scenarios
dynamic-id,dynamic-ood,static-id]``
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import numpy as np
from tqdm import tqdm

import handover_env  # noqa: F401
from agents.reactive import ReactiveAgent
from agents.static import StaticAgent
from handover_env.rollout import run_episode

SCENARIOS = {
    # name: (env id, receiver kind, first seed, agent factory, success target)
    "dynamic-id": ("handover_env/DynamicHandover-v0", "id", 0, ReactiveAgent, 0.9),
    "dynamic-ood": ("handover_env/DynamicHandover-v0", "ood", 10_000, ReactiveAgent, 0.8),
    "static-id": ("handover_env/StaticHandover-v0", "id", 0, StaticAgent, None),
}


def evaluate(scenario: str, n: int) -> dict:
    """Run ``n`` seeded episodes of one scenario; returns the summary figures."""
    env_id, kind, seed0, make_agent, _ = SCENARIOS[scenario]
    env = gym.make(env_id)
    agent = make_agent()
    f_r = env.unwrapped.params.release_force
    tick = env.unwrapped.controller.dt
    infos, bad_release = [], 0
    for seed in tqdm(range(seed0, seed0 + n), desc=scenario, leave=False):
        info = run_episode(env, agent, seed=seed, options={"receiver": kind})
        if info["released"]:
            t_grasp = info["receiver_grasp_time"]
            t_release = env.unwrapped.t_release
            if t_grasp is None or t_release < t_grasp + 0.5 * tick or info["release_force"] <= f_r:
                bad_release += 1
        infos.append(info)
    env.close()
    ok = [i for i in infos if i["is_success"]]

    def med(key: str) -> float:
        return float(np.median([i[key] for i in ok])) if ok else float("nan")

    outcomes = {
        o: sum(i["outcome"] == o for i in infos) for o in sorted({i["outcome"] for i in infos})
    }
    peaks = [i["peak_contact_force"] for i in infos]
    return {
        "n": n,
        "success": len(ok) / n,
        "median_time": med("handover_time"),
        "median_time_with_delay": med("handover_time_with_delay"),
        "median_release_force": med("release_force"),
        "median_peak_force": float(np.median(peaks)),
        "max_peak_force": float(np.max(peaks)),
        "drops": outcomes.get("dropped", 0),
        "releases_without_pull": bad_release,
        "outcomes": outcomes,
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true", help="10 walkers per scenario")
    parser.add_argument("--n", type=int, default=50)
    parser.add_argument("--scenarios", default=",".join(SCENARIOS))
    args = parser.parse_args(argv)
    n = 10 if args.quick else args.n
    for name in args.scenarios.split(","):
        if name not in SCENARIOS:
            raise SystemExit(f"unknown scenario {name!r}; choose from {list(SCENARIOS)}")
        start = time.perf_counter()
        r = evaluate(name, n)
        target = SCENARIOS[name][4]
        goal = f" (target >= {100 * target:.0f}%)" if target is not None else ""
        delay = (f" ({r['median_time_with_delay']:.2f} s with the 2 s delay)"
                 if name.startswith("static") else "")
        print(
            f"{name:11s}: success {100 * r['success']:.0f}% of {n}{goal}, "
            f"median handover time {r['median_time']:.2f} s{delay}, "
            f"median release force {r['median_release_force']:.2f} N, "
            f"peak force median {r['median_peak_force']:.1f} N / max {r['max_peak_force']:.1f} N, "
            f"drops {r['drops']}, releases without a receiver pull > f_r "
            f"{r['releases_without_pull']}, "
            f"outcomes {r['outcomes']} [{time.perf_counter() - start:.0f} s]",
            flush=True,
        )


if __name__ == "__main__":
    main()
