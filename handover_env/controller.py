"""Cartesian impedance control of the UR5e at 200 Hz (paper Sec. III-A, Eq. 1).

The paper's desired impedance is ``F = M Δẍ + B Δẋ + K Δx`` (Eq. 1) with Δ = desired - actual.
We implement it as a torque controller, run every ``ticks`` physics steps on a global tick:

* **Reference.** The agent's Cartesian target (x, y, z, yaw) arrives at 30 Hz. A critically
  damped second-order filter (natural frequency ``ref_omega``) turns the piecewise-constant
  target into a smooth desired trajectory ``x_d, ẋ_d, ẍ_d`` at the control rate.
* **Translation.** ``F = Λ(q) ẍ_d + B (ẋ_d - ẋ) + K (x_d - x)`` with K, B from Θ
  (:class:`handover_env.config.HandoverParams`). For the inertia M we use the arm's own
  operational-space inertia ``Λ(q) = (J M(q)^-1 Jᵀ)^-1`` (computed every tick, damped near
  singularities). Then no inertia shaping and no force feedback are needed, and the closed loop
  is Eq. 1 with M = Λ(q): ``Λ(ẍ_d - ẍ) + B Δẋ + K Δx = -F_ext``. Δẍ enters only through the
  feed-forward ``Λ ẍ_d``; the measured acceleration is never differentiated. (The paper sets M to
  a constant "due to the system limitation"; on a torque-controlled arm the natural choice is Λ.)
* **Rotation.** Fixed gains: ``Λ (ω_r² e_r + 2 ζ ω_r Δω)`` through the full 6x6 Λ, so the
  rotational command does not push the TCP (``rot_omega``, ``rot_zeta``). The desired orientation keeps the
  gripper horizontal: its approach axis is ``(cos ψ, sin ψ, 0)`` and the finger axis vertical, so
  only the yaw ψ follows the target (paper Sec. IV-C).
* **Torque.** ``τ = Jᵀ F + qfrc_bias + τ_payload + N τ_posture`` then clipped to the UR5e limits
  (150 N*m joints 1-3, 28 N*m joints 4-6). ``qfrc_bias`` is MuJoCo's gravity + Coriolis
  compensation; ``τ_payload = J_objᵀ m_obj g`` compensates the held object's weight (the object is
  a separate body held by a weld, so ``qfrc_bias`` does not include it), as a robot's payload
  setting does.
* **Posture.** ``N = I - Jᵀ J̄ᵀ`` with the dynamically consistent inverse ``J̄ = M^-1 Jᵀ Λ``, and
  ``τ_posture = k_n (q_rest - q) - d_n q̇`` pulling toward the elbow-up rest posture. The UR5e
  has 6 joints for a 6-D task, so N vanishes away from singularities; with the damped Λ it acts
  only near a singularity, where it keeps the elbow from flipping.
* **Cost.** Λ(q), J M^-1 and the posture torque are refreshed at each replan of the reference
  (about 30 Hz; they change slowly with q); J, the pose and velocity errors, J̇ q̇ and the bias
  forces are updated at every 200 Hz tick. The reference filter is linear, so its next ticks
  are precomputed in one matrix product per replan.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from handover_env.config import HandoverParams
from handover_env.scene import TORQUE_LIMITS, SceneIds

GRAVITY = np.array([0.0, 0.0, -9.81])


@dataclass(frozen=True)
class ControllerConfig:
    """Fixed controller settings (the tuned ones, K and B, are in :class:`HandoverParams`).

    Args:
        ticks: physics steps per controller update (3 at dt = 1/600 s gives 200 Hz).
        rot_omega: natural frequency of the (decoupled) rotational error dynamics, rad/s; the
            rotational stiffness is Λ_rot ω², so turning the gripper does not push the TCP around.
        rot_zeta: damping ratio of the rotational error dynamics.
        ref_omega: natural frequency of the critically damped target filter, rad/s.
        singular_damping: Tikhonov term added to J M^-1 Jᵀ before inverting it.
        posture_stiffness: null-space posture stiffness k_n, N*m/rad.
        posture_damping: null-space posture damping d_n, N*m*s/rad.
        max_linear_speed: the reference filter's speed limit, m/s.
        max_linear_accel: the reference filter's initial-acceleration limit, m/s^2.
        plan_ticks: ticks between replans of the reference toward the goal.
    """

    ticks: int = 3
    rot_omega: float = 15.0
    rot_zeta: float = 1.0
    ref_omega: float = 20.0
    singular_damping: float = 1e-3
    posture_stiffness: float = 10.0
    posture_damping: float = 1.0
    max_linear_speed: float = 1.5
    max_linear_accel: float = 25.0
    plan_ticks: int = 7

    def __post_init__(self) -> None:
        vals = (self.rot_omega, self.rot_zeta, self.ref_omega, self.singular_damping,
                self.posture_stiffness, self.posture_damping, self.max_linear_speed, self.max_linear_accel)
        if not all(math.isfinite(v) for v in vals):
            raise ValueError("ControllerConfig values must be finite")
        if self.ticks < 1 or self.plan_ticks < 1:
            raise ValueError(f"ticks must be >= 1, got {self.ticks}")
        if min(vals) < 0 or self.ref_omega <= 0 or self.max_linear_speed <= 0 or self.max_linear_accel <= 0:
            raise ValueError("gains must be >= 0, ref_omega and max_linear_speed > 0")


def target_rotation(yaw: float) -> np.ndarray:
    """Desired gripper orientation (3x3, columns = gripper x, y, z axes in the world).

    The approach axis z is horizontal at heading ``yaw``; the finger joint axis x points down, so
    the fingers close horizontally around an upright bottle.
    """
    c, s = math.cos(yaw), math.sin(yaw)
    z = np.array([c, s, 0.0])
    x = np.array([0.0, 0.0, -1.0])
    y = np.cross(z, x)
    return np.column_stack([x, y, z])


def _as_slice(idx: np.ndarray) -> slice | np.ndarray:
    """Contiguous index arrays become slices (views instead of copies in the hot path)."""
    idx = np.asarray(idx)
    if idx.size and np.all(np.diff(idx) == 1):
        return slice(int(idx[0]), int(idx[-1]) + 1)
    return idx


def target_rotation_batch(yaw: np.ndarray) -> np.ndarray:
    """:func:`target_rotation` for many yaws at once: (n, 3, 3)."""
    yaw = np.asarray(yaw, dtype=float)
    c, s = np.cos(yaw), np.sin(yaw)
    out = np.zeros(yaw.shape + (3, 3))
    out[..., 2, 0] = -1.0  # x = (0, 0, -1)
    out[..., 0, 1], out[..., 1, 1] = -s, c  # y = z cross x = (-s, c, 0)
    out[..., 0, 2], out[..., 1, 2] = c, s  # z = (c, s, 0)
    return out


class ImpedanceController:
    """Cartesian impedance controller of the UR5e TCP (the 2F-85 ``pinch`` site).

    Args:
        model: the compiled scene.
        ids: index lookup from :func:`handover_env.scene.scene_ids`.
        params: Θ (K and B are used here).
        config: fixed controller settings.
        rest_qpos: the posture the null-space term pulls toward (6,).
    """

    def __init__(self, model: mujoco.MjModel, ids: SceneIds, params: HandoverParams,
                 config: ControllerConfig | None = None, rest_qpos: np.ndarray | None = None) -> None:
        self.model, self.ids = model, ids
        self.config = config or ControllerConfig()
        self.set_params(params)
        nv = model.nv
        self._jac = np.zeros((6, nv))
        self._jacp, self._jacr = self._jac[:3], self._jac[3:]
        self._minv_jt = np.zeros((6, nv))
        self._dof = _as_slice(ids.arm_dof)
        self._qpos_adr = _as_slice(ids.arm_qpos)
        self._damp6 = self.config.singular_damping * np.eye(6)
        self._prev_j = np.zeros((6, 6))
        self._have_prev = False
        self._zero6 = np.zeros(6)
        self._err = np.zeros(6)
        self._tcp = ids.tcp_site
        self._stale = True
        self._tau_posture = np.zeros(6)
        self._verr = np.zeros(6)
        self._posture = self.config.posture_stiffness > 0.0 or self.config.posture_damping > 0.0
        self._kn, self._dn = self.config.posture_stiffness, self.config.posture_damping
        self._wrench = np.zeros(6)
        self._rhs = np.zeros(6)
        self._tmp6 = np.zeros(6)
        self._tmp6b = np.zeros(6)
        self._rest = np.zeros(6) if rest_qpos is None else np.asarray(rest_qpos, float).copy()
        self._eye6 = np.eye(6)
        self._lam = np.zeros((6, 6))
        self._limits = TORQUE_LIMITS.copy()
        self._neg_limits = -self._limits
        # Reference filter state and target.
        self.x_d = np.zeros(3)
        self.v_d = np.zeros(3)
        self.a_d = np.zeros(3)
        self.target_pos = np.zeros(3)
        self.goal_pos = np.zeros(3)
        self.target_yaw = 0.0
        self.yaw_d = 0.0
        self.yaw_rate_d = 0.0
        self._rot_d = target_rotation(0.0)
        self._payload_mass = 0.0  # mass of a held object to compensate, kg
        self._gain = np.zeros((6, 18))  # wrench = G s + c (see _refresh_dynamics)
        self._gain_c = np.zeros(6)
        self._s = np.zeros(18)
        self._twist_prev = np.zeros(6)
        self.last_torque = np.zeros(6)
        self.last_unclipped = np.zeros(6)
        self.dt = model.opt.timestep * self.config.ticks
        self._inv_dt = 1.0 / self.dt
        w = self.config.ref_omega
        self._max_step = min(self.config.max_linear_speed * math.e / w, self.config.max_linear_accel / w**2)
        # Discrete critically damped filter on e = x_d - target: [e, v]_{k+1} = A [e, v]_k
        # (semi-implicit Euler), a_k = -w^2 e_k - 2 w v_k evaluated before the update.
        w, dt = self.config.ref_omega, self.dt
        acc = np.array([-w * w, -2.0 * w])
        step = np.array([[1.0 + dt * dt * acc[0], dt + dt * dt * acc[1]], [dt * acc[0], 1.0 + dt * acc[1]]])
        rows, state = [], np.eye(2)
        for _ in range(self.config.plan_ticks):
            a_row = acc @ state
            state = step @ state
            rows.append(np.vstack([state, a_row]))
        self._powers = np.array(rows)  # (plan_ticks, 3, 2): tick k -> (e, v after the tick, a during it)
        self._x_plan = np.zeros((0, 3))

    @property
    def payload_mass(self) -> float:
        """Mass of the held object whose inertia and weight are compensated at the TCP, kg."""
        return self._payload_mass

    @payload_mass.setter
    def payload_mass(self, mass: float) -> None:
        self._payload_mass = float(mass)
        self._stale = True  # the gain matrix includes it

    def set_params(self, params: HandoverParams) -> None:
        """Use the translational stiffness and damping of Θ."""
        self.params = params
        self._stale = True
        c = self.config
        self._kvec = np.array([params.stiffness] * 3 + [0.0] * 3, dtype=float)
        self._bvec = np.array([params.damping] * 3 + [0.0] * 3, dtype=float)
        self._kr6 = np.array([0.0] * 3 + [c.rot_omega**2] * 3)
        self._br6 = np.array([0.0] * 3 + [2.0 * c.rot_zeta * c.rot_omega] * 3)

    def reset(self, data: mujoco.MjData, rest_qpos: np.ndarray | None = None) -> None:
        """Start the reference at the current TCP pose with zero velocity."""
        if rest_qpos is not None:
            self._rest = np.asarray(rest_qpos, float).copy()
        pos = data.site_xpos[self.ids.tcp_site]
        self.x_d = pos.copy()
        self.v_d = np.zeros(3)
        self.a_d = np.zeros(3)
        self.target_pos[:] = pos
        z = data.site_xmat[self.ids.tcp_site].reshape(3, 3)[:, 2]
        self.yaw_d = math.atan2(z[1], z[0])
        self.yaw_rate_d = 0.0
        self._plan_i = 0
        self.set_target(pos, self.yaw_d)
        self.last_torque[:] = 0.0
        self._have_prev = False

    def set_target(self, pos: np.ndarray, yaw: float) -> None:
        """New Cartesian goal (30 Hz): position (3,) in m and gripper yaw in rad."""
        self.goal_pos[:] = pos
        self.target_yaw = float(yaw)
        self._plan()

    def _plan(self) -> None:
        """Precompute the reference filter for the next ``plan_ticks`` (it is linear, so exactly).

        The filter's input is the goal, but moved at most ``min(v_max e / ω, a_max / ω²)`` from the
        current reference: the critically damped response to such a step peaks at ``v_max`` and
        starts with acceleration ``a_max``. Replanning every ``plan_ticks`` (about one 30 Hz
        step) lets the reference approach far goals at a bounded speed and acceleration.
        """
        i = self._plan_i - 1
        if i >= 0:  # the reference state reached by the last tick of the current plan
            self.x_d = self._x_plan[i]
            self.v_d = self._v_plan[i]
            self.yaw_d = float(self._yaw_plan[i])
            self.yaw_rate_d = float(self._yaw_rate_plan[i])
        step = self.goal_pos - self.x_d
        dist = math.sqrt(float(step @ step))
        if dist > self._max_step:
            step *= self._max_step / dist
        self.target_pos[:] = self.x_d + step
        s0 = np.stack([self.x_d - self.target_pos, self.v_d])  # (2, 3)
        traj = self._powers @ s0  # (n, 3 rows: x-err, v, a, 3)
        self._x_plan = traj[:, 0] + self.target_pos
        self._v_plan = traj[:, 1]
        self._a_plan = traj[:, 2]
        # The yaw goes through the same filter, along the shorter way round.
        dyaw = (self.yaw_d - self.target_yaw + math.pi) % (2 * math.pi) - math.pi
        yaw_traj = self._powers[:, :2] @ np.array([dyaw, self.yaw_rate_d])
        self._yaw_plan = yaw_traj[:, 0] + self.target_yaw
        self._yaw_rate_plan = yaw_traj[:, 1]
        self._rot_plan = target_rotation_batch(self._yaw_plan)
        n = self._x_plan.shape[0]
        self._vd6_plan = np.zeros((n, 6))
        self._vd6_plan[:, :3] = self._v_plan
        self._vd6_plan[:, 5] = self._yaw_rate_plan
        self._a6_plan = np.zeros((n, 6))
        self._a6_plan[:, :3] = self._a_plan
        self._plan_i = 0
        self._stale = True

    def _refresh_dynamics(self, data: mujoco.MjData) -> None:
        """Λ(q) (as a Cholesky factor of Λ^-1), J M^-1 and the null-space posture torque.

        Refreshed at every replan of the reference (about 30 Hz): Λ and the projector change
        slowly with q, while J, the errors and the bias forces are updated at every tick.
        """
        m, ids, dof = self.model, self.ids, self._dof
        jac = self._jac
        mujoco.mj_jacSite(m, data, self._jacp, self._jacr, ids.tcp_site)
        mujoco.mj_solveM(m, data, self._minv_jt, jac)  # rows of J M^-1
        j = jac[:, dof]
        x = self._minv_jt[:, dof]
        lam_inv = x @ j.T
        lam_inv += self._damp6
        mujoco.mju_cholFactor(lam_inv, 0.0)  # Λ^-1 = L Lᵀ; Λ v = cholSolve(v)
        self._lam_chol = lam_inv
        # The control law is linear in s = [Δx (6), Δẋ (6), ẍ_d - J̇q̇ (6)] with Λ frozen until the
        # next replan: wrench = G s + c, with
        #   G = [diag(K) + Λ diag(K_r),  diag(B) + Λ diag(B_r),  Λ + m_obj I_trans],  c = -m_obj g.
        lam = self._lam
        for k in range(6):
            mujoco.mju_cholSolve(lam[k], lam_inv, self._eye6[k])  # Λ is symmetric: rows = columns
        g = self._gain
        np.multiply(lam, self._kr6, out=g[:, 0:6])
        np.multiply(lam, self._br6, out=g[:, 6:12])
        g[:, 12:18] = lam
        for k in range(3):
            g[k, k] += self._kvec[k]
            g[k, 6 + k] += self._bvec[k]
            g[k, 12 + k] += self._payload_mass
        self._gain_c[:3] = -self._payload_mass * GRAVITY
        # Null-space posture term, N = I - Jᵀ J̄ᵀ with J̄ᵀ = Λ J M^-1.
        if self._posture:
            tau0 = self._kn * (self._rest - data.qpos[self._qpos_adr]) - self._dn * data.qvel[dof]
            mujoco.mju_cholSolve(self._tmp6b, lam_inv, x @ tau0)
            self._tau_posture = tau0 - j.T @ self._tmp6b
        else:
            self._tau_posture = self._zero6
        self._stale = False

    def compute(self, data: mujoco.MjData) -> np.ndarray:
        """One control update: advance the reference, return the clipped joint torques (6,).

        The returned array is an internal buffer, overwritten by the next call.
        """
        i = self._plan_i
        if i >= self._x_plan.shape[0]:
            self._plan()
            i = 0
        self._plan_i = i + 1
        if self._stale:
            self._refresh_dynamics(data)
        self.x_d = self._x_plan[i]
        mujoco.mj_jacSite(self.model, data, self._jacp, self._jacr, self._tcp)
        dof = self._dof
        j = self._jac[:, dof]
        qvel = data.qvel[dof]
        twist = j @ qvel
        s = self._s
        # J̇ q̇ by a backward difference of J over one tick (cheaper than mj_jacDot):
        # (J_k - J_{k-1}) q̇_k / dt; s[12:18] = ẍ_d - J̇ q̇.
        if self._have_prev:
            np.subtract(twist, self._prev_j @ qvel, out=self._tmp6)
            self._tmp6 *= self._inv_dt
            np.subtract(self._a6_plan[i], self._tmp6, out=s[12:18])
        else:
            s[12:18] = self._a6_plan[i]
            self._have_prev = True
        self._prev_j[:] = j
        # Pose error: translation, and rotation from R_d Rᵀ (exact axis, sin-scaled magnitude).
        np.subtract(self.x_d, data.site_xpos[self._tcp], out=s[0:3])
        r = (self._rot_plan[i] @ data.site_xmat[self._tcp].reshape(3, 3).T).tolist()
        ex = 0.5 * (r[2][1] - r[1][2])
        ey = 0.5 * (r[0][2] - r[2][0])
        ez = 0.5 * (r[1][0] - r[0][1])
        if r[0][0] + r[1][1] + r[2][2] < -0.5:  # beyond ~120 deg: push at full strength
            scale = 2.0 / max(math.sqrt(ex * ex + ey * ey + ez * ez), 1e-9)
            ex, ey, ez = ex * scale, ey * scale, ez * scale
        s[3], s[4], s[5] = ex, ey, ez
        np.subtract(self._vd6_plan[i], twist, out=s[6:12])
        # Eq. 1 with M = Λ(q): F = K Δx + B Δẋ + Λ (ẍ_d - J̇q̇) for translation (K, B from Θ), plus
        # Λ (ω² e_r + 2ζω Δω) for rotation (fixed gains on the decoupled rotational dynamics), plus
        # the held object's inertia and weight at the TCP: all in one product, wrench = G s + c.
        wrench = self._gain @ s
        wrench += self._gain_c
        tau = j.T @ wrench
        tau += data.qfrc_bias[dof]
        tau += self._tau_posture
        self.last_unclipped = tau
        np.minimum(tau, self._limits, out=self.last_torque)
        np.maximum(self.last_torque, self._neg_limits, out=self.last_torque)
        return self.last_torque


def inverse_kinematics(model: mujoco.MjModel, data: mujoco.MjData, ids: SceneIds, pos: np.ndarray,
                       yaw: float, q0: np.ndarray, iters: int = 200, tol: float = 1e-5) -> np.ndarray:
    """Damped least-squares IK for the TCP pose (pos, horizontal gripper at ``yaw``).

    Works on ``data`` (use a scratch ``MjData``); returns the 6 arm joint angles.

    Raises:
        ValueError: the pose is not reached within ``iters`` iterations (out of the workspace).
    """
    pos = np.asarray(pos, dtype=float)
    rot_d = target_rotation(yaw)
    jac = np.zeros((6, model.nv))
    q = np.asarray(q0, dtype=float).copy()
    err = np.zeros(6)
    for _ in range(iters):
        data.qpos[ids.arm_qpos] = q
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        x = data.site_xpos[ids.tcp_site]
        r_err = rot_d @ data.site_xmat[ids.tcp_site].reshape(3, 3).T
        err[:3] = pos - x
        err[3:] = 0.5 * np.array([r_err[2, 1] - r_err[1, 2], r_err[0, 2] - r_err[2, 0], r_err[1, 0] - r_err[0, 1]])
        if np.linalg.norm(err) < tol:
            return q
        mujoco.mj_jacSite(model, data, jac[:3], jac[3:], ids.tcp_site)
        j = jac[:, ids.arm_dof]
        q = q + j.T @ np.linalg.solve(j @ j.T + 1e-4 * np.eye(6), err)
    raise ValueError(f"IK did not converge to pos={pos.tolist()}, yaw={yaw:.3f} (residual {np.linalg.norm(err):.2e})")
