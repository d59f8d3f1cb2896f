"""``make demo``, ``handover-demo``, ``python -m handover_eval.cli.demo``: the paper's question,
dynamic vs static handover, on the same seeded walkers.

On the embedded default (the synthetic demonstrations; no data download), the SPGP planner is
fitted and meets the demo's six fixed ID walkers in ``DynamicHandover-v0``; the static baseline
meets the same walkers in ``StaticHandover-v0``. One line per episode as it ends, then the
summary (success and median handover time per side, the benchmark's outcome names). The first
walker is filmed side by side (dynamic left, static right) when offscreen rendering works
(``MUJOCO_GL=egl`` or ``osmesa``). Files (``--out``, default ``outputs/demo/``):
``demo_side_by_side.mp4`` and ``.png``, ``demo_summary.md``, ``demo_summary.csv``,
``demo_episodes.csv``.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from handover_env.offline import hub_offline
from handover_env.paths import UnsafePathError, output_folder
from handover_eval.output_lock import OutputLock, OutputLockError


def parse(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """The demo's flags."""
    parser = argparse.ArgumentParser(
        prog="handover-demo", description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--out", default="outputs/demo",
                        help="folder of the mp4, the PNG and the summary (default outputs/demo)")
    parser.add_argument("--no-video", action="store_true",
                        help="run and summarise the episodes without rendering (no mp4 / PNG)")
    return parser.parse_args(argv)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the demo; 2 with a one-line error on a bad ``--out``."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    hub_offline()
    args = parse(argv)
    try:
        out = output_folder(args.out, "--out")
        lock = OutputLock(out).acquire()
    except (UnsafePathError, OutputLockError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    try:
        return _run(out, film=not args.no_video)
    finally:
        lock.release()


def _run(out: Path, film: bool) -> int:
    from handover_eval.demo import output, report, run

    start = time.perf_counter()
    cpu = time.process_time()
    if film and not _gl_works():
        film = False
    result = run.run(film=film, on_episode=lambda e: print(report.episode_line(e), flush=True))
    print(f"\n(planner fitted on the synthetic default in {result.fit_s:.1f} s; all episodes "
          f"{result.total_s:.1f} s)")
    print("\nsummary over walkers " + ", ".join(map(str, run.DEMO_SEEDS)) + ":")
    for line in report.summary_lines(result):
        print("  " + line)
    for path in output.write(result, out):
        print(f"wrote {path}")
    print(f"demo finished in {time.perf_counter() - start:.1f} s "
          f"({time.process_time() - cpu:.1f} s CPU in this process)")
    return 0


def _gl_works() -> bool:
    """True when an offscreen MuJoCo renderer can be made (else the demo says why and goes on
    without video)."""
    import mujoco

    try:
        r = mujoco.Renderer(mujoco.MjModel.from_xml_string("<mujoco/>"), 16, 16)
    except Exception as exc:  # no offscreen GL on this machine
        print(f"(no video: {type(exc).__name__}: {exc}; set MUJOCO_GL=egl or osmesa)")
        return False
    r.close()
    return True


if __name__ == "__main__":
    raise SystemExit(main())
