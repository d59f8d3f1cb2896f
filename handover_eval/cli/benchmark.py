"""The ``benchmark``, ``leaderboard``, ``rescore`` and ``far-pass`` commands of evaluate.py.

``evaluate.py`` keeps only the dispatch; the runs are :mod:`handover_eval.benchmark`'s.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path

from handover_eval import roster
from handover_eval.backend import JobError, session
from handover_eval.benchmark.guard import (
    DEFAULT_EPISODE_LIMIT_S,
    MAX_EPISODE_LIMIT_S,
    AgentError,
)
from handover_eval.benchmark.protocol import PROTOCOL_VERSION, REFERENCE_AGENT
from handover_eval.cli.args import (
    EPOCHS,
    STEPS,
    WORKERS,
    add_backend_arguments,
    backend_from_args,
    folder_option,
    load_replay_data,
)
from handover_eval.methods import MethodOptions, default_workers
from handover_eval.output_lock import OutputLock

COMMANDS = ("benchmark", "leaderboard", "rescore", "far-pass")
SECURITY = (
    "Loading a plug-in agent runs its code: naming a file or module in --agent is asking to run "
    "it, as `python file.py` would. leaderboard and rescore run no code from the files they read "
    "(size-bounded JSON/CSV, every field checked)."
)
BENCHMARK_DESCRIPTION = (
    f"Score an agent under the benchmark's protocol v{PROTOCOL_VERSION} (docs/benchmark.md): "
    "the open-loop track "
    "(Table I's folds; current-frame and 1 s RMS, ADE/FDE at 0.5 s and 1 s) and the closed-loop "
    "track (test-seed ID, OOD and far-pass walkers and recorded replays, against the reactive "
    "reference). Writes result.json (protocol version, fingerprints of the data and receivers, "
    "the agent's name and config, every metric with its CI), the per-episode CSVs and the tables "
    "(benchmark.md, *_table.csv). " + SECURITY
)


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Add the four sub-commands to evaluate.py's parser."""
    p = sub.add_parser("benchmark", help="score any agent (built-in or your own) under protocol "
                       f"v{PROTOCOL_VERSION}",
                       description=BENCHMARK_DESCRIPTION)
    both = [n for n in roster.benchmark_agents() if "openloop" in roster.entry(n).tracks]
    only = [n for n in roster.benchmark_agents() if n not in both]
    p.add_argument(
        "--agent", required=True, metavar="SPEC",
        help=f"the agent: a built-in ({' '.join(both)}, or closed-loop only: {' '.join(only)}"
        "), PKG.MODULE:FACTORY, or path/to/file.py:FACTORY; FACTORY(**config) must return "
        "an agents.base.Agent. A plug-in's code runs (it is loaded in every worker)",
    )
    p.add_argument("--agent-config", default=None, metavar="JSON",
                   help="a JSON object of keyword arguments for FACTORY (default: {}; every "
                   "number finite)")
    p.add_argument("--episode-time-limit", type=episode_seconds, default=DEFAULT_EPISODE_LIMIT_S,
                   metavar="SECONDS",
                   help="stop the run, naming the agent and the episode, when one episode (every "
                   "act() of a closed-loop episode, or every predict() of an open-loop one) takes "
                   f"longer (default {DEFAULT_EPISODE_LIMIT_S:g} s, far above any real agent's "
                   f"episode; at most {MAX_EPISODE_LIMIT_S:g})")
    p.add_argument("--name", default=None, help="the agent's name in the tables (default: the "
                   "built-in name, or FILE_STEM:FACTORY)")
    p.add_argument("--tracks", nargs="+", default=["openloop", "closedloop"],
                   choices=("openloop", "closedloop"), help="tracks to score (default: both)")
    p.add_argument("--data", default=None, metavar="PATH",
                   help="what the agent may fit on: a public-dataset folder (whole_motions/), a "
                   "canonical .npz, or omit for the synthetic default")
    p.add_argument("--replay-data", default=None, metavar="PATH",
                   help="recordings to score on that are not in --data: the agent fits on all of "
                   "--data and meets every recording of PATH (open loop: every episode scored)")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="output folder (default: results/benchmark/<name>, "
                   "results/benchmark-quick/<name> with --quick)")
    p.add_argument("--checkpoints", default=None, metavar="DIR",
                   help="the built-in learned methods' checkpoint cache (default: Table I's, "
                   "results/table1/checkpoints; results/table1-quick/checkpoints with --quick)")
    p.add_argument("--act-steps", type=STEPS, default=None,
                   help="ACT optimisation steps of built-in ACT (default: Table I's)")
    p.add_argument("--bc-epochs", type=EPOCHS, default=None,
                   help="BC-MLP maximum epochs of built-in BC-MLP (default: Table I's)")
    p.add_argument("--workers", type=WORKERS, default=None, metavar="N",
                   help="processes running the folds and episodes (default: one per core, at "
                   "most 2; 1 runs in this process); the results do not depend on it")
    p.add_argument("--quick", action="store_true",
                   help="small fast run for tests: 30 synthetic (or first) episodes, 3 folds, "
                   "query stride 3, 1 walker per set, 2 replays, tiny built-in models; its "
                   "fingerprints differ from a full run's; never for reported numbers")
    p.add_argument("--no-progress", action="store_true", help="hide progress bars")
    add_backend_arguments(p)

    p = sub.add_parser("leaderboard", help="ranked Markdown table + PNG from result.json files",
                       description="Rank result.json files of the same protocol version and "
                       "fingerprints (refused otherwise, with the reason). " + SECURITY)
    p.add_argument("results", nargs="+", metavar="RESULT.json")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="folder for leaderboard.md and leaderboard.png (default: "
                   "results/leaderboard)")
    p.add_argument("--html", action="store_true",
                   help="also write leaderboard.html: one self-contained page (sortable table, "
                   "the figure, per-agent rows, fingerprints; loads nothing from the network)")

    p = sub.add_parser("rescore", help="rebuild the benchmark tables from per-episode CSVs",
                       description="Rebuild benchmark.md and the *_table.csv files from the "
                       "per-episode CSVs of a benchmark run (one per track), without running an "
                       "episode; byte-identical to the run's tables. The closed-loop files of "
                       "several runs are joined (an agent in two of them, such as the reference, "
                       "must have the same rows), and --reference pairs them against another "
                       "agent of theirs. " + SECURITY)
    p.add_argument("episodes", nargs="+", metavar="EPISODES.csv",
                   help="closedloop_episodes.csv / openloop_episodes.csv of benchmark runs")
    p.add_argument("--reference", default=REFERENCE_AGENT, metavar="AGENT",
                   help="the agent every other is paired against on the same receivers (default: "
                   f"{REFERENCE_AGENT}, the protocol's; it must be in one of the closed-loop "
                   "files)")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="output folder (default: results/rescore)")

    p = sub.add_parser("far-pass", help="derive the far-pass set's lateral range from recordings",
                       description="Print the quantiles of the recorded pelvis y at the transfer "
                       "and the far-pass range [q05, q25] the protocol uses "
                       "(handover_eval/calibration/farpass.py).")
    p.add_argument("--data", required=True, metavar="PATH",
                   help="a folder of public-dataset recordings (whole_motions/)")
    p.add_argument("--no-progress", action="store_true", help="hide progress bars")


