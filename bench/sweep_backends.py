"""Completed closed-loop episodes per second: one env, sync and async vector envs, the Ray backend.

All four run the same number of episodes of ``DynamicHandover-v0`` with the null agent (the
object held at the ready pose; the scripted walkers take it), end to end: env construction,
worker start-up and imports included, as a sweep pays them. Printed as ratios to the single env.

* **single**: one env, ``run_episode`` seed after seed, in this process.
* **sync / async**: ``gym.make_vec(..., num_envs=N, vectorization_mode=...)``, stepped until the
  episodes are done (NEXT_STEP autoreset; the walkers after the first N are the envs' own
  autoreset draws, so episode lengths differ a little from the single env's seeds).
* **ray**: the episodes in chunks through :func:`handover_eval.backend.map_jobs` on a
  local Ray instance with N CPUs (its start-up timed on its own, before); then the same again on
  the now warm workers (**ray, warm**: what every later map of a command pays).

Then ``evaluate.py table1 --quick`` wall time with ``--backend process`` and ``--backend ray``
(the latter starting its own Ray, as a user's command does), and Ray's start-up alone.

Usage: ``python bench/sweep_backends.py [--quick] [--episodes E] [--envs N] [--skip-table1]``
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

ENV_ID = "handover_env/DynamicHandover-v0"
READY = np.array([0.3, -0.4, 1.15, -math.pi / 2], dtype=np.float32)
ROOT = Path(__file__).resolve().parent.parent


def _make_env():
    import gymnasium as gym

    import handover_env  # noqa: F401 - registers the envs

    return gym.make(ENV_ID)


def run_episodes(_: object, seeds: tuple[int, ...]) -> list[str]:
    """Null-agent episodes for ``seeds`` in one fresh env; their outcomes (a backend job)."""
    from agents.null import NullAgent
    from handover_env.rollout import run_episode

    env, agent = _make_env(), NullAgent()
    try:
        return [str(run_episode(env, agent, seed=s)["outcome"]) for s in seeds]
    finally:
        env.close()


def bench_single(episodes: int) -> float:
    t0 = time.perf_counter()
    outcomes = run_episodes(None, tuple(range(episodes)))
    assert len(outcomes) == episodes
    return time.perf_counter() - t0


def bench_vector(episodes: int, n_envs: int, mode: str) -> float:
    import gymnasium as gym

    import handover_env  # noqa: F401

    t0 = time.perf_counter()
    envs = gym.make_vec(ENV_ID, num_envs=n_envs, vectorization_mode=mode)
    try:
        envs.reset(seed=list(range(n_envs)))
        actions = np.tile(READY, (n_envs, 1))
        done_count = 0
        while done_count < episodes:
            _, _, terminated, truncated, _ = envs.step(actions)
            done_count += int(np.sum(terminated | truncated))
    finally:
        envs.close()
    return time.perf_counter() - t0


def bench_ray(episodes: int, n_cpus: int) -> tuple[float, float, float]:
    """(Ray start-up s, cold s, warm s) on a local instance of ``n_cpus``: the episodes in chunks
    of ~episodes/(2 n), first on fresh workers (their imports included), then again on the same,
    now warm, workers."""
    from handover_eval.backend import Backend, map_jobs, session

    t0 = time.perf_counter()
    with session(Backend("ray"), workers=n_cpus, log=None) as sess:
        startup = time.perf_counter() - t0
        chunk = max(1, episodes // (2 * n_cpus))
        jobs = [tuple(range(i, min(i + chunk, episodes))) for i in range(0, episodes, chunk)]
        runs = []
        for _ in range(2):
            t1 = time.perf_counter()
            outcomes = map_jobs(run_episodes, None, jobs, progress=False, desc="ray episodes")
            runs.append(time.perf_counter() - t1)
            assert sum(len(o) for o in outcomes) == episodes
        assert sess.started_here
    return startup, runs[0], runs[1]


def bench_table1() -> dict[str, float]:
    """``evaluate.py table1 --quick`` wall time on each backend (fresh output folders)."""
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for backend in ("process", "ray"):
            cmd = [sys.executable, str(ROOT / "evaluate.py"), "table1", "--quick", "--no-progress",
                   "--backend", backend, "--out", str(Path(tmp) / backend)]
            t0 = time.perf_counter()
            subprocess.run(cmd, check=True, cwd=ROOT, stdout=subprocess.DEVNULL)
            out[backend] = time.perf_counter() - t0
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true", help="8 episodes, no table1 timing")
    parser.add_argument(
        "--episodes", type=int, default=None, help="episodes per variant (default 24, 8 quick)"
    )
    parser.add_argument("--envs", type=int, default=2, help="vector envs / Ray CPUs (default 2)")
    parser.add_argument("--skip-table1", action="store_true", help="skip the table1 --quick timing")
    args = parser.parse_args(argv)
    try:
        import ray  # noqa: F401
    except ImportError:
        print("bench/sweep_backends.py needs Ray: pip install -e '.[cluster]'", file=sys.stderr)
        return 2
    episodes = args.episodes or (8 if args.quick else 24)
    if episodes < 1 or args.envs < 1:
        parser.error("--episodes and --envs must be >= 1")
    print(
        f"{episodes} null-agent episodes per variant, {args.envs} envs / CPUs, {os.cpu_count()} "
        "cores",
        flush=True,
    )
    seconds = {"single env": bench_single(episodes),
               f"sync vector x{args.envs}": bench_vector(episodes, args.envs, "sync"),
               f"async vector x{args.envs}": bench_vector(episodes, args.envs, "async")}
    startup, seconds[f"ray x{args.envs}"], seconds[f"ray x{args.envs}, warm"] = bench_ray(
        episodes, args.envs
    )
    base = episodes / seconds["single env"]
    print(f"\n{'variant':<20} {'episodes/s':>10} {'vs single':>10}")
    for name, s in seconds.items():
        print(f"{name:<20} {episodes / s:>10.2f} {episodes / s / base:>9.2f}x")
    print(f"Ray start-up (local instance, {args.envs} CPUs), not in the above: {startup:.1f} s")
    if not (args.quick or args.skip_table1):
        t = bench_table1()
        print(
            f"\nevaluate.py table1 --quick wall time: process {t['process']:.1f} s, ray "
            f"{t['ray']:.1f} s "
            f"(ray / process {t['ray'] / t['process']:.2f}x; includes the command's own Ray "
            "start-up)"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
