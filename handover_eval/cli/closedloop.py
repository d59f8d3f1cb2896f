"""The ``closed-loop``, ``theta-sweep`` and ``sensing-sweep`` commands of evaluate.py: their flags
and their runs.

``evaluate.py`` keeps only the dispatch; the runs are
:func:`handover_eval.closedloop.run.run_closed_loop` and
:func:`handover_eval.closedloop.theta_sweep.run_sweep`; the files are written by
:mod:`handover_eval.closedloop.output`.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path

from handover_env.config import THETA_RANGES, HandoverParams
from handover_env.data.dataset import HandoverDataset
from handover_env.paths import output_folder
from handover_eval import roster
from handover_eval.backend import (
    JobError,
    session,
)
from handover_eval.cli.args import (
    EPOCHS,
    FOLDS,
    SEEDS,
    STEPS,
    WORKERS,
    add_backend_arguments,
    add_person_argument,
    add_sensing_argument,
    backend_from_args,
    check_counts,
    int_in_range,
    load_replay_data,
)
from handover_eval.closedloop.models import rl_forms
from handover_eval.closedloop.output import write_closed_loop, write_theta_sweep
from handover_eval.closedloop.run import ClosedLoopEvalConfig, ClosedLoopRun, run_closed_loop
from handover_eval.closedloop.stats import N_BOOTSTRAP
from handover_eval.methods import MethodOptions, default_workers, with_test_data
from handover_eval.output_lock import OutputLock
from handover_eval.receivers import SETS

COMMANDS = ("closed-loop", "theta-sweep", "sensing-sweep")
QUICK_WALKERS = 2
QUICK_REPLAYS = 3
QUICK_FOLDS = 3
THETA_HAT = HandoverParams()
#: Bounds of the integer options, checked after parsing (a one-line ``evaluate.py: error:``
#: naming the option, status 2); a sub-command without an option skips it.
COUNTS = {
    "--walkers": int_in_range(1, 10_000),
    "--values": int_in_range(2, 101),
    "--replay-folds": int_in_range(0, FOLDS.high - 1),
    "--replays-per-fold": int_in_range(0, 100_000),
    "--folds": FOLDS,
    "--seed": SEEDS,
    "--act-steps": STEPS,
    "--bc-epochs": EPOCHS,
    "--bootstrap": int_in_range(1, 1_000_000),
    "--workers": WORKERS,
}
CLOSED_LOOP_DESCRIPTION = (
    "Closed-loop handovers of every agent with the same scripted ID/OOD walkers and replayed "
    "held-out recordings (the simulated person): success with Wilson CIs, outcomes, handover time, "
    "transfer, forces, receiver effort, jerk, and paired bootstrap comparisons against the "
    "reactive agent. Writes closed_loop.md/.csv/.png, closed_loop_episodes.csv and "
    "closed_loop_paired.csv."
)
THETA_SWEEP_DESCRIPTION = (
    "Sweep each Θ parameter over its CoSpar range (the others at --theta, default Θ̂) for one "
    "agent on the same receivers at every value: every outcome per value with a bootstrap CI over "
    "receivers, and per parameter whether the extreme values differ beyond that noise (paired CI "
    "excluding 0). Writes theta_sweep.md/.csv/.png."
)


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Add the ``closed-loop`` and ``theta-sweep`` sub-commands to evaluate.py's parser."""
    p = sub.add_parser(
        "closed-loop",
        help="every agent hands the bottle to the same simulated receivers (md/csv/png)",
        description=CLOSED_LOOP_DESCRIPTION,
    )
    _common(p)
    p.add_argument(
        "--agents",
        nargs="+",
        default=None,
        metavar="NAME",
        help=f"agents, any of {list(roster.closedloop_agents())} (default: "
        f"{' '.join(roster.compared_agents())}; rl-residual / rl-scratch only with --quick or a "
        "--rl-checkpoint of their form). giver-replay meets replays only; static runs in "
        "StaticHandover-v0 on the same receivers",
    )
    p.add_argument(
        "--reference",
        default="reactive",
        metavar="NAME",
        help="the agent every other is paired against on the same receivers "
        "(closed_loop_paired.csv; default reactive; another must be among --agents)",
    )
    p.add_argument(
        "--sets",
        nargs="+",
        default=list(SETS),
        metavar="SET",
        help="receiver sets: id, ood (scripted walkers), replay (recordings) (default: all three)",
    )
    p.add_argument(
        "--walkers",
        type=int,
        default=None,
        metavar="N",
        help=f"scripted walkers per set, seeds 0..N-1 (ID) and 10000.. (OOD) (default: 50; "
        f"{QUICK_WALKERS} with --quick)",
    )
    p.add_argument(
        "--replay-data",
        default=None,
        metavar="PATH",
        help="recordings to replay that are not in --data (folder, .npz): the learning agents "
        "fit on all of --data and meet every episode of PATH (--replays-per-fold caps how many) "
        "instead of the held-out folds of --data",
    )
    p.add_argument(
        "--rerun",
        default=None,
        metavar="FILE.rrd",
        help="also log one episode for the Rerun viewer (`rerun FILE.rrd`): the first agent and "
        "its first receiver, run again as in the run (the person's skeleton and body, the TCP, "
        "the bottle, the wrist force, the outcome events); needs rerun-sdk (LeRobot installs it)",
    )
    p = sub.add_parser(
        "theta-sweep",
        help="sweep each of K, B, t_f, f_r over the paper's range (md/csv/png)",
        description=THETA_SWEEP_DESCRIPTION,
    )
    _common(p)
    p.add_argument(
        "--agent",
        default="ours",
        metavar="NAME",
        help="the agent swept (default: ours; reactive is the model-free check)",
    )
    p.add_argument(
        "--params",
        nargs="+",
        default=list(THETA_RANGES),
        metavar="NAME",
        help=f"parameters to sweep, any of {list(THETA_RANGES)} (default: all four)",
    )
    p.add_argument(
        "--values",
        type=int,
        default=None,
        metavar="N",
        help="values per parameter, evenly spaced over the paper's range, ends included "
        f"(ranges {THETA_RANGES}) (default: 5; 3 with --quick)",
    )
    p.add_argument(
        "--walkers",
        type=int,
        default=None,
        metavar="N",
        help=f"scripted walkers per set (ID, OOD), the same at every value (default: 20; "
        f"{QUICK_WALKERS} with --quick)",
    )
    add_sensing_parser(sub)


