"""The range of walks the simulated person was calibrated on, and the check of a walk against it.

The person's rules and numbers (:mod:`handover_env.person.receiver`, ``ReceiverConfig``) were
calibrated on the recordings of the calibration half (Table I folds 0-4) of the public dataset's
development copy. :data:`CALIBRATED_RANGE` states over which walks: the range (lowest to
highest) over those recordings of four fields, each measured by one definition for a recording
and a scripted walk (:func:`walk_fields`, :func:`recording_fields`):

* ``speed``: the walk's median speed, m/s (pelvis xy low-passed at 1 Hz, below the step
  frequency; over the whole walk);
* ``height``: body height, m (a recording: the median right-shoulder height over
  :data:`SHOULDER_HEIGHT_RATIO`; a walker: its ``height``);
* ``pass_distance``: the nearest the pelvis comes to the giver (the origin, where the giver and
  the robot stand), horizontally, m;
* ``pause``: the longest pause, s: the speed stays below :data:`PAUSE_SPEED` for at least
  :data:`PAUSE_MIN_TIME` (0 for a walk without one).

:func:`check` lists the fields of a walk outside the range; the env warns once and reports
``info["within_calibration"]``. Nothing outside is refused: a walk that is physically valid is
simulated, but the person's behaviour there is extrapolated.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields

import numpy as np

from handover_env.data.filtering import lowpass, smooth_track

#: Speed low-pass, Hz, and the pause rule (speed below PAUSE_SPEED m/s for at least
#: PAUSE_MIN_TIME s): the walk statistics' (``handover_eval.calibration.walks``).
SPEED_CUTOFF_HZ = 1.0
PAUSE_SPEED = 0.25
PAUSE_MIN_TIME = 0.3
#: Body height = shoulder height / this (:data:`handover_env.person.motion.SHOULDER_HEIGHT_RATIO`,
#: the standard anthropometric acromion-height ratio).
SHOULDER_HEIGHT_RATIO = 0.818
#: BODY_34 pelvis and right shoulder.
PELVIS, R_SHOULDER = 0, 12
RATE_HZ = 30.0
#: The quantiles over recordings of the range (low, high): lowest to highest. The scripted
#: walkers are drawn from the recordings' whole distribution (quantile tables that run to its
#: extremes), so a narrower range would call the person's own default walkers uncalibrated.
LOW_Q, HIGH_Q = 0.0, 1.0
#: (label, unit) of every field.
FIELDS: dict[str, tuple[str, str]] = {
    "speed": ("median walking speed", "m/s"),
    "height": ("body height", "m"),
    "pass_distance": ("nearest the pelvis comes to the giver", "m"),
    "pause": ("longest pause", "s"),
}


@dataclass(frozen=True)
class CalibratedRange:
    """(low, high) of every field of :data:`FIELDS` (module docstring)."""

    speed: tuple[float, float]
    height: tuple[float, float]
    pass_distance: tuple[float, float]
    pause: tuple[float, float]

    def __post_init__(self) -> None:
        for f in fields(self):
            lo, hi = getattr(self, f.name)
            if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
                raise ValueError(f"calibrated range {f.name} must be finite (low, high) with "
                                 f"low <= high, got {(lo, hi)!r}")

    def as_dict(self) -> dict[str, tuple[float, float]]:
        """``{field: (low, high)}``."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


#: Measured by ``handover-data calibrated-range PATH/whole_motions --out docs/calibration`` on the
#: calibration half (Table I folds 0-4; 400 ID + 40 OOD recordings) of the 875-recording
#: development copy (``docs/calibration/calibrated_range.json``; a test checks that these numbers
#: equal it).
CALIBRATED_RANGE = CalibratedRange(
    speed=(0.589, 1.109),
    height=(1.677, 1.763),
    pass_distance=(0.703, 1.264),
    pause=(0.0, 1.867),
)


