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
  rotational command does not push the TCP (``rot_omega``, ``rot_zeta``). The desired orientation
  keeps the
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
  are precomputed in one matrix product per replan. With Λ frozen the whole law is affine in
  the measured TCP pose and twists, so each planned tick gets one (7, 26) matrix at the replan
  and a tick is J, three small products and the clip, one compiled call
  (:mod:`handover_env.robot.impedance_tick`, the replan's Λ, W_k, posture torque and the speed
  check's solve by numpy's own LAPACK too; numpy keeps the limiter's rare matrix inverse).

This module is over 500 lines because the controller is one class whose per-tick law and the
precomputation that makes it affine (gain maps, reference filter, frozen Λ) share the same
matrices and index layout (``_Z_*``/``_B_*``); split apart, each half would only be read with
the other. :func:`inverse_kinematics` (the ready pose) shares :func:`target_rotation`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import mujoco
import numpy as np

from handover_env.config import HandoverParams
from handover_env.mjdata_view import MjDataView
from handover_env.robot import impedance_tick as tk
from handover_env.robot.scene import TORQUE_LIMITS, SceneIds

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
        inertia: M of Eq. 1 for translation, kg: 0 = the arm's own Λ(q) (the ``"lambda"``
            controller), > 0 = the paper's constant M (the ``"constant_m"`` controller; see
            :func:`constant_inertia`).
        joint_speed_limit: rad/s on every arm joint, 0 = none (UR5e datasheet: 180 deg/s).
        joint_accel_limit: rad/s^2 on every arm joint, 0 = none.
        speed_scaling: with a joint speed limit, slow each plan of the reference so that its
            joint velocities stay within the limit, as the UR controller does (True), or leave
            the limit to the torque-level limiter alone (False, the ablation).
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
    inertia: float = 0.0
    joint_speed_limit: float = 0.0
    joint_accel_limit: float = 0.0
    speed_scaling: bool = True

    @property
    def mode(self) -> str:
        """``"lambda"`` (M = Λ(q)) or ``"constant_m"`` (M = ``inertia`` I)."""
        return "constant_m" if self.inertia > 0 else "lambda"

    def __post_init__(self) -> None:
        vals = (
            self.inertia,
            self.joint_speed_limit,
            self.joint_accel_limit,
            self.rot_omega,
            self.rot_zeta,
            self.ref_omega,
            self.singular_damping,
            self.posture_stiffness,
            self.posture_damping,
            self.max_linear_speed,
            self.max_linear_accel,
        )
        if not all(math.isfinite(v) for v in vals):
            raise ValueError("ControllerConfig values must be finite")
        if self.ticks < 1 or self.plan_ticks < 1:
            raise ValueError(f"ticks must be >= 1, got {self.ticks}")
        if (
            min(vals) < 0
            or self.ref_omega <= 0
            or self.max_linear_speed <= 0
            or self.max_linear_accel <= 0
        ):
            raise ValueError("gains must be >= 0, ref_omega and max_linear_speed > 0")


def _target_rotation_cs(c: float, s: float) -> np.ndarray:
    """:func:`target_rotation` from the cosine and sine of the yaw (it is linear in them)."""
    z = np.array([c, s, 0.0])
    x = np.array([0.0, 0.0, -1.0])
    y = np.cross(z, x)
    return np.column_stack([x, y, z])


def target_rotation(yaw: float) -> np.ndarray:
    """Desired gripper orientation (3x3, columns = gripper x, y, z axes in the world).

    The approach axis z is horizontal at heading ``yaw``; the finger joint axis x points down, so
    the fingers close horizontally around an upright bottle.
    """
    return _target_rotation_cs(math.cos(yaw), math.sin(yaw))


def _as_slice(idx: np.ndarray) -> slice | np.ndarray:
    """Contiguous index arrays become slices (views instead of copies in the hot path)."""
    idx = np.asarray(idx)
    if idx.size and np.all(np.diff(idx) == 1):
        return slice(int(idx[0]), int(idx[-1]) + 1)
    return idx


def _chain_dofs(model: mujoco.MjModel, body: int) -> set[int]:
    """The dofs of ``body`` and its ancestors: the only nonzero columns of its Jacobians."""
    dofs: set[int] = set()
    while body > 0:
        adr = int(model.body_dofadr[body])
        dofs.update(range(adr, adr + int(model.body_dofnum[body])))
        body = int(model.body_parentid[body])
    return dofs


