"""The benchmark's files: the per-episode CSVs and result.json, written here and read back with
every field checked.

Reading runs no code: the CSVs go through :mod:`csv` and the JSON through :func:`json.loads`
(size-bounded, duplicate keys, NaN and Infinity refused), and every field is checked for its
exact type and range against the schemas below (every pattern matched in full, so no trailing
newline slips through). An episode file holds at most :data:`MAX_ROWS` rows of at most
:data:`MAX_AGENTS` agents: bounds that keep ``rescore`` of the largest file admitted under 2 GB
of memory and a minute (``tests/security/test_security_results.py``). The values of a
result.json are then checked against each other (:mod:`.result_values`). Any problem is a
:class:`BenchmarkFileError` whose message is one line naming the file and the field (and, in an
episode file, the line).
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
import re
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

from handover_env.regular_file import read_regular_file
from handover_eval.benchmark.outcomes import CHECKS, EVENTS
from handover_eval.benchmark.plugin import NAME_RE
from handover_eval.benchmark.protocol import (
    CLOSEDLOOP_SETS,
    KNOWN_VERSIONS,
    OPENLOOP_FOLDS,
    OPENLOOP_METRICS,
    REPLAY_FOLDS,
    TRACKS,
)
from handover_eval.benchmark.result_values import value_problem
from handover_eval.reporting import write_csv, write_text

RESULT_FORMAT = "handover_env-benchmark-result"
RESULT_NAME = "result.json"
EPISODE_FILES = {"openloop": "openloop_episodes.csv", "closedloop": "closedloop_episodes.csv"}
#: Bounds on what leaderboard and rescore read (a full run's result.json is ~15 kB, its episode
#: files ~0.5 MB and ~1,200 rows of 2 agents).
MAX_JSON_BYTES = 256_000
MAX_CSV_BYTES = 200_000_000
MAX_ROWS = 50_000
MAX_AGENTS = 100
MAX_FIELD_CHARS = 200
OUTCOME_NAMES = (
    "success", "premature_release", "dropped", "unsafe_force", "missed", "unstable", "timeout"
)
# Matched with fullmatch: ``$`` alone would also accept a trailing newline.
KEY_RE = re.compile(r"[A-Za-z0-9_.\-]{1,128}")
INT_RE = re.compile(r"-?[0-9]{1,12}")
FLOAT_RE = re.compile(r"nan|-?([0-9]+\.?[0-9]*|\.[0-9]+)(e[-+]?[0-9]{1,3})?")
HEX32, HEX64 = re.compile(r"[0-9a-f]{32}"), re.compile(r"[0-9a-f]{64}")


class BenchmarkFileError(ValueError):
    """A result or episode file that is not what the benchmark writes (one line: file, field)."""


# ------------------------------------------------------------------------------ CSV schemas
def _parse_str(pattern: re.Pattern) -> Callable[[str], str]:
    def parse(text: str) -> str:
        if not pattern.fullmatch(text):
            raise ValueError(f"{text[:40]!r} is not allowed here")
        return text

    return parse


def _parse_int(text: str) -> int:
    if not INT_RE.fullmatch(text):
        raise ValueError(f"{text[:40]!r} is not an integer")
    return int(text)


def _int_from(low: int, below: int | None = None) -> Callable[[str], int]:
    def parse(text: str) -> int:
        value = _parse_int(text)
        if value < low:
            raise ValueError(f"{value} is below {low}")
        if below is not None and value >= below:
            raise ValueError(f"{value} is not below {below}")
        return value

    return parse


def _opt_int_from(low: int, below: int | None = None) -> Callable[[str], int | str]:
    parse_int = _int_from(low, below)

    def parse(text: str) -> int | str:
        return "" if text == "" else parse_int(text)

    return parse


def _parse_bool(text: str) -> bool:
    if text not in ("True", "False"):
        raise ValueError(f"{text[:40]!r} is not True or False")
    return text == "True"


def _parse_float(text: str) -> float:
    value = float(text) if FLOAT_RE.fullmatch(text) else math.inf
    if math.isinf(value):
        raise ValueError(f"{text[:40]!r} is not a finite number or nan")
    return value


def _parse_amount(text: str) -> float:
    """A time, force, length or error: nan (undefined) or a finite number >= 0."""
    value = _parse_float(text)
    if value < 0:
        raise ValueError(f"{text[:40]!r} is negative")
    return value


def _one_of(names: Sequence[str]) -> Callable[[str], str]:
    def parse(text: str) -> str:
        if text not in names:
            raise ValueError(f"{text[:40]!r} is not one of {list(names)}")
        return text

    return parse


_NAME = _parse_str(NAME_RE)
_KEY = _parse_str(KEY_RE)
#: column -> parser, in the order the CSV holds them. Times (s from the episode's start or the
#: receiver's departure), forces, lengths and errors are nan or >= 0; seeds, steps and counts
#: >= 0; folds those of the protocol's splits (0 .. k-1; a model fold -1: fitted on all of
#: ``--data``); only ``pass_y`` and the replay deltas ``delta_t``, ``delta_x`` may be negative.
CLOSEDLOOP_COLUMNS: dict[str, Callable[[str], Any]] = {
    "agent": _NAME,
    "set": _one_of(CLOSEDLOOP_SETS),
    "receiver": _KEY,
    "seed": _int_from(0),
    "fold": _opt_int_from(0, REPLAY_FOLDS),
    "model_fold": _opt_int_from(-1, REPLAY_FOLDS),
    "is_ood": _parse_bool,
    "pass_y": _parse_float,
    "outcome": _one_of(OUTCOME_NAMES),
    "success": _parse_bool,
    "first_failure": _one_of(("", *CHECKS)),
    **{f"ev_{e}": _parse_bool for e in EVENTS},
    **{c: _parse_amount for c in (
        "handover_time", "transfer_time", "reach_onset_time", "release_time", "release_force",
        "peak_contact_force", "body_contact_force", "penetration", "time_lost", "reach_distance",
        "arm_extended_time", "pull_force", "robot_jerk_rms",
    )},
    "delta_t": _parse_float,
    "delta_x": _parse_float,
    "sim_unstable": _int_from(0),
    "steps": _int_from(0),
}
OPENLOOP_COLUMNS: dict[str, Callable[[str], Any]] = {
    "agent": _NAME,
    "fold": _int_from(0, OPENLOOP_FOLDS),
    "source_id": _KEY,
    "is_ood": _parse_bool,
    "n_queries": _int_from(0),
    **{m: _parse_amount for m in OPENLOOP_METRICS},
}
SCHEMAS = {"closedloop": CLOSEDLOOP_COLUMNS, "openloop": OPENLOOP_COLUMNS}
UNIQUE = {"closedloop": ("agent", "set", "receiver"), "openloop": ("agent", "source_id")}


def write_episodes(rows: Sequence[Mapping[str, Any]], track: str, path: Path) -> Path:
    """The per-episode CSV of ``track``: exactly the schema's columns, in its order."""
    columns = list(SCHEMAS[track])
    missing = [c for c in columns if rows and c not in rows[0]]
    if missing:
        raise ValueError(f"episode rows lack the column(s) {missing}")
    return write_csv([{c: r[c] for c in columns} for r in rows], path)


