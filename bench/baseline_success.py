"""Closed-loop success of the learned baselines (BC-MLP, ACT) in ``DynamicHandover-v0``.

Each agent drives the env through the same agent interface as the planner (``reset()`` /
``act(obs)``, a :class:`agents.predictive.PredictiveAgent`), with the env's parameters Θ̂ (the
same for every agent), over seeded scripted ID walkers (seeds 0..n-1, as
``bench/reactive_success.py``) and optionally OOD walkers (seeds 10000..).

Checkpoints: ``--bc-mlp DIR`` / ``--act DIR`` (default ``runs/bc_mlp`` and ``runs/act``); an agent
whose checkpoint is missing is skipped with a note. Printed per agent: success rate, median
handover time, median release force, outcomes.

Usage: ``python bench/baseline_success.py [--quick] [--n 50] [--kinds id,ood]``
"""

from __future__ import annotations

import os

os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("HF_DATASETS_OFFLINE", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import handover_env  # noqa: E402,F401
from baselines.act import ACTAgent  # noqa: E402
from baselines.bc_mlp import BCMLPAgent  # noqa: E402
from handover_env.rollout import run_episode  # noqa: E402

FIRST_SEED = {"id": 0, "ood": 10_000}


def run(agent, kind: str, n: int) -> dict:
    env = gym.make("handover_env/DynamicHandover-v0")
    infos = []
    t0 = time.perf_counter()
    for seed in range(FIRST_SEED[kind], FIRST_SEED[kind] + n):
        info = run_episode(env, agent, seed=seed, options={"receiver": kind})
        infos.append(info)
    env.close()
    ok = [i for i in infos if i["is_success"]]

    def med(key: str) -> float:
        return float(np.median([i[key] for i in ok])) if ok else float("nan")

    return {
        "success": len(ok) / n,
        "median_time": med("handover_time"),
        "median_release_force": med("release_force"),
        "outcomes": {
            o: sum(i["outcome"] == o for i in infos) for o in sorted({i["outcome"] for i in infos})
        },
        "wall_s": time.perf_counter() - t0,
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true", help="3 walkers per kind")
    parser.add_argument("--n", type=int, default=50, help="walkers per kind (default 50)")
    parser.add_argument(
        "--kinds", default="id", help="comma-separated receiver kinds: id, ood (default id)"
    )
    parser.add_argument(
        "--bc-mlp", default=str(ROOT / "runs" / "bc_mlp"), help="BC-MLP checkpoint folder"
    )
    parser.add_argument("--act", default=str(ROOT / "runs" / "act"), help="ACT checkpoint folder")
    parser.add_argument(
        "--only", choices=["bc-mlp", "act"], default=None, help="run one agent only"
    )
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    n = 3 if args.quick else args.n
    probe = gym.make("handover_env/DynamicHandover-v0")
    params, layout = probe.unwrapped.params, probe.unwrapped.layout
    probe.close()
    print(f"Theta-hat (same for every agent): {params}")
    loaders = {"bc-mlp": (BCMLPAgent, args.bc_mlp), "act": (ACTAgent, args.act)}
    for name, (cls, path) in loaders.items():
        if args.only and name != args.only:
            continue
        try:
            agent = cls.load(path, params=params, layout=layout)
        except Exception as exc:  # noqa: BLE001 - report and go on with the other agent
            print(f"{name}: skipped ({exc})")
            continue
        for kind in args.kinds.split(","):
            r = run(agent, kind.strip(), n)
            print(
                f"{name:6s} {kind:3s} n={n}: success {r['success']:.0%}, median handover time "
                f"{r['median_time']:.2f} s, median release force {r['median_release_force']:.1f} "
                "N, "
                f"outcomes {r['outcomes']} ({r['wall_s']:.0f} s)",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
