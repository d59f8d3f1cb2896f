"""``evaluate.py user-study``: arguments and entry point (light imports until the run starts)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from handover_env.paths import output_folder
from handover_eval.backend import (
    JobError,
    session,
)
from handover_eval.cli.args import (
    ITERATIONS,
    PARTICIPANTS,
    SEEDS,
    WALKS,
    WORKERS,
    add_backend_arguments,
    add_sensing_argument,
    backend_from_args,
    int_in_range,
    theta_grid,
)
from handover_eval.output_lock import OutputLock

#: --quick: a seconds-long run for ``make test``; never for reported numbers.
QUICK = {"participants": 2, "trials": 2, "iterations": 2, "walks": 1, "grid": (3, 3, 3, 3)}


def add_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Register ``user-study`` on ``evaluate.py``'s subcommands."""
    from handover_eval.preference import study as user_study

    p = sub.add_parser(
        "user-study",
        help="the paper's user study (H1, H2, H3) and personalised Θ with simulated participants",
        description=user_study.__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--participants",
        type=int_in_range(2, PARTICIPANTS.high),
        default=8,
        help="simulated participants (paper: 8)",
    )
    p.add_argument("--trials", type=int_in_range(1, 1000), default=5,
                   help="handovers per condition and A/B tests per participant (paper: 5)")
    p.add_argument(
        "--iterations", type=ITERATIONS, default=20, help="CoSpar iterations (paper: 20)"
    )
    p.add_argument(
        "--walks", type=WALKS, default=3, help="tuning walks per proposed Θ (default 3)"
    )
    p.add_argument("--grid", type=theta_grid, default=(7, 6, 6, 7), metavar="NK,NB,NT,NF",
                   help="CoSpar grid points per parameter (default 7,6,6,7)")
    p.add_argument(
        "--seed",
        type=SEEDS,
        default=0,
        help="population, CoSpar and H3 seed (default 0)",
    )
    p.add_argument("--theta", type=float, nargs=4, default=None, metavar=("K", "B", "TF", "FR"),
                   help="use this population Θ̂ instead of running the pooled CoSpar")
    p.add_argument(
        "--no-personalised", action="store_true", help="skip the per-participant CoSpar comparison"
    )
    p.add_argument(
        "--out",
        default=None,
        metavar="DIR",
        help="output folder (default results/user-study, or results/user-study-quick with --quick)",
    )
    p.add_argument(
        "--quick",
        action="store_true",
        help="tiny run for tests: 2 participants, 2 trials, 2 "
        "iterations, 1 walk, a 3x3x3x3 grid; never for reported numbers",
    )
    p.add_argument("--no-progress", action="store_true", help="hide progress bars")
    p.add_argument(
        "--workers",
        type=WORKERS,
        default=1,
        metavar="N",
        help="processes running the per-participant CoSpar in parallel (default 1: in this "
        "process); with --backend ray it sizes the local Ray instance",
    )
    add_sensing_argument(p)
    add_backend_arguments(p)
    return p


def run(args: argparse.Namespace) -> int:
    """Run the study from parsed arguments; 0 on success, 2 with a one-line error on bad input."""
    from handover_eval.preference.study import StudyConfig, run_study
    from handover_eval.preference.study_report import write_report

    try:
        settings = {
            "participants": args.participants,
            "trials": args.trials,
            "iterations": args.iterations,
            "walks": args.walks,
            "grid": args.grid,
        }
        if args.quick:
            settings.update(QUICK)
        config = StudyConfig(
            **settings,
            seed=args.seed,
            theta=tuple(args.theta) if args.theta else None,
            personalised=not args.no_personalised,
            sensing=args.sensing,
            workers=args.workers,
        )
        backend = backend_from_args(args)
        out = (
            output_folder(args.out, "--out")
            if args.out is not None
            else Path("results") / ("user-study-quick" if args.quick else "user-study")
        )
        lock = OutputLock(out).acquire()
    except (ValueError, RuntimeError, OSError) as exc:
        print(f"evaluate.py: error: {exc}", file=sys.stderr)
        return 2
    try:
        with session(backend, config.workers) as sess:
            result = run_study(config, progress=not args.no_progress)
        write_report(result, out)
    except (JobError, ConnectionError) as exc:
        print(f"evaluate.py: error: {exc}", file=sys.stderr)
        return 1
    finally:
        lock.release()
    startup = f" (Ray start-up {sess.startup_s:.1f} s)" if sess.started_here else ""
    print(f"wrote {out}/ in {result.timings['total_s']:.0f} s{startup}")
    return 0
