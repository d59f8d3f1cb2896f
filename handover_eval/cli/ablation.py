"""The ``rl-ablation`` command of evaluate.py: issue 36's ablation table from RL runs and their
closed-loop evaluations (:mod:`handover_eval.rl.ablation`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

COMMAND = "rl-ablation"


def add_parser(sub: argparse._SubParsersAction) -> None:
    """The ``rl-ablation`` sub-command."""
    p = sub.add_parser(
        COMMAND,
        help="RL runs' learning curves beside their closed-loop evaluations (md/csv/png)",
        description="One line per training seed: the learning curve's start and end on the "
        "fixed training receivers, env steps/s and wall time (from the checkpoint folder, read "
        "through the safe loader), and from an `evaluate.py closed-loop --rl-checkpoint` run of "
        "it: success and handover time on the walkers and the replays, body contact over 50 N, "
        "robot jerk, premature releases, and the RL agent minus the run's reference agent paired "
        "on the same receivers; then per configuration the mean and IQM over seeds. Writes "
        "rl_ablation.md/.csv/.png into --out, and with --curves each configuration's learning "
        "curves (every seed and the IQM band).",
    )
    p.add_argument("--run", action="append", default=[], metavar="LABEL=RUN:EVAL",
                   help="one seed: its configuration's label, its train.py rl checkpoint folder "
                   "and the --out folder of its closed-loop evaluation; repeat for every seed "
                   "(seeds of one configuration share the label)")
    p.add_argument("--table", action="append", default=[], metavar="CSV",
                   help="an earlier rl_ablation.csv of this command whose rows join the table "
                   "(seeds trained in another session); a reference agent a --run evaluation "
                   "also ran must have the same scores there; repeatable. --run, --table or "
                   "both")
    p.add_argument("--curves", action="append", default=[], metavar="LABEL=FOLDER",
                   help="a folder of seed-S/train_log.csv files (a train.py rl --seeds output, "
                   "or the committed logs of docs/rl/LABEL): writes LABEL/learning_curves.png "
                   "(every seed and the IQM with its 95 %% stratified bootstrap band) and "
                   "LABEL/seeds_summary.json into --out; repeatable")
    p.add_argument("--references", nargs="+", default=["cv", "reactive"], metavar="AGENT",
                   help="agents shown as rows of their own, from the first evaluation that ran "
                   "them (default: cv reactive)")
    p.add_argument("--out", default="results/rl-ablation", metavar="DIR",
                   help="where to write rl_ablation.md/.csv/.png (default: results/rl-ablation)")


def main(args: argparse.Namespace) -> int:
    """Run the ``rl-ablation`` command; 2 with a one-line error on bad input."""
    from baselines.checkpoint_io import CheckpointError
    from handover_eval.rl.ablation import (
        parse_curves,
        parse_run,
        read_curves,
        run_ablation,
        seed_summary,
    )
    from handover_eval.rl.output import write_ablation
    from handover_eval.rl.report import ablation_markdown

    try:
        specs = [parse_run(t) for t in args.run]
        curve_specs = [parse_curves(t) for t in args.curves]
        rows, refs = run_ablation(specs, args.references, [Path(t) for t in args.table])
        summary = seed_summary(rows)
        curves = {label: read_curves(folder) for label, folder in curve_specs}
    except (ValueError, CheckpointError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    written = write_ablation(rows, refs, summary, Path(args.out), curves)
    print(ablation_markdown(rows, refs, summary))
    print("wrote " + ", ".join(str(w) for w in written))
    return 0
