"""The benchmark's files: the per-episode CSVs and result.json, written here and read back with
every field checked.

Reading runs no code: the CSVs go through :mod:`csv` and the JSON through :func:`json.loads`
(size-bounded, duplicate keys, NaN and Infinity refused), and every field is checked for its
exact type and range against the schemas below. Any problem is a :class:`BenchmarkFileError`
whose message is one line naming the file and the field.
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import math
import re
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from handover_eval.benchmark.outcomes import CHECKS, EVENTS
from handover_eval.benchmark.plugin import NAME_RE
from handover_eval.benchmark.protocol import (
    CLOSEDLOOP_SETS,
    KNOWN_VERSIONS,
    OPENLOOP_METRICS,
    TRACKS,
)
from handover_eval.reporting import write_csv, write_text

RESULT_FORMAT = "handover_env-benchmark-result"
RESULT_NAME = "result.json"
EPISODE_FILES = {"openloop": "openloop_episodes.csv", "closedloop": "closedloop_episodes.csv"}
MAX_JSON_BYTES = 2_000_000
MAX_CSV_BYTES = 200_000_000
MAX_ROWS = 2_000_000
MAX_FIELD_CHARS = 200
OUTCOME_NAMES = (
    "success", "premature_release", "dropped", "unsafe_force", "missed", "unstable", "timeout"
)
KEY_RE = re.compile(r"^[A-Za-z0-9_.\-]{1,128}$")
INT_RE = re.compile(r"^-?[0-9]{1,12}$")
FLOAT_RE = re.compile(r"^(nan|-?([0-9]+\.?[0-9]*|\.[0-9]+)(e[-+]?[0-9]{1,3})?)$")
HEX32, HEX64 = re.compile(r"^[0-9a-f]{32}$"), re.compile(r"^[0-9a-f]{64}$")


class BenchmarkFileError(ValueError):
    """A result or episode file that is not what the benchmark writes (one line: file, field)."""


# ------------------------------------------------------------------------------ CSV schemas
def _parse_str(pattern: re.Pattern) -> Callable[[str], str]:
    def parse(text: str) -> str:
        if not pattern.match(text):
            raise ValueError(f"{text[:40]!r} is not allowed here")
        return text

    return parse


def _parse_int(text: str) -> int:
    if not INT_RE.match(text):
        raise ValueError(f"{text[:40]!r} is not an integer")
    return int(text)


def _parse_opt_int(text: str) -> int | str:
    return "" if text == "" else _parse_int(text)


def _parse_bool(text: str) -> bool:
    if text not in ("True", "False"):
        raise ValueError(f"{text[:40]!r} is not True or False")
    return text == "True"


def _parse_float(text: str) -> float:
    value = float(text) if FLOAT_RE.match(text) else math.inf
    if math.isinf(value):
        raise ValueError(f"{text[:40]!r} is not a finite number or nan")
    return value


def _one_of(names: Sequence[str]) -> Callable[[str], str]:
    def parse(text: str) -> str:
        if text not in names:
            raise ValueError(f"{text[:40]!r} is not one of {list(names)}")
        return text

    return parse


_NAME = _parse_str(NAME_RE)
_KEY = _parse_str(KEY_RE)
#: column -> parser, in the order the CSV holds them.
CLOSEDLOOP_COLUMNS: dict[str, Callable[[str], Any]] = {
    "agent": _NAME,
    "set": _one_of(CLOSEDLOOP_SETS),
    "receiver": _KEY,
    "seed": _parse_int,
    "fold": _parse_opt_int,
    "model_fold": _parse_opt_int,
    "is_ood": _parse_bool,
    "pass_y": _parse_float,
    "outcome": _one_of(OUTCOME_NAMES),
    "success": _parse_bool,
    "first_failure": _one_of(("", *CHECKS)),
    **{f"ev_{e}": _parse_bool for e in EVENTS},
    **{c: _parse_float for c in (
        "handover_time", "transfer_time", "reach_onset_time", "release_time", "release_force",
        "peak_contact_force", "body_contact_force", "penetration", "time_lost", "reach_distance",
        "arm_extended_time", "pull_force", "robot_jerk_rms", "delta_t", "delta_x",
    )},
    "sim_unstable": _parse_int,
    "steps": _parse_int,
}
OPENLOOP_COLUMNS: dict[str, Callable[[str], Any]] = {
    "agent": _NAME,
    "fold": _parse_int,
    "source_id": _KEY,
    "is_ood": _parse_bool,
    "n_queries": _parse_int,
    **{m: _parse_float for m in OPENLOOP_METRICS},
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
    path = Path(path)
    if path.is_symlink() or not path.is_file():
        raise BenchmarkFileError(f"{path}: not a regular file")
    size = path.stat().st_size
    if size > limit:
        raise BenchmarkFileError(f"{path}: {size} bytes, more than the {limit} allowed")
    with path.open("rb") as fh:
        data = fh.read(limit + 1)
    if len(data) > limit:
        raise BenchmarkFileError(f"{path}: more than the {limit} bytes allowed")
    return data


def read_episodes(path: str | Path) -> tuple[str, list[dict]]:
    """``(track, rows)`` of a benchmark per-episode CSV, every value parsed and checked."""
    path = Path(path)
    try:
        text = _read_bounded(path, MAX_CSV_BYTES).decode("utf-8")
    except UnicodeDecodeError as exc:
        raise BenchmarkFileError(f"{path}: not UTF-8 text ({exc.reason})") from None
    reader = csv.reader(io.StringIO(text, newline=""))
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
    rows, seen = [], set()
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


def sha256_file(path: str | Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


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
    return v is None or (isinstance(v, (int, float)) and not isinstance(v, bool)
                         and math.isfinite(v))


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
NAME = _leaf(lambda v: isinstance(v, str) and bool(NAME_RE.match(v)), "an agent name")
HEX32_OR_NULL = _leaf(lambda v: v is None or (isinstance(v, str) and bool(HEX32.match(v))),
                      "32 hex digits or null")
H32 = _leaf(lambda v: isinstance(v, str) and bool(HEX32.match(v)), "32 hex digits")
H64 = _leaf(lambda v: isinstance(v, str) and bool(HEX64.match(v)), "64 hex digits")
H64_OR_EMPTY = _leaf(lambda v: isinstance(v, str) and (v == "" or bool(HEX64.match(v))),
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
    elif not (v is None or isinstance(v, bool) or _num_or_null(v)):
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