SENSING_SWEEP_DESCRIPTION = (
    "One factor at a time around the paper's sensor profile (docs/sensing.md): camera latency "
    "0-300 ms, wrist F/T noise 0-2x the UR5e datasheet, the constant-M vs Λ(q) controller; every "
    "agent on the same receivers at every point: success, handover time and premature releases, "
    "paired against the reactive agent. Writes sensing_sweep.md/.csv/.png."
)


def add_sensing_parser(sub: argparse._SubParsersAction) -> None:
    """The ``sensing-sweep`` sub-command (issue 24)."""
    from handover_eval.closedloop.sensing_sweep import AGENTS as SENSING_AGENTS
    from handover_eval.closedloop.sensing_sweep import FACTORS

    p = sub.add_parser(
        "sensing-sweep",
        help="camera latency, F/T noise and the controller's M, one at a time (md/csv/png)",
        description=SENSING_SWEEP_DESCRIPTION,
    )
    _common(p)
    p.add_argument(
        "--agents",
        nargs="+",
        default=list(SENSING_AGENTS),
        metavar="NAME",
        help=f"agents (default: {list(SENSING_AGENTS)}); reactive, the reference, always runs; "
        "giver-replay meets replays only (--replays-per-fold N)",
    )
    p.add_argument(
        "--factors",
        nargs="+",
        default=list(FACTORS),
        metavar="NAME",
        help=f"factors to sweep, any of {list(FACTORS)} (default: all three)",
    )
    p.add_argument(
        "--walkers",
        type=int,
        default=None,
        metavar="N",
        help=f"scripted walkers per set (ID, OOD), the same at every point (default: 20; "
        f"{QUICK_WALKERS} with --quick)",
    )


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--data",
        default=None,
        metavar="PATH",
        help="public-dataset folder (whole_motions/: replays drive the body with the recorded "
        "skeleton), canonical .npz (pelvis tracks only), or omit for the synthetic default",
    )
    p.add_argument(
        "--out",
        default=None,
        metavar="DIR",
        help="output folder (default: results/<command>, results/<command>-quick with --quick)",
    )
    p.add_argument(
        "--replay-folds",
        nargs="+",
        type=int,
        default=None,
        metavar="F",
        help="folds of Table I's split whose episodes are replayed (default: the held-out half, "
        "folds k//2..k-1 = 5-9 of 10, which the receiver was not calibrated on; 0 with --quick)",
    )
    p.add_argument(
        "--replays-per-fold",
        type=int,
        default=None,
        metavar="N",
        help="at most N replays per fold, spread evenly (default: all for closed-loop, none for "
        f"theta-sweep; {QUICK_REPLAYS} with --quick)",
    )
    p.add_argument(
        "--hand-mode",
        choices=("reach", "recorded"),
        default="reach",
        help="replays: the modelled reaching hand, or the recorded arm with a closing grasp "
        "(needs --data a folder of recordings) (default: reach)",
    )
    p.add_argument(
        "--theta",
        nargs=4,
        type=float,
        default=None,
        metavar=("K", "B", "TF", "FR"),
        help=f"Θ: stiffness N/m, damping N·s/m, forecast time s, release force N "
        f"(default: the paper's Θ̂ = {' '.join(f'{v:g}' for v in THETA_HAT.as_array())})",
    )
    p.add_argument(
        "--folds", type=int, default=10, help="k of Table I's stratified split (default: 10)"
    )
    p.add_argument(
        "--seed",
        type=int,
        default=0,
        help="seed of the split and of the learned baselines, as Table I (default: 0)",
    )
    p.add_argument(
        "--checkpoints",
        default=None,
        metavar="DIR",
        help="Table I's checkpoint cache: BC-MLP/ACT fold models are loaded from it, or trained "
        "into it when missing (default: results/table1/checkpoints, "
        "results/table1-quick/checkpoints with --quick)",
    )
    p.add_argument(
        "--act-steps",
        type=int,
        default=None,
        help="ACT optimisation steps of the fold models (default: Table I's; must match the "
        "checkpoints to reuse them)",
    )
    p.add_argument(
        "--bc-epochs", type=int, default=None, help="BC-MLP maximum epochs (default: Table I's)"
    )
    p.add_argument(
        "--rl-checkpoint",
        nargs="+",
        default=None,
        metavar="DIR",
        help="checkpoint folders of train.py rl for the rl-residual / rl-scratch agents (each "
        "matched by its policy form; with --quick a missing one is trained for a few hundred "
        "steps into the checkpoint cache)",
    )
    p.add_argument(
        "--bootstrap",
        type=int,
        default=N_BOOTSTRAP,
        metavar="N",
        help=f"bootstrap resamples of the CIs, seeded (default: {N_BOOTSTRAP})",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=None,
        metavar="N",
        help="processes running the episodes, each with its own envs and fold models (default: "
        "one per core, at most 2; 1 runs in this process); the results do not depend on it",
    )
    p.add_argument(
        "--quick",
        action="store_true",
        help=f"small fast run for tests: synthetic data, {QUICK_FOLDS} folds, {QUICK_WALKERS} "
        f"walkers per set, {QUICK_REPLAYS} replays of fold 0, tiny ACT/BC-MLP budgets; "
        "never for reported numbers",
    )
    p.add_argument("--no-progress", action="store_true", help="hide progress bars")
    if p.prog.split()[-1] != "sensing-sweep":  # the sensing sweep varies the paper profile
        add_sensing_argument(p)
    add_person_argument(p)
    add_backend_arguments(p)


