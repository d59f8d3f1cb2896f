"""The ``presentation`` command of evaluate.py: a closed-loop run's presentation at the grasp
against the recorded givers' (:mod:`handover_eval.closedloop.presentation`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

COMMAND = "presentation"


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``presentation`` sub-command (issue 36: no exploit of the simulated person)."""
    p = sub.add_parser(
        "presentation",
        help="each agent's presentation at the grasp against the recorded givers' (md/csv/png)",
        description="Reads RUN_FOLDER/closed_loop_episodes.csv of an `evaluate.py closed-loop` "
        "run and compares where and how each agent presented the bottle at the person's grasp "
        "(forward, lateral and up of the pelvis in the walking frame, the bottle's speed, the "
        "robot's jerk) with the recorded human givers at the transfer (5-95 % range over the "
        "calibration half of DATA's recordings). Writes presentation.md/.csv/.png into --out.",
    )
    p.add_argument("run_folder", metavar="RUN_FOLDER",
                   help="the --out folder of an `evaluate.py closed-loop` run")
    p.add_argument("--data", required=True, metavar="PATH",
                   help="the public dataset's whole_motions folder (its calibration half gives "
                   "the recorded range)")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="where to write presentation.md/.csv/.png (default: RUN_FOLDER)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def main(args: argparse.Namespace) -> int:
    """Run the ``presentation`` command; 2 with a one-line error on bad input."""
    from handover_env.data.errors import DatasetError
    from handover_eval.closedloop.output import write_presentation
    from handover_eval.closedloop.presentation import markdown, run_presentation

    try:
        if not Path(args.data).is_dir():
            raise ValueError(f"--data {args.data}: not a folder")
        rows, ranges, table = run_presentation(args.run_folder, args.data,
                                               progress=not args.no_progress)
    except (ValueError, DatasetError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    out = Path(args.run_folder if args.out is None else args.out)
    written = write_presentation(rows, ranges, table, out,
                                 source=f"{Path(args.run_folder).name}/closed_loop_episodes.csv")
    print(markdown(table, ranges))
    print("wrote " + ", ".join(str(w) for w in written))
    return 0
