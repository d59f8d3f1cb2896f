"""Agent steps per second per core: what a reinforcement-learning loop gets out of the env.

Four loops over ``DynamicHandover-v0`` (scripted ID walkers, episodes reset as they end):

* ``reactive``: one env stepped by the reactive agent (``agents/reactive.py``), agent included;
* ``random``: one env stepped by ``action_space.sample()`` (the env alone, almost);
* ``vec sync x2``: ``gym.make_vec(..., num_envs=2, vectorization_mode="sync")``, random actions;
* ``vec async x2``: the same with ``vectorization_mode="async"`` (one worker process per env).

For each: env steps (summed over the sub-envs) per second of wall time and per CPU second (the
CPU time of this process plus, for the async vector env, of its worker processes, read from
``/proc``). Steps per CPU second is the per-core figure; wall time on a shared machine mostly
measures the other processes. Random actions end episodes early or late; every loop runs the
same number of env steps.

Usage: ``python bench/rl_throughput.py [--quick] [--steps N]``
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from pathlib import Path  # noqa: E402

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import handover_env  # noqa: E402, F401
from agents.reactive import ReactiveAgent  # noqa: E402

ENV_ID = "handover_env/DynamicHandover-v0"
OPTIONS = {"receiver": "id"}


def _proc_cpu(pid: int) -> float:
    """CPU seconds (user + system) of process ``pid`` from /proc (0 where /proc is absent)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _single(policy: str, n_steps: int) -> tuple[int, float, float]:
    """(env steps, wall s, CPU s) of one env stepped by ``policy`` for ``n_steps`` steps."""
    env = gym.make(ENV_ID)
    env.action_space.seed(0)
    agent = ReactiveAgent()
    obs, _ = env.reset(seed=0, options=OPTIONS)
    agent.reset()
    episode = 0
    act: Callable[[np.ndarray], np.ndarray] = (
        agent.act if policy == "reactive" else (lambda _obs: env.action_space.sample())
    )
    w0, c0 = time.perf_counter(), time.process_time()
    for _ in range(n_steps):
        obs, _, term, trunc, _ = env.step(act(obs))
        if term or trunc:
            episode += 1
            obs, _ = env.reset(seed=episode, options=OPTIONS)
            agent.reset()
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    env.close()
    return n_steps, wall, cpu


def _vector(mode: str, n_envs: int, n_steps: int) -> tuple[int, float, float]:
    """(env steps summed over sub-envs, wall s, CPU s incl. workers) of a random-action vec env."""
    envs = gym.make_vec(ENV_ID, num_envs=n_envs, vectorization_mode=mode)
    envs.action_space.seed(0)
    envs.reset(seed=0, options=OPTIONS)
    workers = [p.pid for p in getattr(envs, "processes", [])]
    n_vec = max(1, n_steps // n_envs)
    w0, c0 = time.perf_counter(), time.process_time()
    k0 = sum(_proc_cpu(p) for p in workers)
    for _ in range(n_vec):
        envs.step(envs.action_space.sample())
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    cpu += sum(_proc_cpu(p) for p in workers) - k0
    envs.close()
    return n_vec * n_envs, wall, cpu


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true", help="300 env steps per loop")
    parser.add_argument("--steps", type=int, default=None, help="env steps per loop (default 2000)")
    args = parser.parse_args(argv)
    n = args.steps or (300 if args.quick else 2000)
    if n < 2:
        parser.error("--steps must be >= 2")
    rows = [
        ("reactive (1 env)", _single("reactive", n)),
        ("random (1 env)", _single("random", n)),
        ("vec sync x2, random", _vector("sync", 2, n)),
        ("vec async x2, random", _vector("async", 2, n)),
    ]
    print(f"{ENV_ID}, {n} env steps per loop (1 env step = 1/30 s simulated)")
    print(f"{'loop':24s} {'steps/s wall':>13s} {'steps/s per core':>17s} {'real time/core':>15s}")
    for name, (steps, wall, cpu) in rows:
        per_core = steps / cpu if cpu > 0 else float("nan")
        print(f"{name:24s} {steps / wall:13.1f} {per_core:17.1f} {per_core / 30.0:14.1f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
