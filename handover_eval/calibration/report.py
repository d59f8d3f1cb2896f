"""The receiver calibration report: every recording analysed, split into halves, summarised as
quantiles.

``handover-data transfer-stats PATH/whole_motions --out docs/calibration`` runs
:func:`run_transfer_stats`, which

1. loads each ``motion_normal_*`` / ``motion_variation_*`` pickle with the safe loader
   (:func:`~handover_env.data.public.safe_load_pickle`, numpy arrays only) and analyses it with
   :func:`~handover_eval.calibration.measures.analyse_recording`;
2. splits the recordings into a **calibration half** and a **held-out half** with Table I's
   stratified folds (:func:`~handover_env.data.dataset.stratified_fold_ids` over the files in
   :func:`~handover_env.data.public.list_public_files` order, i.e. the order of
   ``load_public_dataset``; 10 folds, seed 0): folds 0-4 calibrate, folds 5-9 are held out;
3. writes ``receiver_calibration.json`` (quantiles 5/25/50/75/95 of every quantity, per half and
   ID / OOD / pooled, detection counts, track noise before and after the filter, the rules'
   constants) and ``receiver_calibration.md`` (the same as tables), plus the figures of
   :mod:`handover_eval.calibration.figures`.

Only statistics over recordings leave this module; no per-recording value is written.
"""

from __future__ import annotations

import json
import os
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

import numpy as np
from tqdm.auto import tqdm

from handover_env.data import detect, filtering
from handover_env.data.dataset import stratified_fold_ids
from handover_env.data.errors import DatasetError
from handover_env.data.public import (
    OOD_PREFIX,
    list_public_files,
    safe_load_pickle,
    validate_record,
)
from handover_eval.calibration import decisions, release
from handover_eval.calibration.measures import (
    HAND_JUMP,
    MEASURES,
    RecordingAnalysis,
    analyse_recording,
    track_noise,
)
from handover_eval.reporting import write_text

QUANTILES = (5, 25, 50, 75, 95)
#: Grasp radii (m) and quantiles (%) of the recorded-hand grasp table.
GRASP_RADII = (0.05, 0.10, 0.15, 0.20, 0.25, 0.30, 0.35)
GRASP_QUANTILES = (50, 80, 90, 95, 99)
HALVES = ("calibration", "held_out")
KINDS = ("id", "ood", "all")
DEFAULT_FOLDS, DEFAULT_SEED, DEFAULT_CALIBRATION_FOLDS = 10, 0, 5
JSON_NAME, MD_NAME = "receiver_calibration.json", "receiver_calibration.md"
T = TypeVar("T")


@dataclass
class RecordingResult:
    """One recording's analysis, kept in memory only (never written).

    Attributes:
        name: file stem, e.g. ``motion_normal_12``.
        is_ood: a ``motion_variation_*`` recording.
        analysis: the :class:`RecordingAnalysis`.
        noise_raw, noise_smooth: :func:`track_noise` of the receiver before / after the filter.
        hampel_replaced: receiver samples (joint coordinates) the outlier pass replaced.
        fold, calibration: Table I fold and whether it is in the calibration half (set by
            :func:`assign_halves`).
    """

    name: str
    is_ood: bool
    analysis: RecordingAnalysis
    noise_raw: dict[str, float]
    noise_smooth: dict[str, float]
    hampel_replaced: int
    fold: int = -1
    calibration: bool = False


def analyse_file(path: str | os.PathLike, rate_hz: float = detect.RATE_HZ) -> RecordingResult:
    """Safely load one public-dataset pickle and analyse it.

    Raises:
        DatasetError: the file cannot be loaded or validated, or is too short to analyse.
    """
    path = Path(path)
    record = validate_record(safe_load_pickle(path), str(path))
    receiver = record["pose_receiver"]
    try:
        analysis = analyse_recording(receiver, record["pose_object"], record["pose_giver"], rate_hz)
    except ValueError as exc:
        raise DatasetError(f"{path}: cannot analyse: {exc}") from exc
    _, replaced = filtering.hampel(receiver)
    smooth = filtering.smooth_track(receiver, rate_hz)
    noise_smooth = track_noise(smooth, rate_hz)
    onset, k = analysis.events["onset"], analysis.events["transfer"]
    steps = np.linalg.norm(np.diff(smooth[:, detect.R_HAND], axis=0), axis=1)
    jumps = np.flatnonzero(steps > HAND_JUMP)
    in_reach = (jumps >= onset - 3) & (jumps <= k + 3) if onset is not None else np.zeros(0, bool)
    noise_smooth["hand_jumps_in_reach"] = float(in_reach.sum())
    return RecordingResult(
        name=path.stem,
        is_ood=path.name.startswith(OOD_PREFIX),
        analysis=analysis,
        noise_raw=track_noise(receiver, rate_hz),
        noise_smooth=noise_smooth,
        hampel_replaced=int(replaced.sum()),
    )


