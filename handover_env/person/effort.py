"""What a handover costs the simulated person: how far they reached, how long the arm was out, and
how far contact pushed them off their path (``info`` keys ``reach_distance``,
``arm_extended_time``, ``path_deviation``; :class:`handover_env.person.receiver.Receiver` adds the
time lost to slowing down and the slowest speed factor).

``reach_distance`` is the one reach statistic of the project, defined as for the recordings
(:func:`handover_eval.calibration.measures.analyse_recording`'s ``object_shoulder_transfer``): the
distance from the right shoulder joint to the object's centre at the moment the person takes the
object. The recordings' median is 0.50 m, IQR 0.44-0.56 m
(``docs/calibration/receiver_calibration.md``).
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from handover_env.compiled import kernel
from handover_env.person.body_model import BodyIds
from handover_env.person.rotations import length
from handover_env.person.skeleton import RIGHT_ARM

# Slots of Effort's array: the measures, then one step's inputs and the body's indices.
REACH_DISTANCE, REACH_MAX, ARM_OUT_TIME, PATH_DEVIATION = 0, 1, 2, 3
ARM_OUT, DT, TARGET_X, TARGET_Y, SHOULDER, GRIP, PELVIS = 4, 5, 6, 7, 8, 9, 10
SLOTS = 11


@kernel
def track_kernel(xpos: np.ndarray, site_xpos: np.ndarray, acc: np.ndarray) -> None:
    """One env step of :meth:`Effort.track` on MuJoCo's body and site positions."""
    if acc[ARM_OUT] > 0.0:
        acc[ARM_OUT_TIME] += acc[DT]
        s, g = int(acc[SHOULDER]), int(acc[GRIP])
        d0, d1, d2 = (site_xpos[g, 0] - xpos[s, 0], site_xpos[g, 1] - xpos[s, 1],
                      site_xpos[g, 2] - xpos[s, 2])
        reach = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        acc[REACH_MAX] = max(acc[REACH_MAX], reach)
    p = int(acc[PELVIS])
    off = math.hypot(xpos[p, 0] - acc[TARGET_X], xpos[p, 1] - acc[TARGET_Y])
    acc[PATH_DEVIATION] = max(acc[PATH_DEVIATION], off)


class Effort:
    """The person's effort over an episode, measured on the simulated body after each env step.

    Args:
        body: the person's indices in the compiled scene.

    Attributes:
        reach_distance: m, right shoulder to the object's centre when the person took the object
            (0 until they take it).
        reach_max: m, the largest grip-shoulder distance while the arm was out.
        arm_out_time: s, how long the arm was out (reaching, raised, or holding before the
            release).
        path_deviation: m, the largest horizontal distance of the pelvis from its nominal target.
    """

    def __init__(self, body: BodyIds) -> None:
        self.body = body
        self._acc = np.zeros(SLOTS)
        self._acc[SHOULDER] = body.bodies[RIGHT_ARM[0]]
        self._acc[GRIP] = body.grip_site
        self._acc[PELVIS] = body.bodies[0]
        self._bound: mujoco.MjData | None = None
        self.reset()

    reach_distance = property(lambda self: float(self._acc[REACH_DISTANCE]))
    reach_max = property(lambda self: float(self._acc[REACH_MAX]))
    arm_out_time = property(lambda self: float(self._acc[ARM_OUT_TIME]))
    path_deviation = property(lambda self: float(self._acc[PATH_DEVIATION]))

    def measures(self) -> list[float]:
        """``[reach_distance, reach_max, arm_out_time, path_deviation]`` (one read)."""
        return self._acc[:PATH_DEVIATION + 1].tolist()

    def reset(self) -> None:
        """Nothing measured yet (a new episode)."""
        self._acc[:PATH_DEVIATION + 1] = 0.0

    def track(
        self, data: mujoco.MjData, arm_out: bool, pelvis_target: np.ndarray, dt: float
    ) -> None:
        """Add one env step of ``dt`` s (:func:`track_kernel`); ``pelvis_target`` is the nominal
        pelvis at its end."""
        acc = self._acc
        acc[ARM_OUT], acc[DT] = arm_out, dt
        acc[TARGET_X], acc[TARGET_Y] = pelvis_target.tolist()[:2]
        if data is not self._bound:  # MjData's buffers never move: its views are kept
            self._bound, self._xpos, self._site_xpos = data, data.xpos, data.site_xpos
        track_kernel(self._xpos, self._site_xpos, acc)

    def took(self, data: mujoco.MjData, object_pos: np.ndarray) -> None:
        """The person took the object now: record the shoulder-object distance
        (``reach_distance``)."""
        shoulder = data.xpos[self.body.bodies[RIGHT_ARM[0]]]
        self._acc[REACH_DISTANCE] = length(np.asarray(object_pos) - shoulder)