def _rotation_error_map(rot_d: np.ndarray) -> np.ndarray:
    """The linear map (4, 9) from vec(R) (row-major) to [e_r (3), trace(R_d Rᵀ)].

    With r = R_d Rᵀ the orientation error is e_r = ½ (r21 - r12, r02 - r20, r10 - r01) and
    r_ab = R_d[a] · R[b]: both e_r and the trace are linear in R.
    """
    out = np.zeros((4, 9))
    out[0, 3:6] += 0.5 * rot_d[2]
    out[0, 6:9] -= 0.5 * rot_d[1]
    out[1, 6:9] += 0.5 * rot_d[0]
    out[1, 0:3] -= 0.5 * rot_d[2]
    out[2, 0:3] += 0.5 * rot_d[1]
    out[2, 3:6] -= 0.5 * rot_d[0]
    out[3] = rot_d.reshape(9)
    return out


def _rotation_error_basis() -> np.ndarray:
    """(3, 36): ``[1, cos ψ, sin ψ] @ basis`` is :func:`_rotation_error_map` of
    ``target_rotation(ψ)``.

    ``target_rotation`` is linear in (cos ψ, sin ψ) and the error map is linear in R_d.
    """
    a0 = _target_rotation_cs(0.0, 0.0)
    parts = (a0, _target_rotation_cs(1.0, 0.0) - a0, _target_rotation_cs(0.0, 1.0) - a0)
    return np.stack([_rotation_error_map(p).reshape(36) for p in parts])


# Layout of z, the per-tick input of the control law (see ImpedanceController): TCP position (3),
# twist J q̇ (6), J_prev q̇ (6), 1 (constant wrench), 1 (feed-forward of the plan), vec R (9).
# The first 16 columns of W_k are the same for every planned tick.
_Z_POS, _Z_TWIST, _Z_PREV, _Z_CONST, _Z_FF, _Z_ROT, _Z_SIZE = 0, 3, 9, 15, 16, 17, 26
# Columns of the per-replan matrix Λ P + C (see ImpedanceController._gain_maps).
_B_TICK = _Z_FF  # [-G_x | -(G_v + G_a / dt) | G_a / dt | c]: W_k[:6, :_Z_FF] for every k
_B_FF = slice(_Z_FF, _Z_FF + 12)  # Gᵀ rows that multiply one plan tick [x, ψ, v, ψ̇, a, ψ̈]
_B_ROT = slice(_Z_FF + 12, _Z_FF + 15)  # G_r, the gain on the rotation error
_B_SIZE = _Z_FF + 15


