"""The walker calibration report: recorded and scripted walks measured alike, summarised as
quantiles (``handover-data walk-stats PUBLIC_DIR --out docs/calibration``).

:func:`run_walk_stats`

1. measures every recording of the folder (:func:`~handover_eval.calibration.walks.recorded_walk`
   and :func:`~handover_eval.calibration.walks.walk_statistics`; the safe loader, numpy arrays
   only) and splits them into Table I's folds as the receiver calibration does
   (:func:`~handover_env.data.dataset.stratified_fold_ids` over the files in
   :func:`~handover_env.data.public.list_public_files` order, 10 folds, seed 0): folds 0-4 are the
   **calibration half**, 5-9 are **held out**;
2. measures ``walkers`` scripted ID and OOD walkers with the closed-loop evaluation's seeds
   (ID 0.., OOD 10000..) (:func:`~handover_eval.calibration.walks.scripted_walk`);
3. writes ``walkers.json`` (the quantiles), ``walkers.md`` (the calibration table: recorded OOD
   median [IQR] on either half, scripted OOD median, their ratio, and whether it lies within
   :data:`TOLERANCE` of the calibration half's median) and ``walkers.png``.

Only statistics over recordings leave this module; no per-recording value is written.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from handover_env.data.dataset import stratified_fold_ids
from handover_env.data.errors import DatasetError
from handover_env.data.public import (
    OOD_PREFIX,
    safe_load_pickle,
    validate_record,
)
from handover_eval.calibration.report import measure_files, write_json
from handover_eval.calibration.walks import (
    PAUSE_MIN_TIME,
    PAUSE_SPEED,
    STATISTICS,
    WalkStatistics,
    recorded_walk,
    scripted_walk,
    walk_statistics,
)
from handover_eval.reporting import write_png, write_text

JSON_NAME, MD_NAME, FIGURE_NAME = "walkers.json", "walkers.md", "walkers.png"
DEFAULT_FOLDS, DEFAULT_SEED, DEFAULT_CALIBRATION_FOLDS = 10, 0, 5
DEFAULT_WALKERS = 400
#: The seeds of the closed-loop evaluation's scripted walkers (handover_eval closedloop).
FIRST_SEED = {"id": 0, "ood": 10_000}
#: The scripted OOD median must lie within this fraction of the recorded OOD median (issue 23).
TOLERANCE = 0.20
#: Derived over walks: the share of walks with at least one pause, and the median pause (over
#: all pauses of the group, not over walks).
DERIVED: dict[str, tuple[str, str, int]] = {
    "pause_share": ("walks with a pause (share)", "", 2),
    "pause_duration": ("pause duration (median over pauses)", "s", 2),
}
LABELS = {**STATISTICS, **DERIVED}
#: The statistics the OOD walkers are calibrated to, and why (each differs between the recorded ID
#: and OOD walks, and each is a different aspect of "wanders or pauses").
CHOSEN: dict[str, str] = {
    "heading_change": "the path's shape: how much the walker turns (meanders, loops, corners)",
    "detour": "how far off the direct line the walker goes (wide swings, loops, turn-backs)",
    "speed_cv": "the speed profile: slowing down, stopping and speeding up again",
    "pause_share": "how often a walk has a pause (a recorded ID walk almost never does)",
    "pause_duration": "how long a pause lasts",
}
GROUPS = (
    "recorded/calibration/id",
    "recorded/calibration/ood",
    "recorded/held_out/id",
    "recorded/held_out/ood",
    "scripted/id",
    "scripted/ood",
)


def measure_folder(
    folder: str | os.PathLike, *, skip_bad: bool = False, progress: bool = True
) -> tuple[list[tuple[WalkStatistics, bool]], list[tuple[str, str]]]:
    """Every recording's walk statistics and whether it is OOD, in :func:`list_public_files`
    order; ``skipped`` lists ``(file name, reason)`` of files that failed with ``skip_bad``."""
    def measure(path: Path) -> tuple[WalkStatistics, bool]:
        try:
            record = validate_record(safe_load_pickle(path), str(path))
            stats = walk_statistics(recorded_walk(record["pose_receiver"]))
        except (DatasetError, OSError, ValueError) as exc:
            raise DatasetError(f"{path}: {exc}") from exc
        return stats, path.name.startswith(OOD_PREFIX)

    return measure_files(folder, measure, desc="walk-stats", skip_bad=skip_bad,
                         progress=progress)


def measure_walkers(
    kind: str, n: int, progress: bool = True
) -> tuple[list[WalkStatistics], dict[str, int]]:
    """The walk statistics of ``n`` seeded scripted walkers of ``kind``, and how many walk in
    each OOD mode (``{"none": n}`` for ID)."""
    if n < 1:
        raise ValueError(f"walkers must be >= 1, got {n}")
    out, modes = [], {}
    seeds = range(FIRST_SEED[kind], FIRST_SEED[kind] + n)
    for seed in tqdm(seeds, desc=f"{kind} walkers", unit="walker", disable=not progress):
        xy, mode = scripted_walk(kind, seed)
        out.append(walk_statistics(xy))
        modes[mode or "none"] = modes.get(mode or "none", 0) + 1
    return out, modes


def summary_of(walks: Sequence[WalkStatistics]) -> dict[str, dict[str, float | int | None]]:
    """Median and 25/75 % of every statistic over ``walks`` (and of the pauses, over pauses)."""
    out: dict[str, dict[str, float | int | None]] = {}

    def q(values: list[float]) -> dict[str, float | int | None]:
        v = np.asarray(values, dtype=np.float64)
        v = v[np.isfinite(v)]
        if not v.size:
            return {"n": 0, "median": None, "q25": None, "q75": None}
        q25, med, q75 = np.percentile(v, [25, 50, 75])
        return {"n": int(v.size), "median": round(float(med), 4),
                "q25": round(float(q25), 4), "q75": round(float(q75), 4)}

    for name in STATISTICS:
        out[name] = q([w[name] for w in walks])
    share = float(np.mean([w["pauses"] > 0 for w in walks])) if walks else math.nan
    out["pause_share"] = {"n": len(walks), "median": round(share, 4), "q25": None, "q75": None}
    out["pause_duration"] = q([d for w in walks for d in w.pause_durations])
    return out


def calibration_table(summary: dict) -> list[dict]:
    """Per statistic: recorded OOD (calibration, held-out), recorded ID (calibration), scripted
    OOD and ID medians, the scripted / recorded OOD ratio and whether a chosen statistic lies
    within :data:`TOLERANCE` of the calibration half's median."""
    g = summary["groups"]
    rows = []
    for name in LABELS:
        cal = g["recorded/calibration/ood"][name]["median"]
        scripted = g["scripted/ood"][name]["median"]
        ratio = scripted / cal if cal and scripted is not None else math.nan
        held = g["recorded/held_out/ood"][name]["median"]
        rows.append({
            "statistic": name,
            "chosen": name in CHOSEN,
            "ratio": ratio,
            "ratio_held_out": scripted / held if held and scripted is not None else math.nan,
            "within": bool(math.isfinite(ratio) and abs(ratio - 1.0) <= TOLERANCE + 1e-12),
        })
    return rows


