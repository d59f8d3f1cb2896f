"""The MuJoCo targets that move the simulated person's body, at every controller tick.

Each body segment follows a mocap target through a soft weld
(:mod:`handover_env.person.body_model`). :class:`BodyTargets` holds the pose decided for the
start and the end of an env step (two keyframes, 30 Hz) and moves the targets between them at
every 200 Hz controller tick, with a velocity and acceleration feed-forward that makes up for the
welds' lag (:func:`handover_env.person.body_model.weld_lag_times`). With the opt-in person
setting ``arm_yield``, the right arm's targets are limited while the robot touches it
(:class:`handover_env.person.arm_yield.ArmYield`).

The per-step interpolation (:func:`plan_kernel`) and the per-tick targets (:func:`tick_kernel`)
are compiled (:func:`handover_env.compiled.kernel`): plain IEEE arithmetic in the order the
formulas below write it, so the targets are bit for bit those of the same formulas in numpy.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from handover_env.compiled import kernel
from handover_env.person.arm_yield import ArmYield
from handover_env.person.body_model import BodyIds, weld_lag_times
from handover_env.person.person import RATE
from handover_env.person.pose import quat_mul
from handover_env.person.settings import MAX_SEGMENT_SPEED
from handover_env.person.skeleton import SEGMENTS

#: Acceleration up to which a segment's target is led by the feed-forward, m/s^2 (with
#: :data:`~handover_env.person.settings.MAX_SEGMENT_SPEED` for the speed).
MAX_SEGMENT_ACCEL = 30.0

Pose = tuple[np.ndarray, np.ndarray]  # segment origins (S, 3) and quaternions (S, 4)

# Columns of the per-segment rows of the step plan (BodyTargets._plan, (S, PLAN_COLS)).
POS0, DPOS, QUAT0, DQUAT, VEL = 0, 3, 6, 10, 14
PLAN_COLS = 17
# Columns of the per-segment feed-forward settings (BodyTargets._ff, (S, 5)).
LAG_DT, LAG, ACC_GAIN, SPEED_LIMIT, ACCEL_LIMIT = 0, 1, 2, 3, 4
# Rows of BodyTargets._ticks: [0]: the tick index; [1:]: the tick fractions of the step.


def clip_norm(v: np.ndarray, limit: float) -> np.ndarray:
    """Rows of ``v`` scaled down to norm ``limit`` where longer."""
    norm = np.linalg.norm(v, axis=1, keepdims=True)
    return v * np.minimum(1.0, limit / np.maximum(norm, 1e-12))


@kernel
def plan_kernel(keys: np.ndarray, ff: np.ndarray, plan: np.ndarray) -> None:
    """The step's target interpolation from the keyframes ``keys`` (2, S, 7) (origin, quaternion
    at the step's start and end): per segment, the start targets and their increments over the
    step, with the weld-lag feed-forward (``ff``, (S, 5)); writes ``plan`` (S, PLAN_COLS), whose
    VEL columns hold the previous step's velocity on entry and this step's on return.

    Angular velocity from q0 to q1 (world frame) is 2 log(q1 q0^-1) / dt; dq = q1 conj(q0),
    sign-flipped to w >= 0 (only its vector part and the sign of w are needed). A weld with
    damping b and stiffness k lags a target moving at v by (b / k) v (and at acceleration a by
    a / k), so the target is placed that far ahead (the segment then sits on the nominal pose and
    its weld force is zero in free motion): the feed-forward rotation ff = (1, dq_xyz lag / dt)
    multiplies both keyframes (with w = 1 the Hamilton product's 1 * q terms are exact), and the
    position lead is the velocity and the acceleration, each clipped to a human norm (beyond them
    a recorded segment lags its motion instead of being pulled by a target far ahead of it), times
    their gains.
    """
    dt = 1.0 / RATE
    for s in range(keys.shape[1]):
        w0, x0, y0, z0 = keys[0, s, 3], keys[0, s, 4], keys[0, s, 5], keys[0, s, 6]
        w1, x1, y1, z1 = keys[1, s, 3], keys[1, s, 4], keys[1, s, 5], keys[1, s, 6]
        dw = w1 * w0 - x1 * -x0 - y1 * -y0 - z1 * -z0
        sign = -1.0 if dw < 0 else 1.0
        lag_dt = ff[s, LAG_DT]
        fx = ((w1 * -x0 + x1 * w0 + y1 * -z0 - z1 * -y0) * sign) * lag_dt
        fy = ((w1 * -y0 - x1 * -z0 + y1 * w0 + z1 * -x0) * sign) * lag_dt
        fz = ((w1 * -z0 + x1 * -y0 - y1 * -x0 + z1 * w0) * sign) * lag_dt
        a0 = w0 - fx * x0 - fy * y0 - fz * z0
        a1 = x0 + fx * w0 + fy * z0 - fz * y0
        a2 = y0 - fx * z0 + fy * w0 + fz * x0
        a3 = z0 + fx * y0 - fy * x0 + fz * w0
        plan[s, QUAT0], plan[s, QUAT0 + 1], plan[s, QUAT0 + 2], plan[s, QUAT0 + 3] = a0, a1, a2, a3
        plan[s, DQUAT] = (w1 - fx * x1 - fy * y1 - fz * z1) - a0
        plan[s, DQUAT + 1] = (x1 + fx * w1 + fy * z1 - fz * y1) - a1
        plan[s, DQUAT + 2] = (y1 - fx * z1 + fy * w1 + fz * x1) - a2
        plan[s, DQUAT + 3] = (z1 + fx * y1 - fy * x1 + fz * w1) - a3
        d0 = keys[1, s, 0] - keys[0, s, 0]
        d1 = keys[1, s, 1] - keys[0, s, 1]
        d2 = keys[1, s, 2] - keys[0, s, 2]
        v0, v1, v2 = d0 / dt, d1 / dt, d2 / dt
        c0 = (v0 - plan[s, VEL]) / dt
        c1 = (v1 - plan[s, VEL + 1]) / dt
        c2 = (v2 - plan[s, VEL + 2]) / dt
        sv = min(1.0, ff[s, SPEED_LIMIT] / max(math.sqrt(v0 * v0 + v1 * v1 + v2 * v2), 1e-12))
        sa = min(1.0, ff[s, ACCEL_LIMIT] / max(math.sqrt(c0 * c0 + c1 * c1 + c2 * c2), 1e-12))
        gv, ga = ff[s, LAG], ff[s, ACC_GAIN]
        plan[s, DPOS], plan[s, DPOS + 1], plan[s, DPOS + 2] = d0, d1, d2
        plan[s, VEL], plan[s, VEL + 1], plan[s, VEL + 2] = v0, v1, v2
        plan[s, POS0] = (keys[0, s, 0] + (v0 * sv) * gv) + (c0 * sa) * ga
        plan[s, POS0 + 1] = (keys[0, s, 1] + (v1 * sv) * gv) + (c1 * sa) * ga
        plan[s, POS0 + 2] = (keys[0, s, 2] + (v2 * sv) * gv) + (c2 * sa) * ga


@kernel
def targets_kernel(plan: np.ndarray, a: float, mocap_pos: np.ndarray,
                   mocap_quat: np.ndarray) -> None:
    """The targets at the fraction ``a`` of the step (linear between the keyframes; MuJoCo
    normalises mocap quaternions)."""
    for s in range(plan.shape[0]):
        for c in range(3):
            mocap_pos[s, c] = plan[s, DPOS + c] * a + plan[s, POS0 + c]
        for c in range(4):
            mocap_quat[s, c] = plan[s, DQUAT + c] * a + plan[s, QUAT0 + c]


@kernel
def tick_kernel(plan: np.ndarray, ticks: np.ndarray, mocap_pos: np.ndarray,
                mocap_quat: np.ndarray) -> None:
    """The targets at the step's next controller tick: the fraction ``ticks[1 + i]`` for the
    i-th call since the plan (``ticks[0]`` counts them; 1 past the listed ticks)."""
    i = int(ticks[0])
    ticks[0] = i + 1
    a = ticks[1 + i] if 1 + i < ticks.shape[0] else 1.0
    targets_kernel(plan, a, mocap_pos, mocap_quat)


class BodyTargets:
    """The person's mocap targets: two keyframes per env step, interpolated at the ticks.

    Args:
        model: the compiled scene.
        body: the person's indices in it.
        arm_yield: the opt-in person setting ``arm_yield`` (the right arm yields to the robot).
    """

    def __init__(self, model: mujoco.MjModel, body: BodyIds, arm_yield: bool = False) -> None:
        self.model, self.body = model, body
        self._bound: mujoco.MjData | None = None
        self._keys = np.zeros((2, len(SEGMENTS), 7))
        self._tick_rows: dict[tuple[float, ...], np.ndarray] = {}
        #: The right arm's yield to the robot's touch (limits its targets while touched).
        self.arm = ArmYield(body, enabled=arm_yield)
        self.reset()

    @property
    def key0(self) -> Pose:
        """The pose at the start of the env step: origins (S, 3), quaternions (S, 4)."""
        return self._keys[0, :, :3], self._keys[0, :, 3:]

    @property
    def key1(self) -> Pose:
        """The pose at the end of the env step: origins (S, 3), quaternions (S, 4)."""
        return self._keys[1, :, :3], self._keys[1, :, 3:]

    def reset(self) -> None:
        """Forget the keyframes (a new episode)."""
        self._keys[:] = 0.0
        self._ticks = np.zeros(2)  # before any plan: the step's start
        self.arm.reset()

    def resize(self) -> None:
        """Read the welds' lag times again (after the body was resized for a new person)."""
        lag, acc_gain = weld_lag_times(self.model, self.body)
        n = len(lag)
        ff = np.empty((n, 5))
        ff[:, LAG_DT] = lag / (1.0 / RATE)
        ff[:, LAG], ff[:, ACC_GAIN] = lag, acc_gain
        ff[:, SPEED_LIMIT], ff[:, ACCEL_LIMIT] = MAX_SEGMENT_SPEED, MAX_SEGMENT_ACCEL
        self._ff = ff
        self._plan = np.zeros((n, PLAN_COLS))

    def start(self, data: mujoco.MjData, pose: Pose) -> None:
        """Put the body and its targets at ``pose``, at rest (call at reset, before
        ``mj_forward``)."""
        self._keys[0, :, :3] = self._keys[1, :, :3] = pose[0]
        self._keys[0, :, 3:] = self._keys[1, :, 3:] = pose[1]
        self._plan[:] = 0.0
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

    def next_key(self) -> np.ndarray:
        """The keyframe (S, 7) to pose for the end of the next env step, to be written in place
        (origins, then quaternions); the last step's end becomes its start."""
        keys = self._keys
        keys[0] = keys[1]
        return keys[1]

    def plan_ticks(self, alphas: list[float]) -> None:
        """The fractions of this env step at which controller ticks fall; prepares the step's
        target interpolation (:func:`plan_kernel`)."""
        key = tuple(alphas)
        ticks = self._tick_rows.get(key)
        if ticks is None:  # the env's tick schedules repeat: one row per schedule
            ticks = self._tick_rows[key] = np.array((0.0, *key), dtype=np.float64)
        ticks[0] = 0.0
        self._ticks = ticks
        plan_kernel(self._keys, self._ff, self._plan)

    def _mocap(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        if data is not self._bound:
            self._bound = data
            self._mocap_pos = data.mocap_pos[self.body.mocap]
            self._mocap_quat = data.mocap_quat[self.body.mocap]
        return self._mocap_pos, self._mocap_quat

    def apply_tick(self, data: mujoco.MjData) -> None:
        """Move the targets to their pose at the next tick (linear between the step's keyframes)."""
        if data is not self._bound:
            self._mocap(data)
        tick_kernel(self._plan, self._ticks, self._mocap_pos, self._mocap_quat)
        if self.arm.blocked:
            self.arm.limit(data, self._mocap_pos, self._mocap_quat)

    def apply(self, data: mujoco.MjData, a: float) -> None:
        """Targets at the fraction ``a`` of the step (MuJoCo normalises mocap quaternions)."""
        if data is not self._bound:
            self._mocap(data)
        targets_kernel(self._plan, a, self._mocap_pos, self._mocap_quat)
        if self.arm.blocked:
            self.arm.limit(data, self._mocap_pos, self._mocap_quat)
