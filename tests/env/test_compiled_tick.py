"""The compiled per-tick kernels give the bits of the library calls they stand for: MuJoCo's
``mju_mulMatVec`` and ``mj_jacSite``, numpy's small ``matmul``; and MjData's fields reach them
through one array (:class:`handover_env.mjdata_view.MjDataView`)."""

from __future__ import annotations

import gymnasium as gym
import mujoco
import numpy as np

import handover_env  # noqa: F401
from handover_env.kernel_math import mat3_mul, mat3_vec, mat3t_vec, mj_dot
from handover_env.mjdata_view import MjDataView


def test_mj_dot_is_mujocos_dot_product_bit_for_bit() -> None:
    rng = np.random.default_rng(0)
    for n in list(range(1, 20)) + [26, 62, 63]:
        for _ in range(50):
            m, v, out = rng.standard_normal((1, n)), rng.standard_normal(n), np.zeros(1)
            mujoco.mju_mulMatVec(out, m, v)
            assert mj_dot(m[0], 0, v, 0, n) == out[0]


def test_3x3_products_are_numpys_matmul_bit_for_bit() -> None:
    rng = np.random.default_rng(1)
    out = np.zeros(9)
    for _ in range(500):
        a, b, x = rng.standard_normal((3, 3)), rng.standard_normal((3, 3)), rng.standard_normal(3)
        mat3_mul(out, 0, a.ravel(), 0, b.ravel(), 0, False)
        assert np.array_equal(out.reshape(3, 3), a @ b)
        mat3_mul(out, 0, a.ravel(), 0, b.ravel(), 0, True)
        assert np.array_equal(out.reshape(3, 3), a @ b.T)
        assert np.array_equal(np.array(mat3_vec(a.ravel(), 0, *x)), a @ x)
        assert np.array_equal(np.array(mat3t_vec(a.ravel(), 0, *x)), a.T @ x)


def test_data_view_reads_and_writes_the_mjdata_fields() -> None:
    env = gym.make("handover_env/DynamicHandover-v0").unwrapped
    env.reset(seed=0)
    d = env.data
    view = MjDataView(d)
    for name in ("qpos", "qvel", "ctrl", "site_xmat", "cdof", "cvel", "qfrc_bias"):
        a = np.asarray(getattr(d, name)).ravel()
        o = view.offset(name)
        assert np.array_equal(view.mem[o:o + a.size], a)
    view.mem[view.offset("ctrl") + 2] = 12.5
    assert d.ctrl[2] == 12.5
    assert view.offset("site_xmat", 1) == view.offset("site_xmat") + 9


def test_controller_tick_jacobian_and_torques_are_mujocos() -> None:
    env = gym.make("handover_env/DynamicHandover-v0").unwrapped
    obs, _ = env.reset(seed=3)
    m, d, c = env.model, env.data, env.controller
    jacp, jacr = np.zeros((3, m.nv)), np.zeros((3, m.nv))
    for _ in range(10):
        obs, *_ = env.step(np.array([0.5, -0.6, 1.2, -1.0], dtype=np.float32))
        tau = c.compute(d).copy()
        mujoco.mj_jacSite(m, d, jacp, jacr, c.ids.tcp_site)
        assert np.array_equal(c._jac12[:3], jacp) and np.array_equal(c._jac12[3:6], jacr)
        assert np.array_equal(d.ctrl[np.asarray(c.ids.arm_act)], tau)  # written to ctrl
        twist = np.zeros(6)
        mujoco.mju_mulMatVec(twist, c._jac12[:6], d.qvel)
        assert np.array_equal(c._z[3:9], twist)  # z = [x, J q̇, J_prev q̇, 1, 1, vec R]
        assert np.all(np.abs(tau) <= c._limits)


def test_observation_is_mujocos_pose_and_twist_of_the_tcp() -> None:
    env = gym.make("handover_env/DynamicHandover-v0").unwrapped
    obs, _ = env.reset(seed=5)
    m, d, layout = env.model, env.data, env.layout
    tcp = env.ids.tcp_site
    for _ in range(8):
        obs, *_ = env.step(np.array([0.4, -0.5, 1.1, -1.2], dtype=np.float32))
        quat, vel = np.zeros(4), np.zeros(6)
        mujoco.mju_mat2Quat(quat, d.site_xmat[tcp])
        mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_SITE, tcp, vel, 0)
        assert np.array_equal(layout.part(obs, "ee_quat"), quat.astype(np.float32))
        assert np.array_equal(layout.part(obs, "ee_linvel"), vel[3:].astype(np.float32))
        assert np.array_equal(layout.part(obs, "ee_angvel"), vel[:3].astype(np.float32))
        assert np.array_equal(layout.part(obs, "ee_pos"), d.site_xpos[tcp].astype(np.float32))
        assert np.array_equal(layout.part(obs, "wrist_torque"),
                              env.wrist.tau_ext.astype(np.float32))


def test_posture_torque_and_solves_are_numpys_and_mujocos() -> None:
    """impedance_posture against τ_0 - Jᵀ Λ J M^-1 τ_0 by numpy's dot and mju_cholSolve, and the
    kernels' mj_solveM (J M^-1, the limiter's rows) against the binding's."""
    env = gym.make("handover_env/DynamicHandover-v0").unwrapped
    env.reset(seed=0)
    m, d, c = env.model, env.data, env.controller
    rng = np.random.default_rng(0)
    for _ in range(100):
        d.qpos[c._qpos_adr] += rng.normal(scale=0.05, size=6)
        d.qvel[:] = rng.normal(scale=0.3, size=m.nv)
        mujoco.mj_forward(m, d)
        c._stale = True
        c.compute(d)
        minv_jt, rows = np.zeros((6, m.nv)), np.zeros((6, m.nv))
        mujoco.mj_solveM(m, d, minv_jt, c._jac12[:6])
        assert np.array_equal(c._minv_jt, minv_jt)
        mujoco.mj_solveM(m, d, rows, c._arm_rows)
        assert np.array_equal(c._minv_rows, rows)
        tau0, tmp, sol = np.empty(6), np.empty(6), np.empty(6)
        np.subtract(c._rest, d.qpos[c._qpos_adr], out=tau0)
        tau0 *= c.config.posture_stiffness
        np.multiply(d.qvel[c._dof], c.config.posture_damping, out=tmp)
        tau0 -= tmp
        np.dot(c._minv_jt[:, c._dof], tau0, out=tmp)
        mujoco.mju_cholSolve(sol, c._lam_inv, tmp)
        np.dot(sol, c._jac12[0:6, c._dof], out=tmp)
        assert np.array_equal(c._tau_posture, tau0 - tmp)
        assert np.abs(c._tau_posture).max() > 0.0