def summarise(
    recorded: list[tuple[WalkStatistics, bool]],
    scripted: dict[str, list[WalkStatistics]],
    modes: dict[str, int],
    *,
    source: str = "",
    folds: int = DEFAULT_FOLDS,
    seed: int = DEFAULT_SEED,
    calibration_folds: int = DEFAULT_CALIBRATION_FOLDS,
    skipped: Sequence[tuple[str, str]] = (),
) -> dict:
    """The JSON-able summary: split, thresholds, per-group quantiles, the calibration table."""
    if not 1 <= calibration_folds < folds:
        raise ValueError(f"calibration_folds must be in [1, {folds - 1}], got {calibration_folds}")
    ood = np.array([o for _, o in recorded])
    fold = stratified_fold_ids(ood, folds, seed)
    groups: dict[str, list[WalkStatistics]] = {}
    for (stats, is_ood), f in zip(recorded, fold, strict=True):
        half = "calibration" if f < calibration_folds else "held_out"
        groups.setdefault(f"recorded/{half}/{'ood' if is_ood else 'id'}", []).append(stats)
    for kind, walks in scripted.items():
        groups[f"scripted/{kind}"] = walks
    summary = {
        "source": source,
        "recordings": len(recorded),
        "skipped_files": len(skipped),
        "split": {
            "method": "Table I stratified folds (handover_env.data.dataset.stratified_fold_ids) "
            "over the files in list_public_files order",
            "folds": folds, "seed": seed,
            "calibration_folds": list(range(calibration_folds)),
            "held_out_folds": list(range(calibration_folds, folds)),
        },
        "walkers": {k: len(v) for k, v in scripted.items()},
        "walker_seeds": {k: FIRST_SEED[k] for k in scripted},
        "ood_modes": modes,
        "thresholds": {"pause_speed": PAUSE_SPEED, "pause_min_time": PAUSE_MIN_TIME,
                       "tolerance": TOLERANCE},
        "counts": {name: len(groups.get(name, [])) for name in GROUPS},
        "groups": {name: summary_of(groups.get(name, [])) for name in GROUPS},
    }
    summary["table"] = calibration_table(summary)
    return summary


def _fmt(value: float | int | None, digits: int) -> str:
    if value is None or not math.isfinite(float(value)):
        return "–"
    return f"{float(value):.{digits}f}"