def analyse_folder(
    folder: str | os.PathLike,
    *,
    skip_bad: bool = False,
    progress: bool = True,
    limit: int | None = None,
) -> tuple[list[RecordingResult], list[tuple[str, str]]]:
    """Analyse every dataset file of ``folder`` (ID first, then OOD, natural order).

    Args:
        folder: the dataset's ``whole_motions`` folder.
        skip_bad: skip files that fail to load or analyse instead of raising.
        progress: show a tqdm bar.
        limit: analyse only the first ``limit`` files of each kind (a quick look; the split is
            then not Table I's).

    Returns:
        ``(results, skipped)`` with ``skipped`` as ``(file name, reason)`` pairs.
    """
    files = list_public_files(folder)
    if limit is not None:
        ood = [p for p in files if p.name.startswith(OOD_PREFIX)]
        files = [p for p in files if not p.name.startswith(OOD_PREFIX)][:limit] + ood[:limit]
    return measure_files(folder, analyse_file, desc="transfer-stats", skip_bad=skip_bad,
                         progress=progress, files=files, verb="analysed")


def measure_files(
    folder: str | os.PathLike,
    measure: Callable[[Path], T],
    *,
    desc: str,
    skip_bad: bool = False,
    progress: bool = True,
    files: list[Path] | None = None,
    verb: str = "measured",
) -> tuple[list[T], list[tuple[str, str]]]:
    """``measure(path)`` of every dataset file of ``folder`` (``files``, default
    :func:`list_public_files` order), under a tqdm bar named ``desc``: the calibration family's
    one file loop.

    A file whose ``measure`` raises :class:`DatasetError` or ``OSError`` is re-raised, or with
    ``skip_bad`` left out and listed as ``(file name, reason)``, the reason without the
    ``"{path}: "`` its message starts with.

    Raises:
        DatasetError: no file of ``folder`` could be measured (``verb`` names how).
    """
    files = list_public_files(folder) if files is None else files
    rows: list[T] = []
    skipped: list[tuple[str, str]] = []
    for path in tqdm(files, desc=desc, unit="file", disable=not progress):
        try:
            rows.append(measure(path))
        except (DatasetError, OSError) as exc:
            if not skip_bad:
                raise
            skipped.append((path.name, str(exc).removeprefix(f"{path}: ")))
    if not rows:
        raise DatasetError(f"{folder}: none of the {len(files)} dataset file(s) could be {verb}")
    return rows, skipped


def assign_halves(
    results: list[RecordingResult],
    folds: int = DEFAULT_FOLDS,
    seed: int = DEFAULT_SEED,
    calibration_folds: int = DEFAULT_CALIBRATION_FOLDS,
) -> None:
    """Set each result's Table I fold and half: folds ``0 .. calibration_folds - 1`` calibrate.

    The fold assignment is :func:`stratified_fold_ids` over the results in their order (that of
    :func:`list_public_files`, i.e. of Table I's dataset), so it is Table I's own split.
    """
    fold_of = table1_folds([r.is_ood for r in results], folds, seed, calibration_folds)
    for result, fold in zip(results, fold_of):
        result.fold, result.calibration = int(fold), bool(fold < calibration_folds)


def table1_folds(
    is_ood: list[bool], folds: int, seed: int, calibration_folds: int
) -> np.ndarray:
    """Table I's fold of each recording (:func:`stratified_fold_ids` in the given order), after
    checking that folds ``0 .. calibration_folds - 1`` leave a held-out half."""
    if not 1 <= calibration_folds < folds:
        raise ValueError(f"calibration_folds must be in [1, {folds - 1}], got {calibration_folds}")
    return stratified_fold_ids(np.array(is_ood), folds, seed)