class ImpedanceController:
    """Cartesian impedance controller of the UR5e TCP (the 2F-85 ``pinch`` site).

    Args:
        model: the compiled scene.
        ids: index lookup from :func:`handover_env.robot.scene.scene_ids`.
        params: Θ (K and B are used here).
        config: fixed controller settings.
        rest_qpos: the posture the null-space term pulls toward (6,).

    How a tick is evaluated: with Λ frozen between replans the control law is affine in the
    measured quantities ``z = [x (3), J q̇ (6), J_prev q̇ (6), 1, 1, vec R (9)]`` (TCP position,
    twist with this tick's and the previous tick's Jacobian, TCP orientation), so
    ``[wrench, trace(R_d Rᵀ)] = W_k z`` with one (7, 26) matrix per planned tick k, built at each
    replan (:meth:`_refresh_dynamics`). A tick is then J and a few small products, compiled
    (:func:`~handover_env.robot.impedance_tick.impedance_tick`) on one float64 workspace whose
    views are the buffers the replan writes (``_jac12``, ``_w_plan``, ...), with MuJoCo's order of
    summation, so the torques are those of MuJoCo's ``mju_mulMatVec``/``mju_mulMatTVec``.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        ids: SceneIds,
        params: HandoverParams,
        config: ControllerConfig | None = None,
        rest_qpos: np.ndarray | None = None,
    ) -> None:
        self.model, self.ids = model, ids
        self.config = config or ControllerConfig()
        nv = model.nv
        n = self.config.plan_ticks
        self._n_plan = n
        self._dof = _as_slice(ids.arm_dof)
        self._qpos_adr = _as_slice(ids.arm_qpos)
        self._tcp = ids.tcp_site
        self._payload_mass = 0.0  # mass of a held object to compensate, kg
        # The tick's buffers live in one float64 workspace (fw) with an int64 one (iw) holding
        # its offsets and the index lists: the compiled tick (impedance_tick) takes both.
        sizes = {tk.I_JAC: 12 * nv, tk.I_W: n * 7 * _Z_SIZE, tk.I_Z: _Z_SIZE, tk.I_OUT: 7,
                 tk.I_TAUF: nv, tk.I_TAU: 6, tk.I_POST: 6, tk.I_LIMITS: 6, tk.I_LAST: 6,
                 tk.I_MINV: 36, tk.I_MINVR: 6 * nv, tk.I_ACC: 6, tk.I_CORR: 6, tk.I_SCAL: tk.S_SIZE,
                 tk.I_MINVJT: 6 * nv, tk.I_LAMINV: 36, tk.I_LAM: 36, tk.I_GAINS: 6 * _B_SIZE,
                 tk.I_PGAIN: 6 * _B_SIZE, tk.I_CGAIN: 6 * _B_SIZE, tk.I_TRAJ: n * 12,
                 tk.I_ROTMAPS: 36 * n, tk.I_PLAN: tk.P_SIZE, tk.I_POWERS: 9 * n, tk.I_CS: 3 * n,
                 tk.I_ROTB: 108, tk.I_JACPLAN: 36, tk.I_TWIST: 6 * n, tk.I_ARMROWS: 6 * nv,
                 tk.I_REST: 6, tk.I_PTMP: 18, tk.I_SOLVE: 36 + 6 * n}
        chain = sorted(_chain_dofs(model, int(model.site_bodyid[ids.tcp_site])))
        lists = chain + [int(i) for part in (ids.arm_dof, ids.arm_act, ids.arm_qpos)
                         for i in np.asarray(part)]
        self._iw = iw = np.zeros(tk.I_SIZE + len(lists) + tk.L_SIZE, dtype=np.int64)
        iw[tk.I_NV], iw[tk.I_NCHAIN], iw[tk.I_NPLAN] = nv, len(chain), n
        iw[tk.I_SIZE:tk.I_SIZE + len(lists)] = lists
        iw[tk.I_LAPACK] = tk.I_SIZE + len(lists)
        self._fw = fw = np.zeros(sum(sizes.values()))
        views, at = {}, 0
        for slot, size in sizes.items():
            iw[slot] = at
            views[slot] = fw[at:at + size]
            at += size
        self._scal = views[tk.I_SCAL]
        self._p_gain = views[tk.I_PGAIN].reshape(6, _B_SIZE)
        self._c_gain = views[tk.I_CGAIN].reshape(6, _B_SIZE)
        self._scal[tk.S_DAMP] = self.config.singular_damping
        self.set_params(params)
        # Jacobians: rows 0:6 this tick's (translation, rotation), rows 6:12 the previous tick's.
        self._jac12 = views[tk.I_JAC].reshape(12, nv)
        self._jac_cur, self._jac_prev = self._jac12[0:6], self._jac12[6:12]
        self._jacp, self._jacr = self._jac12[0:3], self._jac12[3:6]
        self._plan_twist = views[tk.I_TWIST].reshape(n, 6)  # the speed check's twists
        self._jjt = views[tk.I_PLAN][tk.P_JJT:tk.P_JJT + 36].reshape(6, 6)
        self.scaled_plans = 0  # replans slowed by the joint speed limit (since reset)
        self._j2 = self._jac12[:, self._dof]  # (12, 6) arm columns of both
        self._j = self._jac12[0:6, self._dof]
        self._minv_jt = views[tk.I_MINVJT].reshape(6, nv)
        self._x_minv = self._minv_jt[:, self._dof]
        self._lam_inv = views[tk.I_LAMINV].reshape(6, 6)
        self._stale = True
        self._tau_posture = views[tk.I_POST]
        self._posture = self.config.posture_stiffness > 0.0 or self.config.posture_damping > 0.0
        self._scal[tk.S_KN] = self.config.posture_stiffness
        self._scal[tk.S_DN] = self.config.posture_damping
        self._rest = views[tk.I_REST]
        if rest_qpos is not None:
            self._rest[:] = np.asarray(rest_qpos, float)
        self._lam = views[tk.I_LAM].reshape(6, 6)
        self._limits = views[tk.I_LIMITS]
        self._limits[:] = TORQUE_LIMITS
        # Joint speed / acceleration limiter (see _limit_joint_motion).
        self._arm_rows = views[tk.I_ARMROWS].reshape(6, nv)
        self._arm_rows[np.arange(6), np.asarray(ids.arm_dof)] = 1.0
        self._minv_rows = views[tk.I_MINVR].reshape(6, nv)
        self._minv_aa = views[tk.I_MINV].reshape(6, 6)
        self._m_aa = np.zeros((6, 6))
        self._corr = views[tk.I_CORR]
        self.limited_ticks = 0  # ticks at which the limiter reduced the torque (since reset)
        self._minv_age = 2  # 2: M^-1 stale, 1: M^-1 fresh and M stale, 0: both fresh
        # Reference filter state and target.
        self._ps = ps = views[tk.I_PLAN]
        self._x_start = ps[tk.P_X:tk.P_X + 3]  # reference state at the start of the current plan
        self.v_d = ps[tk.P_V:tk.P_V + 3]
        self.a_d = np.zeros(3)
        self.target_pos = ps[tk.P_TARGET:tk.P_TARGET + 3]
        self.goal_pos = ps[tk.P_GOAL:tk.P_GOAL + 3]
        self._gains = views[tk.I_GAINS].reshape(6, _B_SIZE)  # Λ P + C (see _gain_maps)
        self._w_plan = views[tk.I_W].reshape(n, 7, _Z_SIZE)  # W_k for each planned tick
        self._z = views[tk.I_Z]
        self._z[_Z_CONST] = self._z[_Z_FF] = 1.0
        self._z_pos = self._z[_Z_POS:_Z_TWIST]
        self._z_twists = self._z[_Z_TWIST:_Z_CONST]
        self._z_rot = self._z[_Z_ROT:_Z_SIZE]
        self._out = views[tk.I_OUT]  # [wrench (6), trace(R_d Rᵀ)]
        self._wrench = self._out[:6]
        self._tau = views[tk.I_TAU]
        self.last_torque = views[tk.I_LAST]
        self.last_unclipped = self._tau
        self._bound: mujoco.MjData | None = None
        self._static_views = isinstance(self._dof, slice) and isinstance(self._qpos_adr, slice)
        self.dt = model.opt.timestep * self.config.ticks
        self._inv_dt = 1.0 / self.dt
        self._scal[tk.S_INV_DT] = self._inv_dt
        self._scal[tk.S_GM] = -GRAVITY[2] * self._payload_mass
        self._set_limit_values()
        # Discrete critically damped filter on e = x_d - target: [e, v]_{k+1} = A [e, v]_k
        # (semi-implicit Euler), a_k = -w^2 e_k - 2 w v_k evaluated before the update.
        w, dt = self.config.ref_omega, self.dt
        acc = np.array([-w * w, -2.0 * w])
        step = np.array(
            [[1.0 + dt * dt * acc[0], dt + dt * dt * acc[1]], [dt * acc[0], 1.0 + dt * acc[1]]]
        )
        rows, state = [], np.eye(2)
        for _ in range(n):
            a_row = acc @ state
            state = step @ state
            rows.append(np.vstack([state, a_row]))
        # (plan_ticks, 3, 3): tick k -> (x_d, v after the tick, a during it) from (e, v, target) at
        # the start of the plan, e = x_d - target; the third column adds the target to x_d.
        self._powers = views[tk.I_POWERS].reshape(n, 3, 3)
        self._powers[:, :, :2] = np.array(rows)
        self._powers[:, 0, 2] = 1.0
        # Plan buffers, overwritten at each replan. Columns of the filter state: x, y, z, yaw.
        # tick k -> rows (x_d, v, a), columns (x, y, z, yaw)
        self._traj = views[tk.I_TRAJ].reshape(n, 3, 4)
        self._x_plan = self._traj[:, 0, :3]
        self._rot_basis_t = views[tk.I_ROTB].reshape(36, 3)
        self._rot_basis_t[...] = _rotation_error_basis().T
        # _rotation_error_map(R_d,k) flattened, layout (4, 9, n)
        self._rot_maps = views[tk.I_ROTMAPS].reshape(36, n)
        self._rot_l = self._rot_maps[:27].reshape(3, 9 * n)  # L_k for all k, layout (3, 9, n)
        self._plan_i = 0

    @property
    def x_d(self) -> np.ndarray:
        """The desired TCP position at the last tick (a copy), m."""
        i = self._plan_i - 1
        return self._x_plan[i].copy() if i >= 0 else self._x_start.copy()

    @x_d.setter
    def x_d(self, value: np.ndarray) -> None:
        self._x_start[:] = np.asarray(value, dtype=float)

    @property
    def yaw_d(self) -> float:
        """The reference's yaw at the start of the current plan, rad."""
        return float(self._ps[tk.P_YAW])

    @yaw_d.setter
    def yaw_d(self, value: float) -> None:
        self._ps[tk.P_YAW] = value

    @property
    def yaw_rate_d(self) -> float:
        """The reference's yaw rate at the start of the current plan, rad/s."""
        return float(self._ps[tk.P_YAW_RATE])

    @yaw_rate_d.setter
    def yaw_rate_d(self, value: float) -> None:
        self._ps[tk.P_YAW_RATE] = value

    @property
    def target_yaw(self) -> float:
        """The goal's yaw, rad."""
        return float(self._ps[tk.P_GOAL_YAW])

    @target_yaw.setter
    def target_yaw(self, value: float) -> None:
        self._ps[tk.P_GOAL_YAW] = value

    @property
    def payload_mass(self) -> float:
        """Mass of the held object whose inertia and weight are compensated at the TCP, kg."""
        return self._payload_mass

    @payload_mass.setter
    def payload_mass(self, mass: float) -> None:
        self._payload_mass = float(mass)
        self._scal[tk.S_GM] = -GRAVITY[2] * self._payload_mass  # the held weight, N per unit J_z
        self._gain_maps()
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
        self._gain_maps()

    def _gain_maps(self) -> None:
        """P and C such that Λ P + C holds every gain block the ticks need (fixed between replans).

        The control law is linear in s = [Δx (6), Δẋ (6), ẍ_d - J̇q̇ (6)]: wrench = G s + c with
            G = [diag(K) + Λ diag(K_r),  diag(B) + Λ diag(B_r),  Λ + m_obj I_trans],  c = -m_obj g,
        i.e. G = Λ P_G + C_G. The blocks used are linear column maps S of [G | 0]: the constant
        columns of W_k (-G_x; -(G_v + G_a / dt) on J q̇; G_a / dt on J_prev q̇, from the backward
        difference J̇ q̇ ≈ (J - J_prev) q̇ / dt; c), the feed-forward rows and G_r.
        """
        dt_inv = 1.0 / (self.model.opt.timestep * self.config.ticks)
        p_g = np.zeros((6, 19))
        p_g[:, 0:6] = np.diag(self._kr6)
        p_g[:, 6:12] = np.diag(self._br6)
        p_g[:, 12:18] = np.eye(6)
        c_g = np.zeros((6, 19))
        c_g[:, 0:6] = np.diag(self._kvec)
        c_g[:, 6:12] = np.diag(self._bvec)
        c_g[0:3, 12:15] = self._payload_mass * np.eye(3)
        if self.config.inertia > 0.0:
            # constant M (paper Eq. 1): the translational acceleration columns are M I, not Λ's
            p_g[:, 12:15] = 0.0
            c_g[0:3, 12:15] += self.config.inertia * np.eye(3)
        sel = np.zeros((19, _B_SIZE))  # column 18 of [G | 0] is the zero pad
        for k in range(6):
            if k < 3:
                sel[k, _Z_POS + k] = -1.0
            sel[6 + k, _Z_TWIST + k] = -1.0
            sel[12 + k, _Z_TWIST + k] = -dt_inv
            sel[12 + k, _Z_PREV + k] = dt_inv
        for r, col in enumerate((0, 1, 2, 18, 6, 7, 8, 11, 12, 13, 14, 18)):  # x, ψ, v, ψ̇, a, ψ̈
            sel[col, _B_FF.start + r] = 1.0
        for k in range(3):
            sel[3 + k, _B_ROT.start + k] = 1.0
        self._p_gain[...] = p_g @ sel
        self._c_gain[...] = c_g @ sel
        self._c_gain[0:3, _Z_CONST] = -self._payload_mass * GRAVITY

    def _set_limit_values(self) -> None:
        c = self.config
        w = c.ref_omega
        self._max_step = min(c.max_linear_speed * math.e / w, c.max_linear_accel / w**2)
        self._ps[tk.P_MAX_STEP] = self._max_step
        self._vlim, self._alim = c.joint_speed_limit, c.joint_accel_limit
        self._limit_motion = self._vlim > 0.0 or self._alim > 0.0
        if self._vlim <= 0.0:
            self._vlim = math.inf
        self._scale_speed = c.speed_scaling and self._vlim < math.inf
        self._iw[tk.I_LIMIT] = int(self._limit_motion)
        self._scal[tk.S_VLIM], self._scal[tk.S_ALIM] = self._vlim, self._alim

    def set_limits(self, inertia: float | None = None, joint_speed_limit: float | None = None,
                   joint_accel_limit: float | None = None,
                   max_linear_speed: float | None = None) -> None:
        """Change the controller's M and its limits (e.g. per episode); ``None`` keeps a value.

        Args:
            inertia: M, kg (0 = Λ(q)); see :class:`ControllerConfig`.
            joint_speed_limit, joint_accel_limit: rad/s, rad/s^2 (0 = none).
            max_linear_speed: the reference filter's speed limit, m/s (the TCP speed limit).
        """
        changes = {k: float(v) for k, v in (
            ("inertia", inertia), ("joint_speed_limit", joint_speed_limit),
            ("joint_accel_limit", joint_accel_limit), ("max_linear_speed", max_linear_speed),
        ) if v is not None}
        self.config = replace(self.config, **changes)
        self._set_limit_values()
        self._gain_maps()
        self._stale = True

    def _limit_joint_motion(self) -> None:
        """Reduce the commanded torque so that no arm joint exceeds its speed (or acceleration)
        limit at the next tick.

        With M of the arm joints (at the last replan, as Λ) the command's joint acceleration is
        ``q̈ = M^-1 (τ - c)``, c the static part (the bias forces and the held object's weight,
        which the grasp carries). Each joint's admissible acceleration over one tick h is
        ``[(-v_max - q̇_i) / h, (v_max - q̇_i) / h]`` (intersected with ``±a_max``). A joint
        whose q̈ leaves its interval is clamped to it, and the torque becomes
        ``τ + M (clip(q̈) - q̈)``: the other joints keep their commanded acceleration, and a joint
        already too fast (e.g. pushed) is brought back to the limit within the tick. A joint
        speed limit thus acts like the UR's own: the arm moves no faster, the Cartesian path
        bends while a joint is at its limit. The torque limits are applied afterwards.

        The tick (:func:`~handover_env.robot.impedance_tick.impedance_tick`) computes q̈, checks
        the bounds and leaves ``clip(q̈) - q̈`` in ``_corr``; this applies it (M inverted at most
        once per replan, only when a correction needs it).
        """
        if self._minv_age:
            self._m_aa[...] = np.linalg.inv(self._minv_aa)
            self._minv_age = 0
        self._tau += self._m_aa @ self._corr.copy()
        self.limited_ticks += 1

    def reset(self, data: mujoco.MjData, rest_qpos: np.ndarray | None = None) -> None:
        """Start the reference at the current TCP pose with zero velocity."""
        if rest_qpos is not None:
            self._rest[:] = np.asarray(rest_qpos, float)
        self._bind(data)
        pos = data.site_xpos[self.ids.tcp_site]
        self.x_d = pos.copy()
        self.v_d[:] = 0.0
        self.a_d = np.zeros(3)
        self.target_pos[:] = pos
        z = data.site_xmat[self.ids.tcp_site].reshape(3, 3)[:, 2]
        self.yaw_d = math.atan2(z[1], z[0])
        self.yaw_rate_d = 0.0
        self._plan_i = 0
        self.set_target(pos, self.yaw_d)
        self.last_torque[:] = 0.0
        self._iw[tk.I_HAVE_PREV] = 0
        self.limited_ticks = 0
        self.scaled_plans = 0

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

        With a joint speed limit the plan is speed-scaled. The UR controller does not bend a
        commanded path at a joint speed limit: it slows the whole motion down ("speed scaling",
        reported as RTDE ``speed_scaling``; see the UR ROS 2 driver's
        ``scaled_joint_trajectory_controller`` and ros2_controllers' speed-scaling page,
        "On-Robot speed scaling ... One example of such robots are the Universal Robots
        manipulators"). Here: the joint velocities ``J⁻¹ [v_d; ψ̇_d ẑ]`` the plan's reference
        twist asks for at each tick (this state's arm Jacobian, damped as Λ is), and the plan
        slowed by ``q̇_max`` over their largest magnitude if that exceeds ``q̇_max``. The plan is
        linear in its step and initial velocity, so scaling both scales every velocity of it by
        the same factor while its start stays where the reference is. The torque-level limiter
        (:meth:`_limit_joint_motion`) stays as the backstop for the feedback's own joint speeds.

        One compiled call (:func:`~handover_env.robot.impedance_tick.impedance_replan`: the plan,
        the damped least squares by numpy's own LAPACK ``dgesv`` and the scaling), so the solve
        has ``numpy.linalg.solve``'s bits. Without numpy's bundled LAPACK
        (:mod:`handover_env.lapack_calls`) and when the damped system is singular, the solve is
        numpy's in Python between :func:`~handover_env.robot.impedance_tick.impedance_plan` and
        :func:`~handover_env.robot.impedance_tick.impedance_plan_scale` (numpy raises its
        ``LinAlgError`` for a singular system).
        """
        check = self._scale_speed and self._bound is not None
        mem = self._view.mem if self._bound is not None else self._fw
        replan = tk.impedance_replan if tk.impedance_replan is not None else tk.impedance_plan
        scaled = replan(mem, self._fw, self._iw, self._plan_i - 1, check)
        if scaled == tk.SOLVE:
            sol = np.linalg.solve(self._jjt, self._plan_twist.T)
            scaled = tk.impedance_plan_scale(self._fw, self._iw, sol)
        self.scaled_plans += scaled
        self._plan_i = 0
        self._stale = True

    def _refresh_dynamics(self, data: mujoco.MjData) -> None:
        """Λ(q) (as a Cholesky factor of Λ^-1), J M^-1, the null-space posture torque and W_k.

        Refreshed at every replan of the reference (about 30 Hz): Λ and the projector change
        slowly with q, while J, the errors and the bias forces are updated at every tick. Uses
        this tick's Jacobian (already in ``_jac_cur``).
        """
        # J M^-1 (mj_solveM), Λ^-1 = J M^-1 Jᵀ + damping (Cholesky-factored in place), Λ, and
        # W_k z = G s_k + c for every planned tick k, with
        # s = [x_d - x, L_k vec R, v_d - J q̇, a_d - (J q̇ - J_prev q̇) / dt]
        # (x_d, v_d, a_d, R_d from the plan; L_k the rotation error map of R_d,k):
        # compiled (impedance_refresh), in MuJoCo's and numpy's order of summation.
        tk.impedance_refresh(self._fw, self._iw)
        self._minv_age = 2  # the limiter's M^-1 and M of the arm are refreshed when used
        # Null-space posture term, N = I - Jᵀ J̄ᵀ with J̄ᵀ = Λ J M^-1 (compiled too).
        if self._posture:
            tk.impedance_posture(self._view.mem, self._fw, self._iw)
        self._stale = False

    def _bind(self, data: mujoco.MjData) -> None:
        """Keep views of the ``data`` arrays read at every tick (MjData buffers never move)."""
        if data is not self._bound:
            view = self._view = MjDataView(data)
            iw, tcp = self._iw, self._tcp
            root = int(self.model.body_rootid[self.model.site_bodyid[tcp]])
            iw[tk.I_XPOS] = view.offset("site_xpos", tcp)
            iw[tk.I_XMAT] = view.offset("site_xmat", tcp)
            iw[tk.I_QVEL], iw[tk.I_CDOF] = view.offset("qvel"), view.offset("cdof")
            iw[tk.I_COM] = view.offset("subtree_com", root)
            iw[tk.I_BIAS], iw[tk.I_CTRL] = view.offset("qfrc_bias"), view.offset("ctrl")
            if data.qvel.shape[0] != self.model.nv:
                raise ValueError("data is not an MjData of this controller's model")
            iw[tk.I_MODEL], iw[tk.I_DATA] = self.model._address, data._address
            iw[tk.I_QPOS] = view.offset("qpos")
        self._bound = data
        self._xpos_v = data.site_xpos[self._tcp]
        self._xmat_v = data.site_xmat[self._tcp]
        self._qvel_v = data.qvel[self._dof]
        self._qvel_full = data.qvel
        self._qpos_v = data.qpos[self._qpos_adr]
        self._bias_v = data.qfrc_bias[self._dof]

    def _far_rotation(self, i: int) -> None:
        """Beyond ~120 deg of orientation error: push at full strength (the sin-scaled error,
        rescaled to magnitude 2, replaces the one already in the wrench)."""
        e = self._rot_l.reshape(3, 9, self._n_plan)[:, :, i] @ self._z_rot
        ex, ey, ez = e.tolist()
        scale = 2.0 / max(math.sqrt(ex * ex + ey * ey + ez * ez), 1e-9)
        self._wrench += self._gains[:, _B_ROT] @ (e * (scale - 1.0))

    def compute(self, data: mujoco.MjData) -> np.ndarray:
        """One control update: advance the reference, write the clipped joint torques (6,) to
        the arm's actuators in ``data.ctrl`` and return them.

        The returned array is an internal buffer, overwritten by the next call. The tick itself
        is :func:`~handover_env.robot.impedance_tick.impedance_tick` (J from this tick's
        ``cdof``, J̇ q̇ by a backward difference of J over one tick, then Eq. 1 with M = Λ(q):
        F = K Δx + B Δẋ + Λ (ẍ_d - J̇q̇) for translation (K, B from Θ), plus Λ (ω² e_r + 2ζω Δω)
        for rotation, plus the held object's inertia and weight, all in one product
        ``[wrench, tr] = W_i z``; then τ and the limits). At a replan Λ and W are refreshed
        between the Jacobian and the law.
        """
        i = self._plan_i
        if i >= self._n_plan:
            self._plan()
            i = 0
        self._plan_i = i + 1
        if data is not self._bound or not self._static_views:
            self._bind(data)
        mem, fw, iw = self._view.mem, self._fw, self._iw
        phase = tk.ALL
        if self._stale:
            tk.impedance_tick(mem, fw, iw, i, tk.JAC)
            self._refresh_dynamics(data)
            phase = tk.WRENCH | tk.TORQUE | tk.CLIP
        if self._minv_age and self._limit_motion:
            # The limiter's M^-1 of the arm joints with this tick's M(q), at every tick from a
            # replan until the first correction, whose M^-1 (and M) then hold until the next
            # replan; the tick gathers its arm columns (GATHER).
            self._minv_age = 1  # M itself is inverted only if a correction needs it
            phase |= tk.GATHER
        code = tk.impedance_tick(mem, fw, iw, i, phase)
        if code == tk.FAR_ROTATION:
            self._far_rotation(i)
            code = tk.impedance_tick(mem, fw, iw, i, tk.TORQUE | tk.CLIP | (phase & tk.GATHER))
        if code == tk.LIMITED:
            self._limit_joint_motion()
            tk.impedance_tick(mem, fw, iw, i, tk.CLIP)
        return self.last_torque


def translational_inertia(model: mujoco.MjModel, ids: SceneIds, qpos: np.ndarray) -> np.ndarray:
    """The TCP's translational operational-space inertia ``Λ_t(q) = (J_p M(q)^-1 J_pᵀ)^-1``, kg.

    ``qpos`` sets the arm joints of a fresh ``MjData`` (everything else at the model's defaults);
    M from ``mj_fullM``, J_p from ``mj_jacSite`` at the TCP site. The held object is not part of
    M (it is a separate body held by a weld; the controller adds its mass itself).
    """
    q = np.asarray(qpos, dtype=np.float64)
    if q.shape != (len(ids.arm_qpos),) or not np.isfinite(q).all():
        raise ValueError(f"qpos must be {len(ids.arm_qpos)} finite joint angles, got {qpos!r}")
    data = mujoco.MjData(model)
    data.qpos[ids.arm_qpos] = q
    mujoco.mj_forward(model, data)
    jp = np.zeros((3, model.nv))
    mujoco.mj_jacSite(model, data, jp, None, ids.tcp_site)
    m_full = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, m_full)
    return np.linalg.inv(jp @ np.linalg.solve(m_full, jp.T))


def constant_inertia(model: mujoco.MjModel, ids: SceneIds, qpos: np.ndarray) -> float:
    """The constant M of paper Eq. 1 for the ``"constant_m"`` controller: trace(Λ_t(q)) / 3, kg.

    The paper sets M "to a constant value due to the system limitation" and gives no value; the
    mean of Λ_t's eigenvalues at the ready pose (``qpos``, the arm holding the bottle there) is the
    one constant that matches the arm's own translational inertia on average over directions
    (the scene's UR5e at ``READY_POS``: eigenvalues 1.5 / 3.8 / 8.7 kg, M = 4.66 kg; the
    profiles round it to 4.7 kg, docs/sensing.md). With the orientation held (the 6x6 Λ's
    translational block) the same pose gives 8.7 kg.
    """
    return float(np.trace(translational_inertia(model, ids, qpos)) / 3.0)


def inverse_kinematics(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    ids: SceneIds,
    pos: np.ndarray,
    yaw: float,
    q0: np.ndarray,
    iters: int = 200,
    tol: float = 1e-5,
) -> np.ndarray:
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
        err[3:] = 0.5 * np.array(
            [r_err[2, 1] - r_err[1, 2], r_err[0, 2] - r_err[2, 0], r_err[1, 0] - r_err[0, 1]]
        )
        if np.linalg.norm(err) < tol:
            return q
        mujoco.mj_jacSite(model, data, jac[:3], jac[3:], ids.tcp_site)
        j = jac[:, ids.arm_dof]
        q = q + j.T @ np.linalg.solve(j @ j.T + 1e-4 * np.eye(6), err)
    raise ValueError(
        f"IK did not converge to pos={pos.tolist()}, yaw={yaw:.3f} (residual "
        f"{np.linalg.norm(err):.2e})"
    )
