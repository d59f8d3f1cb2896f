"""The simulated person's decisions for any walk: when an object is left behind, when and where
they will meet it, and how far they will reach for it.

Pure functions of the person's **remaining nominal path** (:class:`PathAhead`: the right
shoulder and the walking direction at every frame still to come, as the person intends to walk
it, pauses, loops and turn-backs included) and of the object's position and velocity now. The
same functions decide for :class:`handover_env.person.receiver.Receiver` and are run on the
recordings by the calibration analysis (:mod:`handover_eval.calibration.decisions`), which shows
that they never declare a recorded object left behind while its recorded transfer is still to
come (``docs/calibration/receiver_calibration.md``, section "Walks that are not straight").

* **Left behind** (:func:`left_behind`): the object is more than ``behind`` behind the shoulder
  (along the walk), within ``within`` of it, *and at no frame of the remaining path is it ahead
  of the shoulder again within that distance* (held where it is). A person who pauses, loops or
  turns back toward the object has not left it behind.
* **Meeting** (:func:`meet`): along the remaining path, with the object moving on at its current
  velocity for at most ``extrapolate`` s, the first frame at which it is within the person's
  take distance and not behind the shoulder; if it never comes that close, the frame of its
  closest approach, if that is within reach.
* **Take distance** (:func:`take_distance`): how far from the shoulder a person takes the
  object, ``TAKE_INTERCEPT + TAKE_CLOSEST * closest + offset`` (between :data:`MIN_TAKE` and the
  person's comfortable reach), where ``closest`` is the nearest the remaining path comes to the
  object where it is at the reach onset: a person reaches as far as the object is held from
  their path, not always to full extension. The line (the part that answers the giver) is the
  least-squares fit on the calibration half of the recordings
  (:func:`handover_eval.calibration.decisions.reach_summary`); ``offset`` is the person's own
  (:mod:`handover_env.person.take`: drawn for a scripted walker, a recorded person's own for a
  replay).
  The object's speed toward the receiver before the transfer correlates with the recorded reach
  too (r = +0.51), but it is mostly the object already moving *with* the receiver (median
  -0.21 m/s, i.e. along the walk) around a transfer that the detector dates late, not something a
  person sees before reaching; a fit that used it made the simulated person put the grasp off
  while a replayed object moved on, so it is not used.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from handover_env.compiled import kernel

#: Take distance = TAKE_INTERCEPT + TAKE_CLOSEST * closest approach (m): the least-squares fit on
#: the calibration half (folds 0-4, ID + OOD, 427 recordings, r = 0.44) of the shoulder-object
#: distance at the transfer against the closest approach of the shoulder's path from the reach
#: onset on to the object where it was at the onset (``docs/calibration/receiver_calibration.md``,
#: "Reach": least squares 0.411 + 0.250 x; held-out r = 0.48).
TAKE_INTERCEPT = 0.411
TAKE_CLOSEST = 0.250
#: The shortest take distance, m: the recorded 1 % quantile of the shoulder-object distance at
#: the transfer is about 0.31 m; a hand closer to the shoulder than this is not reaching.
MIN_TAKE = 0.30


@dataclass(frozen=True)
class PathAhead:
    """The person's remaining nominal path, one row per frame from now on.

    Attributes:
        time: (N,) s from now at which the person will be at each frame (0 first).
        shoulder: (N, 3) right shoulder, m.
        forward: (N, 3) horizontal unit walking direction.
    """

    time: np.ndarray
    shoulder: np.ndarray
    forward: np.ndarray

    def __post_init__(self) -> None:
        n = self.time.shape[0]
        if n < 1 or self.shoulder.shape != (n, 3) or self.forward.shape != (n, 3):
            raise ValueError(
                f"PathAhead needs (N,), (N, 3), (N, 3) with N >= 1, got {self.time.shape}, "
                f"{self.shoulder.shape}, {self.forward.shape}"
            )


@dataclass(frozen=True)
class Meeting:
    """Where the person will meet the object along their remaining path.

    Attributes:
        time: s from now to the meeting (when not ``reachable``: to the closest approach).
        distance: shoulder-object distance then, m.
        closest: the nearest the remaining path comes to the object held where it is now, m.
        take: the take distance used, m.
        reachable: the object comes within ``reach`` of the shoulder on the remaining path.
    """

    time: float
    distance: float
    closest: float
    take: float
    reachable: bool


@kernel
def along(r0: float, r1: float, r2: float, f0: float, f1: float, f2: float) -> float:
    """r . f of two 3-vectors, summed as ``np.einsum("ij,ij->i", ...)`` sums a row of 3 (its
    two-lane loop: the first and third products, then the second), so bit for bit its value."""
    return (r0 * f0 + r2 * f2) + r1 * f1


@kernel
def left_behind_rows(obj: np.ndarray, shoulder: np.ndarray, forward: np.ndarray, behind: float,
                     within: float) -> bool:
    """:func:`left_behind` on the rows of a path's shoulder (N, 3) and forward (N, 3)."""
    for j in range(shoulder.shape[0]):
        r0, r1, r2 = obj[0] - shoulder[j, 0], obj[1] - shoulder[j, 1], obj[2] - shoulder[j, 2]
        fwd = along(r0, r1, r2, forward[j, 0], forward[j, 1], forward[j, 2])
        dist = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
        if j == 0:
            if not (fwd < -behind and dist < within):
                return False
        elif fwd >= -behind and dist < within:
            return False
    return True