def _groups(results: list[RecordingResult]) -> dict[str, list[RecordingResult]]:
    """``{half}/{kind}`` -> results, plus ``all/all``."""
    out: dict[str, list[RecordingResult]] = {}
    for half in HALVES:
        mine = [r for r in results if r.calibration == (half == "calibration")]
        out[f"{half}/id"] = [r for r in mine if not r.is_ood]
        out[f"{half}/ood"] = [r for r in mine if r.is_ood]
        out[f"{half}/all"] = mine
    out["all/all"] = list(results)
    return out


def quantiles(values: np.ndarray) -> dict[str, float | int | None]:
    """``n`` finite values and their 5/25/50/75/95 % quantiles (None when there are none)."""
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    out: dict[str, float | int | None] = {"n": int(v.size)}
    for q in QUANTILES:
        out[f"p{q}"] = round(float(np.percentile(v, q)), 4) if v.size else None
    return out


def _detection(group: list[RecordingResult]) -> dict:
    events = ("transfer", "onset", "release", "arm_back")
    counts = {e: sum(r.analysis.events[e] is not None for r in group) for e in events}
    failures = Counter(r.analysis.failure for r in group if r.analysis.events["transfer"] is None)
    return {"recordings": len(group), **counts, "no_transfer": dict(sorted(failures.items()))}


def _noise(group: list[RecordingResult]) -> dict:
    out: dict = {}
    for stage in ("raw", "smooth"):
        rows = [getattr(r, f"noise_{stage}") for r in group]
        speed = np.array([n["pelvis_max_speed"] for n in rows])
        step = np.array([n["hand_max_step"] for n in rows])
        jumps = np.array([n["hand_jumps"] for n in rows])
        out[stage] = {
            "pelvis_max_speed": quantiles(speed),
            "recordings_pelvis_over_2mps": int((speed > 2.0).sum()),
            "pelvis_max_speed_max": round(float(speed.max()), 3) if speed.size else None,
            "hand_max_step": quantiles(step),
            "recordings_with_hand_jump": int((jumps > 0).sum()),
            "hand_jump_frames": int(jumps.sum()),
        }
    out["smooth"]["hand_jump_frames_within_reach"] = int(
        sum(r.noise_smooth.get("hand_jumps_in_reach", 0) for r in group)
    )
    out["hampel_replaced_samples"] = int(sum(r.hampel_replaced for r in group))
    return out


def grasp_radius(group: list[RecordingResult]) -> dict[str, list[float]]:
    """How often a replayed recorded hand (joint 15, smoothed) would close on the object.

    For each radius of :data:`GRASP_RADII`: the fraction of the group's recordings whose hand
    comes within it of the object in the window :data:`~.measures.GRASP_WINDOW` around the
    transfer (recordings without a transfer count as misses), and anywhere in the recording.
    Also the 50/80/90/95/99 % quantiles of the joint-15 distance at the transfer and its minimum
    over that window, over recordings with a transfer.
    """
    n = max(1, len(group))
    window = np.array([r.analysis.measures["d15_min_window"] for r in group], dtype=np.float64)
    anywhere = np.array([r.analysis.measures["d15_min"] for r in group], dtype=np.float64)
    out: dict[str, list[float]] = {
        "radius": list(GRASP_RADII),
        "within_window": [round(float(np.sum(window <= r)) / n, 4) for r in GRASP_RADII],
        "anywhere": [round(float(np.sum(anywhere <= r)) / n, 4) for r in GRASP_RADII],
        "quantile": list(GRASP_QUANTILES),
    }
    for name in ("d15_transfer", "d15_min_window"):
        v = np.array([r.analysis.measures[name] for r in group], dtype=np.float64)
        v = v[np.isfinite(v)]
        out[name] = [
            round(float(np.percentile(v, q)), 4) if v.size else None for q in GRASP_QUANTILES
        ]
    return out


