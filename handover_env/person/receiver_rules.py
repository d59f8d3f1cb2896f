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
  object, ``TAKE_INTERCEPT + TAKE_CLOSEST * closest`` (between :data:`MIN_TAKE` and the
  person's comfortable reach), where ``closest`` is the nearest the remaining path comes to the
  object where it is at the reach onset: a person reaches as far as the object is held from
  their path, not always to full extension. The line is the least-squares fit on the
  calibration half of the recordings (:func:`handover_eval.calibration.decisions.reach_summary`).
  The object's speed toward the receiver before the transfer correlates with the recorded reach
  too (r = +0.51), but it is mostly the object already moving *with* the receiver (median
  -0.21 m/s, i.e. along the walk) around a transfer that the detector dates late, not something a
  person sees before reaching; a fit that used it made the simulated person put the grasp off
  while a replayed object moved on, so it is not used.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

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


def _offsets(obj: np.ndarray, path: PathAhead) -> tuple[np.ndarray, np.ndarray]:
    rel = obj - path.shoulder
    return np.einsum("ij,ij->i", rel, path.forward), np.linalg.norm(rel, axis=1)


def left_behind(obj: np.ndarray, path: PathAhead, behind: float, within: float) -> bool:
    """True if the person has left the object (held where it is) behind for good.

    It is more than ``behind`` behind the shoulder along the walk and within ``within`` of it now,
    and at no later frame of the remaining path is it less than ``behind`` behind the shoulder
    within ``within`` of it (the person does not turn back to it).
    """
    fwd, dist = _offsets(np.asarray(obj, dtype=np.float64), path)
    if not (fwd[0] < -behind and dist[0] < within):
        return False
    return not bool(np.any((fwd[1:] >= -behind) & (dist[1:] < within)))


def closest_approach(obj: np.ndarray, path: PathAhead) -> float:
    """The nearest the remaining path's shoulder comes to ``obj`` (held where it is), m."""
    return float(np.min(np.linalg.norm(path.shoulder - np.asarray(obj, dtype=np.float64), axis=1)))


def take_distance(closest: float, comfort: float) -> float:
    """How far from the shoulder the person takes an object whose closest approach to their path
    is ``closest``, m, at most ``comfort`` (see the module docstring)."""
    return float(min(max(TAKE_INTERCEPT + TAKE_CLOSEST * closest, MIN_TAKE), comfort))


def meet(
    obj: np.ndarray,
    obj_vel: np.ndarray,
    path: PathAhead,
    reach: float,
    extrapolate: float,
    comfort: float,
    closest: float | None = None,
    take: float | None = None,
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
    """
    obj = np.asarray(obj, dtype=np.float64)
    obj_vel = np.asarray(obj_vel, dtype=np.float64)
    if closest is None:
        closest = closest_approach(obj, path)
    if take is None:
        take = take_distance(closest, comfort)
    future = obj + np.minimum(path.time, extrapolate)[:, None] * obj_vel
    rel = future - path.shoulder
    fwd = np.einsum("ij,ij->i", rel, path.forward)
    dist = np.linalg.norm(rel, axis=1)
    hit = np.flatnonzero((dist <= take) & (fwd >= 0.0))
    j = int(hit[0]) if hit.size else int(np.argmin(dist))
    return Meeting(float(path.time[j]), float(dist[j]), closest, take, bool(dist[j] <= reach))


__all__ = [
    "MIN_TAKE",
    "Meeting",
    "PathAhead",
    "TAKE_CLOSEST",
    "TAKE_INTERCEPT",
    "closest_approach",
    "left_behind",
    "meet",
    "take_distance",
]