def _read_bounded(path: Path, limit: int) -> bytes:
    """The bytes of a regular file (no link) of at most ``limit`` bytes, checked and read on one
    descriptor (:func:`handover_env.regular_file.read_regular_file`)."""
    path = Path(path)
    if not (path.exists() or path.is_symlink()):
        raise BenchmarkFileError(f"{path}: no such file")
    if path.is_symlink() or not path.is_file():
        raise BenchmarkFileError(f"{path}: not a regular file (a link, folder or device)")
    size = path.stat().st_size
    if size > limit:
        raise BenchmarkFileError(f"{path}: {size} bytes, more than the {limit} allowed")
    return read_regular_file(path, limit, path.parent, error=BenchmarkFileError)


def _lines(text: str) -> Iterator[str]:
    """The lines of ``text``, each with its ``\n``, without a copy of the whole text."""
    start, end = 0, len(text)
    while start < end:
        stop = text.find("\n", start)
        stop = end if stop < 0 else stop + 1
        yield text[start:stop]
        start = stop


def read_episodes(path: str | Path) -> tuple[str, list[dict]]:
    """``(track, rows)`` of a benchmark per-episode CSV, every value parsed and checked."""
    path = Path(path)
    try:
        text = _read_bounded(path, MAX_CSV_BYTES).decode("utf-8")
    except UnicodeDecodeError as exc:
        raise BenchmarkFileError(f"{path}: not UTF-8 text ({exc.reason})") from None
    reader = csv.reader(_lines(text))
    try:
        header = next(reader)
    except StopIteration:
        raise BenchmarkFileError(f"{path}: empty file") from None
    except csv.Error as exc:
        raise BenchmarkFileError(f"{path}: not CSV ({exc})") from None
    track = next((t for t, cols in SCHEMAS.items() if header == list(cols)), None)
    if track is None:
        raise BenchmarkFileError(
            f"{path}: the header is not a benchmark episode file's (expected the columns of "
            f"{EPISODE_FILES['closedloop']} or {EPISODE_FILES['openloop']})"
        )
    schema = SCHEMAS[track]
    rows, seen, agents = [], set(), set()
    try:
        for line, cells in enumerate(reader, start=2):
            if len(rows) >= MAX_ROWS:
                raise BenchmarkFileError(f"{path}: more than {MAX_ROWS} rows")
            if len(cells) != len(schema):
                raise BenchmarkFileError(
                    f"{path}: line {line} has {len(cells)} fields, the header {len(schema)}"
                )
            row = {}
            for (col, parse), cell in zip(schema.items(), cells, strict=True):
                if len(cell) > MAX_FIELD_CHARS:
                    raise BenchmarkFileError(f"{path}: line {line}, {col}: field too long")
                try:
                    row[col] = parse(cell)
                except ValueError as exc:
                    raise BenchmarkFileError(f"{path}: line {line}, {col}: {exc}") from None
            key = tuple(row[c] for c in UNIQUE[track])
            if key in seen:
                raise BenchmarkFileError(f"{path}: line {line}: {key} appears twice")
            seen.add(key)
            agents.add(row["agent"])
            if len(agents) > MAX_AGENTS:
                raise BenchmarkFileError(f"{path}: line {line}, agent: more than {MAX_AGENTS} "
                                         "agents in one file")
            if track == "closedloop":
                _check_closed_row(path, line, row)
            rows.append(row)
    except csv.Error as exc:
        raise BenchmarkFileError(f"{path}: not CSV ({exc})") from None
    if not rows:
        raise BenchmarkFileError(f"{path}: no episode rows")
    return track, rows