def _cell(q: dict, digits: int) -> str:
    if q["median"] is None:
        return "–"
    if q["q25"] is None:
        return _fmt(q["median"], digits)
    return f"{_fmt(q['median'], digits)} [{_fmt(q['q25'], digits)}, {_fmt(q['q75'], digits)}]"


def markdown(summary: dict, figure: str | None = FIGURE_NAME) -> str:
    """walkers.md: what was measured, the calibration table, the ID/OOD contrast."""
    g, c = summary["groups"], summary["counts"]
    th = summary["thresholds"]
    table = {r["statistic"]: r for r in summary["table"]}
    chosen_ok = all(table[n]["within"] for n in CHOSEN)

    def row(name: str) -> str:
        label, unit, digits = LABELS[name]
        r = table[name]
        cells = [
            f"{'**' if name in CHOSEN else ''}{label}{'**' if name in CHOSEN else ''}"
            + (f" ({unit})" if unit else ""),
            _cell(g["recorded/calibration/ood"][name], digits),
            _cell(g["recorded/held_out/ood"][name], digits),
            _fmt(g["scripted/ood"][name]["median"], digits),
            _fmt(r["ratio"], 2),
            _fmt(r["ratio_held_out"], 2),
            ("yes" if r["within"] else "**no**") if name in CHOSEN else "(not chosen)",
            _cell(g["recorded/calibration/id"][name], digits),
            _fmt(g["scripted/id"][name]["median"], digits),
        ]
        return "| " + " | ".join(cells) + " |"

    lines = [
        "# Scripted walkers against the recorded walks",
        "",
        "Generated by `handover-data walk-stats PUBLIC_DIR --out docs/calibration` "
        "(`handover_eval/calibration/walks.py` defines the statistics, `walks_report.py` writes "
        "this page). Statistics over recordings only; nothing per recording.",
        "",
        f"Recordings: {summary['recordings']} ({summary['source']}); calibration half = Table I "
        f"folds {summary['split']['calibration_folds']} ({c['recorded/calibration/id']} ID + "
        f"{c['recorded/calibration/ood']} OOD), held out = folds "
        f"{summary['split']['held_out_folds']} ({c['recorded/held_out/id']} ID + "
        f"{c['recorded/held_out/ood']} OOD). Scripted walkers: {summary['walkers'].get('id', 0)} "
        f"ID (seeds {summary['walker_seeds'].get('id', 0)}..) and "
        f"{summary['walkers'].get('ood', 0)} OOD (seeds {summary['walker_seeds'].get('ood', 0)}.., "
        f"the closed-loop evaluation's; modes {summary['ood_modes']}), drawn by "
        "`handover_env.person.motion.sample_walker` and walked by "
        "`handover_env.person.trajectory.base_trajectory` (the nominal pelvis path).",
        "",
        "## How a walk is measured",
        "",
        "The same code (`walk_statistics`) measures both: a recorded walk is the receiver's pelvis "
        "(BODY_34 joint 0) after the filter the env applies to a replay (`smooth_track`), a "
        "scripted walk is the walker's nominal pelvis track at 30 Hz. Every statistic is over the "
        "**whole walk** (the recording from its first to its last frame, the scripted walk from "
        "its start to `end_x`, the same stretch of floor: the receiver approaches, passes the "
        "giver, takes the object and walks on to x ~ -0.8), so it needs no transfer detector. "
        "Speed: the track low-passed at 1 Hz (below the step frequency); heading: low-passed at "
        "0.5 Hz (below the stride frequency), counted while faster than 0.1 m/s. A **pause**: the "
        f"speed stays below {th['pause_speed']:g} m/s for at least {th['pause_min_time']:g} s. "
        "**Detour**: path length / net displacement - 1.",
        "",
        "## Calibration table (OOD)",
        "",
        "Median [25 %, 75 %] over walks (pause duration: over pauses; walks with a pause: the "
        "share). Ratio = scripted OOD median / recorded OOD median (calibration half; held-out "
        f"half beside it). Chosen statistics in bold; each must lie within {100 * TOLERANCE:.0f} % "
        "of the calibration half's recorded OOD median. The OOD walkers were calibrated on the "
        "calibration half only; the ID walkers were not changed.",
        "",
        "| statistic | recorded OOD, calibration | recorded OOD, held out | scripted OOD | ratio "
        "| ratio (held out) | within 20 % | recorded ID, calibration | scripted ID |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
        *(row(name) for name in LABELS),
        "",
        f"All chosen statistics within {100 * TOLERANCE:.0f} %: "
        f"**{'yes' if chosen_ok else 'no'}**.",
        "",
        "## Why these statistics",
        "",
        "Each chosen statistic separates the recorded OOD walks from the recorded ID walks (the "
        "last two columns against the first), and each is a different part of \"wanders or "
        "pauses\" (paper Sec. V-A):",
        "",
        *(f"* **{LABELS[n][0]}**: {why}." for n, why in CHOSEN.items()),
        "",
        "Not chosen: the median speed (OOD walkers walk about as fast as ID ones when they walk: "
        "it does not separate them), the slowest speed and the time paused (their OOD medians "
        "differ by more than 2x between the two recorded halves: a median of a mixture of "
        "walks with and without a stop, too unstable to calibrate to), the time walking back "
        "(its recorded OOD median is 0 on one half and a fraction of a second on the other; "
        "the scripted walkers walk back only inside their loops, so it stays lower: a "
        "difference that remains) and the duration (a consequence of the detour, the pauses "
        "and the speed). They are reported as checks.",
        "",
        "The two recorded halves hold about 40 OOD walks each and differ from each other (e.g. "
        "in the share of walks with a pause); the held-out ratio measures that difference as "
        "well as the walkers'.",
    ]
    if figure:
        lines += [
            "",
            f"![walk statistics](./{figure})",
            "",
            "Median and 25-75 % / 5-95 % ranges per group: recorded ID and OOD (calibration "
            "half), scripted ID and OOD.",
        ]
    return "\n".join(lines) + "\n"


