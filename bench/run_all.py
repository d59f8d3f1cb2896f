"""Run every benchmark in this folder, one after another, and print their side-by-side ratios.

Each benchmark is a standalone script that times our code against a reference in the same run
(the env against raw ``mj_step``, the SPGP planner against IAAL, the baselines against the
planner) and prints ratios: absolute times on a shared machine are noise, ratios are not.

Usage: ``python bench/run_all.py [--quick] [--only NAME ...]``
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
    "physics_breakdown",
    "planner_latency",
    "baseline_latency",
    "reactive_success",
    "sweep_backends",
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
    args = parser.parse_args(argv)
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
    if failures:
        print(f"\nfailed: {failures}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