def episode_seconds(text: str) -> float:
    """argparse type of ``--episode-time-limit``: seconds in (0, MAX_EPISODE_LIMIT_S]."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of seconds, got {text!r}") from None
    if not (math.isfinite(value) and 0 < value <= MAX_EPISODE_LIMIT_S):
        raise argparse.ArgumentTypeError(
            f"must be a number of seconds in (0, {MAX_EPISODE_LIMIT_S:g}], got {text!r}")
    return value


def _error(exc: BaseException) -> int:
    print(f"evaluate.py: error: {exc}", file=sys.stderr)
    return 2


def main(args: argparse.Namespace, load_dataset: Callable) -> int:
    """Run ``args.command``; 2 with a one-line error on bad input or a bad file."""
    if args.command == "leaderboard":
        return _leaderboard(args)
    if args.command == "rescore":
        return _rescore(args)
    if args.command == "far-pass":
        return _far_pass(args)
    return _benchmark(args, load_dataset)


def _leaderboard(args: argparse.Namespace) -> int:
    from handover_eval.benchmark.leaderboard import (
        leaderboard_figure,
        leaderboard_markdown,
        load_results,
    )
    from handover_eval.reporting import write_png, write_text

    try:
        out = folder_option(args.out, "--out", Path("results") / "leaderboard")
        with OutputLock(out):
            results = load_results(args.results)
            text = leaderboard_markdown(results)
            write_text(text, out / "leaderboard.md")
            png = write_png(leaderboard_figure(results), out / "leaderboard.png")
            if args.html:
                from handover_eval.benchmark.html import leaderboard_html

                write_text(leaderboard_html(results, png.read_bytes()), out / "leaderboard.html")
    except (ValueError, OSError) as exc:
        return _error(exc)
    print(text)
    print(f"wrote {out}/leaderboard.md and leaderboard.png"
          + (" and leaderboard.html" if args.html else ""))
    return 0


def _rescore(args: argparse.Namespace) -> int:
    from handover_eval.benchmark.output import rescore

    try:
        out = folder_option(args.out, "--out", Path("results") / "rescore")
        with OutputLock(out):
            _, files = rescore([Path(p) for p in args.episodes], out, args.reference)
    except (ValueError, OSError) as exc:
        return _error(exc)
    print(files[-1].read_text())
    print("wrote " + ", ".join(str(f) for f in files))
    return 0


def _far_pass(args: argparse.Namespace) -> int:
    from handover_env.data.public import list_public_files
    from handover_eval.calibration.farpass import derivation_text, derive_range

    try:
        if not Path(args.data).is_dir():
            raise ValueError(f"--data {args.data}: not a folder of recordings")
        d = derive_range(list_public_files(args.data), progress=not args.no_progress)
    except (ValueError, OSError) as exc:
        return _error(exc)
    print(derivation_text(d))
    return 0


def _benchmark(args: argparse.Namespace, load_dataset: Callable) -> int:
    from handover_eval.benchmark.plugin import resolve
    from handover_eval.benchmark.protocol import BenchmarkSettings

    try:
        source = resolve(args.agent, args.name, args.agent_config, args.episode_time_limit)
        tracks = tuple(dict.fromkeys(args.tracks))
        settings = BenchmarkSettings(quick=args.quick)
        options = MethodOptions(
            seed=0, quick=args.quick, act_steps=args.act_steps, bc_epochs=args.bc_epochs,
            workers=default_workers() if args.workers is None else args.workers,
        )
        safe = source.name.replace(" ", "_").replace(":", "-")
        out = folder_option(
            args.out, "--out",
            Path("results") / ("benchmark-quick" if args.quick else "benchmark") / safe,
        )
        cache = folder_option(
            args.checkpoints, "--checkpoints",
            Path("results") / ("table1-quick" if args.quick else "table1") / "checkpoints",
        )
        backend = backend_from_args(args)
        lock = OutputLock(out).acquire()
    except (ValueError, OSError, RuntimeError) as exc:
        return _error(exc)
    try:
        return _run(args, load_dataset, source, tracks, settings, options, out, cache, backend)
    except KeyboardInterrupt as exc:  # Ctrl-C, or the agent's own (AgentInterrupted names it)
        print(f"evaluate.py: interrupted{': ' + str(exc) if str(exc) else ''}", file=sys.stderr)
        return 130
    finally:
        lock.release()


def _run(args, load_dataset, source, tracks, settings, options, out, cache, backend) -> int:
    from handover_eval.benchmark.output import write_benchmark
    from handover_eval.benchmark.run import run_benchmark

    try:
        dataset = load_dataset(args.data, args.quick, 0, not args.no_progress)
        replay = load_replay_data(load_dataset, args.replay_data, args.quick, 0,
                                  not args.no_progress)
    except (ValueError, OSError, RuntimeError) as exc:
        return _error(exc)
    print(f"benchmark: {source.name} on {list(tracks)}, fit on {dataset.name} ({len(dataset)} "
          f"episodes)" + (f", replays of {replay.name} ({len(replay)})" if replay else ""),
          flush=True)
    start = time.perf_counter()
    try:
        with session(backend, options.workers):
            run = run_benchmark(source, tracks, settings, dataset, args.data, options, cache,
                                replay, args.replay_data, progress=not args.no_progress)
            result = write_benchmark(run, out)
    except (ValueError, TypeError) as exc:
        return _error(exc)
    except (JobError, ConnectionError, AgentError) as exc:
        print(f"evaluate.py: error: {exc}", file=sys.stderr)
        return 1
    print((out / "benchmark.md").read_text())
    fps = ", ".join(f"{t} {v['fingerprint'][:12]}" for t, v in result["fingerprints"].items())
    print(f"protocol v{result['protocol_version']}, fingerprints {fps}")
    print(f"wrote {out}/ in {time.perf_counter() - start:.0f} s")
    return 0
