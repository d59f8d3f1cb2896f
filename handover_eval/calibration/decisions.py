"""Walks that are not straight, and the reach, in the recordings (issue 23): pauses, turn-backs,
the simulated person's left-behind rule run on the recorded walk, and what the reach extent
depends on.

:func:`walk_measures` adds to one recording's :data:`~handover_eval.calibration.measures.MEASURES`
(every track already smoothed):

* ``pause_before`` / ``longest_pause`` (s): time with the pelvis slower than :data:`PAUSE_SPEED`
  from the start to the transfer, in all and in the longest stretch;
* ``turn_back`` (m): the farthest the receiver walked back along their starting direction before
  the transfer (the largest drop of the pelvis' progress below its running maximum);
  ``max_turn`` (deg): the largest turn of the walking direction away from the starting one;
* ``path_closest_onset`` (m): the nearest the right shoulder's path from the reach onset on
  comes to the object held where it was at the onset
  (:func:`handover_env.person.receiver_rules.closest_approach`): how far the object was held
  from the person's path;
* ``object_toward_speed`` (m/s): the object's mean speed toward the receiver (against the walk)
  over the 0.5 s before the transfer;
* ``old_left_behind`` (s, relative to the transfer, NaN if never): the first frame before the
  transfer at which the simulated person's former rule (the object more than
  :data:`GIVE_UP_BEHIND` behind the shoulder along the walk, within
  :data:`~handover_env.person.settings.PASS_DISTANCE`) would have left the object behind;
  ``left_behind`` likewise for the rule the person now uses
  (:func:`handover_env.person.receiver_rules.left_behind`: also never ahead again on the rest of
  the recorded walk), each frame judged with the object where it was then.
"""

from __future__ import annotations

import math

import numpy as np

from handover_env.data.detect import PELVIS, R_SHOULDER, WalkingFrame
from handover_env.person.receiver_rules import PathAhead, closest_approach, left_behind
from handover_env.person.settings import PASS_DISTANCE, ReceiverConfig

#: Slower than this (m/s, the walking speed of :func:`~handover_env.data.detect.
#: walking_frame`) the receiver pauses.
PAUSE_SPEED = 0.2
#: The simulated person's default ``give_up_behind`` (m).
GIVE_UP_BEHIND = ReceiverConfig().give_up_behind
#: Window before the transfer of ``object_toward_speed``, s.
TOWARD_WINDOW = 0.5

WALK_MEASURES: dict[str, tuple[str, str, str]] = {
    "pause_before": ("walk", "time paused (pelvis < 0.2 m/s), start to transfer", "s"),
    "longest_pause": ("walk", "longest pause before the transfer", "s"),
    "turn_back": ("walk", "farthest walked back along the starting direction before transfer", "m"),
    "max_turn": ("walk", "largest turn from the starting direction before transfer", "deg"),
    "old_left_behind": (
        "walk",
        "former 'left behind' rule: first firing before the transfer (rel. to it)",
        "s",
    ),
    "left_behind": (
        "walk",
        "current 'left behind' rule: first firing before the transfer (rel. to it)",
        "s",
    ),
    "path_closest_onset": (
        "reach against presentation",
        "closest approach of the shoulder's path (onset on) to the object at the onset",
        "m",
    ),
    "object_toward_speed": (
        "reach against presentation",
        "object speed toward the receiver, 0.5 s before transfer",
        "m/s",
    ),
}


def _longest_run(mask: np.ndarray) -> int:
    best = run = 0
    for m in mask:
        run = run + 1 if m else 0
        best = max(best, run)
    return best


def walk_measures(
    r: np.ndarray,
    o: np.ndarray,
    walking: WalkingFrame,
    transfer: int,
    onset: int | None,
    rate_hz: float,
) -> dict[str, float]:
    """The :data:`WALK_MEASURES` of one recording (smoothed skeleton ``r``, object ``o``)."""
    k = transfer
    out = {name: math.nan for name in WALK_MEASURES}
    speed = walking.speed[: k + 1]
    slow = speed < PAUSE_SPEED
    out["pause_before"] = float(slow.sum() / rate_hz)
    out["longest_pause"] = float(_longest_run(slow) / rate_hz)
    pelvis = r[:, PELVIS, :2]
    start = walking.forward[0]
    progress = (pelvis[: k + 1] - pelvis[0]) @ start
    out["turn_back"] = float(np.max(np.maximum.accumulate(progress) - progress))
    cos = np.clip(walking.forward[: k + 1] @ start, -1.0, 1.0)
    out["max_turn"] = float(np.degrees(np.arccos(cos)).max())
    shoulder = r[:, R_SHOULDER]
    forward = np.column_stack([walking.forward, np.zeros(len(walking.forward))])
    frames = np.arange(r.shape[0], dtype=np.float64) / rate_hz
    old = new = None
    for f in range(k):
        rel = o[f] - shoulder[f]
        behind = rel @ forward[f] < -GIVE_UP_BEHIND
        if old is None and behind and np.linalg.norm(rel) < PASS_DISTANCE:
            old = f
        if new is None:
            path = PathAhead(frames[f:] - frames[f], shoulder[f:], forward[f:])
            if left_behind(o[f], path, GIVE_UP_BEHIND, PASS_DISTANCE):
                new = f
        if old is not None and new is not None:
            break
    out["old_left_behind"] = math.nan if old is None else (old - k) / rate_hz
    out["left_behind"] = math.nan if new is None else (new - k) / rate_hz
    if onset is not None:
        path = PathAhead(frames[onset:] - frames[onset], shoulder[onset:], forward[onset:])
        out["path_closest_onset"] = closest_approach(o[onset], path)
    window = slice(max(0, k - int(round(TOWARD_WINDOW * rate_hz))), k + 1)
    v = np.gradient(o[:, :2], axis=0) * rate_hz
    out["object_toward_speed"] = float(
        -np.mean(np.einsum("ij,ij->i", v[window], walking.forward[window]))
    )
    return out


