"""The range of walks the person was calibrated on, measured on the recordings
(``handover-data calibrated-range PATH/whole_motions --out docs/calibration``).

:func:`run_calibrated_range`

1. loads every recording of the folder with the safe loader and measures the fields of
   :func:`handover_env.person.calibrated_range.recording_fields` (median walking speed, body
   height, the nearest the pelvis comes to the giver, the longest pause), the definitions the env
   applies to a walker or a replay;
2. splits the recordings into Table I's halves as the receiver calibration does
   (:func:`~handover_env.data.dataset.stratified_fold_ids` over the files in
   :func:`~handover_env.data.public.list_public_files` order, 10 folds, seed 0): folds 0-4 are the
   **calibration half**;
3. on the calibration half (ID and OOD pooled: the person was calibrated on both), the range of
   each field is lowest to highest over its recordings
   (:data:`~handover_env.person.calibrated_range.LOW_Q`, ``HIGH_Q``): the person's rules were
   fitted to every one of them, and the scripted walkers are drawn from the whole recorded
   distribution, so a 2.5-97.5 % range would call 15 % of the calibration recordings themselves
   and a fifth of the default walkers uncalibrated (``calibrated_range.md`` gives the counts);
4. writes ``calibrated_range.json`` and ``calibrated_range.md`` (quantiles over recordings,
   per half and ID / OOD, for groups of at least :data:`MIN_N`; how many recordings of each
   group lie within the range).

Nothing per recording is written but the range's two ends, which are bounds over recordings.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from handover_env.data.errors import DatasetError
from handover_env.data.public import (
    OOD_PREFIX,
    safe_load_pickle,
    validate_record,
)
from handover_env.person.calibrated_range import (
    FIELDS,
    HIGH_Q,
    LOW_Q,
    CalibratedRange,
    check,
    recording_fields,
)
from handover_eval.calibration.report import (
    DEFAULT_CALIBRATION_FOLDS,
    DEFAULT_FOLDS,
    DEFAULT_SEED,
    measure_files,
    table1_folds,
    write_json,
)
from handover_eval.reporting import markdown_table, write_text

JSON_NAME, MD_NAME = "calibrated_range.json", "calibrated_range.md"
COMMAND = "handover-data calibrated-range PATH/whole_motions --out docs/calibration"
#: Quantiles reported per group, for groups of at least MIN_N recordings (in a smaller group a
#: quantile is close to one recording's own value).
PROBABILITIES = (0.01, 0.025, 0.05, 0.25, 0.50, 0.75, 0.95, 0.975, 0.99)
MIN_N = 10
GROUPS = ("calibration/id", "calibration/ood", "calibration/all",
          "held_out/id", "held_out/ood", "held_out/all")


def measure_folder(
    folder: str | os.PathLike, *, skip_bad: bool = False, progress: bool = True
) -> tuple[list[dict], list[tuple[str, str]]]:
    """``recording_fields`` of every recording (in memory only) with ``is_ood``, and the skipped
    files as ``(name, reason)``."""
    def measure(path: Path) -> dict:
        try:
            record = validate_record(safe_load_pickle(path), str(path))
            values = recording_fields(record["pose_receiver"])
        except (DatasetError, OSError, ValueError) as exc:
            raise DatasetError(f"{path}: {exc}") from exc
        return {**values, "is_ood": path.name.startswith(OOD_PREFIX)}

    return measure_files(folder, measure, desc="calibrated-range", skip_bad=skip_bad,
                         progress=progress)


def assign_halves(
    rows: list[dict], folds: int, seed: int, calibration_folds: int
) -> None:
    """Set each row's ``calibration`` flag: Table I folds ``0 .. calibration_folds - 1``."""
    fold_of = table1_folds([r["is_ood"] for r in rows], folds, seed, calibration_folds)
    for row, fold in zip(rows, fold_of, strict=True):
        row["calibration"] = bool(fold < calibration_folds)


def _group(rows: list[dict], name: str) -> list[dict]:
    half, kind = name.split("/")
    return [r for r in rows if r["calibration"] == (half == "calibration")
            and (kind == "all" or r["is_ood"] == (kind == "ood"))]


def _quantiles(values: np.ndarray) -> dict:
    v = values[np.isfinite(values)]
    return {"n": int(v.size),
            **{f"p{100 * p:g}": (float(np.quantile(v, p)) if v.size >= MIN_N else None)
               for p in PROBABILITIES}}


