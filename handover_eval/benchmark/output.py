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
from handover_eval.benchmark.protocol import (
    BOOTSTRAP,
    BOOTSTRAP_SEED,
    PROTOCOL_VERSION,
    REFERENCE_AGENT,
)
from handover_eval.benchmark.run import BenchmarkRun
from handover_eval.reporting import write_csv, write_text

TABLE_FILES = {"openloop": "openloop_table.csv", "closedloop": "closedloop_table.csv"}
MARKDOWN = "benchmark.md"


def metrics_of(track_rows: Mapping[str, list[dict]],
               reference: str = REFERENCE_AGENT) -> dict[str, dict]:
    """track -> agent -> set -> metrics, from rows read back from the episode files (the
    closed-loop track paired against ``reference``)."""
    out = {}
    if "openloop" in track_rows:
        out["openloop"] = tables.openloop_metrics(track_rows["openloop"], BOOTSTRAP,
                                                  BOOTSTRAP_SEED)
    if "closedloop" in track_rows:
        out["closedloop"] = tables.closedloop_metrics(track_rows["closedloop"], BOOTSTRAP,
                                                      BOOTSTRAP_SEED, reference)
    return out


def tables_markdown(metrics: Mapping[str, dict], reference: str = REFERENCE_AGENT) -> str:
    parts = ["# Benchmark tables (protocol v%d)\n" % PROTOCOL_VERSION]
    if "openloop" in metrics:
        parts.append(tables.openloop_markdown(metrics["openloop"]))
    if "closedloop" in metrics:
        parts.append(tables.closedloop_markdown(metrics["closedloop"], reference))
    return "\n".join(parts)


def write_tables(track_rows: Mapping[str, list[dict]], out: Path,
                 reference: str = REFERENCE_AGENT) -> tuple[dict, list[Path]]:
    """The tables of ``track_rows`` into ``out``; returns (metrics, the files written)."""
    metrics = metrics_of(track_rows, reference)
    files = []
    if "openloop" in metrics:
        files.append(write_csv(tables.openloop_table_rows(metrics["openloop"]),
                               out / TABLE_FILES["openloop"]))
    if "closedloop" in metrics:
        files.append(write_csv(tables.closedloop_table_rows(metrics["closedloop"]),
                               out / TABLE_FILES["closedloop"]))
    files.append(write_text(tables_markdown(metrics, reference), out / MARKDOWN))
    return metrics, files


def _same(rows: list[dict]) -> list[str]:
    """``rows`` in a form that compares equal when their values are (NaN equal to NaN)."""
    return [repr(sorted(r.items())) for r in rows]


def _merge(track: str, have: list[dict], rows: list[dict], path: Path) -> list[dict]:
    """``rows`` of a further episode file of ``track`` added to ``have``: an agent already
    there must have the very same rows (the reference, run again on the same receivers)."""
    by_agent: dict[str, list[dict]] = {}
    for r in rows:
        by_agent.setdefault(r["agent"], []).append(r)
    known = {r["agent"] for r in have}
    for agent, mine in by_agent.items():
        if agent not in known:
            have = have + mine
        elif _same(mine) != _same([r for r in have if r["agent"] == agent]):
            raise ValueError(f"{path}: {agent}'s {track} episodes differ from an earlier file's "
                             "(another protocol, receivers or code?)")
    return have


def rescore(paths: list[Path], out: Path, reference: str = REFERENCE_AGENT
            ) -> tuple[dict, list[Path]]:
    """``evaluate.py rescore``: the tables from per-episode files, paired against
    ``reference``. Several files of one track are joined (the closed loop of two benchmark
    runs: an agent in both must have the same rows, as the reference has); ``reference`` must
    be an agent of the closed-loop files."""
    track_rows: dict[str, list[dict]] = {}
    for path in paths:
        track, rows = read_episodes(path)
        track_rows[track] = _merge(track, track_rows[track], rows, path) if (
            track in track_rows) else rows
    if "closedloop" in track_rows and not any(r["agent"] == reference
                                              for r in track_rows["closedloop"]):
        raise ValueError(f"no closed-loop episodes of the reference agent {reference!r} in "
                         f"{', '.join(str(p) for p in paths)}")
    return write_tables(track_rows, out, reference)


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
