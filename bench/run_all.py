"""Run every benchmark in this folder, one after another, and print their side-by-side ratios.

Each benchmark is a standalone script that times our code against a reference in the same run
(the env against raw ``mj_step``, the SPGP planner against IAAL, the baselines against the
planner) and prints ratios: absolute times on a shared machine are noise, ratios are not.

``rl_throughput`` (agent steps per second per core, one and two vector envs) and
``agent_episode_cost`` (CPU seconds per closed-loop episode of every agent) report throughput
rather than a ratio. ``make_test_time`` (the
wall time of ``make install`` and of ``make test`` on a fresh clone) installs a whole
environment, so it runs only when asked: ``--make-test-clone PATH`` (with ``--dry-run`` it prints
its commands instead).

Usage: ``python bench/run_all.py [--quick] [--only NAME ...] [--make-test-clone PATH [--dry-run]]``
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

BENCH_DIR = Path(__file__).resolve().parent
ORDER = (
    "env_speed",
    "env_overhead",
    "physics_breakdown",
    "planner_latency",
    "baseline_latency",
    "reactive_success",
    "sweep_backends",
    "rl_throughput",
    "agent_episode_cost",
    "spurious_force",
)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--quick", action="store_true", help="pass --quick to every benchmark (small sizes)"
    )
    parser.add_argument(
        "--only", nargs="*", default=None, help="benchmark names to run (default: all)"
    )
    parser.add_argument(
        "--make-test-clone", default=None, metavar="PATH",
        help="also time make install / make test in this fresh clone (bench/make_test_time.py)",
    )
    parser.add_argument(
        "--dry-run", action="store_true", help="with --make-test-clone: print its commands only"
    )
    args = parser.parse_args(argv)
    if args.dry_run and not args.make_test_clone:
        parser.error("--dry-run applies to --make-test-clone")
    names = [n for n in ORDER if (BENCH_DIR / f"{n}.py").is_file()]
    if args.only:
        unknown = sorted(set(args.only) - set(names))
        if unknown:
            parser.error(f"unknown benchmark(s) {unknown}; available: {names}")
        names = [n for n in names if n in args.only]
    env = dict(os.environ, PYTHONPATH=str(BENCH_DIR.parent))
    failures = []
    for name in names:
        print(f"\n=== bench/{name}.py ===", flush=True)
        cmd = [sys.executable, str(BENCH_DIR / f"{name}.py")] + (["--quick"] if args.quick else [])
        start = time.perf_counter()
        code = subprocess.call(cmd, env=env)
        print(f"--- {name}: exit {code}, {time.perf_counter() - start:.1f} s wall", flush=True)
        if code:
            failures.append(name)
    if args.make_test_clone:
        print("\n=== bench/make_test_time.py ===", flush=True)
        cmd = [sys.executable, str(BENCH_DIR / "make_test_time.py"), args.make_test_clone]
        if subprocess.call(cmd + (["--dry-run"] if args.dry_run else []), env=env):
            failures.append("make_test_time")
    if failures:
        print(f"\nfailed: {failures}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