def figure(summary_groups: dict[str, list[WalkStatistics]]):
    """Quantile bars (5/25/50/75/95 %) of the chosen statistics per group; returns the figure."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [n for n in CHOSEN if n in STATISTICS] + ["pause_duration"]
    colours = {"recorded ID": "tab:blue", "recorded OOD": "tab:red",
               "scripted ID": "tab:cyan", "scripted OOD": "tab:orange"}
    fig, axes = plt.subplots(1, len(names), figsize=(3.0 * len(names), 3.4), dpi=110)
    for ax, name in zip(axes, names, strict=True):
        for k, (label, walks) in enumerate(summary_groups.items()):
            if name == "pause_duration":
                v = np.array([d for w in walks for d in w.pause_durations])
            else:
                v = np.array([w[name] for w in walks])
            v = v[np.isfinite(v)]
            if v.size < 5:
                continue
            p5, p25, p50, p75, p95 = np.percentile(v, [5, 25, 50, 75, 95])
            ax.plot([k, k], [p5, p95], color=colours[label], lw=1)
            ax.plot([k, k], [p25, p75], color=colours[label], lw=6, alpha=0.6)
            ax.plot(k, p50, "o", color="k", ms=4)
        ax.set_xticks(range(len(summary_groups)))
        ax.set_xticklabels(list(summary_groups), rotation=35, ha="right", fontsize=7)
        label, unit, _ = LABELS[name]
        ax.set_title(label + (f" ({unit})" if unit else ""), fontsize=8)
        ax.grid(alpha=0.3, axis="y")
    fig.suptitle("Walk statistics: median, 25-75 % (thick), 5-95 % (thin)", fontsize=9)
    fig.tight_layout()
    return fig


def run_walk_stats(
    folder: str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    walkers: int = DEFAULT_WALKERS,
    folds: int = DEFAULT_FOLDS,
    seed: int = DEFAULT_SEED,
    calibration_folds: int = DEFAULT_CALIBRATION_FOLDS,
    skip_bad: bool = False,
    figures: bool = True,
    progress: bool = True,
) -> tuple[dict, list[Path]]:
    """Measure ``folder`` and the scripted walkers; write walkers.json/.md/.png into ``out_dir``.

    Returns:
        ``(summary, written paths)``.
    """
    recorded, skipped = measure_folder(folder, skip_bad=skip_bad, progress=progress)
    scripted, modes = {}, {}
    for kind in ("id", "ood"):
        scripted[kind], m = measure_walkers(kind, walkers, progress)
        if kind == "ood":
            modes = m
    summary = summarise(
        recorded, scripted, modes, source=Path(folder).name, folds=folds, seed=seed,
        calibration_folds=calibration_folds, skipped=skipped,
    )
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = [write_json(summary, out / JSON_NAME)]
    if figures:
        fold = stratified_fold_ids(np.array([o for _, o in recorded]), folds, seed)
        cal = [(w, o) for (w, o), f in zip(recorded, fold, strict=True) if f < calibration_folds]
        fig = figure({
            "recorded ID": [w for w, o in cal if not o],
            "recorded OOD": [w for w, o in cal if o],
            "scripted ID": scripted["id"],
            "scripted OOD": scripted["ood"],
        })
        written.append(write_png(fig, out / FIGURE_NAME))
    written.append(write_text(markdown(summary, FIGURE_NAME if figures else None), out / MD_NAME))
    return summary, written