def _params(theta: list[float] | None) -> HandoverParams:
    if theta is None:
        return THETA_HAT
    params = HandoverParams(*theta)
    outside = [
        n
        for n, v in zip(THETA_RANGES, params.as_array(), strict=True)
        if not THETA_RANGES[n][0] <= v <= THETA_RANGES[n][1]
    ]
    if outside:
        print(f"note: --theta {outside} outside the paper's ranges {THETA_RANGES}", file=sys.stderr)
    return params


def main(args: argparse.Namespace, load_dataset: Callable) -> int:
    """Run ``args.command`` (closed-loop or theta-sweep); 2 with a one-line error on bad input."""
    try:
        workers = default_workers() if args.workers is None else args.workers
        options = MethodOptions(
            seed=args.seed,
            quick=args.quick,
            act_steps=args.act_steps,
            bc_epochs=args.bc_epochs,
            workers=workers,
            rl_checkpoints=tuple(str(Path(d))
                                 for d in args.rl_checkpoint or ()),
        )
        check_counts(args, COUNTS)
        quick = args.quick
        replay_folds = tuple(args.replay_folds) if args.replay_folds else ((0,) if quick else None)
        per_fold = (
            args.replays_per_fold
            if args.replays_per_fold is not None
            else (QUICK_REPLAYS if quick and getattr(args, "replay_data", None) is None else None)
        )  # --replay-data: every episode of it, unless capped
        receivers = ClosedLoopEvalConfig(
            agents=tuple(
                roster.default_agents(args.quick, rl_forms(options.rl_checkpoints))
                if getattr(args, "agents", ["reactive"]) is None
                else getattr(args, "agents", ["reactive"])
            ),
            sets=tuple(getattr(args, "sets", SETS)),
            walkers=args.walkers
            if args.walkers is not None
            else (QUICK_WALKERS if quick else (50 if args.command == "closed-loop" else 20)),
            replay_folds=replay_folds,
            replays_per_fold=per_fold,
            hand_mode=args.hand_mode,
            params=_params(args.theta),
            folds=QUICK_FOLDS if quick else args.folds,
            seed=args.seed,
            workers=workers,
            sensing=getattr(args, "sensing", "paper"),
            person=tuple(args.person),
            reference=getattr(args, "reference", "reactive"),
        )
        sweep = None
        if args.command == "sensing-sweep":
            from handover_eval.closedloop.sensing_sweep import SensingSweepConfig

            sweep = SensingSweepConfig(
                agents=tuple(args.agents),
                factors=tuple(args.factors),
                walkers=receivers.walkers,
                replays_per_fold=per_fold or 0,  # --quick: a few replays, for giver-replay
                receivers=dataclasses.replace(receivers, agents=("reactive",)),
            )
        if args.command == "theta-sweep":
            from handover_eval.closedloop.theta_sweep import SweepConfig

            sweep = SweepConfig(
                agent=args.agent,
                params=tuple(args.params),
                values=args.values if args.values is not None else (3 if quick else 5),
                walkers=receivers.walkers,
                replays_per_fold=args.replays_per_fold or 0,
                receivers=receivers,
            )
        out = (
            output_folder(args.out, "--out")
            if args.out is not None
            else Path("results") / (args.command + ("-quick" if quick else ""))
        )
        cache = (  # shared with table1 and written one model at a time: checked, not locked
            output_folder(args.checkpoints, "--checkpoints")
            if args.checkpoints is not None
            else Path("results") / ("table1-quick" if quick else "table1") / "checkpoints"
        )
        if getattr(args, "rerun", None) is not None:
            from handover_eval.rerun_log import check_rerun_path

            args.rerun = check_rerun_path(args.rerun)
        backend = backend_from_args(args)
        lock = OutputLock(out).acquire()  # held until the last file is written
    except (ValueError, OSError, RuntimeError) as exc:
        print(f"evaluate.py: error: {exc}", file=sys.stderr)
        return 2
    try:
        return _run(args, load_dataset, receivers, sweep, options, backend, out, cache)
    finally:
        lock.release()


