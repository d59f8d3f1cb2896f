"""The person's remaining path at every env step, and the step's two judgements on it.

At every env step the receiver judges the object against the path it still intends to walk
(:mod:`handover_env.person.receiver_rules`): has it been left behind for good, and when and how
far from the shoulder will the person meet it. :func:`judge_kernel` builds that path in place
(the right shoulder and the walking direction now, interpolated at the playback position, then at
every later frame, timed at the current speed factor) and runs both rules on it
(:func:`~handover_env.person.receiver_rules.left_behind_rows`,
:func:`~handover_env.person.receiver_rules.meet_rows`), in one compiled call
(:func:`handover_env.compiled.kernel`) on preallocated arrays.
"""

from __future__ import annotations

import math

import numpy as np

from handover_env.compiled import kernel
from handover_env.person.person import RATE
from handover_env.person.receiver_rules import left_behind_rows, meet_rows

#: Slots of the judgement's input / output array (:func:`judge_kernel`'s ``io``).
TAU, RHO, MIN_SPEED, OBJ, OBJ_VEL, BEHIND, WITHIN, REACH, LEAD, COMFORT, CLOSEST, TAKE = (
    0, 1, 2, 3, 6, 9, 10, 11, 12, 13, 14, 15)
LEFT, MEETING = 16, 17  # outputs: left behind (0 / 1); the meeting's five values
OFFSET = 22  # in: the person's own reach offset (receiver_rules.take_distance)
IO_SIZE = 23


def track_rows(shoulder: np.ndarray, forward: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The per-frame track (T, 6) (shoulder, forward) :func:`judge_kernel` reads, and the path
    buffer (T + 1, 7) it writes (time, shoulder, forward)."""
    track = np.ascontiguousarray(np.hstack([shoulder, forward]), dtype=np.float64)
    return track, np.zeros((track.shape[0] + 1, 7))


@kernel
def judge_kernel(track: np.ndarray, path: np.ndarray, io: np.ndarray) -> None:
    """Build the remaining path into ``path`` and judge the object on it.

    Args:
        track: (T, 6) the right shoulder and the horizontal walking direction at every frame.
        path: (T + 1, 7) scratch: the path's rows (time from now, shoulder, forward).
        io: in: the playback position and speed factor, the slowest speed factor (the path's
            timing never assumes a slower walk), the object and its velocity, the rules'
            settings, the reaching person's kept closest approach and take distance (< 0: none)
            and their own reach offset;
            out: ``io[LEFT]`` left behind (0 / 1) and ``io[MEETING:MEETING + 5]`` the meeting.
    """
    n_frames = track.shape[0]
    tau, rate = io[TAU], RATE * max(io[RHO], io[MIN_SPEED])
    f = min(max(tau, 0.0), n_frames - 1.0)  # the interpolated row now (pose.interp)
    i = min(int(f), n_frames - 2)
    a = f - i
    path[0, 0] = (tau - tau) / rate
    for c in range(6):
        path[0, 1 + c] = track[i, c] * (1.0 - a) + track[i + 1, c] * a
    f0 = int(math.floor(tau)) + 1
    n = 1
    for k in range(f0, n_frames):
        path[n, 0] = (float(k) - tau) / rate
        for c in range(6):
            path[n, 1 + c] = track[k, c]
        n += 1
    rows = path[:n]
    obj = io[OBJ:OBJ + 3]
    left = left_behind_rows(obj, rows[:, 1:4], rows[:, 4:7], io[BEHIND], io[WITHIN])
    io[LEFT] = 1.0 if left else 0.0
    meet_rows(obj, io[OBJ_VEL:OBJ_VEL + 3], rows[:, 0], rows[:, 1:4], rows[:, 4:7], io[REACH],
              io[LEAD], io[COMFORT], io[CLOSEST], io[TAKE], io[OFFSET], io[MEETING:MEETING + 5])
