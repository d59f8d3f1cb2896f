"""Reproduce the paper's simulation results (Kim et al., ICRA 2025, Sec. V-A) with one command each.

    python evaluate.py table1 --data PATH --folds 10 --seed 0     # Table I: RMS (mm), ID / OOD
    python evaluate.py sample-efficiency --data PATH              # RMS vs training-data ratio
    python evaluate.py tradeoff --data PATH                       # RMS vs per-frame inference time
    python evaluate.py closed-loop --data PATH                    # every agent with the simulated
    person
    python evaluate.py theta-sweep --data PATH                    # does each of K, B, t_f, f_r
    matter?
    python evaluate.py user-study --participants 8 --trials 5     # H1-H3 with simulated
    participants
    python evaluate.py benchmark --agent my_agent.py:make_agent   # score your agent
    python evaluate.py leaderboard a/result.json b/result.json    # ranked table + PNG
    python evaluate.py rescore a/closedloop_episodes.csv          # rebuild the tables, no episode

PATH is a folder of the public dataset's pickles (``whole_motions/``), a canonical ``.npz``, or
omitted for the embedded synthetic default. Every method is scored by the same open-loop protocol
(``handover_eval/openloop/protocol.py``, summarised in docs/results.md). Results go to ``--out``
(default ``results/<command>/``): Markdown and CSV tables, per-fold and per-episode CSVs, PNG plots.
A running command locks its ``--out`` (``handover_eval.output_lock``): a second run is refused.
Trained BC-MLP / ACT checkpoints are kept under ``<out>/checkpoints`` and reused when the method
configuration and the training set match (``--no-reuse`` retrains); closed-loop and theta-sweep
reuse Table I's (``--checkpoints``, default ``results/table1/checkpoints``).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from handover_env.offline import hub_offline
from handover_env.paths import output_folder
from handover_eval.backend import (
    JobError,
    session,
)
from handover_eval.cli import ablation, benchmark, closedloop, presentation, user_study
from handover_eval.cli.args import (
    EPOCHS,
    FOLDS,
    FRAMES,
    SEEDS,
    STEPS,
    WORKERS,
    add_backend_arguments,
    backend_from_args,
    check_counts,
    int_in_range,
    load_replay_data,
)
from handover_eval.methods import (
    ACT_EVAL_STEPS,
    METHODS,
    QUICK_ACT_STEPS,
    MethodOptions,
    check_methods,
    default_workers,
)
from handover_eval.output_lock import OutputLock

QUICK_EPISODES = 30
#: Bounds of the integer options of table1, sample-efficiency and tradeoff, checked after parsing
#: (a one-line ``evaluate.py: error:`` naming the option, status 2).
COUNTS = {
    "--folds": FOLDS,
    "--seed": SEEDS,
    "--horizon": FRAMES,
    "--stride": FRAMES,
    "--first-query": int_in_range(0, FRAMES.high),
    "--act-steps": STEPS,
    "--bc-epochs": EPOCHS,
    "--workers": WORKERS,
    "--timing-episodes": int_in_range(1, 100_000),
}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="evaluate.py",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def common(
        p: argparse.ArgumentParser, default_methods: tuple[str, ...], default_folds: int
    ) -> None:
        p.add_argument(
            "--data",
            default=None,
            metavar="PATH",
            help="public-dataset folder (whole_motions/), canonical .npz, or omit for the "
                 "synthetic default",
        )
        p.add_argument(
            "--out",
            default=None,
            metavar="DIR",
            help="output folder (default: results/<command>, or results/<command>-quick with "
                 "--quick)",
        )
        p.add_argument(
            "--methods",
            nargs="+",
            default=list(default_methods),
            metavar="NAME",
            help=f"methods to run, any of {list(METHODS)} (default: {' '.join(default_methods)})",
        )
        p.add_argument("--folds", type=int, default=default_folds,
                       help=f"k of the stratified (ID/OOD) k-fold split (default: {default_folds})")
        p.add_argument(
            "--seed",
            type=int,
            default=0,
            help="seed of the fold split and of the learned baselines",
        )
        p.add_argument(
            "--horizon",
            type=int,
            default=30,
            help="predicted frames per query, 30 = 1 s (default: 30)",
        )
        p.add_argument(
            "--stride",
            type=int,
            default=1,
            help="frames between open-loop queries (default: 1 = every frame)",
        )
        p.add_argument("--first-query", type=int, default=5,
                       help="frames of receiver history before the first query (default: 5)")
        p.add_argument("--inducing-ratio", type=float, default=0.4,
                       help="SPGP inducing ratio of 'ours' (paper: 0.4)")
        p.add_argument(
            "--act-steps",
            type=int,
            default=None,
            help=f"ACT optimisation steps (default: {ACT_EVAL_STEPS} for the k-fold evaluations, "
            f"{QUICK_ACT_STEPS} with --quick; train.py keeps the agent's own 8000)",
        )
        p.add_argument(
            "--bc-epochs",
            type=int,
            default=None,
            help="BC-MLP maximum epochs (default: the BC-MLP agent's)",
        )
        p.add_argument(
            "--giver-state",
            action="store_true",
            help="also give BC-MLP and ACT the giver's position at the query frame "
                 "(observation.state); "
            "off by default, as in the paper, where every module sees the receiver base pose only",
        )
        p.add_argument(
            "--workers",
            type=int,
            default=None,
            metavar="N",
            help="processes that train ACT's fold models, and then run the folds (table1) or "
            "the fold x ratio cells (sample-efficiency) or the variant x fold fits (tradeoff), "
            "in parallel, one torch thread each (default: one per core, at most 2; 1 runs "
            "everything in this process; with --backend ray it sizes the local Ray instance); "
            "the results do not depend on it. tradeoff then times each variant on one core",
        )
        p.add_argument(
            "--no-reuse",
            action="store_true",
            help="retrain BC-MLP/ACT even if a matching checkpoint exists",
        )
        p.add_argument(
            "--quick",
            action="store_true",
            help=f"small fast run for tests: {QUICK_EPISODES} episodes, 3 folds, query stride 3, "
            "tiny training budgets; never for reported numbers",
        )
        p.add_argument("--no-progress", action="store_true", help="hide progress bars")
        add_backend_arguments(p)

    p = sub.add_parser(
        "table1",
        help="Table I: stratified k-fold RMS of every method, ID and OOD",
        description="Stratified k-fold open-loop RMS (mm) of BC-MLP, ACT, IAAL and ours; writes "
        "table1.md (with the paper's numbers beside ours), table1.csv, per-fold and "
        "per-episode CSVs.",
    )
    common(p, METHODS, 10)
    p.add_argument(
        "--replay-data",
        default=None,
        metavar="PATH",
        help="recordings to score on that are not in --data (folder, .npz): every method fits "
        "on all of --data and is scored on every episode of PATH, instead of the k-fold split",
    )
    p = sub.add_parser(
        "sample-efficiency",
        help="RMS vs training-data ratio (PNG + CSV)",
        description="For each fold and data ratio, train on that stratified fraction of the "
        "training folds and score the test fold; writes sample_efficiency.png/.csv.",
    )
    common(p, METHODS, 5)
    p.add_argument("--ratios", nargs="+", type=float, default=[0.1, 0.25, 0.5, 0.75, 1.0],
                   help="training-data ratios in (0, 1] (default: 0.1 0.25 0.5 0.75 1.0)")
    p = sub.add_parser(
        "tradeoff",
        help="RMS vs per-frame inference time, ours at several inducing rates and IAAL",
        description="k-fold RMS and the median per-frame streaming cost (update + predict, one "
        "core, same run) of ours at each inducing rate and of IAAL; tradeoff.png/.csv.",
    )
    common(p, ("ours", "iaal"), 10)
    p.add_argument(
        "--rates",
        nargs="+",
        type=float,
        default=[0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0],
        help="inducing rates of ours (default: 0.1 to 1.0 in steps of 0.1)",
    )
    p.add_argument("--timing-episodes", type=int, default=20,
                   help="test episodes streamed frame by frame to time each variant (default: 20)")
    closedloop.add_parsers(sub)
    presentation.add_parser(sub)
    ablation.add_parser(sub)
    user_study.add_parser(sub)
    benchmark.add_parsers(sub)
    return parser


def load_dataset(path: str | None, quick: bool, seed: int, progress: bool = True):
    """``--data``: the synthetic default (with --quick), a canonical .npz or a public-dataset folder
    (``progress``: its loading bar)."""
    from handover_env.person.demos import load_any
    from handover_env.person.synthetic import generate_synthetic

    if path is not None and not Path(path).exists():
        raise FileNotFoundError(f"--data {path}: no such file or folder")
    if path is None and quick:
        return generate_synthetic(n=QUICK_EPISODES, ood_fraction=0.2, seed=seed)
    data = load_any(path, progress=progress)
    if quick and len(data) > QUICK_EPISODES:
        from handover_env.data.dataset import HandoverDataset

        mask = data.ood_mask
        n_ood = min(int(mask.sum()), QUICK_EPISODES // 5)
        import numpy as np

        idx = np.concatenate(
            [np.flatnonzero(~mask)[: QUICK_EPISODES - n_ood], np.flatnonzero(mask)[:n_ood]]
        )
        data = HandoverDataset(
            [data[i] for i in np.sort(idx)], rate_hz=data.rate_hz, name=data.name + " (quick)"
        )
    return data


def main(argv: list[str] | None = None) -> int:
    hub_offline()
    args = build_parser().parse_args(argv)
    if args.command in closedloop.COMMANDS:
        return closedloop.main(args, load_dataset)
    if args.command == presentation.COMMAND:
        return presentation.main(args)
    if args.command == ablation.COMMAND:
        return ablation.main(args)
    if args.command == "user-study":
        return user_study.run(args)
    if args.command in benchmark.COMMANDS:
        return benchmark.main(args, load_dataset)
    from handover_eval.openloop.protocol import OpenLoopProtocol

    try:
        methods = check_methods(args.methods)
        if args.command == "tradeoff" and not set(methods) <= {"ours", "iaal"}:
            raise ValueError(
                "tradeoff compares the nonparametric methods only: --methods ours [iaal]"
            )
        folds, stride = (3, max(3, args.stride)) if args.quick else (args.folds, args.stride)
        protocol = OpenLoopProtocol(
            horizon=args.horizon, first_query=args.first_query, stride=stride
        )
        options = MethodOptions(
            seed=args.seed,
            quick=args.quick,
            inducing_ratio=args.inducing_ratio,
            act_steps=args.act_steps,
            bc_epochs=args.bc_epochs,
            horizon=args.horizon,
            giver_state=args.giver_state,
            workers=default_workers() if args.workers is None else args.workers,
        )
        check_counts(args, COUNTS)
        out = (
            output_folder(args.out, "--out")
            if args.out is not None
            else Path("results") / (args.command + ("-quick" if args.quick else ""))
        )
        backend = backend_from_args(args)
        lock = OutputLock(out).acquire()  # held until the last file is written
    except (ValueError, OSError, RuntimeError) as exc:
        print(f"evaluate.py: error: {exc}", file=sys.stderr)
        return 2
    try:
        return _run_open_loop(args, methods, folds, protocol, options, out, backend)
    finally:
        lock.release()


def _run_open_loop(args, methods, folds, protocol, options, out: Path, backend) -> int:
    """table1, sample-efficiency or tradeoff into the locked folder ``out``; the exit status."""
    from handover_eval.openloop import experiments, output, report

    replay_path = getattr(args, "replay_data", None)
    try:
        dataset = load_dataset(args.data, args.quick, args.seed, not args.no_progress)
        test_data = load_replay_data(load_dataset, replay_path, args.quick, args.seed,
                                     not args.no_progress)
    except (ValueError, OSError, RuntimeError) as exc:
        print(f"evaluate.py: error: {exc}", file=sys.stderr)
        return 2
    progress = not args.no_progress
    n_ood = int(dataset.ood_mask.sum())
    print(
        f"{args.command}: {len(dataset) - n_ood} ID + {n_ood} OOD episodes ({dataset.name}), "
        f"{folds} folds, "
        f"methods {methods}, {os.cpu_count()} cores",
        flush=True,
    )
    start = time.perf_counter()
    try:
        with session(backend, options.workers) as sess:
            if args.command == "table1":
                run = experiments.run_table1(
                    dataset,
                    methods,
                    folds,
                    args.seed,
                    options,
                    protocol,
                    out,
                    reuse=not args.no_reuse,
                    progress=progress,
                    test_data=test_data,
                )
                output.write_table1(
                    run, dataset, folds, args.seed, protocol, options.giver_state, out, test_data
                )
                print("\n" + report.table1_summary(run.rows))
            elif args.command == "sample-efficiency":
                run = experiments.run_sample_efficiency(
                    dataset,
                    methods,
                    args.ratios,
                    folds,
                    args.seed,
                    options,
                    protocol,
                    out,
                    reuse=not args.no_reuse,
                    progress=progress,
                )
                output.write_sample_efficiency(run, methods, out)
                print("\n" + report.sample_efficiency_summary(run.rows))
                line = report.degradation_line(run.rows, args.ratios)
                if line:
                    print(line)
            else:
                rates = args.rates if "ours" in methods else []
                run = experiments.run_tradeoff(
                    dataset,
                    rates,
                    folds,
                    args.seed,
                    options,
                    protocol,
                    out,
                    timing_episodes=args.timing_episodes,
                    include_iaal="iaal" in methods,
                    progress=progress,
                )
                output.write_tradeoff(run, out)
                print("\n" + report.tradeoff_summary(run.rows))
                print(f"timed on 1 core of {os.cpu_count()}")
    except ValueError as exc:
        print(f"evaluate.py: error: {exc}", file=sys.stderr)
        return 2
    except (
        JobError,
        ConnectionError,
    ) as exc:  # failed jobs named; or no Ray cluster at the address
        print(f"evaluate.py: error: {exc}", file=sys.stderr)
        return 1
    startup = f" (Ray start-up {sess.startup_s:.1f} s)" if sess.started_here else ""
    print(f"wrote {out}/ in {time.perf_counter() - start:.0f} s{startup}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
