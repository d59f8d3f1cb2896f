"""Wall time of ``make test`` on a fresh clone, split into the install and the tests.

``make test`` on a fresh machine first creates ``.venv`` and installs the project (``make
install``: pip, the dependencies, the editable package), then lints and runs pytest. The budget
(under 15 minutes on 2 cores) is for the whole; this script times the parts separately, in a
clone you made for it:

    git clone <repo> /path/to/fresh && python bench/make_test_time.py /path/to/fresh

1. ``make -C CLONE install`` (venv + pip; the download and build time);
2. ``make -C CLONE test`` (ruff, then pytest exactly as the Makefile runs it, with its
   ``TEST_WORKERS``), with ``PYTEST_ADDOPTS=--durations=15`` so the slowest tests are listed.

It refuses a folder that is not a clone of this project (no ``Makefile``/``pyproject.toml``) or
whose ``.venv`` already exists (that would time a warm install; ``--allow-existing-venv`` to time
anyway). ``--dry-run`` prints the commands and runs nothing. It is not part of ``make bench``'s
default run (it installs a whole environment): run it on a machine of its own.

Usage: ``python bench/make_test_time.py CLONE [--dry-run] [--allow-existing-venv]
[--torch-index URL]``
"""

from __future__ import annotations

import argparse
import os
import shlex
import subprocess
import sys
import time
from pathlib import Path


def commands(clone: Path, torch_index: str | None = None) -> list[tuple[str, list[str]]]:
    """The timed steps: (label, argv), all run with ``cwd=clone``."""
    make_install = ["make", "-C", str(clone), "install"]
    if torch_index:
        make_install.append(f"TORCH_INDEX={torch_index}")
    return [
        ("install (make install)", make_install),
        ("lint + tests (make test)", ["make", "-C", str(clone), "test"]),
    ]


def check_clone(clone: Path, allow_existing_venv: bool) -> None:
    """A clear error unless ``clone`` looks like a fresh clone of this project."""
    if not clone.is_dir():
        raise SystemExit(f"error: {clone} is not a folder (clone the repository there first)")
    missing = [n for n in ("Makefile", "pyproject.toml") if not (clone / n).is_file()]
    if missing:
        raise SystemExit(f"error: {clone} is not a clone of handover_env (no {', '.join(missing)})")
    if (clone / ".venv").exists() and not allow_existing_venv:
        raise SystemExit(
            f"error: {clone / '.venv'} exists: the install would not be timed from scratch "
            "(use a fresh clone, or --allow-existing-venv)"
        )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("clone", type=Path, help="a fresh git clone of the project")
    parser.add_argument("--dry-run", action="store_true",
                        help="print the commands, run nothing")
    parser.add_argument("--allow-existing-venv", action="store_true",
                        help="time even though CLONE/.venv exists (a warm install)")
    parser.add_argument("--torch-index", default=None, metavar="URL",
                        help="passed to make install as TORCH_INDEX (e.g. the CPU-only wheels)")
    args = parser.parse_args(argv)
    clone = args.clone.resolve()
    steps = commands(clone, args.torch_index)
    if args.dry_run:
        print(f"# would run in {clone}:")
        for label, cmd in steps:
            print(f"{shlex.join(cmd)}    # {label}")
        return 0
    check_clone(clone, args.allow_existing_venv)
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1",
               PYTEST_ADDOPTS="--durations=15")
    env.pop("PYTHONPATH", None)  # the clone's own package, not the caller's tree
    times = []
    for label, cmd in steps:
        print(f"\n=== {label}: {shlex.join(cmd)}", flush=True)
        start = time.perf_counter()
        code = subprocess.call(cmd, cwd=clone, env=env)
        times.append((label, time.perf_counter() - start, code))
        if code:
            break
    print("\nwall time:")
    for label, sec, code in times:
        print(f"  {label:30s} {sec / 60:6.1f} min" + (f"  (exit {code})" if code else ""))
    total = sum(t for _, t, _ in times)
    print(f"  {'make test total (all of it)':30s} {total / 60:6.1f} min  (budget 10 min)")
    return max((c for *_, c in times), default=0)


if __name__ == "__main__":
    sys.exit(main())
