"""What a handover costs the simulated person: how far and how long the arm is out, and how far
contact pushed them off their path (``info`` keys ``reach_distance``, ``arm_extended_time``,
``path_deviation``; :class:`handover_env.person.receiver.Receiver` adds the time lost to slowing
down and the slowest speed factor)."""

from __future__ import annotations

import mujoco
import numpy as np

from handover_env.person.body_model import BodyIds
from handover_env.person.skeleton import RIGHT_ARM


class Effort:
    """The person's effort over an episode, measured on the simulated body after each env step.

    Args:
        body: the person's indices in the compiled scene.

    Attributes:
        reach_distance: m, the largest grip-shoulder distance while the arm was out.
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
            self.reach_distance = max(self.reach_distance, float(np.linalg.norm(grip - shoulder)))
        pelvis = data.xpos[b.bodies[0]]
        self.path_deviation = max(
            self.path_deviation, float(np.hypot(*(pelvis[:2] - pelvis_target[:2])))
        )
