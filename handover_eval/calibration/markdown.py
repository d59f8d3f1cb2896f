"""Markdown rendering of the receiver calibration summary
(:mod:`handover_eval.calibration.report`)."""

from __future__ import annotations

import os
from pathlib import Path

from handover_eval.reporting import write_text

HALF_LABEL = {"calibration": "calibration", "held_out": "held-out", "all": "all"}
KIND_LABEL = {"id": "ID", "ood": "OOD", "all": "pooled"}
COLUMNS = (
    "calibration/id", "calibration/ood", "calibration/all",
    "held_out/id", "held_out/ood", "held_out/all",
)


def _label(group: str) -> str:
    half, kind = group.split("/")
    return f"{HALF_LABEL[half]} {KIND_LABEL[kind]}"


def _fmt(value: float | None, unit: str = "") -> str:
    if value is None:
        return "–"
    digits = 1 if unit == "deg" else 2 if unit in ("s", "m/s", "") else 3
    return f"{value:.{digits}f}"


def _cell(q: dict, unit: str) -> str:
    if not q["n"]:
        return "–"
    return f"{_fmt(q['p50'], unit)} [{_fmt(q['p25'], unit)}, {_fmt(q['p75'], unit)}]"


def _header(columns: list[str]) -> list[str]:
    return ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]


def _detection_table(summary: dict) -> list[str]:
    lines = _header(["group", "recordings", "transfer", "reach onset", "giver release",
                     "arm drawn back", "no transfer, by cause"])
    for group in (*COLUMNS, "all/all"):
        d = summary["detection"][group]
        causes = ", ".join(f"{k} {v}" for k, v in d["no_transfer"].items()) or "–"
        n = d["recordings"]
        pct = f" ({100 * d['transfer'] / n:.1f} %)" if n else ""
        lines.append(
            f"| {_label(group)} | {n} | {d['transfer']}{pct} | {d['onset']} | {d['release']} | "
            f"{d['arm_back']} | {causes} |"
        )
    return lines


def _headline(summary: dict) -> list[str]:
    lines: list[str] = []
    section = None
    for name, meta in summary["measures"].items():
        if meta["section"] != section:
            section = meta["section"]
            lines += ["", f"### {section}", ""]
            lines += _header(["quantity", "unit"] + [_label(g) for g in COLUMNS])
        q = summary["quantiles"][name]
        cells = " | ".join(_cell(q[g], meta["unit"]) for g in COLUMNS)
        lines.append(f"| {meta['label']} (`{name}`) | {meta['unit'] or '–'} | {cells} |")
    return lines


def _full(summary: dict) -> list[str]:
    lines = _header(["quantity", "group", "n", "5 %", "25 %", "50 %", "75 %", "95 %"])
    for name, meta in summary["measures"].items():
        for group in (*COLUMNS, "all/all"):
            q = summary["quantiles"][name][group]
            values = " | ".join(_fmt(q[f"p{p}"], meta["unit"]) for p in (5, 25, 50, 75, 95))
            lines.append(f"| `{name}` | {_label(group)} | {q['n']} | {values} |")
    return lines


