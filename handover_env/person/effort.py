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

import mujoco
import numpy as np

from handover_env.person.body_model import BodyIds
from handover_env.person.rotations import length
from handover_env.person.skeleton import RIGHT_ARM


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
        self.reset()

    def reset(self) -> None:
        """Nothing measured yet (a new episode)."""
        self.reach_distance = 0.0
        self.reach_max = 0.0
        self.arm_out_time = 0.0
        self.path_deviation = 0.0

    def track(
        self, data: mujoco.MjData, arm_out: bool, pelvis_target: np.ndarray, dt: float
    ) -> None:
        """Add one env step of ``dt`` s; ``pelvis_target`` is the nominal pelvis at its end."""
        b = self.body
        if arm_out:
            self.arm_out_time += dt
            shoulder = data.xpos[b.bodies[RIGHT_ARM[0]]]
            grip = data.site_xpos[b.grip_site]
            self.reach_max = max(self.reach_max, length(grip - shoulder))
        pelvis = data.xpos[b.bodies[0]]
        self.path_deviation = max(
            self.path_deviation, float(np.hypot(*(pelvis[:2] - pelvis_target[:2])))
        )

    def took(self, data: mujoco.MjData, object_pos: np.ndarray) -> None:
        """The person took the object now: record the shoulder-object distance
        (``reach_distance``)."""
        shoulder = data.xpos[self.body.bodies[RIGHT_ARM[0]]]
        self.reach_distance = length(np.asarray(object_pos) - shoulder)