def _run(args, load_dataset, receivers, sweep, options, backend, out: Path, cache: Path) -> int:
    """The closed-loop run or Θ sweep into the locked folder ``out``; the exit status."""
    replay_data = getattr(args, "replay_data", None)
    try:
        dataset = load_dataset(args.data, args.quick, args.seed, not args.no_progress)
        replay = load_replay_data(load_dataset, replay_data, args.quick, args.seed,
                                  not args.no_progress)
    except (ValueError, OSError, RuntimeError) as exc:
        print(f"evaluate.py: error: {exc}", file=sys.stderr)
        return 2
    progress = not args.no_progress
    start = time.perf_counter()
    print(
        f"{args.command}: {dataset.name} ({len(dataset)} episodes), "
        f"Θ = {receivers.params.as_array()}, {receivers.workers} worker(s), {os.cpu_count()} cores",
        flush=True,
    )
    try:
        with session(backend, receivers.workers) as sess:
            if args.command == "sensing-sweep":
                from handover_eval.closedloop.sensing_sweep import (
                    run_sensing_sweep,
                    write_sensing_sweep,
                )

                swept = run_sensing_sweep(sweep, dataset, args.data, options, cache, progress)
                write_sensing_sweep(
                    swept, sweep, dataset, out, args.bootstrap, args.seed, args.quick
                )
            elif sweep is None:
                run = run_closed_loop(
                    receivers, dataset, args.data, options, cache, progress, replay, replay_data
                )
                shown = dataset if replay is None else with_test_data(dataset, replay)
                write_closed_loop(
                    run, receivers, shown, out, args.bootstrap, args.seed, args.quick
                )
                if getattr(args, "rerun", None) is not None:
                    _rerun(args.rerun, receivers, run, shown, options, cache, replay is not None)
            else:
                from handover_eval.closedloop.theta_sweep import run_sweep

                swept = run_sweep(sweep, dataset, args.data, options, cache, progress)
                write_theta_sweep(swept, sweep, dataset, out, args.bootstrap, args.seed, args.quick)
    except ValueError as exc:
        print(f"evaluate.py: error: {exc}", file=sys.stderr)
        return 2
    except (JobError, ConnectionError) as exc:
        print(f"evaluate.py: error: {exc}", file=sys.stderr)
        return 1
    startup = f" (Ray start-up {sess.startup_s:.1f} s)" if sess.started_here else ""
    print(f"wrote {out}/ in {time.perf_counter() - start:.0f} s{startup}")
    return 0


def _rerun(path: Path, config: ClosedLoopEvalConfig, run: ClosedLoopRun,
           dataset: HandoverDataset, options: MethodOptions, cache: Path, fit_all: bool) -> None:
    """``--rerun``: the first agent's episode with its first receiver, logged to ``path``."""
    from handover_eval.rerun_log import first_job, log_job

    job = first_job(config, run.receivers, dataset, options, cache, fit_all)
    row = log_job(dataset, job, path)
    print(f"wrote {path}: {row['agent']} meets {row['set']} {row['receiver']} "
          f"(seed {row['seed']}): {row['outcome']}")