def _noise(summary: dict) -> list[str]:
    lines = _header(["group", "stage", "pelvis max speed, m/s: median [95 %] (max)",
                     "recordings with pelvis > 2 m/s", "hand max step, m: median [95 %]",
                     "recordings with a hand step > 0.1 m", "hand steps > 0.1 m"])
    for group, noise in summary["noise"].items():
        for stage, label in (("raw", "recorded"), ("smooth", "smooth_track")):
            s = noise[stage]
            sp, st = s["pelvis_max_speed"], s["hand_max_step"]
            lines.append(
                f"| {_label(group)} | {label} | {_fmt(sp['p50'], 's')} [{_fmt(sp['p95'], 's')}] "
                f"({_fmt(s['pelvis_max_speed_max'], 's')}) | {s['recordings_pelvis_over_2mps']} | "
                f"{_fmt(st['p50'], 'm')} [{_fmt(st['p95'], 'm')}] | "
                f"{s['recordings_with_hand_jump']} | "
                f"{s['hand_jump_frames']} |"
            )
    within = {g: n["smooth"]["hand_jump_frames_within_reach"] for g, n in summary["noise"].items()}
    lines += [
        "",
        "After the filter, the hand steps over 0.1 m that fall within the reach (onset - 3 "
        "frames .. transfer + 3 frames: a fast reach while walking, not noise): "
        + ", ".join(f"{_label(g)} {v}" for g, v in within.items())
        + ".",
    ]
    hampel = {g: n["hampel_replaced_samples"] for g, n in summary["noise"].items()}
    lines += ["", "Samples (joint coordinates) changed by the outlier pass: "
              + ", ".join(f"{_label(g)} {v}" for g, v in hampel.items()) + "."]
    return lines


def _grasp(summary: dict) -> list[str]:
    groups = ("calibration/all", "held_out/all", "calibration/id", "calibration/ood")
    first = summary["grasp_radius"][groups[0]]
    lines = _header(["group", "what"] + [f"r = {r:.2f} m" for r in first["radius"]])
    for g in groups:
        gr = summary["grasp_radius"][g]
        for key, what in (("within_window", "within r, transfer -0.2 .. +0.5 s"),
                          ("anywhere", "within r, anywhere")):
            cells = " | ".join(f"{100 * v:.0f} %" for v in gr[key])
            lines.append(f"| {_label(g)} | {what} | {cells} |")
    lines += ["", *_header(["group", "joint 15 to object"] + [f"{q} %" for q in first["quantile"]])]
    for g in groups:
        gr = summary["grasp_radius"][g]
        for key, what in (
            ("d15_transfer", "at the transfer"),
            ("d15_min_window", "min, -0.2 .. +0.5 s"),
        ):
            lines.append(
                f"| {_label(g)} | {what} | " + " | ".join(_fmt(v, "m") for v in gr[key]) + " |"
            )
    return lines


def _walks(summary: dict) -> list[str]:
    """The left-behind rules run on the recorded walks (issue 23)."""
    rules = summary["rules"]
    lines = [
        "Each frame before the recorded transfer is judged as the simulated person judges it, "
        "with the object where it was then and the recorded right shoulder's path from there on "
        "as the person's remaining walk. **Former rule**: the object more than "
        f"{rules['decisions.GIVE_UP_BEHIND']} m behind the shoulder along the walk and within "
        "1.2 m of it. **Current rule** (`handover_env.person.receiver_rules.left_behind`, what "
        "`missed` now rests on): the same, and at no later frame of the remaining walk is the "
        "object again less than that far behind the shoulder within 1.2 m (the person does not "
        "turn back to it). A firing before the transfer is a false `missed`: the recorded person "
        "did take the object later.",
        "",
        *_header(["group", "recordings with a transfer", "former rule fires before the transfer",
                  "earliest (s before it)", "current rule fires before the transfer",
                  "earliest"]),
    ]
    for g in (*COLUMNS, "all/all"):
        c = summary["left_behind_check"][g]
        old, new = c["old_left_behind_earliest"], c["left_behind_earliest"]
        lines.append(
            f"| {_label(g)} | {c['recordings']} | {c['old_left_behind_count']} | "
            f"{'–' if old is None else f'{-old:.2f}'} | {c['left_behind_count']} | "
            f"{'–' if new is None else f'{-new:.2f}'} |"
        )
    return lines


