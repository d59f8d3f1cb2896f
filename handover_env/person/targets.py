"""The MuJoCo targets that move the simulated person's body, at every controller tick.

Each body segment follows a mocap target through a soft weld
(:mod:`handover_env.person.body_model`). :class:`BodyTargets` holds the pose decided for the
start and the end of an env step (two keyframes, 30 Hz) and moves the targets between them at
every 200 Hz controller tick, with a velocity and acceleration feed-forward that makes up for the
welds' lag (:func:`handover_env.person.body_model.weld_lag_times`).
"""

from __future__ import annotations

import mujoco
import numpy as np

from handover_env.person.body_model import BodyIds, weld_lag_times
from handover_env.person.person import RATE
from handover_env.person.pose import QUAT_CONJ, quat_mul
from handover_env.person.settings import MAX_SEGMENT_SPEED
from handover_env.person.skeleton import SEGMENTS

#: Acceleration up to which a segment's target is led by the feed-forward, m/s^2 (with
#: :data:`~handover_env.person.settings.MAX_SEGMENT_SPEED` for the speed).
MAX_SEGMENT_ACCEL = 30.0

Pose = tuple[np.ndarray, np.ndarray]  # segment origins (S, 3) and quaternions (S, 4)


def clip_norm(v: np.ndarray, limit: float) -> np.ndarray:
    """Rows of ``v`` scaled down to norm ``limit`` where longer."""
    norm = np.linalg.norm(v, axis=1, keepdims=True)
    return v * np.minimum(1.0, limit / np.maximum(norm, 1e-12))


class BodyTargets:
    """The person's mocap targets: two keyframes per env step, interpolated at the ticks.

    Args:
        model: the compiled scene.
        body: the person's indices in it.
    """

    def __init__(self, model: mujoco.MjModel, body: BodyIds) -> None:
        self.model, self.body = model, body
        self._bound: mujoco.MjData | None = None
        self.reset()

    def reset(self) -> None:
        """Forget the keyframes (a new episode)."""
        self.key0: Pose | None = None
        self.key1: Pose | None = None
        self._ticks: list[float] = [0.0]
        self._tick_i = 0

    def resize(self) -> None:
        """Read the welds' lag times again (after the body was resized for a new person)."""
        self._lag, self._acc_gain = weld_lag_times(self.model, self.body)

    def start(self, data: mujoco.MjData, pose: Pose) -> None:
        """Put the body and its targets at ``pose``, at rest (call at reset, before
        ``mj_forward``)."""
        self.key0 = self.key1 = pose
        self._vel = np.zeros((len(pose[0]), 3))
        b = self.body
        data.qpos[b.root_qpos:b.root_qpos + 3] = pose[0][0]
        data.qpos[b.root_qpos + 3:b.root_qpos + 7] = pose[1][0]
        # Ball joints: the relative rotation of each segment to its parent.
        for i in range(1, len(pose[1])):
            parent = SEGMENTS[i].parent
            rel = quat_mul(pose[1][parent] * np.array([1, -1, -1, -1]), pose[1][i])
            adr = int(self.model.jnt_qposadr[self.model.body_jntadr[b.bodies[i]]])
            data.qpos[adr:adr + 4] = rel
        data.qvel[b.dofs] = 0.0
        data.mocap_pos[b.mocap] = pose[0]
        data.mocap_quat[b.mocap] = pose[1]

    def push(self, pose: Pose) -> None:
        """The pose at the end of the next env step (the last one's end becomes its start)."""
        self.key0, self.key1 = self.key1, pose

    def plan_ticks(self, alphas: list[float]) -> None:
        """The fractions of this env step at which controller ticks fall; prepares the step's
        target interpolation (start pose and increment, velocity feed-forward included)."""
        self._ticks = alphas
        self._tick_i = 0
        dt = 1.0 / RATE
        (o0, q0), (o1, q1) = self.key0, self.key1
        # Angular velocity from q0 -> q1 (world frame): 2 log(q1 q0^-1) / dt.
        dq = quat_mul(q1, q0 * QUAT_CONJ)
        dq *= np.where(dq[:, :1] < 0, -1.0, 1.0)
        # Velocity feed-forward: a weld with damping b and stiffness k lags a target moving at v
        # by (b / k) v, so the target is placed that far ahead (the segment then sits on the
        # nominal pose and its weld force is zero in free motion). The feed-forward rotation is
        # constant over the step, so it is applied to both keyframes once here.
        lag = self._lag[:, None]
        ff_q = np.concatenate([np.ones((len(lag), 1)), dq[:, 1:] * (lag / dt)], axis=1)
        vel = (o1 - o0) / dt
        acc = (vel - self._vel) / dt
        self._vel = vel
        # The feed-forward assumes human speeds and accelerations (a recorded arm can be tracked
        # at several m/s for a frame or two): beyond them a segment lags its recorded motion
        # instead of being pulled by a target far ahead of it.
        self._pos0 = (o0 + clip_norm(vel, MAX_SEGMENT_SPEED) * lag
                      + clip_norm(acc, MAX_SEGMENT_ACCEL) * self._acc_gain[:, None])
        self._dpos = o1 - o0
        self._quat0 = quat_mul(ff_q, q0)
        self._dquat = quat_mul(ff_q, q1) - self._quat0

    def apply_tick(self, data: mujoco.MjData) -> None:
        """Move the targets to their pose at the next tick (linear between the step's keyframes)."""
        a = self._ticks[self._tick_i] if self._tick_i < len(self._ticks) else 1.0
        self._tick_i += 1
        self.apply(data, a)

    def apply(self, data: mujoco.MjData, a: float) -> None:
        """Targets at the fraction ``a`` of the step (MuJoCo normalises mocap quaternions)."""
        if data is not self._bound:
            self._bound = data
            self._mocap_pos = data.mocap_pos[self.body.mocap]
            self._mocap_quat = data.mocap_quat[self.body.mocap]
        np.multiply(self._dpos, a, out=self._mocap_pos)
        self._mocap_pos += self._pos0
        np.multiply(self._dquat, a, out=self._mocap_quat)
        self._mocap_quat += self._quat0
