"""Acceptance figures of the reactive agent with Θ-hat: success, median handover time and release
force over seeded scripted ID and OOD walkers; counts drops before release and releases without
a receiver pull above f_r.

Usage: ``python bench/reactive_success.py [--quick] [--n 50]``
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np
from tqdm import tqdm

import handover_env  # noqa: F401
from agents.reactive import ReactiveAgent


def evaluate(kind: str, n: int, seed0: int = 0) -> dict:
    env = gym.make("handover_env/DynamicHandover-v0")
    agent = ReactiveAgent()
    f_r = env.unwrapped.params.release_force
    infos, bad_release = [], 0
    for seed in tqdm(range(seed0, seed0 + n), desc=kind, leave=False):
        obs, info = env.reset(seed=seed, options={"receiver": kind})
        agent.reset()
        while True:
            obs, _, term, trunc, info = env.step(agent.act(obs))
            if term or trunc:
                break
        if info["released"] and (info["receiver_grasp_time"] is None or info["release_force"] <= f_r):
            bad_release += 1
        infos.append(info)
    ok = [i for i in infos if i["is_success"]]
    outcomes = {o: sum(i["outcome"] == o for i in infos) for o in sorted({i["outcome"] for i in infos})}
    return {
        "n": n,
        "success": len(ok) / n,
        "median_time": float(np.median([i["handover_time"] for i in ok])) if ok else float("nan"),
        "median_release_force": float(np.median([i["release_force"] for i in ok])) if ok else float("nan"),
        "drops": outcomes.get("dropped", 0),
        "releases_without_pull": bad_release,
        "outcomes": outcomes,
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="10 walkers per scenario")
    parser.add_argument("--n", type=int, default=50)
    args = parser.parse_args(argv)
    n = 10 if args.quick else args.n
    for kind, target in (("id", 0.9), ("ood", 0.8)):
        r = evaluate(kind, n, seed0=0 if kind == "id" else 10_000)
        print(f"{kind.upper():3s}: success {100 * r['success']:.0f}% of {n} (target >= {100 * target:.0f}%), "
              f"median handover time {r['median_time']:.2f} s, median release force {r['median_release_force']:.2f} N, "
              f"drops {r['drops']}, releases without a receiver pull > f_r {r['releases_without_pull']}, "
              f"outcomes {r['outcomes']}")


if __name__ == "__main__":
    main()