@kernel
def closest_rows(obj: np.ndarray, shoulder: np.ndarray) -> float:
    """:func:`closest_approach` on the rows of a path's shoulder (N, 3) (NaN if any row is)."""
    best = math.inf
    for j in range(shoulder.shape[0]):
        r0, r1, r2 = shoulder[j, 0] - obj[0], shoulder[j, 1] - obj[1], shoulder[j, 2] - obj[2]
        d = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
        if d < best or d != d:
            best = d
            if d != d:
                break
    return best


@kernel
def meet_rows(obj: np.ndarray, obj_vel: np.ndarray, time: np.ndarray, shoulder: np.ndarray,
              forward: np.ndarray, reach: float, extrapolate: float, comfort: float,
              closest: float, take: float, offset: float, out: np.ndarray) -> None:
    """:func:`meet` on a path's rows: ``closest`` / ``take`` < 0 stand for None; writes the
    meeting's (time, distance, closest, take, reachable as 0 / 1) into ``out[:5]``."""
    if closest < 0.0:
        closest = closest_rows(obj, shoulder)
    if take < 0.0:
        take = min(max((TAKE_INTERCEPT + TAKE_CLOSEST * closest) + offset, MIN_TAKE), comfort)
    first = -1
    best, best_j = math.inf, -1
    for j in range(time.shape[0]):
        t = min(time[j], extrapolate)
        r0 = (obj[0] + t * obj_vel[0]) - shoulder[j, 0]
        r1 = (obj[1] + t * obj_vel[1]) - shoulder[j, 1]
        r2 = (obj[2] + t * obj_vel[2]) - shoulder[j, 2]
        fwd = along(r0, r1, r2, forward[j, 0], forward[j, 1], forward[j, 2])
        dist = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
        if dist <= take and fwd >= 0.0:
            first = j
            best = dist
            break
        if best_j < 0 or dist < best:
            best, best_j = dist, j
    j = first if first >= 0 else best_j
    out[0], out[1], out[2], out[3] = time[j], best, closest, take
    out[4] = 1.0 if best <= reach else 0.0


def left_behind(obj: np.ndarray, path: PathAhead, behind: float, within: float) -> bool:
    """True if the person has left the object (held where it is) behind for good.

    It is more than ``behind`` behind the shoulder along the walk and within ``within`` of it now,
    and at no later frame of the remaining path is it less than ``behind`` behind the shoulder
    within ``within`` of it (the person does not turn back to it).
    """
    return bool(left_behind_rows(np.asarray(obj, dtype=np.float64), path.shoulder, path.forward,
                                 float(behind), float(within)))


def closest_approach(obj: np.ndarray, path: PathAhead) -> float:
    """The nearest the remaining path's shoulder comes to ``obj`` (held where it is), m."""
    return float(closest_rows(np.asarray(obj, dtype=np.float64), path.shoulder))


def take_distance(closest: float, comfort: float, offset: float = 0.0) -> float:
    """How far from the shoulder the person takes an object whose closest approach to their path
    is ``closest``, m, with their own ``offset`` (m), at most ``comfort`` (see the module
    docstring)."""
    return float(min(max((TAKE_INTERCEPT + TAKE_CLOSEST * closest) + offset, MIN_TAKE), comfort))


def meeting_of(out: np.ndarray) -> Meeting:
    """The :class:`Meeting` that :func:`meet_rows` wrote into ``out[:5]``."""
    t, distance, closest, take, reachable = out[:5].tolist()
    return Meeting(t, distance, closest, take, reachable > 0.0)


def meet(
    obj: np.ndarray,
    obj_vel: np.ndarray,
    path: PathAhead,
    reach: float,
    extrapolate: float,
    comfort: float,
    closest: float | None = None,
    take: float | None = None,
    offset: float = 0.0,
) -> Meeting:
    """When and how far from the shoulder the person will meet the object (module docstring).

    Args:
        obj, obj_vel: the object's position (3,) and velocity (3,) now.
        path: the remaining nominal path.
        reach: the farthest the person can take the object from the shoulder, m.
        extrapolate: the object moves on at ``obj_vel`` for at most this long, s, then stays.
        comfort: the farthest the person likes to take it from, m (the take distance's cap).
        closest: the closest approach to report (default: now's, :func:`closest_approach`).
        take: the take distance (default: :func:`take_distance` of ``closest``; a reaching
            person keeps the one of their reach onset, so that an object brought toward their
            path is not put off to later and later).
        offset: the person's own reach offset, m (:func:`take_distance`).
    """
    out = np.empty(5)
    meet_rows(np.asarray(obj, dtype=np.float64), np.asarray(obj_vel, dtype=np.float64),
              np.asarray(path.time, dtype=np.float64), path.shoulder, path.forward, float(reach),
              float(extrapolate), float(comfort), -1.0 if closest is None else float(closest),
              -1.0 if take is None else float(take), float(offset), out)
    return meeting_of(out)


__all__ = [
    "MIN_TAKE",
    "Meeting",
    "PathAhead",
    "TAKE_CLOSEST",
    "TAKE_INTERCEPT",
    "closest_approach",
    "left_behind",
    "meet",
    "meeting_of",
    "take_distance",
]