def rules() -> dict[str, float | int | str]:
    """The constants of the detectors and of the filter, for the report."""
    names = (
        "NEAR_RADIUS HOLD_RADIUS HOLD_TIME ARRIVAL_SPEED COMOVE_TIME COMOVE_FRACTION LEAD_FRACTION "
        "MAX_LEAD_TIME HEADING_CUTOFF_HZ SPEED_CUTOFF_HZ MIN_HEADING_SPEED BASELINE_GAP "
        "MIN_BASELINE_FRAMES ONSET_RISE ONSET_BACKTRACK RELEASE_BASELINE_TIME RELEASE_MARGIN "
        "RELEASE_HOLD_TIME RELEASE_SPEED ARM_BACK_MARGIN"
    ).split()
    out: dict[str, float | int | str] = {
        f"transfer.{n}": getattr(release if n.startswith(("RELEASE", "ARM_BACK")) else detect, n)
        for n in names
    }
    for n in ("CUTOFF_HZ", "ORDER", "HAMPEL_HALF_WINDOW", "HAMPEL_SIGMAS", "HAMPEL_MIN_DEVIATION"):
        out[f"filtering.{n}"] = getattr(filtering, n)
    out["hand joints"] = "nearest of " + ", ".join(map(str, detect.HAND_JOINTS))
    out["decisions.PAUSE_SPEED"] = decisions.PAUSE_SPEED
    out["decisions.GIVE_UP_BEHIND"] = decisions.GIVE_UP_BEHIND
    out["decisions.TOWARD_WINDOW"] = decisions.TOWARD_WINDOW
    return out


def summarise(
    results: list[RecordingResult],
    *,
    source: str = "",
    folds: int = DEFAULT_FOLDS,
    seed: int = DEFAULT_SEED,
    calibration_folds: int = DEFAULT_CALIBRATION_FOLDS,
    skipped: list[tuple[str, str]] | None = None,
) -> dict:
    """The JSON-able summary: split, rules, detection counts, quantiles of every measure, noise."""
    groups = _groups(results)
    return {
        "source": source,
        "rate_hz": detect.RATE_HZ,
        "recordings": len(results),
        "skipped_files": len(skipped or []),
        "split": {
            "method": "Table I stratified folds (handover_env.data.dataset.stratified_fold_ids) "
            "over the files in list_public_files order",
            "folds": folds,
            "seed": seed,
            "calibration_folds": list(range(calibration_folds)),
            "held_out_folds": list(range(calibration_folds, folds)),
        },
        "groups": {g: len(v) for g, v in groups.items()},
        "rules": rules(),
        "failures": detect.FAILURES,
        "detection": {g: _detection(v) for g, v in groups.items()},
        "measures": {
            name: {"section": sec, "label": label, "unit": unit}
            for name, (sec, label, unit) in MEASURES.items()
        },
        "quantiles": {
            name: {
                g: quantiles(np.array([r.analysis.measures[name] for r in v], dtype=np.float64))
                for g, v in groups.items()
            }
            for name in MEASURES
        },
        "noise": {g: _noise(v) for g, v in groups.items() if g.endswith("/all")},
        "grasp_radius": {g: grasp_radius(v) for g, v in groups.items()},
        "left_behind_check": {
            g: decisions.rule_check([r.analysis.measures for r in v if r.analysis.events["transfer"]
                                 is not None])
            for g, v in groups.items()
        },
        "reach": decisions.reach_summary(
            [r.analysis.measures for r in groups["calibration/all"]],
            [r.analysis.measures for r in groups["held_out/all"]],
        ),
    }


def write_json(summary: dict, path: str | os.PathLike) -> Path:
    """Write the summary as indented JSON (:func:`handover_eval.reporting.write_text`)."""
    return write_text(json.dumps(summary, indent=1) + "\n", path)


def run_transfer_stats(
    folder: str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    folds: int = DEFAULT_FOLDS,
    seed: int = DEFAULT_SEED,
    calibration_folds: int = DEFAULT_CALIBRATION_FOLDS,
    skip_bad: bool = False,
    figures: bool = True,
    progress: bool = True,
    limit: int | None = None,
) -> tuple[dict, list[Path]]:
    """Analyse ``folder``, split it, write the JSON, the markdown and the figures into ``out_dir``.

    Returns:
        ``(summary, written paths)``.
    """
    from handover_eval.calibration.markdown import write_markdown

    results, skipped = analyse_folder(folder, skip_bad=skip_bad, progress=progress, limit=limit)
    assign_halves(results, folds, seed, calibration_folds)
    summary = summarise(
        results, source=Path(folder).name, folds=folds, seed=seed,
        calibration_folds=calibration_folds, skipped=skipped,
    )
    summary["limit"] = limit
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = [write_json(summary, out / JSON_NAME)]
    figure_names: list[str] = []
    if figures:
        from handover_eval.calibration.figures import write_figures

        paths = write_figures(results, out)
        written += paths
        figure_names = [p.name for p in paths]
    written.append(write_markdown(summary, out / MD_NAME, figure_names, skipped))
    return summary, written
