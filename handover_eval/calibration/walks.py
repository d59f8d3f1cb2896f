"""Walk statistics: how a receiver's pelvis moves over a whole walk, one definition for recorded
and scripted walks.

The paper's OOD receivers (Sec. V-A) "wander or pause" on the way to the giver. To calibrate the
scripted OOD walkers (:func:`handover_env.person.motion.sample_walker`) to the recorded OOD walks,
both are measured by the same code, :func:`walk_statistics`, on the pelvis xy track at 30 Hz:

* a **recorded** walk is the receiver's pelvis (ZED BODY_34 joint 0) after the filter the env
  applies to a replay (:func:`handover_env.data.filtering.smooth_track`; :func:`recorded_walk`);
* a **scripted** walk is the nominal pelvis track of a seeded walker
  (:func:`handover_env.person.trajectory.base_trajectory`, gait sway included;
  :func:`scripted_walk`).

Every statistic is over the **whole walk**: the recording from its first to its last frame (the
receiver is already walking, passes the giver, takes the object and walks on to x ~ -0.8), and the
scripted walk from its start point to ``end_x`` (the same stretch of floor). The transfer is not
needed to cut the walk, so the statistics do not depend on a transfer detector. The speed is that
of the track low-passed at :data:`SPEED_CUTOFF_HZ` (below the ~1.6 Hz step frequency, so the
step-rate ripple does not count as slowing); the heading is that of the track low-passed at
:data:`HEADING_CUTOFF_HZ` (below the ~0.8 Hz stride frequency, so the lateral gait sway does not
swing it), counted only while the pelvis moves faster than :data:`MIN_HEADING_SPEED`.

Statistics (:data:`STATISTICS`):

* ``heading_change``: total absolute change of the walking direction, deg (a straight walk: ~0;
  one loop: 360);
* ``detour``: path length over net displacement, minus 1 (the extra metres walked per metre of
  progress; the path length is that of the speed track, so sway and tracker jitter do not count);
* ``speed_median`` and ``speed_cv``: the median walking speed, m/s, and the coefficient of variation
  (std / mean) of the speed over the walk;
* ``slowest_speed``: the lowest walking speed, m/s;
* ``pauses`` and ``pause_time``: how many times, and for how long in all (s), the speed stays below
  :data:`PAUSE_SPEED` for at least :data:`PAUSE_MIN_TIME`; each pause's duration is kept too
  (:attr:`WalkStatistics.pause_durations`), so the report can give the median pause;
* ``turn_back_time``: time spent walking away from the giver's side of the room (velocity toward
  +x above :data:`TURN_BACK_SPEED`), s;
* ``duration``: the walk's duration, s.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from handover_env.data.filtering import lowpass, smooth_track

RATE_HZ = 30.0
PELVIS = 0
#: Speed low-pass, Hz: below the step frequency (~1.6 Hz; handover_env/data/filtering.py), as the
#: transfer detector's walking speed (:data:`handover_env.data.detect.SPEED_CUTOFF_HZ`).
SPEED_CUTOFF_HZ = 1.0
#: Heading low-pass, Hz: below the stride frequency (~0.8 Hz), as the detector's walking frame.
HEADING_CUTOFF_HZ = 0.5
#: Below this speed the walking direction is not defined (standing), m/s.
MIN_HEADING_SPEED = 0.1
#: A pause: the speed stays below PAUSE_SPEED for at least PAUSE_MIN_TIME. Development copy: the
#: slowest 1 Hz speed of an ID recording is 0.58 m/s (median; 0.49 at 25 %), while OOD recordings
#: dip to 0.15 (median); 0.25 m/s is a shuffle at most, and 0.3 s (9 frames) is longer than one
#: step, so a single slow step is not a pause.
PAUSE_SPEED = 0.25
PAUSE_MIN_TIME = 0.3
#: Walking back: velocity toward +x (away from where the walk goes) above this, m/s.
TURN_BACK_SPEED = 0.1
MIN_FRAMES = 10

#: name -> (label, unit, digits) of the per-walk statistics.
STATISTICS: dict[str, tuple[str, str, int]] = {
    "heading_change": ("total heading change", "deg", 0),
    "detour": ("detour (path / net displacement - 1)", "", 3),
    "speed_median": ("median speed", "m/s", 3),
    "speed_cv": ("speed coefficient of variation", "", 3),
    "slowest_speed": ("slowest speed", "m/s", 3),
    "pauses": ("pauses per walk", "", 2),
    "pause_time": ("time paused", "s", 2),
    "turn_back_time": ("time walking back (+x)", "s", 2),
    "duration": ("walk duration", "s", 2),
}


@dataclass(frozen=True)
class WalkStatistics:
    """The statistics of one walk (:data:`STATISTICS`), and each pause's duration (s)."""

    values: Mapping[str, float]
    pause_durations: tuple[float, ...] = field(default=())

    def __getitem__(self, name: str) -> float:
        return self.values[name]


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``(start, stop)`` index pairs of the runs of True in a bool array."""
    padded = np.concatenate([[False], mask, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    return list(zip(edges[0::2].tolist(), edges[1::2].tolist(), strict=True))


def walk_statistics(xy: np.ndarray, rate_hz: float = RATE_HZ) -> WalkStatistics:
    """The statistics of a pelvis track (module docstring).

    Args:
        xy: (T, 2) pelvis xy, m, at ``rate_hz`` (a recorded track already filtered as the env
            filters it, :func:`recorded_walk`; or a scripted track, :func:`scripted_walk`).
        rate_hz: sampling rate, Hz.

    Raises:
        ValueError: not a finite (T, 2) track of at least :data:`MIN_FRAMES` frames, or a walk
            that does not get anywhere (net displacement under 0.1 m).
    """
    arr = np.asarray(xy, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 2 or arr.shape[0] < MIN_FRAMES:
        raise ValueError(f"a walk is a (T >= {MIN_FRAMES}, 2) pelvis xy track, got {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError("the walk has NaN/inf samples")
    if not (math.isfinite(rate_hz) and rate_hz > 2 * SPEED_CUTOFF_HZ):
        raise ValueError(f"rate_hz must be above {2 * SPEED_CUTOFF_HZ:g} Hz, got {rate_hz!r}")
    dt = 1.0 / rate_hz
    vel = np.gradient(lowpass(arr, rate_hz, SPEED_CUTOFF_HZ), dt, axis=0)
    speed = np.linalg.norm(vel, axis=1)
    vel_h = np.gradient(lowpass(arr, rate_hz, HEADING_CUTOFF_HZ), dt, axis=0)
    moving = np.linalg.norm(vel_h, axis=1) > MIN_HEADING_SPEED
    heading = np.arctan2(vel_h[:, 1], vel_h[:, 0])
    both = moving[1:] & moving[:-1]
    turn = np.abs(np.angle(np.exp(1j * np.diff(heading))))[both]
    net = float(np.linalg.norm(arr[-1] - arr[0]))
    if net < 0.1:
        raise ValueError(f"the walk gets nowhere: {net:.3f} m from its start to its end")
    path = float(np.sum(0.5 * (speed[1:] + speed[:-1])) * dt)
    pauses = [
        (b - a) * dt for a, b in _runs(speed < PAUSE_SPEED) if (b - a) * dt >= PAUSE_MIN_TIME - 1e-9
    ]
    mean = float(speed.mean())
    values = {
        "heading_change": math.degrees(float(turn.sum())),
        "detour": path / net - 1.0,
        "speed_median": float(np.median(speed)),
        "speed_cv": float(speed.std() / mean) if mean > 0 else math.nan,
        "slowest_speed": float(speed.min()),
        "pauses": float(len(pauses)),
        "pause_time": float(sum(pauses)),
        "turn_back_time": float(np.sum(vel[:, 0] > TURN_BACK_SPEED) * dt),
        "duration": arr.shape[0] * dt,
    }
    return WalkStatistics(values, tuple(pauses))


def recorded_walk(receiver_pose: np.ndarray, rate_hz: float = RATE_HZ) -> np.ndarray:
    """A recording's pelvis xy track (T, 2) as the env replays it: the receiver's BODY_34 skeleton
    (T, 34, 3) filtered by :func:`~handover_env.data.filtering.smooth_track` (per channel, so this
    is the pelvis of the filtered skeleton), joint 0."""
    pose = np.asarray(receiver_pose)
    if pose.ndim != 3 or pose.shape[1] <= PELVIS or pose.shape[2] < 2:
        raise ValueError(f"receiver_pose must be (T, 34, 3), got {pose.shape}")
    return smooth_track(pose[:, PELVIS, :2], rate_hz)


def scripted_walk(kind: str, seed: int, rate_hz: float = RATE_HZ) -> tuple[np.ndarray, str | None]:
    """The nominal pelvis xy track (T, 2) of the scripted walker drawn with ``seed``, and its
    ``ood_mode``: :func:`~handover_env.person.motion.sample_walker` on
    ``np.random.default_rng(seed)`` (the generator ``reset(seed=seed)`` gives the env), walked by
    :func:`~handover_env.person.trajectory.base_trajectory`."""
    from handover_env.person.motion import sample_walker
    from handover_env.person.trajectory import base_trajectory

    walker = sample_walker(np.random.default_rng(seed), kind)
    return base_trajectory(walker, rate_hz).xy, walker.ood_mode
