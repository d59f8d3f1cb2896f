"""Success against the scripted walker's speed, and where the person was calibrated.

Seeded ID walkers (seeds 5000.., ``options["speed"]`` fixed) meet the reactive agent and the null
agent (which holds the bottle still: its failures are the person's) in ``DynamicHandover-v0``,
paper sensor profile, Θ̂. Per speed: the success count per agent, the most common other outcome,
and how many of the walkers the env found within the calibrated range
(``info["within_calibration"]``, ``docs/calibration/calibrated_range.md``: median speed 0.59-1.11
m/s).

``--person`` sets person switches apart from their defaults (``docs/simulator.md``, e.g.
``--person reach_offset``); without it, the default person.

Usage: ``python bench/speed_range.py [--walkers 20] [--speeds 0.6 1.0 1.4 1.8 2.2]
[--person SWITCH ...]``
"""

from __future__ import annotations

import argparse
import warnings
from collections import Counter

FIRST_SEED = 5000


def measure(speeds: list[float], walkers: int,
            person: dict[str, bool] | None = None) -> list[dict[str, object]]:
    """One row per speed: successes and outcomes per agent, walkers within the range
    (``person``: person switches, e.g. ``{"reach_offset": True}``)."""
    import gymnasium as gym

    import handover_env  # noqa: F401 - registers the envs
    from agents.null import NullAgent
    from agents.reactive import ReactiveAgent
    from handover_env.rollout import run_episode

    env = gym.make("handover_env/DynamicHandover-v0", sensing="paper", person=person)
    agents = {"reactive": ReactiveAgent(), "null": NullAgent()}
    rows = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # the range is counted below
        for speed in speeds:
            row: dict[str, object] = {"speed": speed, "n": walkers}
            within = 0
            for name, agent in agents.items():
                outcomes: Counter[str] = Counter()
                for i in range(walkers):
                    info = run_episode(env, agent, seed=FIRST_SEED + i,
                                       options={"receiver": "id", "speed": speed})
                    outcomes[info["outcome"]] += 1
                    within += name == "reactive" and bool(info["within_calibration"])
                row[name] = outcomes
            row["within"] = within
            rows.append(row)
    env.close()
    return rows


def main() -> None:
    from handover_env.person.settings import switch_tokens
    from handover_eval.cli.args import add_person_argument

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--walkers", type=int, default=20)
    p.add_argument("--speeds", type=float, nargs="+", default=[0.6, 1.0, 1.4, 1.8, 2.2])
    add_person_argument(p)
    args = p.parse_args()
    print("| speed (m/s) | within the calibrated range | success reactive / null | mostly |")
    print("| --- | --- | --- | --- |")
    for r in measure(args.speeds, args.walkers, switch_tokens(args.person) or None):
        rx, nl = r["reactive"], r["null"]
        other = (rx + nl).copy()
        del other["success"]
        mostly = other.most_common(1)[0][0] if other else "-"
        print(f"| {r['speed']:.1f} | {r['within']} of {r['n']} | {rx['success']} / "
              f"{nl['success']} of {r['n']} | {mostly} |")


if __name__ == "__main__":
    main()