def derive_range(rows: list[dict]) -> CalibratedRange:
    """The range of the calibration half (module docstring), its ends rounded outward to 1/1000
    of the unit.

    Raises:
        ValueError: fewer than 2 calibration recordings.
    """
    calib = _group(rows, "calibration/all")
    if len(calib) < 2:
        raise ValueError(f"only {len(calib)} calibration recording(s): cannot state a range")
    out: dict[str, tuple[float, float]] = {}
    for name in FIELDS:
        v = np.array([r[name] for r in calib], dtype=np.float64)
        lo, hi = float(np.quantile(v, LOW_Q)), float(np.quantile(v, HIGH_Q))
        # to 1/1000 of the unit, outward (every calibration recording stays within)
        out[name] = (math.floor(lo * 1000.0) / 1000.0, math.ceil(hi * 1000.0) / 1000.0)
    return CalibratedRange(**out)


def summarise(
    rows: list[dict],
    *,
    source: str = "",
    folds: int = DEFAULT_FOLDS,
    seed: int = DEFAULT_SEED,
    calibration_folds: int = DEFAULT_CALIBRATION_FOLDS,
    skipped: Sequence[tuple[str, str]] = (),
) -> dict:
    """The JSON-able summary (module docstring)."""
    rng = derive_range(rows)
    groups = {g: _group(rows, g) for g in GROUPS}
    within = {}
    for g, members in groups.items():
        inside = [not check({k: r[k] for k in FIELDS}, rng) for r in members]
        per_field = {name: sum(not check({name: r[name]}, rng) for r in members)
                     for name in FIELDS}
        within[g] = {"n": len(members), "all_fields": int(sum(inside)), **per_field}
    return {
        "command": COMMAND,
        "source": source,
        "recordings": len(rows),
        "skipped_files": len(skipped),
        "split": {
            "method": "Table I stratified folds (handover_env.data.dataset.stratified_fold_ids) "
                      "over the files in list_public_files order",
            "folds": folds, "seed": seed,
            "calibration_folds": list(range(calibration_folds)),
            "held_out_folds": list(range(calibration_folds, folds)),
        },
        "quantile_range": [LOW_Q, HIGH_Q],
        "min_group_for_quantiles": MIN_N,
        "fields": {name: {"label": label, "unit": unit} for name, (label, unit) in FIELDS.items()},
        "range": {name: list(v) for name, v in rng.as_dict().items()},
        "quantiles": {
            name: {g: _quantiles(np.array([r[name] for r in m], dtype=np.float64))
                   for g, m in groups.items()}
            for name in FIELDS
        },
        "pause_walks": {g: int(sum(r["pause"] > 0 for r in m)) for g, m in groups.items()},
        "pause_quantiles_over_paused": {
            g: _quantiles(np.array([r["pause"] for r in m if r["pause"] > 0], dtype=np.float64))
            for g, m in groups.items()
        },
        "within": within,
    }


def _f(v: float | None, digits: int) -> str:
    return "–" if v is None or not math.isfinite(v) else f"{v:.{digits}f}"


