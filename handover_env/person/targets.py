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
from handover_env.person.pose import quat_mul
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
        n = len(self._lag)
        self._lag_dt = self._lag / (1.0 / RATE)  # lag / dt
        # Per-row gain and limit of the stacked [velocity; acceleration] feed-forward.
        self._gains = np.concatenate([self._lag, self._acc_gain])[:, None]
        self._limits = np.repeat([MAX_SEGMENT_SPEED, MAX_SEGMENT_ACCEL], n)[:, None].astype(float)
        self._dq = np.zeros((3, n))
        self._keys = np.zeros((2, n, 4))
        self._quats = np.zeros((2, n, 4))
        self._dquat = np.zeros((n, 4))
        self._dpos = np.zeros((n, 3))
        self._vel_acc = np.zeros((2 * n, 3))

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
        target interpolation (start pose and increment, velocity feed-forward included).

        Every value is the same elementwise arithmetic as :func:`quat_mul` and :func:`clip_norm`
        on the keyframes (so the targets are bit for bit those of the plain formulas), batched
        into a few numpy calls on preallocated buffers: this runs at every env step.
        """
        self._ticks = alphas
        self._tick_i = 0
        dt = 1.0 / RATE
        (o0, q0), (o1, q1) = self.key0, self.key1
        # Angular velocity from q0 -> q1 (world frame): 2 log(q1 q0^-1) / dt; dq = q1 conj(q0),
        # sign-flipped to w >= 0 (only its vector part and the sign of w are needed).
        w1, x1, y1, z1 = q1.T
        w0, x0, y0, z0 = q0.T
        dq = self._dq
        dw = w1 * w0 - x1 * -x0 - y1 * -y0 - z1 * -z0
        dq[0] = w1 * -x0 + x1 * w0 + y1 * -z0 - z1 * -y0
        dq[1] = w1 * -y0 - x1 * -z0 + y1 * w0 + z1 * -x0
        dq[2] = w1 * -z0 + x1 * -y0 - y1 * -x0 + z1 * w0
        # Velocity feed-forward: a weld with damping b and stiffness k lags a target moving at v
        # by (b / k) v, so the target is placed that far ahead (the segment then sits on the
        # nominal pose and its weld force is zero in free motion). The feed-forward rotation
        # ff = (1, dq_xyz lag / dt) is constant over the step, so it is applied to both
        # keyframes once here (with w = 1 the Hamilton product's 1 * q terms are exact).
        sign = np.where(dw < 0, -1.0, 1.0)
        dq *= sign
        fx, fy, fz = np.multiply(dq, self._lag_dt, out=dq)
        keys = self._keys
        keys[0], keys[1] = q0, q1
        kw, kx, ky, kz = keys.transpose(2, 0, 1)  # (2, S) each: both keyframes at once
        quat = self._quats
        quat[..., 0] = kw - fx * kx - fy * ky - fz * kz
        quat[..., 1] = kx + fx * kw + fy * kz - fz * ky
        quat[..., 2] = ky - fx * kz + fy * kw + fz * kx
        quat[..., 3] = kz + fx * ky - fy * kx + fz * kw
        self._quat0 = quat[0]
        np.subtract(quat[1], quat[0], out=self._dquat)
        vel_acc = self._vel_acc  # rows [0, S): velocity, [S, 2S): acceleration
        n = len(o0)
        vel, acc = vel_acc[:n], vel_acc[n:]
        np.subtract(o1, o0, out=self._dpos)
        np.divide(self._dpos, dt, out=vel)
        np.subtract(vel, self._vel, out=acc)
        acc /= dt
        self._vel = vel.copy()
        # The feed-forward assumes human speeds and accelerations (a recorded arm can be tracked
        # at several m/s for a frame or two): beyond them a segment lags its recorded motion
        # instead of being pulled by a target far ahead of it (clip_norm of both at once).
        norm = np.sqrt(np.add.reduce(vel_acc * vel_acc, axis=1, keepdims=True))
        scale = np.minimum(1.0, self._limits / np.maximum(norm, 1e-12))
        lead = vel_acc * scale
        lead *= self._gains
        self._pos0 = o0 + lead[:n]
        self._pos0 += lead[n:]

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