def reach_fit(x: np.ndarray, y: np.ndarray) -> dict[str, float]:
    """Straight-line fits of the reach ``y`` on a presentation variable ``x`` (NaNs dropped).

    Returns the least-squares intercept and slope (``ls_a``, ``ls_b``), the reduced-major-axis
    ones (``rma_a``, ``rma_b``: slope sd(y)/sd(x) with the sign of r, so that the fitted values
    spread as the recorded ones do), Pearson ``r`` and ``n``.
    """
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if x.size < 3 or np.std(x) == 0.0 or np.std(y) == 0.0:
        return {"n": int(x.size)}
    r = float(np.corrcoef(x, y)[0, 1])
    ls_b = r * float(np.std(y) / np.std(x))
    rma_b = math.copysign(float(np.std(y) / np.std(x)), r)
    return {
        "n": int(x.size),
        "r": r,
        "ls_a": float(y.mean() - ls_b * x.mean()),
        "ls_b": ls_b,
        "rma_a": float(y.mean() - rma_b * x.mean()),
        "rma_b": rma_b,
    }


#: Presentation variables whose correlation with the reach and the arm-out time is reported.
REACH_PREDICTORS = (
    "path_closest_onset",
    "object_toward_speed",
    "object_toward_receiver",
    "object_lat_onset",
    "walking_speed_onset",
    "walking_speed_transfer",
)
#: The reach statistic (shoulder-object at the transfer) and the arm-out time.
REACH_RESPONSES = ("object_shoulder_transfer", "arm_extended")


def rule_check(measures: list[dict[str, float]]) -> dict[str, float | int]:
    """How many recordings each left-behind rule would have declared before their transfer, and
    the earliest such firing relative to the transfer (s; None if none)."""
    out: dict[str, float | int] = {"recordings": len(measures)}
    for rule in ("old_left_behind", "left_behind"):
        t = np.array([m[rule] for m in measures], dtype=np.float64)
        fired = t[np.isfinite(t)]
        out[f"{rule}_count"] = int(fired.size)
        out[f"{rule}_earliest"] = float(fired.min()) if fired.size else None
    return out


def reach_summary(
    calibration: list[dict[str, float]], held_out: list[dict[str, float]]
) -> dict:
    """The reach analysis: correlations of :data:`REACH_RESPONSES` with
    :data:`REACH_PREDICTORS` in each half, and the fits of the reach on ``path_closest_onset`` on
    the calibration half with their correlation on the held-out half."""

    def column(rows: list[dict[str, float]], name: str) -> np.ndarray:
        return np.array([m[name] for m in rows], dtype=np.float64)

    def corr(rows: list[dict[str, float]], a: str, b: str) -> float | None:
        x, y = column(rows, a), column(rows, b)
        ok = np.isfinite(x) & np.isfinite(y)
        if ok.sum() < 3:
            return None
        return float(np.corrcoef(x[ok], y[ok])[0, 1])

    out: dict = {"correlations": {}}
    for half, rows in (("calibration", calibration), ("held_out", held_out)):
        out["correlations"][half] = {
            resp: {pred: corr(rows, resp, pred) for pred in REACH_PREDICTORS}
            for resp in REACH_RESPONSES
        }
    fit = reach_fit(
        column(calibration, "path_closest_onset"), column(calibration, "object_shoulder_transfer")
    )
    x_h = column(held_out, "path_closest_onset")
    y_h = column(held_out, "object_shoulder_transfer")
    ok = np.isfinite(x_h) & np.isfinite(y_h)
    if "rma_b" in fit and ok.sum() >= 3:
        pred = fit["rma_a"] + fit["rma_b"] * x_h[ok]
        fit["held_out_r"] = float(np.corrcoef(pred, y_h[ok])[0, 1])
        fit["held_out_n"] = int(ok.sum())
        fit["held_out_sd_rma"] = float(np.std(pred))
        fit["held_out_sd_ls"] = float(np.std(fit["ls_a"] + fit["ls_b"] * x_h[ok]))
        fit["held_out_sd"] = float(np.std(y_h[ok]))
    out["fit"] = fit
    return out


__all__ = [
    "GIVE_UP_BEHIND",
    "PAUSE_SPEED",
    "REACH_PREDICTORS",
    "REACH_RESPONSES",
    "WALK_MEASURES",
    "reach_fit",
    "reach_summary",
    "rule_check",
    "walk_measures",
]