def _runs(mask: np.ndarray) -> list[int]:
    """Lengths of the runs of True in a bool array."""
    padded = np.concatenate([[False], mask, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    return (edges[1::2] - edges[0::2]).tolist()


def walk_fields(pelvis_xy: np.ndarray, rate_hz: float = RATE_HZ) -> dict[str, float]:
    """``speed``, ``pass_distance`` and ``pause`` of a pelvis track (module docstring).

    Args:
        pelvis_xy: (T, 2) pelvis xy, m: a recording's smoothed pelvis or a walker's nominal track.
        rate_hz: its rate, Hz.

    Raises:
        ValueError: not a finite (T >= 10, 2) track.
    """
    xy = np.asarray(pelvis_xy, dtype=np.float64)
    if xy.ndim != 2 or xy.shape[1] != 2 or xy.shape[0] < 10:
        raise ValueError(f"a walk is a (T >= 10, 2) pelvis xy track, got {xy.shape}")
    if not np.isfinite(xy).all():
        raise ValueError("the walk has NaN/inf samples")
    dt = 1.0 / rate_hz
    speed = np.linalg.norm(np.gradient(lowpass(xy, rate_hz, SPEED_CUTOFF_HZ), dt, axis=0), axis=1)
    pauses = [n * dt for n in _runs(speed < PAUSE_SPEED) if n * dt >= PAUSE_MIN_TIME - 1e-9]
    return {
        "speed": float(np.median(speed)),
        "pass_distance": float(np.min(np.linalg.norm(xy, axis=1))),
        "pause": float(max(pauses, default=0.0)),
    }


def recording_fields(receiver_pose: np.ndarray, rate_hz: float = RATE_HZ) -> dict[str, float]:
    """Every field of a recorded receiver: the BODY_34 skeleton (T, 34, 3), raw as recorded; it is
    filtered here as a replay is (:func:`~handover_env.data.filtering.smooth_track`)."""
    pose = np.asarray(receiver_pose, dtype=np.float64)
    if pose.ndim != 3 or pose.shape[1] <= R_SHOULDER or pose.shape[2] != 3:
        raise ValueError(f"receiver_pose must be a (T, 34, 3) skeleton, got {pose.shape}")
    smooth = smooth_track(pose[:, [PELVIS, R_SHOULDER]], rate_hz)
    out = walk_fields(smooth[:, 0, :2], rate_hz)
    out["height"] = float(np.median(smooth[:, 1, 2]) / SHOULDER_HEIGHT_RATIO)
    return out


def check(
    values: Mapping[str, float], calibrated: CalibratedRange = CALIBRATED_RANGE
) -> list[tuple[str, float, tuple[float, float]]]:
    """``(field, value, (low, high))`` for every field of ``values`` outside its range (fields
    not given, or NaN, are not checked).

    Raises:
        ValueError: a field that is not one of :data:`FIELDS`.
    """
    unknown = sorted(set(values) - set(FIELDS))
    if unknown:
        raise ValueError(f"unknown calibrated-range field(s) {unknown}; known: {sorted(FIELDS)}")
    ranges = calibrated.as_dict()
    out = []
    for name in FIELDS:
        if name not in values:
            continue
        v = float(values[name])
        lo, hi = ranges[name]
        if math.isfinite(v) and not lo <= v <= hi:
            out.append((name, v, (lo, hi)))
    return out


def _decimals(value: float, low: float, high: float) -> int:
    """The fewest decimals, 2 to 6, at which ``value`` reads apart from both bounds (a body
    height of 1.7604 m is outside [1.68, 1.76] only at four)."""
    for d in range(2, 6):
        if f"{value:.{d}f}" not in (f"{low:.{d}f}", f"{high:.{d}f}"):
            return d
    return 6


def warning_text(outside: list[tuple[str, float, tuple[float, float]]], what: str) -> str:
    """One warning naming every field outside the range, e.g. for ``what = "walker (seed 3)"``;
    each value and its range at the decimals that tell them apart (:func:`_decimals`)."""
    parts = [f"{FIELDS[n][0]} ({n}) {v:.{d}f} {FIELDS[n][1]} outside [{lo:.{d}f}, {hi:.{d}f}]"
             for n, v, (lo, hi) in outside for d in (_decimals(v, lo, hi),)]
    return (f"{what} is outside the walks the simulated person was calibrated on: "
            + "; ".join(parts)
            + " (docs/calibration/calibrated_range.md); the person's behaviour there is "
            "extrapolated")


__all__ = [
    "CALIBRATED_RANGE",
    "FIELDS",
    "CalibratedRange",
    "check",
    "recording_fields",
    "walk_fields",
    "warning_text",
]
