"""Command line for handover datasets: ``handover-data <command> ...`` (also
``python -m handover_eval.cli.data``).

Commands (each has ``--help``)::

    info PATH                          counts, frames and distributions of a dataset
    convert PUBLIC_DIR OUT.npz         public-dataset pickles -> canonical .npz (safe loader)
    synth [--n --ood-fraction --seed] OUT.npz
                                       synthetic demonstrations (the embedded default generator)
    compare A B                        two datasets side by side: medians, relative difference, KS
    export-lerobot DATASET ROOT        canonical dataset -> local LeRobotDataset (no network)
    plot DATASET OUT.png               top-down receiver and giver paths, ID and OOD
    transfer-stats PUBLIC_DIR --out DIR
                                       receiver calibration: when/where the object changes hands
    sensing PUBLIC_DIR [--limit N]     camera-model figures: jitter, hand error, re-fit bursts
    walk-stats PUBLIC_DIR --out DIR    walker calibration: scripted vs recorded walk statistics
    reach-spread PUBLIC_DIR --out DIR  the reach: the giver's part and the per-person offsets
    calibrated-range PUBLIC_DIR --out DIR
                                       the walks the person was calibrated on (speed, height, ...)
    grasp-height PUBLIC_DIR --out DIR  the recorded arm at the transfer: hand below the object,
                                       the elbow's swivel direction

The module is over 500 lines because it holds the one parser of the twelve subcommands and a
short handler for each (argparse lives only in ``cli/``).

Wherever a dataset is read, PATH may be a ``.npz``, a public-dataset folder, or ``synthetic``
for the embedded default (900 ID + 100 OOD, seed 0).

The argument types are :mod:`handover_eval.cli.args`'s; the calibration commands
(``transfer-stats``, ``sensing``, ``walk-stats``, ``reach-spread``, ``calibrated-range``,
``grasp-height``) run :mod:`handover_eval.calibration`, whose files go through
:mod:`handover_eval.reporting`'s writers. A dataset file is written by its format's own writer
(:meth:`HandoverDataset.save`), a LeRobot export by LeRobot's, a plot by
:func:`handover_env.data.plot.plot_paths` (PNG, PDF or SVG).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from handover_env.data.dataset import HandoverDataset
from handover_env.data.errors import DatasetError
from handover_env.data.limits import MAX_EPISODES
from handover_env.offline import hub_offline
from handover_eval.cli.args import FOLDS, FRAMES, SEEDS, closed_fraction, int_in_range

DEFAULT_KEYWORD = "synthetic"
#: Episodes (synthesised, drawn, or read per kind with --limit): as many as a dataset may hold.
EPISODES = int_in_range(1, MAX_EPISODES)
#: The Table I folds that form the calibration half (the rest are held out).
CALIBRATION_FOLDS = int_in_range(1, FOLDS.high - 1)
#: Scripted walkers per kind of walk-stats.
WALKERS = int_in_range(1, 100_000)


def _load(path: str, skip_bad: bool = False) -> HandoverDataset:
    from handover_env.data.public import LoadReport, load_public_dataset
    from handover_env.person.demos import load_any

    if path == DEFAULT_KEYWORD and not Path(path).exists():
        return load_any(None)
    if Path(path).is_dir():
        report = LoadReport()
        dataset = load_public_dataset(
            path, skip_bad=skip_bad, progress=True, report=report, on_skip=lambda *_: None
        )
        if report.skipped:
            print(report.summary(), file=sys.stderr)
        return dataset
    return load_any(path)


def _header(dataset: HandoverDataset) -> str:
    n_ood = int(dataset.ood_mask.sum())
    lengths = dataset.lengths
    return (
        f"{dataset.name or 'dataset'}\n"
        f"episodes: {len(dataset)} ({len(dataset) - n_ood} ID, {n_ood} OOD)\n"
        f"frames: {dataset.n_frames:,} at {dataset.rate_hz:g} Hz "
        f"(per episode {lengths.min()} .. {lengths.max()}, median "
        f"{int(sorted(lengths)[len(lengths) // 2])})"
    )


def cmd_info(args: argparse.Namespace) -> int:
    from handover_env.data.stats import episode_statistics, format_distribution

    dataset = _load(args.path, args.skip_bad)
    print(_header(dataset))
    print()
    print(format_distribution(episode_statistics(dataset)))
    return 0


def _check_npz_output(out: str) -> None:
    """Refuse an output that cannot become a dataset file, before any work is done."""
    path = Path(out)
    if path.suffix != ".npz":
        raise ValueError(f"{out}: dataset files end in .npz")
    if path.is_dir() or (path.exists() and not path.is_file()):
        raise DatasetError(f"{out}: exists and is not a file (a folder?); choose a file name")


def cmd_convert(args: argparse.Namespace) -> int:
    from handover_env.data.public import LoadReport, load_public_dataset

    _check_npz_output(args.out)
    start = time.perf_counter()
    report = LoadReport()
    dataset = load_public_dataset(
        args.public_dir,
        skip_bad=args.skip_bad,
        progress=True,
        report=report,
        on_skip=lambda *_: None,
    )
    out = dataset.save(args.out)
    print(report.summary())
    print(_header(dataset))
    print(f"wrote {out} in {time.perf_counter() - start:.1f} s")
    return 0


def cmd_synth(args: argparse.Namespace) -> int:
    from handover_env.person.synthetic import generate_synthetic

    _check_npz_output(args.out)
    start = time.perf_counter()
    dataset = generate_synthetic(args.n, args.ood_fraction, args.seed, progress=True)
    out = dataset.save(args.out)
    print(_header(dataset))
    print(f"wrote {out} in {time.perf_counter() - start:.1f} s")
    return 0


def cmd_compare(args: argparse.Namespace) -> int:
    from handover_env.data.stats import compare_statistics, episode_statistics, format_comparison

    a, b = _load(args.a), _load(args.b)
    sa, sb = episode_statistics(a), episode_statistics(b)
    print(f"A: {_header(a)}\n\nB: {_header(b)}\n")
    compared = 0
    for subset in args.subset:
        print(f"[{subset} episodes]")
        empty = [label for label, s in (("A", sa), ("B", sb)) if not _count(s, subset)]
        if empty:
            print(
                f"nothing to compare: {' and '.join(empty)} {'has' if len(empty) == 1 else 'have'} "
                f"no {subset.upper()} episodes\n"
            )
            continue
        print(format_comparison(compare_statistics(sa, sb, subset), "A", "B"))
        print()
        compared += 1
    if not compared:
        raise DatasetError(f"no subset of {args.subset} has episodes on both sides")
    return 0


def _count(stats: dict, subset: str) -> int:
    """Episodes of ``subset`` ("all", "id" or "ood") in per-episode statistics."""
    ood = stats["is_ood"]
    return int(ood.size if subset == "all" else (ood.sum() if subset == "ood" else (~ood).sum()))


def cmd_export_lerobot(args: argparse.Namespace) -> int:
    from handover_env.paths import check_replaceable_root

    # before loading anything: "", ".", "/", home are refused; "~" is expanded here, once, and
    # this path is the one checked and written
    root = check_replaceable_root(args.root)
    source = os.path.expanduser(args.dataset)
    inputs = [source] if Path(source).exists() else []
    try:
        from handover_env.data.lerobot_export import check_overwrite, export_lerobot
    except ImportError as exc:
        raise DatasetError(
            f"the LeRobot export is not available ({exc}); it lives in "
            "handover_env/data/lerobot_export.py"
        ) from exc
    check_overwrite(root, args.overwrite, inputs)  # refused before the dataset is read
    dataset = _load(source)
    start = time.perf_counter()
    root = export_lerobot(
        dataset,
        root,
        repo_id=args.repo_id,
        history=args.history,
        horizon=args.horizon,
        overwrite=args.overwrite,
        progress=True,
        inputs=inputs,
    )
    print(
        f"exported {len(dataset)} episodes ({dataset.n_frames:,} frames) to {root} "
        f"as {args.repo_id!r} in {time.perf_counter() - start:.1f} s"
    )
    return 0


def cmd_plot(args: argparse.Namespace) -> int:
    from handover_env.data.plot import check_figure_path, plot_paths

    check_figure_path(args.out)
    dataset = _load(args.dataset)
    out = plot_paths(dataset, args.out, max_episodes=args.max_episodes, seed=args.seed)
    print(f"wrote {out}")
    return 0


def cmd_transfer_stats(args: argparse.Namespace) -> int:
    from handover_eval.calibration.report import run_transfer_stats

    start = time.perf_counter()
    summary, written = run_transfer_stats(
        args.public_dir,
        args.out,
        folds=args.folds,
        seed=args.seed,
        calibration_folds=args.calibration_folds,
        skip_bad=args.skip_bad,
        figures=not args.no_figures,
        limit=args.limit,
    )
    d = summary["detection"]["all/all"]
    print(
        f"{d['recordings']} recordings: transfer {d['transfer']}, reach onset {d['onset']}, "
        f"giver release {d['release']}; no transfer: {d['no_transfer'] or 'none'}"
    )
    for path in written:
        print(f"wrote {path}")
    print(f"done in {time.perf_counter() - start:.1f} s")
    return 0


def cmd_sensing(args: argparse.Namespace) -> int:
    from handover_eval.calibration.sensing import format_figures, sensing_figures

    print(format_figures(sensing_figures(args.public_dir, limit=args.limit)))
    return 0


def cmd_walk_stats(args: argparse.Namespace) -> int:
    from handover_eval.calibration.walks_report import run_walk_stats

    summary, written = run_walk_stats(args.public_dir, args.out, walkers=args.walkers,
                                      skip_bad=args.skip_bad, figures=not args.no_figures)
    bad = [r["statistic"] for r in summary["table"] if r["chosen"] and not r["within"]]
    print(f"{summary['recordings']} recordings, {args.walkers} walkers per kind; chosen "
          f"statistics outside 20 %: {bad or 'none'}")
    for path in written:
        print(f"wrote {path}")
    return 0


def cmd_reach_spread(args: argparse.Namespace) -> int:
    from handover_eval.calibration.reach_spread import run_reach_spread

    summary, written = run_reach_spread(
        args.public_dir, args.out, folds=args.folds, seed=args.seed,
        calibration_folds=args.calibration_folds, skip_bad=args.skip_bad,
        figures=not args.no_figures,
    )
    line, off, held = summary["line"], summary["offset"], summary["held_out"]["all"]
    print(f"line (calibration, n = {line['n']}): reach = {line['intercept']:.3f} + "
          f"{line['slope']:.3f} x closest; offset SD {off['sd']:.3f} m "
          f"({off['distribution']}); held out (n = {held['n']}): r = {held.get('r', 'nan'):.2f}, "
          f"RMSE {held.get('rmse', 'nan'):.3f} m")
    for path in written:
        print(f"wrote {path}")
    return 0


def cmd_calibrated_range(args: argparse.Namespace) -> int:
    from handover_eval.calibration.calibrated_range import run_calibrated_range

    summary, written = run_calibrated_range(
        args.public_dir, args.out, folds=args.folds, seed=args.seed,
        calibration_folds=args.calibration_folds, skip_bad=args.skip_bad,
    )
    for name, (lo, hi) in summary["range"].items():
        print(f"{name}: {lo:.3f} .. {hi:.3f} {summary['fields'][name]['unit']}")
    for path in written:
        print(f"wrote {path}")
    return 0


def cmd_grasp_height(args: argparse.Namespace) -> int:
    from handover_eval.calibration.grasp_height import JOINT_NAMES, SHORT
    from handover_eval.calibration.grasp_height_report import run_grasp_height

    def num(x: float | None) -> str:
        return "–" if x is None else f"{x:.3f}"

    def vec(v: Sequence[float] | None) -> str:
        return "–" if v is None else "(" + ", ".join(f"{x:+.3f}" for x in v) + ")"

    summary, written = run_grasp_height(
        args.public_dir, args.out, folds=args.folds, seed=args.seed,
        calibration_folds=args.calibration_folds, skip_bad=args.skip_bad,
    )
    for half in ("calibration", "held_out"):
        group = f"{half}/all"
        joints = "; ".join(
            f"{SHORT[j]} {100 * (v['share_below'] or 0):.1f} % (median {v['p50']:+.3f} m)"
            for j in JOINT_NAMES for v in (summary["height"][j][group],))
        fore = summary["forearm_elevation"][group]
        print(f"{half.replace('_', '-')} (n = {summary['detection'][group]['transfer']}): below "
              f"the object's centre: {joints}; forearm elevation median {fore['p50']:.1f} deg")
        pole = summary["elbow_pole"][half]["pooled"]
        print(f"  elbow swivel direction (forward, left, up; n = {pole['n']}, skipped "
              f"{sum(pole['skipped'].values())}): normalised mean {vec(pole['direction'])}, "
              f"R = {num(pole['resultant_length'])}, median {vec(pole['median'])}; "
              f"shoulder-to-wrist median {vec(pole['shoulder_to_wrist_median'])}, "
              f"{num(pole['shoulder_to_wrist_distance_median'])} m")
    for name, why in summary["skipped"]:
        print(f"skipped {name}: {why}", file=sys.stderr)
    for path in written:
        print(f"wrote {path}")
    return 0


def _split_arguments(p: argparse.ArgumentParser) -> None:
    """--folds, --seed, --calibration-folds and --skip-bad of the calibration commands."""
    p.add_argument(
        "--folds", type=FOLDS, default=10, help="number of Table I folds (default 10)"
    )
    p.add_argument(
        "--seed", type=SEEDS, default=0, help="seed of the fold split (default 0, as Table I)"
    )
    p.add_argument(
        "--calibration-folds",
        type=CALIBRATION_FOLDS,
        default=5,
        help="folds 0 .. N-1 form the calibration half, the rest are held out (default 5)",
    )
    p.add_argument(
        "--skip-bad", action="store_true", help="skip files that fail to load and list them"
    )


def build_parser() -> argparse.ArgumentParser:
    """The argparse parser with one subcommand per operation."""
    parser = argparse.ArgumentParser(
        prog="handover-data",
        description="Handover datasets: inspect, convert the public dataset safely, synthesise, "
        "compare, export to LeRobot, plot, calibrate the simulated receiver (transfer-stats).",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    dataset_help = (
        f"a .npz, a public-dataset folder, or '{DEFAULT_KEYWORD}' for the embedded default"
    )

    p = sub.add_parser(
        "info",
        help="counts, frames and distributions of a dataset",
        description="Print episode counts (ID/OOD), frames, and the distributions of "
        "walking speed, duration, transfer height/position/time and start point.",
    )
    p.add_argument("path", help=dataset_help)
    p.add_argument(
        "--skip-bad", action="store_true", help="for a folder: skip bad files and report them"
    )
    p.set_defaults(func=cmd_info)

    p = sub.add_parser(
        "convert",
        help="public-dataset pickles -> canonical .npz",
        description="Load a folder of motion_normal_*.pkl / motion_variation_*.pkl "
        "with the safe unpickler (numpy arrays only), validate, save one .npz.",
    )
    p.add_argument("public_dir", help="the public dataset's data/whole_motions folder")
    p.add_argument("out", help="output .npz")
    p.add_argument(
        "--skip-bad", action="store_true", help="skip bad files and report them instead of failing"
    )
    p.set_defaults(func=cmd_convert)

    p = sub.add_parser(
        "synth",
        help="generate synthetic demonstrations",
        description="Generate synthetic handovers calibrated to the public data's statistics.",
    )
    p.add_argument("out", help="output .npz")
    p.add_argument(
        "--n", type=EPISODES, default=1000, help="number of episodes (default 1000)"
    )
    p.add_argument(
        "--ood-fraction", type=closed_fraction, default=0.1,
        help="fraction of OOD episodes, in [0, 1] (default 0.1)",
    )
    p.add_argument("--seed", type=SEEDS, default=0, help="random seed (default 0)")
    p.set_defaults(func=cmd_synth)

    p = sub.add_parser(
        "compare",
        help="two datasets side by side",
        description="Medians of A and B, relative difference (B - A)/|A| and the "
        "two-sample Kolmogorov-Smirnov statistic for each statistic.",
    )
    p.add_argument("a", help=f"reference dataset ({dataset_help})")
    p.add_argument("b", help=f"candidate dataset ({dataset_help})")
    p.add_argument(
        "--subset",
        nargs="+",
        choices=("all", "id", "ood"),
        default=["all", "id", "ood"],
        help="which episodes to compare (default: all, id and ood)",
    )
    p.set_defaults(func=cmd_compare)

    p = sub.add_parser(
        "export-lerobot",
        help="export to a local LeRobotDataset",
        description="Write a LeRobotDataset (use_videos=False, no network) that the "
        "ACT baseline trains on.",
    )
    p.add_argument("dataset", help=dataset_help)
    p.add_argument("root", help="output folder of the LeRobotDataset")
    p.add_argument("--repo-id", default="local/handover", help="repo id recorded in the metadata")
    p.add_argument(
        "--history", type=FRAMES, default=10, help="frames of receiver history (default 10)"
    )
    p.add_argument(
        "--horizon",
        type=FRAMES,
        default=30,
        help="frames of future giver positions (default 30)",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an existing ROOT, only if it is an earlier export and nothing else: its "
        "meta/handover.json validates, it holds only the files that export wrote (listed there "
        "with their size and SHA-256), and not DATASET; any other folder is refused and nothing "
        "is deleted",
    )
    p.set_defaults(func=cmd_export_lerobot)

    p = sub.add_parser(
        "plot",
        help="top-down paths of receiver and giver",
        description="Save a PNG of receiver (solid) and giver/object (dashed) paths "
        "seen from above, ID blue and OOD red, and the object height over time.",
    )
    p.add_argument("dataset", help=dataset_help)
    p.add_argument("out", help="output image (.png, .pdf or .svg), not a folder")
    p.add_argument(
        "--max-episodes",
        type=EPISODES,
        default=200,
        help="episodes drawn per kind (default 200)",
    )
    p.add_argument("--seed", type=SEEDS, default=0, help="seed of the choice of episodes")
    p.set_defaults(func=cmd_plot)

    p = sub.add_parser(
        "transfer-stats",
        help="receiver calibration: when/where the object changes hands",
        description="Detect, in every recording of the public dataset, the transfer (the "
        "receiver's hand takes the object), the reach onset, the giver's release and the arm "
        "drawn back, and measure where and how (body frame, reach extent, slow-down, hand-object "
        "distance, track noise before/after the filter). Writes receiver_calibration.md, "
        "receiver_calibration.json and PNG figures into --out: quantiles 5/25/50/75/95 over "
        "recordings, ID/OOD/pooled, for a calibration half and a held-out half of Table I's "
        "stratified folds. Nothing per recording is written.",
    )
    p.add_argument("public_dir", help="the public dataset's data/whole_motions folder")
    p.add_argument("--out", required=True, help="output folder (e.g. docs/calibration)")
    _split_arguments(p)
    p.add_argument("--no-figures", action="store_true", help="write only the .md and .json")
    p.add_argument(
        "--limit",
        type=EPISODES,
        default=None,
        help="analyse only the first N ID and N OOD files (a quick look; not Table I's split)",
    )
    p.set_defaults(func=cmd_transfer_stats)

    p = sub.add_parser(
        "sensing",
        help="camera-model figures derived from the recordings",
        description="Measure, over the ID recordings, the pelvis jitter, the ZED hand's error "
        "against the OptiTrack object while carrying, and the tracker's re-fit bursts: the "
        "numbers of the 'paper' camera profile (handover_env.sensors). Prints them only.",
    )
    p.add_argument("public_dir", help="the public dataset's data/whole_motions folder")
    p.add_argument("--limit", type=EPISODES, default=None,
                   help="use only the first N ID recordings (a quick look)")
    p.set_defaults(func=cmd_sensing)

    p = sub.add_parser(
        "walk-stats",
        help="walker calibration: scripted vs recorded walk statistics",
        description="Measure the receiver's walk (heading change, detour, speed profile, pauses, "
        "walking back) in every recording (pelvis after the replay filter) and on seeded scripted "
        "ID/OOD walkers with the same code; write walkers.md (the OOD calibration table), "
        "walkers.json and walkers.png into --out. Nothing per recording is written.",
    )
    p.add_argument("public_dir", help="the public dataset's data/whole_motions folder")
    p.add_argument("--out", required=True, help="output folder (e.g. docs/calibration)")
    p.add_argument("--walkers", type=WALKERS, default=400,
                   help="scripted walkers per kind (ID seeds 0.., OOD 10000..; default 400)")
    p.add_argument("--skip-bad", action="store_true", help="skip files that fail to load")
    p.add_argument("--no-figures", action="store_true", help="write only the .md and .json")
    p.set_defaults(func=cmd_walk_stats)

    p = sub.add_parser(
        "reach-spread",
        help="the reach: the giver's part and the per-person offsets",
        description="Fit, on the calibration half of Table I's folds, the line of the reach "
        "(shoulder to object at the transfer) on the closest approach of the shoulder's path "
        "to the object (the giver's part); describe its residuals (the per-person offsets: SD, "
        "shape, the chosen distribution); report how the line predicts the held-out half "
        "(r, RMSE). Writes reach_spread.md, reach_spread.json and reach_spread.png into --out. "
        "Nothing per recording is written.",
    )
    p.add_argument("public_dir", help="the public dataset's data/whole_motions folder")
    p.add_argument("--out", required=True, help="output folder (e.g. docs/calibration)")
    _split_arguments(p)
    p.add_argument("--no-figures", action="store_true", help="write only the .md and .json")
    p.set_defaults(func=cmd_reach_spread)

    p = sub.add_parser(
        "calibrated-range",
        help="the walks the person was calibrated on",
        description="Measure, in every recording, the median walking speed, the body height, "
        "the nearest the pelvis comes to the giver and the longest pause (the definitions the "
        "env checks a walker or a replay with); state the calibration half's 2.5-97.5 %% range "
        "of each (the pause: 0 .. 97.5 %% over walks that pause). Writes calibrated_range.md "
        "and calibrated_range.json into --out. Nothing per recording is written.",
    )
    p.add_argument("public_dir", help="the public dataset's data/whole_motions folder")
    p.add_argument("--out", required=True, help="output folder (e.g. docs/calibration)")
    _split_arguments(p)
    p.set_defaults(func=cmd_calibrated_range)

    p = sub.add_parser(
        "grasp-height",
        help="the recorded arm at the transfer: the hand below the object's centre or above, "
        "and the elbow's swivel direction",
        description="Detect the transfer in every recording (receiver and object filtered as "
        "a replay is) and measure there the height of the receiver's right wrist, hand, hand "
        "tip and elbow (BODY_34) relative to the object's recorded position (the bottle's "
        "centre), and the forearm's elevation: quantiles 5/25/50/75/95 and the share of "
        "recordings below the centre; and the elbow's swivel direction off the shoulder-wrist "
        "line in the walking frame (normalised mean, R, medians); ID/OOD/pooled, for the "
        "calibration half and the held-out half of Table I's folds (the evidence of the "
        "person's grasp_below switch and of its arm IK's elbow pole). Writes "
        "grasp_height.md and grasp_height.json into --out. Nothing per recording is written.",
    )
    p.add_argument("public_dir", help="the public dataset's data/whole_motions folder")
    p.add_argument("--out", required=True, help="output folder (e.g. docs/calibration)")
    _split_arguments(p)
    p.set_defaults(func=cmd_grasp_height)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; returns the exit status (2 for a dataset or file error)."""
    hub_offline()
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args))
    except (DatasetError, OSError, ValueError) as exc:  # one line, naming the file
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except MemoryError as exc:  # the loaders bound every allocation; this is a last resort
        print(
            f"error: out of memory ({exc or 'MemoryError'}) running {args.command}", file=sys.stderr
        )
        return 2


if __name__ == "__main__":
    sys.exit(main())