def markdown(summary: dict) -> str:
    """The page ``calibrated_range.md``."""
    split = summary["split"]
    digits = {"speed": 2, "height": 3, "pass_distance": 2, "pause": 2}
    text = (
        "# The walks the simulated person was calibrated on\n\n"
        f"Generated by `{summary['command']}` from `{summary['source']}` "
        f"({summary['recordings']} recordings, {summary['skipped_files']} skipped). Code: "
        "`handover_eval/calibration/calibrated_range.py` (this page), "
        "`handover_env/person/calibrated_range.py` (the definitions, the range as constants, the "
        "check the env runs at reset). Statistics over recordings only.\n\n"
        f"The person was calibrated on the calibration half (Table I folds "
        f"{split['calibration_folds'][0]}-{split['calibration_folds'][-1]}, seed "
        f"{split['seed']}). The range of a field is lowest to highest over those recordings (ID "
        "and OOD pooled): the person's rules were fitted to every one of them, and the scripted "
        "walkers are drawn from the recordings' whole distribution (quantile tables that run to "
        "its extremes). A 2.5-97.5 % range would call a sixth of the calibration recordings "
        "themselves, and about a fifth of the default scripted walkers, uncalibrated (the last "
        "table counts the recordings within the range).\n\n"
        "## The range\n\n"
    )
    rows = []
    for name, (lo, hi) in summary["range"].items():
        label, unit = summary["fields"][name]["label"], summary["fields"][name]["unit"]
        rows.append((f"`{name}`", label, unit, _f(lo, digits[name]), _f(hi, digits[name])))
    text += markdown_table(("field", "what", "unit", "low", "high"), rows)
    text += (
        "\nDefinitions (`handover_env.person.calibrated_range`), the same for a recording and a "
        "scripted walk: `speed`: median speed of the pelvis xy low-passed at 1 Hz, over the "
        "whole walk; `height`: a recording's median right-shoulder (BODY_34 joint 12) height / "
        "0.818, a walker's `height`; `pass_distance`: the nearest the pelvis comes to the giver "
        "at the origin, horizontally; `pause`: the longest stretch with that speed below "
        "0.25 m/s for at least 0.3 s (as `walkers.md`), 0 if none. Recordings are filtered "
        "as a replay is (`smooth_track`); a scripted walker is measured on its nominal pelvis "
        "track. The recorded heights are the body tracker's: its skeleton has nearly fixed "
        "proportions (`shared/data` README: bone lengths vary by under 6 %), so their range "
        "is narrow.\n\n"
        "## What the person does outside it\n\n"
        "Nothing outside is refused: a walk that is physically valid is simulated, the env "
        "warns once (naming the field and the range) and sets `info[\"within_calibration\"]` to "
        "False. The person's rules then run on numbers fitted to other walks: a faster walker "
        "meets the object sooner than the reach lead time allows for and more often walks past "
        "it (`missed`); a taller or shorter one reaches with the take-distance line and the "
        "comfort fraction fitted at the recorded heights; a longer pause holds the reach "
        "decision for longer.\n\n"
        "## Quantiles over recordings\n\n"
    )
    for name in FIELDS:
        label, unit = summary["fields"][name]["label"], summary["fields"][name]["unit"]
        text += f"### `{name}`: {label} ({unit})\n\n"
        q = summary["quantiles"][name]
        probs = [k for k in next(iter(q.values())) if k != "n"]
        text += markdown_table(
            ("group", "n", *(k.replace("p", "") + " %" for k in probs)),
            [(g.replace("_", "-").replace("/", " "), v["n"],
              *(_f(v[k], digits[name]) for k in probs)) for g, v in q.items()],
        )
        text += "\n"
    text += ("### `pause` over the walks that pause (s)\n\nQuantiles only for groups of at "
             f"least {MIN_N} walks that pause.\n\n")
    q = summary["pause_quantiles_over_paused"]
    probs = [k for k in next(iter(q.values())) if k != "n"]
    text += markdown_table(
        ("group", "walks that pause", *(k.replace("p", "") + " %" for k in probs)),
        [(g.replace("_", "-").replace("/", " "), v["n"], *(_f(v[k], 2) for k in probs))
         for g, v in q.items()],
    )
    text += "\n## Recordings within the range\n\n"
    text += markdown_table(
        ("group", "n", "all fields", *(f"`{n}`" for n in FIELDS)),
        [(g.replace("_", "-").replace("/", " "), v["n"], v["all_fields"],
          *(v[n] for n in FIELDS)) for g, v in summary["within"].items()],
    )
    return text


def run_calibrated_range(
    folder: str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    folds: int = DEFAULT_FOLDS,
    seed: int = DEFAULT_SEED,
    calibration_folds: int = DEFAULT_CALIBRATION_FOLDS,
    skip_bad: bool = False,
    progress: bool = True,
) -> tuple[dict, list[Path]]:
    """Measure ``folder``, split it, write the JSON and the page into ``out_dir``."""
    rows, skipped = measure_folder(folder, skip_bad=skip_bad, progress=progress)
    assign_halves(rows, folds, seed, calibration_folds)
    summary = summarise(rows, source=Path(folder).name, folds=folds, seed=seed,
                        calibration_folds=calibration_folds, skipped=skipped)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    return summary, [write_json(summary, out / JSON_NAME),
                     write_text(markdown(summary), out / MD_NAME)]


__all__ = ["assign_halves", "derive_range", "markdown", "measure_folder", "run_calibrated_range",
           "summarise"]
