"""The page of ``handover-data grasp-height``: the recorded receivers' right arm at the transfer
(which part of the object the hand takes, where the elbow is) as Markdown, and the command's
runner, which measures (:mod:`handover_eval.calibration.grasp_height`), writes the JSON and the
page."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from handover_eval.calibration.grasp_height import (
    AXES,
    CLEAR_SHARE,
    HALVES,
    HAND_NAMES,
    JOINT_NAMES,
    JSON_NAME,
    MD_NAME,
    SHORT,
    SWIVEL_JOINTS,
    assign_halves,
    measure_folder,
    summarise,
)
from handover_eval.calibration.report import (
    DEFAULT_CALIBRATION_FOLDS,
    DEFAULT_FOLDS,
    DEFAULT_SEED,
    QUANTILES,
    write_json,
)
from handover_eval.reporting import markdown_table, write_text


def _f(v: float | None, digits: int = 3) -> str:
    return "–" if v is None or not math.isfinite(v) else f"{v:.{digits}f}"


def _pct(v: float | None) -> str:
    return "–" if v is None else f"{100.0 * v:.1f} %"


def _label(group: str) -> str:
    half, kind = group.split("/")
    return f"{half.replace('_', '-')} {'pooled' if kind == 'all' else kind.upper()}"


def _shares(summary: dict, half: str, names: Sequence[str]) -> str:
    h = summary["height"]
    return ", ".join(f"{SHORT[n]} {_pct(h[n][half]['share_below'])}" for n in names)


def _medians(summary: dict, half: str, names: Sequence[str]) -> str:
    h = summary["height"]
    return ", ".join(f"{SHORT[n]} {_f(h[n][half]['p50'])} m" for n in names)


def _vec(v: Sequence[float] | None, digits: int = 3) -> str:
    return "–" if v is None else "(" + ", ".join(_f(x, digits) for x in v) + ")"


#: The words of a walking-frame component's sign (for the right arm: left is in, right is out).
_WORDS = {"forward": ("forward", "back"), "left": ("in to the left", "out to the right"),
          "up": ("up", "down")}


def describe(direction: Sequence[float]) -> str:
    """Words for a walking-frame unit direction, largest component first: components of at
    least 0.25 named plainly, of 0.05-0.25 as "slightly", smaller ones left out."""
    parts = sorted(zip(AXES, direction, strict=True), key=lambda p: -abs(p[1]))
    main = [_WORDS[a][c < 0] for a, c in parts if abs(c) >= 0.25]
    minor = [_WORDS[a][c < 0] for a, c in parts if 0.05 <= abs(c) < 0.25]
    text = (", ".join(main[:-1]) + " and " + main[-1] if len(main) > 1
            else main[0] if main else "nowhere in particular")
    return text + "".join(f", slightly {w}" for w in minor)


def _angle(a: Sequence[float] | None, b: Sequence[float] | None) -> float | None:
    if a is None or b is None:
        return None
    x, y = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    c = float(x @ y) / float(np.linalg.norm(x) * np.linalg.norm(y))
    return math.degrees(math.acos(min(max(c, -1.0), 1.0)))


def _elbow_section(summary: dict) -> str:
    """The page's section on the elbow's swivel direction."""
    pole = summary["elbow_pole"]
    rows = [(f"{h.replace('_', '-')} {'pooled' if k == 'pooled' else k.upper()}", v)
            for h in HALVES for k, v in pole[h].items()]
    frame = pole["frame"].split(": ", 1)[1]
    text = (
        "## The elbow's swivel direction at the transfer\n\n"
        "At the transfer frame f, with S, E, W the receiver's right shoulder, elbow and wrist "
        "of the filtered skeleton (BODY_34 "
        + ", ".join(f"{n} {i}" for n, i in pole["joints"].items() if n in SWIVEL_JOINTS)
        + "): u = (W - S) / |W - S|, perp = (E - S) - ((E - S) . u) u, and the elbow's swivel "
        "direction d = perp / |perp|, the unit direction in which the elbow sits off the "
        f"shoulder-wrist line. It is expressed in the receiver's walking frame there: {frame}; "
        "components (forward, left, up). A recording with a transfer is skipped, and counted, "
        "when "
        + "; ".join(f"{why} (`{k}`)" for k, why in pole["skip_rules"].items())
        + ". Per group: the normalised mean direction (the mean of the d's divided by its norm) "
        "and the mean resultant length R (the norm of that mean: 1 when every d is the same, "
        "near 0 when they scatter), the mean itself, the per-component median, the angle of "
        "each d from the normalised mean, and the median shoulder-to-wrist direction u and "
        "distance |W - S|.\n\n"
        "Why: the simulated person's two-link arm IK (`handover_env/person/posing.py`, "
        "`arm_kernel`) places the elbow in the plane of the shoulder-wrist line and a \"pole\" "
        "direction given in the torso frame (x forward, y left, z up). That pole was "
        f"{_vec(pole['old_pole']['value'], 2)} normalised, that is "
        f"{_vec(pole['old_pole']['direction'])}: down and out to the right, an uncited "
        "choice. For a folded arm (an object taken close to the body) it swung the elbow out "
        "toward the robot, past the gripper; the recordings hold it down and back. The pole is "
        "to become the calibration half's pooled normalised mean direction, JSON "
        "`elbow_pole.calibration.pooled.direction` ([forward, left, up]).\n\n"
        "**Caveat: one recording's direction says little.** The ZED joints are noisy (about "
        "0.1 m; `handover_env/data/detect.py`), shoulder, elbow and wrist alike, so a single "
        "recording's d is rough; the direction is an average over several hundred recordings, "
        "and R and the angles from it show how widely single recordings scatter around it.\n\n"
        "### Direction of the elbow off the shoulder-wrist line (walking frame: forward, left, "
        "up)\n\n"
    )
    text += markdown_table(
        ("group", "n", "skipped", "normalised mean direction", "R", "mean", "median",
         "angle from the direction, 25 / 50 / 75 % (deg)"),
        [(label, v["n"], ", ".join(f"{k} {c}" for k, c in v["skipped"].items() if c) or "–",
          _vec(v["direction"]), _f(v["resultant_length"]), _vec(v["mean"]), _vec(v["median"]),
          " / ".join(_f(v["angle_from_direction_deg"][f"p{q}"], 1) for q in (25, 50, 75)))
         for label, v in rows],
    )
    text += "\n### The shoulder-to-wrist line (walking frame: forward, left, up)\n\n"
    text += markdown_table(
        ("group", "n", "median direction u", "median distance abs(W - S) (m)"),
        [(label, v["n"], _vec(v["shoulder_to_wrist_median"]),
          _f(v["shoulder_to_wrist_distance_median"])) for label, v in rows],
    )
    return text + "\n"


def markdown(summary: dict) -> str:
    """The page ``grasp_height.md``."""
    split, height = summary["split"], summary["height"]
    n = {h: summary["detection"][f"{h}/all"]["transfer"] for h in ("calibration", "held_out")}
    clear = all((height[j][f"{h}/all"]["share_below"] or 0.0) >= CLEAR_SHARE
                for j in HAND_NAMES for h in ("calibration", "held_out"))
    fore = {h: summary["forearm_elevation"][f"{h}/all"] for h in ("calibration", "held_out")}
    hand = summary["distance"]["RIGHT_HAND"]["calibration/all"]
    hand_z = height["RIGHT_HAND"]["calibration/all"]
    offset = (f"{_f(-hand_z['p95'], 2)}-{_f(-hand_z['p5'], 2)} m below the object's centre"
              if (hand_z["p95"] or 0.0) < 0.0 else
              f"{_f(hand_z['p5'], 2)} .. {_f(hand_z['p95'], 2)} m above the object's centre")
    elbow_below = all((height["RIGHT_ELBOW"][f"{h}/all"]["share_below"] or 0.0) >= CLEAR_SHARE
                      for h in ("calibration", "held_out"))
    verdict = (
        "**The recorded receivers took the object from below its centre.**"
        if clear else
        f"**The recorded hands were not below the object's centre in {100 * CLEAR_SHARE:g} % of "
        "the recordings of both halves.**"
    )
    text = (
        "# The receiver's arm at the transfer: which part of the object the hand takes, and "
        "where the elbow is\n\n"
        f"Generated by `{summary['command']}` from `{summary['source']}` "
        f"({summary['recordings']} recordings, {summary['skipped_files']} skipped; "
        f"{n['calibration']} calibration and {n['held_out']} held-out recordings with a detected "
        "transfer). Code: `handover_eval/calibration/grasp_height.py`. Statistics over "
        "recordings only.\n\n"
        "At the detected transfer (`handover_env.data.detect.detect_transfer` on the receiver's "
        "skeleton and the object's track filtered as a replay is, `smooth_track` at "
        f"{summary['rate_hz']:g} Hz; the frame `transfer-stats` and `reach-spread` use), the "
        "height (z) of the receiver's right-arm BODY_34 joints minus the height of the object's "
        "recorded position (`pose_object`, an episode's `giver_xyz`: the object's mocap "
        "position, which the env treats as the bottle's centre). Negative: below the centre. "
        "Joints: "
        + ", ".join(f"{SHORT[j]} ({i})" for j, i in summary["joints"].items())
        + ". The forearm's elevation is the angle of the elbow-to-wrist direction above "
        "horizontal. The elbow's swivel direction (the direction in which the elbow sat off the "
        "shoulder-wrist line, in the receiver's walking frame) is defined in its own section "
        "below.\n\n"
        f"Split: Table I's stratified folds (seed {split['seed']}): folds "
        f"{split['calibration_folds'][0]}-{split['calibration_folds'][-1]} calibrate, "
        f"{split['held_out_folds'][0]}-{split['held_out_folds'][-1]} are held out."
        + "".join(f" Skipped: `{name}` ({why})." for name, why in summary["skipped"])
        + "\n\n## Result\n\n"
        f"{verdict} In the calibration half (n = {n['calibration']}) the right hand joints were "
        "below the object's centre at the transfer in: "
        f"{_shares(summary, 'calibration/all', HAND_NAMES)} "
        f"of the recordings (medians: {_medians(summary, 'calibration/all', HAND_NAMES)}); the "
        f"elbow in {_pct(height['RIGHT_ELBOW']['calibration/all']['share_below'])} (median "
        f"{_f(height['RIGHT_ELBOW']['calibration/all']['p50'])} m). The held-out half "
        f"(n = {n['held_out']}): {_shares(summary, 'held_out/all', JOINT_NAMES)}. The "
        f"forearm's elevation, elbow to wrist: median {_f(fore['calibration']['p50'], 1)} deg "
        f"(25-75 %: {_f(fore['calibration']['p25'], 1)} .. {_f(fore['calibration']['p75'], 1)} "
        f"deg; held out median {_f(fore['held_out']['p50'], 1)} deg), the wrist above the "
        f"elbow in {_pct(fore['calibration']['share_wrist_above_elbow'])} of the calibration "
        "recordings"
        + ("; with the elbow below the centre as well, the whole forearm was below the object"
           if elbow_below else "")
        + ".\n\n"
        "The simulated person's modelled hand follows this with the switch `grasp_below` "
        "(`handover_env/person/settings.py`): it takes the bottle by its lower "
        "part, below the robot gripper's pads, approached from below, instead of its top "
        "part.\n\n"
        "**Caveat: only the side is used, not the height.** The ZED body tracker's hand joints "
        "are noisy (about 0.1 m; `handover_env/data/detect.py`) and are not where the fingers "
        f"close: at the transfers the hand joint sits {offset} (5-95 % of the calibration half) "
        f"and {_f(hand['p5'], 2)}-{_f(hand['p95'], 2)} m from it (median {_f(hand['p50'], 2)} "
        "m). So these numbers say on which side of the centre the hand took the object (the "
        "sign), not at what height it held it.\n\n"
    )
    pole = summary["elbow_pole"]
    cal, held = pole["calibration"]["pooled"], pole["held_out"]["pooled"]
    skips = {h: sum(pole[h]["pooled"]["skipped"].values()) for h in HALVES}
    words = describe(cal["direction"]) if cal["direction"] is not None else "undetermined"
    old_angle = _angle(pole["old_pole"]["direction"], cal["direction"])
    text += (
        f"**The elbow: {words}.** In the calibration half the elbow sat off the shoulder-wrist "
        "line, in the receiver's walking frame (forward, left, up), in the normalised mean "
        f"direction **{_vec(cal['direction'])}** (JSON `elbow_pole.calibration.pooled.direction`; "
        f"R = {_f(cal['resultant_length'])}, n = {cal['n']}, {skips['calibration']} skipped; "
        f"per-component median {_vec(cal['median'])}; half of the recordings within "
        f"{_f(cal['angle_from_direction_deg']['p50'], 1)} deg of it). The held-out half: "
        f"{_vec(held['direction'])}, R = {_f(held['resultant_length'])} (n = {held['n']}, "
        f"{skips['held_out']} skipped), "
        f"{_f(_angle(cal['direction'], held['direction']), 1)} deg from the calibration half's. "
        f"The shoulder-to-wrist direction: median {_vec(cal['shoulder_to_wrist_median'])}, "
        f"distance median {_f(cal['shoulder_to_wrist_distance_median'])} m. The simulated "
        f"arm's old pole {_vec(pole['old_pole']['direction'])} (down and out to the right) is "
        f"{_f(old_angle, 1)} deg from the calibration direction; the pole is to become it (the "
        "section on the elbow below says why, and its caveat: a noisy average).\n\n"
    )
    text += ("## Height above the object's centre at the transfer (m; negative = below)\n\n")
    for name in JOINT_NAMES:
        text += f"### {SHORT[name]} (`{name}`, joint {summary['joints'][name]})\n\n"
        text += markdown_table(
            ("group", "n", *(f"{q} %" for q in QUANTILES), "below the centre"),
            [(_label(g), v["n"], *(_f(v[f"p{q}"]) for q in QUANTILES), _pct(v["share_below"]))
             for g, v in height[name].items()],
        )
        text += "\n"
    text += "## Forearm elevation, elbow to wrist (degrees above horizontal)\n\n"
    text += markdown_table(
        ("group", "n", *(f"{q} %" for q in QUANTILES), "wrist above elbow"),
        [(_label(g), v["n"], *(_f(v[f"p{q}"], 1) for q in QUANTILES),
          _pct(v["share_wrist_above_elbow"])) for g, v in summary["forearm_elevation"].items()],
    )
    text += "\n## Distance of each joint from the object's centre at the transfer (m)\n\n"
    text += markdown_table(
        ("joint", "group", "n", *(f"{q} %" for q in QUANTILES)),
        [(SHORT[name], _label(g), v["n"], *(_f(v[f"p{q}"]) for q in QUANTILES))
         for name in JOINT_NAMES for g, v in summary["distance"][name].items()],
    )
    text += "\n" + _elbow_section(summary)
    text += "## Recordings and detected transfers\n\n"
    text += markdown_table(
        ("group", "recordings", "with a transfer", "no transfer (why)"),
        [(_label(g), v["recordings"], v["transfer"],
          ", ".join(f"{k} {c}" for k, c in v["no_transfer"].items()) or "–")
         for g, v in summary["detection"].items()],
    )
    return text


def run_grasp_height(
    folder: str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    folds: int = DEFAULT_FOLDS,
    seed: int = DEFAULT_SEED,
    calibration_folds: int = DEFAULT_CALIBRATION_FOLDS,
    skip_bad: bool = False,
    progress: bool = True,
) -> tuple[dict, list[Path]]:
    """Measure ``folder``, split it, write the JSON and the page into ``out_dir``.

    Returns:
        ``(summary, written paths)``.
    """
    rows, skipped = measure_folder(folder, skip_bad=skip_bad, progress=progress)
    assign_halves(rows, folds, seed, calibration_folds)
    summary = summarise(rows, source=Path(folder).name, folds=folds, seed=seed,
                        calibration_folds=calibration_folds, skipped=skipped)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    return summary, [write_json(summary, out / JSON_NAME),
                     write_text(markdown(summary), out / MD_NAME)]


__all__ = ["describe", "markdown", "run_grasp_height"]
