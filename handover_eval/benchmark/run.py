"""A benchmark run: the scored agent on the chosen tracks, returning values (no files).

Open loop: :func:`.open_loop.run_openloop`. Closed loop: the receivers of the protocol
(:func:`receivers_of`) for the agent and the reactive reference,
:func:`.closed_loop.run_closedloop`. Each track's rows are checked as their episode file would
hold them as soon as the track ends (:func:`check_rows`), so a value the file cannot hold stops
the run naming the agent and the episode before any file is written. The files are written by
:mod:`.output`.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from handover_env.data.dataset import HandoverDataset
from handover_eval.benchmark.closed_loop import run_closedloop
from handover_eval.benchmark.files import SCHEMAS, UNIQUE
from handover_eval.benchmark.open_loop import run_openloop
from handover_eval.benchmark.plugin import AgentSource, agent_config, build_plugin
from handover_eval.benchmark.protocol import (
    QUICK_FOLDS,
    REFERENCE_AGENT,
    REPLAY_FOLDS,
    REPLAY_SEED,
    THETA,
    BenchmarkSettings,
    BenchReceiver,
    fingerprints,
    replay_receivers,
    walker_receivers,
)
from handover_eval.methods import MethodOptions, build_agent, with_test_data
from handover_eval.receivers import (
    FIT_ALL,
    fold_of,
    other_replays,
    recording_paths,
    replays,
)

REFERENCE = AgentSource(REFERENCE_AGENT, "roster", REFERENCE_AGENT, spec=REFERENCE_AGENT)


@dataclass
class BenchmarkRun:
    """What :func:`run_benchmark` returns."""

    source: AgentSource
    tracks: tuple[str, ...]
    settings: BenchmarkSettings
    rows: dict[str, list[dict]]
    fingerprints: dict[str, dict]
    config: dict
    seconds: dict[str, float] = field(default_factory=dict)


def _cell_text(value: Any) -> str:
    """A value as :func:`handover_eval.reporting.write_csv` writes it (floats ``.6g``)."""
    if isinstance(value, float):
        return f"{value:.6g}"
    return "" if value is None else str(value)


def check_rows(track: str, rows: Sequence[Mapping[str, Any]]) -> None:
    """Every value of a run's rows as its episode file would hold it, before the file is written.

    A value the file could not hold (a metric made infinite by an agent's huge predictions, a
    negative time) is a ValueError naming the agent, the episode and the column, so that a run
    never writes an episode file that it would then refuse.
    """
    schema, keys = SCHEMAS[track], UNIQUE[track][1:]
    for row in rows:
        for col, parse in schema.items():
            try:
                parse(_cell_text(row.get(col)))
            except ValueError as exc:
                episode = " ".join(str(row[k]) for k in keys)
                raise ValueError(f"agent {row['agent']!r}, {track} episode {episode}: {col}: {exc} "
                                 "(the agent's output gave a value its episode file cannot hold)"
                                 ) from None


def receivers_of(
    settings: BenchmarkSettings,
    dataset: HandoverDataset,
    data_path: str | None,
    replay: HandoverDataset | None,
    replay_path: str | None,
) -> tuple[list[BenchReceiver], dict[int, tuple[np.ndarray, np.ndarray]], HandoverDataset]:
    """The closed-loop receivers, the model folds they need and the dataset the workers get."""
    walkers = walker_receivers(settings.walkers)
    if replay is None:
        k = QUICK_FOLDS if settings.quick else REPLAY_FOLDS
        specs = replays(dataset, fold_of(dataset, k, REPLAY_SEED), settings.replay_folds,
                        recording_paths(data_path, dataset), settings.replays_per_fold)
        splits = dict(enumerate(dataset.stratified_kfold(k, REPLAY_SEED)))
        return walkers + replay_receivers(specs), splits, dataset
    specs = other_replays(replay, len(dataset), recording_paths(replay_path, replay),
                          settings.replays_per_fold)
    n = len(dataset)
    splits = {FIT_ALL: (np.arange(n, dtype=np.int64), np.arange(n, n + len(replay)))}
    return walkers + replay_receivers(specs), splits, with_test_data(dataset, replay)


def describe_agent(source: AgentSource, options: MethodOptions) -> dict:
    """The agent's configuration for result.json (a plug-in's factory runs once here)."""
    if source.kind == "plugin":
        return agent_config(source, build_plugin(source))
    if source.kind == "method":
        return agent_config(source, build_agent(source.target, options))
    return agent_config(source, None)


def run_benchmark(
    source: AgentSource,
    tracks: tuple[str, ...],
    settings: BenchmarkSettings,
    dataset: HandoverDataset,
    data_path: str | None,
    options: MethodOptions,
    cache_dir: Path,
    replay: HandoverDataset | None = None,
    replay_path: str | None = None,
    progress: bool = True,
) -> BenchmarkRun:
    """Score ``source`` on ``tracks`` (module docstring)."""
    bad = [t for t in tracks if t not in source.tracks]
    if bad:
        raise ValueError(f"{source.name} cannot be scored on {bad}: it is a closed-loop-only agent")
    is_reference = source.kind == "roster" and source.target == REFERENCE_AGENT
    if source.name == REFERENCE_AGENT and not is_reference:
        raise ValueError(f"only the reference agent may be named {REFERENCE_AGENT!r}: pass --name")
    config = describe_agent(source, options)
    rows: dict[str, list[dict]] = {}
    seconds: dict[str, float] = {}
    receivers = None
    if "openloop" in tracks:
        t0 = time.perf_counter()
        rows["openloop"] = run_openloop(source, dataset, settings.folds, settings.openloop,
                                        options, cache_dir, replay, progress)
        seconds["openloop"] = time.perf_counter() - t0
        check_rows("openloop", rows["openloop"])
    if "closedloop" in tracks:
        t0 = time.perf_counter()
        receivers, splits, shared = receivers_of(settings, dataset, data_path, replay, replay_path)
        sources = [source] + ([] if is_reference else [REFERENCE])
        rows["closedloop"] = run_closedloop(sources, receivers, dataset, shared, splits, THETA,
                                            options, cache_dir, progress)
        seconds["closedloop"] = time.perf_counter() - t0
        check_rows("closedloop", rows["closedloop"])
    prints = fingerprints(settings, dataset, replay, receivers, tracks)
    return BenchmarkRun(source, tracks, settings, rows, prints, config, seconds)
