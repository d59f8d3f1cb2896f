"""The files of a benchmark run and of ``rescore``: per-episode CSVs, tables, result.json.

:func:`write_tables` builds every table from per-episode rows *as read back from the CSV files*
(:func:`.files.read_episodes`), so a run (:func:`write_benchmark`) and ``rescore`` on the same
files write the same bytes. Tables: ``closedloop_table.csv``, ``openloop_table.csv`` and
``benchmark.md`` (the tracks present).

A run removes an earlier run's ``result.json`` from ``--out`` before it writes any file and
writes its own last, so a run that fails half-way leaves no result file beside episode files it
does not describe (and :func:`.leaderboard.load_results` refuses a result whose episode files'
hashes differ).
"""

from __future__ import annotations

import platform
from collections.abc import Mapping
from pathlib import Path

from handover_env import __version__
from handover_eval.benchmark import tables
from handover_eval.benchmark.files import (
    EPISODE_FILES,
    RESULT_FORMAT,
    RESULT_NAME,
    read_episodes,
    sha256_file,
    write_episodes,
    write_result,
)
from handover_eval.benchmark.protocol import BOOTSTRAP, BOOTSTRAP_SEED, PROTOCOL_VERSION
from handover_eval.benchmark.run import BenchmarkRun
from handover_eval.reporting import write_csv, write_text

TABLE_FILES = {"openloop": "openloop_table.csv", "closedloop": "closedloop_table.csv"}
MARKDOWN = "benchmark.md"


def metrics_of(track_rows: Mapping[str, list[dict]]) -> dict[str, dict]:
    """track -> agent -> set -> metrics, from rows read back from the episode files."""
    out = {}
    if "openloop" in track_rows:
        out["openloop"] = tables.openloop_metrics(track_rows["openloop"], BOOTSTRAP,
                                                  BOOTSTRAP_SEED)
    if "closedloop" in track_rows:
        out["closedloop"] = tables.closedloop_metrics(track_rows["closedloop"], BOOTSTRAP,
                                                      BOOTSTRAP_SEED)
    return out


def tables_markdown(metrics: Mapping[str, dict]) -> str:
    parts = ["# Benchmark tables (protocol v%d)\n" % PROTOCOL_VERSION]
    if "openloop" in metrics:
        parts.append(tables.openloop_markdown(metrics["openloop"]))
    if "closedloop" in metrics:
        parts.append(tables.closedloop_markdown(metrics["closedloop"]))
    return "\n".join(parts)


def write_tables(track_rows: Mapping[str, list[dict]], out: Path) -> tuple[dict, list[Path]]:
    """The tables of ``track_rows`` into ``out``; returns (metrics, the files written)."""
    metrics = metrics_of(track_rows)
    files = []
    if "openloop" in metrics:
        files.append(write_csv(tables.openloop_table_rows(metrics["openloop"]),
                               out / TABLE_FILES["openloop"]))
    if "closedloop" in metrics:
        files.append(write_csv(tables.closedloop_table_rows(metrics["closedloop"]),
                               out / TABLE_FILES["closedloop"]))
    files.append(write_text(tables_markdown(metrics), out / MARKDOWN))
    return metrics, files


def rescore(paths: list[Path], out: Path) -> tuple[dict, list[Path]]:
    """``evaluate.py rescore``: the tables from per-episode files (at most one per track)."""
    track_rows: dict[str, list[dict]] = {}
    for path in paths:
        track, rows = read_episodes(path)
        if track in track_rows:
            raise ValueError(f"{path}: a second {track} episode file (give one per track)")
        track_rows[track] = rows
    return write_tables(track_rows, out)


def remove_result(out: Path) -> None:
    """Remove ``out``'s result.json (a link is removed, never followed); a folder of that name
    is refused."""
    path = out / RESULT_NAME
    if path.is_symlink() or path.is_file():
        path.unlink()
    elif path.exists():
        raise ValueError(f"{path}: not a file; a benchmark run writes its result there")


def write_benchmark(run: BenchmarkRun, out: Path) -> dict:
    """Episode CSVs, tables and result.json of ``run`` into ``out`` (an earlier result.json
    removed first); returns the result."""
    remove_result(out)
    episodes, track_rows = {}, {}
    for track in run.tracks:
        path = write_episodes(run.rows[track], track, out / EPISODE_FILES[track])
        _, rows = read_episodes(path)
        track_rows[track] = rows
        episodes[track] = {"file": path.name, "sha256": sha256_file(path), "rows": len(rows)}
    metrics, _ = write_tables(track_rows, out)
    src = run.source
    result = {
        "format": RESULT_FORMAT,
        "protocol_version": PROTOCOL_VERSION,
        "quick": run.settings.quick,
        "agent": {
            "name": src.name,
            "kind": src.kind,
            "spec": src.spec,
            "source_sha256": src.source_sha256,
            "config": run.config,
        },
        "tracks": list(run.tracks),
        "fingerprints": run.fingerprints,
        "metrics": {t: metrics[t][src.name] for t in run.tracks},
        "episodes": episodes,
        "software": {"handover_env": __version__, "python": platform.python_version()},
        "timing": {f"{t}_seconds": round(s, 3) for t, s in run.seconds.items()},
    }
    write_result(result, out / RESULT_NAME)
    return result