def _reach(summary: dict) -> list[str]:
    """What the reach extent and the arm-out time depend on (issue 23)."""
    reach = summary["reach"]
    names = list(next(iter(next(iter(reach["correlations"].values())).values())))
    lines = [
        "Pearson r over recordings, per half, of the reach statistic (`object_shoulder_transfer`: "
        "right shoulder to object at the transfer, the one the env reports as `reach_distance`) "
        "and of the arm-out time (`arm_extended`) with how the object is presented and how the "
        "receiver walks.",
        "",
        *_header(["response", "half"] + [f"`{n}`" for n in names]),
    ]
    for half, table in reach["correlations"].items():
        for resp, row in table.items():
            cells = " | ".join("–" if v is None else f"{v:+.2f}" for v in row.values())
            lines.append(f"| `{resp}` | {HALF_LABEL[half]} | {cells} |")
    f = reach["fit"]
    if "rma_b" in f:
        lines += [
            "",
            f"Fit on the calibration half (n = {f['n']}, r = {f['r']:.2f}) of the reach on the "
            "closest approach `path_closest_onset`: least squares "
            f"{f['ls_a']:.3f} + {f['ls_b']:.3f} x; reduced major axis (the fitted reaches "
            f"spread as the recorded ones) {f['rma_a']:.3f} + {f['rma_b']:.3f} x. On the "
            f"held-out half (n = {f.get('held_out_n', 0)}) the line predicts the recorded reach "
            f"at r = {f.get('held_out_r', float('nan')):.2f}; SD of the predictions "
            f"{f.get('held_out_sd_rma', float('nan')):.3f} m (reduced major axis) / "
            f"{f.get('held_out_sd_ls', float('nan')):.3f} m (least squares) against the "
            f"recorded {f.get('held_out_sd', float('nan')):.3f} m.",
        ]
    return lines