def _check_closed_row(path: Path, line: int, row: dict) -> None:
    if row["success"] != (row["first_failure"] == ""):
        raise BenchmarkFileError(
            f"{path}: line {line}, first_failure: {row['first_failure']!r} contradicts success "
            f"{row['success']}"
        )
    if row["success"] and row["outcome"] != "success":
        raise BenchmarkFileError(f"{path}: line {line}, success: outcome is {row['outcome']!r}")
    if row["success"] and math.isnan(row["handover_time"]):
        raise BenchmarkFileError(f"{path}: line {line}, handover_time: nan on a success (every "
                                 "success has a handover time)")


def sha256_file(path: str | Path) -> str:
    """The SHA-256 of a file we just wrote."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def sha256_episode_file(path: str | Path) -> str:
    """The SHA-256 of an episode file we did not write (a regular file within the size limit)."""
    return hashlib.sha256(_read_bounded(Path(path), MAX_CSV_BYTES)).hexdigest()


# ------------------------------------------------------------------------------ result.json
def _nan_to_none(value: Any) -> Any:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _nan_to_none(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_nan_to_none(v) for v in value]
    return value


def write_result(result: Mapping[str, Any], path: Path) -> Path:
    """result.json: sorted keys, 2-space indent, non-finite numbers as null; checked first."""
    data = _nan_to_none(dict(result))
    text = json.dumps(data, sort_keys=True, indent=2, allow_nan=False) + "\n"
    check_result(json.loads(text), str(path))
    return write_text(text, path)


def _dup_free(pairs: list[tuple[str, Any]]) -> dict:
    out = {}
    for k, v in pairs:
        if k in out:
            raise ValueError(f"duplicate key {k!r}")
        out[k] = v
    return out


def _bad_constant(name: str) -> None:
    raise ValueError(f"{name} is not allowed")


def load_json(path: str | Path) -> Any:
    """A JSON file parsed without running code (size-bounded; no duplicate keys, NaN or
    Infinity), not yet checked."""
    path = Path(path)
    raw = _read_bounded(path, MAX_JSON_BYTES)
    try:
        return json.loads(raw.decode("utf-8"), object_pairs_hook=_dup_free,
                          parse_constant=_bad_constant)
    except (UnicodeDecodeError, json.JSONDecodeError, ValueError, RecursionError) as exc:
        raise BenchmarkFileError(f"{path}: not a result file: {exc}") from None


def protocol_version_of(data: Any, file: str) -> Any:
    """The ``protocol_version`` field as the file holds it (checked only to exist)."""
    if not isinstance(data, dict) or "protocol_version" not in data:
        raise BenchmarkFileError(f"{file}: field protocol_version is missing: not a result file")
    return data["protocol_version"]


def read_result(path: str | Path) -> dict:
    """A result.json, parsed without running code and checked field by field."""
    data = load_json(path)
    check_result(data, str(path))
    return data


# A tiny schema language: dict = exactly these keys; ("map", keys, spec) = a subset of keys;
# ("list", spec); ("json",) any JSON of bounded size; callables check a leaf.
def _num_or_null(v: Any) -> bool:
    if isinstance(v, int) and not isinstance(v, bool):
        return abs(v) <= 2**53  # exactly a float; a 400-digit integer is not a number of ours
    return v is None or (isinstance(v, float) and math.isfinite(v))


def _int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and 0 <= v <= 10**9


def _leaf(check: Callable[[Any], bool], what: str) -> Callable[[Any, str, str], None]:
    def run(v: Any, where: str, file: str) -> None:
        if not check(v):
            shown = type(v).__name__ if not isinstance(v, (str, int, float)) else repr(v)[:40]
            raise BenchmarkFileError(f"{file}: field {where} must be {what}, got {shown}")

    return run


NUM = _leaf(_num_or_null, "a finite number or null")
INT = _leaf(_int, "an integer in [0, 1e9]")
BOOL = _leaf(lambda v: isinstance(v, bool), "true or false")
NAME = _leaf(lambda v: isinstance(v, str) and bool(NAME_RE.fullmatch(v)), "an agent name")
HEX32_OR_NULL = _leaf(lambda v: v is None or (isinstance(v, str) and bool(HEX32.fullmatch(v))),
                      "32 hex digits or null")
H32 = _leaf(lambda v: isinstance(v, str) and bool(HEX32.fullmatch(v)), "32 hex digits")
H64 = _leaf(lambda v: isinstance(v, str) and bool(HEX64.fullmatch(v)), "64 hex digits")
H64_OR_EMPTY = _leaf(lambda v: isinstance(v, str) and (v == "" or bool(HEX64.fullmatch(v))),
                     "64 hex digits or empty")
TEXT = _leaf(lambda v: isinstance(v, str) and len(v) <= 4096 and v.isprintable(),
             "printable text of at most 4096 characters")
VERSION = _leaf(lambda v: isinstance(v, int) and not isinstance(v, bool) and v in KNOWN_VERSIONS,
                f"a known protocol version {list(KNOWN_VERSIONS)}")
FILE_NAME = _leaf(lambda v: v in EPISODE_FILES.values(), f"one of {list(EPISODE_FILES.values())}")
KIND = _leaf(lambda v: v in ("method", "roster", "plugin"), "method, roster or plugin")
FORMAT = _leaf(lambda v: v == RESULT_FORMAT, repr(RESULT_FORMAT))


def _json_any(v: Any, where: str, file: str, depth: int = 0) -> None:
    if depth > 8:
        raise BenchmarkFileError(f"{file}: field {where} is nested too deeply")
    if isinstance(v, dict):
        if len(v) > 500:
            raise BenchmarkFileError(f"{file}: field {where} has too many keys")
        for k, x in v.items():
            _json_any(x, f"{where}.{k}", file, depth + 1)
    elif isinstance(v, list):
        if len(v) > 5000:
            raise BenchmarkFileError(f"{file}: field {where} is too long")
        for i, x in enumerate(v):
            _json_any(x, f"{where}[{i}]", file, depth + 1)
    elif isinstance(v, str):
        TEXT(v, where, file)
    elif isinstance(v, (int, float)) and not isinstance(v, bool) and not _num_or_null(v):
        raise BenchmarkFileError(f"{file}: field {where} must be a finite number of magnitude at "
                                 f"most 2**53, got {repr(v)[:40]}")
    elif not (v is None or isinstance(v, (bool, int, float))):
        raise BenchmarkFileError(f"{file}: field {where} is not JSON data")


ANY = ("json",)
CI = {"value": NUM, "low": NUM, "high": NUM, "n": INT}
OPEN_METRIC = {**CI, "fold_mean": NUM, "fold_std": NUM}
PAIRED = {"diff": NUM, "low": NUM, "high": NUM, "n": INT}
CLOSED_SET = {
    "n": INT,
    "success": {"value": NUM, "low": NUM, "high": NUM, "k": INT},
    "first_failure": {c: INT for c in CHECKS},
    "handover_time": CI,
    "paired": ("nullable", {"success": PAIRED, "handover_time": PAIRED}),
}
FINGERPRINT = {
    "fingerprint": H32,
    "protocol_version": VERSION,
    "data": H32,
    "replay_data": HEX32_OR_NULL,
    "protocol": ANY,
    "receivers": ("optional", H32),
    "n_receivers": ("optional", INT),
}
RESULT_SCHEMA = {
    "format": FORMAT,
    "protocol_version": VERSION,
    "quick": BOOL,
    "agent": {"name": NAME, "kind": KIND, "spec": TEXT, "source_sha256": H64_OR_EMPTY,
              "config": ANY},
    "tracks": ("list", _leaf(lambda v: v in TRACKS, f"one of {list(TRACKS)}")),
    "fingerprints": ("map", TRACKS, FINGERPRINT),
    "metrics": ("map", TRACKS, ANY),
    "episodes": ("map", TRACKS, {"file": FILE_NAME, "sha256": H64, "rows": INT}),
    "software": ANY,
    "timing": ANY,
}
METRIC_SCHEMAS = {
    "openloop": ("map", ("id", "ood", "all"), {m: OPEN_METRIC for m in OPENLOOP_METRICS}),
    "closedloop": ("map", (*CLOSEDLOOP_SETS, "all"), CLOSED_SET),
}


def _check(v: Any, spec: Any, where: str, file: str) -> None:
    if callable(spec):
        spec(v, where, file)
    elif isinstance(spec, dict):
        if not isinstance(v, dict):
            raise BenchmarkFileError(f"{file}: field {where} must be an object")
        required = {k for k, s in spec.items() if not (isinstance(s, tuple) and s[0] == "optional")}
        missing, extra = sorted(required - set(v)), sorted(set(v) - set(spec))
        if missing or extra:
            what = f"lacks {missing}" if missing else f"has unknown field(s) {extra[:5]}"
            raise BenchmarkFileError(f"{file}: field {where or '(top)'} {what}")
        for k, x in v.items():
            _check(x, spec[k], f"{where}.{k}" if where else k, file)
    elif spec[0] == "optional":
        _check(v, spec[1], where, file)
    elif spec[0] == "nullable":
        if v is not None:
            _check(v, spec[1], where, file)
    elif spec[0] == "list":
        if not isinstance(v, list) or not v or len(v) != len(set(map(str, v))):
            raise BenchmarkFileError(f"{file}: field {where} must be a non-empty list, no repeats")
        for i, x in enumerate(v):
            _check(x, spec[1], f"{where}[{i}]", file)
    elif spec[0] == "map":
        if not isinstance(v, dict):
            raise BenchmarkFileError(f"{file}: field {where} must be an object")
        for k, x in v.items():
            if k not in spec[1]:
                raise BenchmarkFileError(f"{file}: field {where}.{k} is not one of {list(spec[1])}")
            _check(x, spec[2], f"{where}.{k}", file)
    elif spec[0] == "json":
        _json_any(v, where, file)
    else:  # pragma: no cover - a schema error of ours
        raise AssertionError(spec)


def check_result(data: Any, file: str) -> None:
    """Every field of a parsed result.json (a :class:`BenchmarkFileError` naming the first bad)."""
    if isinstance(data, dict) and "protocol_version" in data:
        VERSION(data["protocol_version"], "protocol_version", file)  # the reason first
    _check(data, RESULT_SCHEMA, "", file)
    tracks = data["tracks"]
    for part in ("fingerprints", "metrics", "episodes"):
        if sorted(data[part]) != sorted(tracks):
            raise BenchmarkFileError(f"{file}: field {part} must hold exactly the tracks {tracks}")
    for track in tracks:
        metrics = data["metrics"][track]
        if not isinstance(metrics, dict) or not metrics:
            raise BenchmarkFileError(f"{file}: field metrics.{track} must be a non-empty object")
        _check(metrics, METRIC_SCHEMAS[track], f"metrics.{track}", file)
        if data["fingerprints"][track]["protocol_version"] != data["protocol_version"]:
            raise BenchmarkFileError(f"{file}: field fingerprints.{track}.protocol_version differs "
                                     "from protocol_version")
    problem = value_problem(data)
    if problem is not None:
        raise BenchmarkFileError(f"{file}: field {problem}")
