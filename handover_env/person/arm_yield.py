"""The reaching arm yields to the robot: a drive bounded as a human arm's, and a push that stops
on contact.

The person's segments follow their mocap targets through soft welds
(:mod:`handover_env.person.body_model`); the right arm's welds hold it with the hand's endpoint
stiffness :data:`~handover_env.person.body_model.ARM_POSTURE_STIFFNESS` (1 kN/m). In free
motion a target leads its segment only by the welds' own lag, and no force results. When the
robot stands in the way, the target runs on while the arm cannot, and the weld's spring would
press the arm into the robot with a force that grows without bound. A person does not: their
arm pushes at most as hard as its muscles can, and they stop pushing once they feel the contact.
:class:`ArmYield` does the same to the right arm's targets (upper arm, forearm, hand), at every
200 Hz controller tick while the robot touches any of them:

* **bounded drive**: each target is kept within :data:`MAX_ARM_PUSH` / ``ARM_POSTURE_STIFFNESS``
  of its segment, so its spring pushes with at most the human arm's maximal one-handed push;
* **the push stops**: :data:`TACTILE_LATENCY` after the first touch, the targets are held on the
  segments (position and orientation): the arm no longer pushes and gives way to the robot;
* the hand's reach starts again from where the hand is at the next env step (the receiver
  re-plans it), so the plan does not keep driving through the robot.

Sources: :data:`MAX_ARM_PUSH`: Seo, Armstrong, Chaffin & Ashton-Miller (2008), "The effect of
handle friction and inward or outward torque on maximum axial push force", Human Factors 50(2):
227-236, table 2: maximum one-handed straight push along a handle, men, 107 +- 20 N (aluminium
handle; 112 +- 27 N on rubber; all participants 85 N). The authors found that push limited by the
hand's coupling to the handle rather than by the arm, so it is a low estimate of what an arm can
push with, not a high one. :data:`TACTILE_LATENCY`: Pruszynski, Johansson & Flanagan (2016), "A
rapid tactile-motor reflex automatically guides reaching toward handheld objects", Current
Biology 26(6): 788-792: touch corrects an ongoing reach in under 100 ms.

The yield is opt-in (the person setting ``arm_yield``, off by default: :meth:`ArmYield.feel`
then feels nothing and the targets are never limited).

The ISO/TS 15066 judgement of the contact (:mod:`handover_env.envs.contacts`, ``unsafe_force``)
is unchanged: this changes what the person does, not how it is judged.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from handover_env.person.body_model import ARM_POSTURE_STIFFNESS, BodyIds
from handover_env.person.skeleton import SEG

#: The human arm's maximal one-handed push, N (module docstring: Seo et al. 2008).
MAX_ARM_PUSH = 107.0
#: From the first touch to the push withdrawn, s (module docstring: Pruszynski et al. 2016).
TACTILE_LATENCY = 0.1
#: The reaching arm's segments (right upper arm, forearm, hand).
ARM = (SEG["upper_arm_r"], SEG["forearm_r"], SEG["hand_r"])


class ArmYield:
    """The right arm's response to the robot's touch (module docstring).

    Args:
        body: the person's indices in the compiled scene.
        enabled: the person setting ``arm_yield`` (off: the arm never yields).
    """

    def __init__(self, body: BodyIds, enabled: bool = True) -> None:
        self.body = body
        self.enabled = enabled
        self._arm = np.array(ARM, dtype=np.int64)
        self._bodies = body.bodies[self._arm]
        self.reach = MAX_ARM_PUSH / ARM_POSTURE_STIFFNESS
        self.reset()

    def reset(self) -> None:
        """A new episode: no touch."""
        self.touching = False
        self.t_touch = math.nan
        self.touched_in_step = False
        #: How many env steps had the robot touching the arm (the episode's count).
        self.touched_steps = 0

    @property
    def blocked(self) -> bool:
        """The targets are limited: the robot touches the arm, or touched it in this env step."""
        return self.touching or self.touched_in_step

    def feel(self, robot_force: np.ndarray | None, t: float) -> None:
        """This tick's robot normal force per segment (S,), N (None: no contact scanned)."""
        if not self.enabled:
            return
        touching = robot_force is not None and bool(np.any(robot_force[self._arm] > 0.0))
        if touching and not self.blocked:
            self.t_touch = t
        self.touching = touching
        self.touched_in_step = self.touched_in_step or touching

    def end_step(self) -> bool:
        """An env step ends: True if the robot touched the arm during it (the reach re-plans
        from where the hand is); the limit is lifted once a whole step passed without touch."""
        touched = self.touched_in_step
        if touched:
            self.touched_steps += 1
        self.touched_in_step = self.touching
        if not self.blocked:
            self.t_touch = math.nan
        return touched

    def limit(self, data: mujoco.MjData, mocap_pos: np.ndarray, mocap_quat: np.ndarray) -> None:
        """Limit the arm's targets (rows of ``mocap_pos`` / ``mocap_quat`` in segment order) to
        the bounded drive, or hold them on the segments after the latency."""
        if not self.blocked:
            return
        held = float(data.time) - self.t_touch >= TACTILE_LATENCY
        for seg, b in zip(self._arm, self._bodies, strict=True):
            pos = data.xpos[b]
            if held:
                mocap_pos[seg] = pos
                mocap_quat[seg] = data.xquat[b]
                continue
            lead = mocap_pos[seg] - pos
            dist = float(np.linalg.norm(lead))
            if dist > self.reach:
                mocap_pos[seg] = pos + lead * (self.reach / dist)


__all__ = ["ARM", "MAX_ARM_PUSH", "TACTILE_LATENCY", "ArmYield"]