def write_markdown(
    summary: dict,
    path: str | os.PathLike,
    figures: list[str] | None = None,
    skipped: list[tuple[str, str]] | None = None,
) -> Path:
    """Write ``receiver_calibration.md`` from a :func:`.report.summarise` dict."""
    split = summary["split"]
    rules = summary["rules"]
    lines = [
        "# Receiver calibration: when and where the object changes hands",
        "",
        "Generated by `handover-data transfer-stats PATH/whole_motions --out "
        f"docs/calibration` from `{summary['source']}` ({summary['recordings']} recordings"
        + (f", first {summary['limit']} of each kind only" if summary.get("limit") else "")
        + f", {summary['skipped_files']} skipped). Statistics over recordings only; no recording's "
        "own values are stored. Code: `handover_env/data/detect.py` (rules), "
        "`calibration/measures.py` and `calibration/decisions.py` (quantities), "
        "`handover_env/data/filtering.py` (the track filter).",
        "",
        "## Split",
        "",
        f"Table I's stratified {split['folds']}-fold split (seed {split['seed']}, "
        "`stratified_fold_ids` over the files in `list_public_files` order, the order Table I "
        f"loads them): folds {split['calibration_folds'][0]}-{split['calibration_folds'][-1]} are "
        "the "
        f"**calibration half**, folds {split['held_out_folds'][0]}-{split['held_out_folds'][-1]} "
        "the "
        "**held-out half**. Calibrate on the first; check on the second. Sizes: "
        + ", ".join(f"{_label(g)} {n}" for g, n in summary["groups"].items())
        + ".",
        "",
        "## Rules (all tracks first smoothed by `smooth_track`)",
        "",
        "- **Transfer** (the receiver's hand takes the object): the first frame at which the "
        "nearest "
        "of the right wrist/hand/tip/thumb (joints 14-17) is within "
        f"{rules['transfer.NEAR_RADIUS']} m "
        f"of the object and stays within {rules['transfer.HOLD_RADIUS']} m for "
        f"{rules['transfer.HOLD_TIME']} s; from there the first frame at which the hand closes in "
        f"slower than {rules['transfer.ARRIVAL_SPEED']} m/s (the end of the reach). The object "
        "must "
        "then move with the receiver (mean velocity along the walk over "
        f"{rules['transfer.COMOVE_TIME']} s "
        f">= {rules['transfer.COMOVE_FRACTION']} x walking speed) and must not already have "
        "travelled "
        f"with the receiver (>= {rules['transfer.LEAD_FRACTION']} x walking speed) for over "
        f"{rules['transfer.MAX_LEAD_TIME']} s.",
        f"- **Giver release** (end of the shared hold): the giver's nearest hand joint gets "
        f"{rules['transfer.RELEASE_MARGIN']} m beyond its holding distance (median over the "
        f"{rules['transfer.RELEASE_BASELINE_TIME']} s before the transfer) for "
        f"{rules['transfer.RELEASE_HOLD_TIME']} s; the release is the last frame before that at "
        "which "
        f"it moved away slower than {rules['transfer.RELEASE_SPEED']} m/s.",
        "- **Reach onset**: the last frame before the transfer with the right hand (joint 15) at "
        "most "
        f"{rules['transfer.ONSET_RISE']} m above its walking height (median height above the "
        "pelvis "
        f"from the start to {rules['transfer.BASELINE_GAP']} s before the transfer), stepped back "
        f"(at most {rules['transfer.ONSET_BACKTRACK']} s) to the bottom from which the hand rises.",
        "- **Arm drawn back** (end of arm-extended time): from the transfer, the first frame at "
        "which "
        "the hand's horizontal distance from the pelvis is within "
        f"{rules['transfer.ARM_BACK_MARGIN']} m "
        "of its walking median.",
        f"- **Body frame**: origin pelvis, x forward along the pelvis velocity low-passed at "
        f"{rules['transfer.HEADING_CUTOFF_HZ']} Hz, y left, z up (heights 'above pelvis'; add "
        "`pelvis_z_transfer` for height above the floor). Walking speed: pelvis velocity "
        "low-passed "
        f"at {rules['transfer.SPEED_CUTOFF_HZ']} Hz. Time to contact: object forward of the right "
        "shoulder / walking speed, treating the object as still.",
        "",
        "No-transfer causes: "
        + "; ".join(f"`{k}`: {v}" for k, v in summary["failures"].items())
        + ".",
        "",
        "## Detection counts",
        "",
        *_detection_table(summary),
        "",
        "## Quantities: median [25 %, 75 %] over recordings",
        *_headline(summary),
        "",
        "## Grasp radius for a replayed recorded hand",
        "",
        "Share of all recordings (no transfer = a miss) whose smoothed joint 15 comes within r of "
        "the "
        "object, and quantiles of that distance over recordings with a transfer. The recorded hand "
        "is offset from the OptiTrack object by the ZED-OptiTrack calibration and the tracker: "
        "it is never on the object.",
        "",
        *_grasp(summary),
        "",
        "## Walks that are not straight: when is an object left behind?",
        "",
        *_walks(summary),
        "",
        "## Reach: how far the receiver reaches, against how the object is presented",
        "",
        *_reach(summary),
        "",
        "## Track noise, recorded and after `smooth_track`",
        "",
        "`smooth_track`: outlier pass (running median over "
        f"{2 * rules['filtering.HAMPEL_HALF_WINDOW'] + 1} "
        f"frames; a sample more than max({rules['filtering.HAMPEL_SIGMAS']} robust sigmas, "
        f"{rules['filtering.HAMPEL_MIN_DEVIATION']} m) from it is replaced by it), then a "
        "zero-phase "
        f"order-{rules['filtering.ORDER']} Butterworth low-pass at {rules['filtering.CUTOFF_HZ']} "
        "Hz "
        "(`sosfiltfilt`). Pelvis speed: frame-to-frame xy; hand step: joint 15, 3D, per frame.",
        "",
        *_noise(summary),
    ]
    if figures:
        lines += ["", "## Figures (calibration half)", ""]
        lines += [f"![{name}]({name})" for name in figures]
    if skipped:
        lines += ["", "## Skipped files", ""] + [f"- {name}: {why}" for name, why in skipped]
    lines += ["", "## All quantiles (5/25/50/75/95 %)", "", *_full(summary), ""]
    return write_text("\n".join(lines), path)
