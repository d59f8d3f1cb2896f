"""The controller's replan in one compiled call: its solve is numpy's ``linalg.solve`` bit for bit
(numpy's own LAPACK ``dgesv``, handover_env.lapack_calls), the Python path without it gives the
same controller, and a singular system still raises numpy's error."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from handover_env import lapack_calls
from handover_env.config import HandoverParams
from handover_env.robot import impedance_tick as tk
from handover_env.robot.controller import ControllerConfig, ImpedanceController, inverse_kinematics
from handover_env.robot.scene import build_model, place_object_in_gripper, scene_ids

needs_lapack = pytest.mark.skipif(lapack_calls.dgesv is None,
                                  reason="numpy without its bundled LAPACK: the Python path")
N_PLAN = 7


@pytest.fixture(scope="module")
def model():
    return build_model()


def _workspace(offset: int) -> tuple[np.ndarray, np.ndarray]:
    """fw and iw holding just what plan_solve reads, its buffer ``offset`` floats further."""
    iw = np.zeros(tk.I_SIZE + tk.L_SIZE, dtype=np.int64)
    iw[tk.I_NPLAN], iw[tk.I_PLAN], iw[tk.I_TWIST] = N_PLAN, 0, tk.P_SIZE
    iw[tk.I_SOLVE], iw[tk.I_LAPACK] = tk.P_SIZE + 6 * N_PLAN + offset, tk.I_SIZE
    return np.zeros(tk.P_SIZE + 12 * N_PLAN + 36 + 8), iw


@needs_lapack
def test_lapack_is_numpys_bundled_library():
    assert "openblas64" in lapack_calls.LIBRARY
    assert "numpy" in lapack_calls.LIBRARY


@needs_lapack
@pytest.mark.parametrize("offset", range(4))  # the buffer at different alignments
def test_kernel_solve_is_numpys_bit_for_bit_on_damped_jjt_systems(offset):
    """2,000 systems ``(J Jᵀ + d I) x = twistᵀ`` per offset: arm-like Jacobians (columns of
    0.01-1 m), the controller's damping and smaller, twists [v, 0, 0, ψ̇] as the plan's; a third
    near a singularity (two rows almost parallel)."""
    rng = np.random.default_rng(34 + offset)
    fw, iw = _workspace(offset)
    jjt = fw[tk.P_JJT:tk.P_JJT + 36].reshape(6, 6)
    tw = fw[tk.P_SIZE:tk.P_SIZE + 6 * N_PLAN].reshape(N_PLAN, 6)
    b = iw[tk.I_SOLVE] + 36
    sol = fw[b:b + 6 * N_PLAN].reshape(N_PLAN, 6).T
    differ = 0
    for i in range(2000):
        j = rng.normal(size=(6, 6)) * rng.uniform(0.01, 1.0, size=(1, 6))
        if i % 3 == 0:
            j[5] = j[4] + 1e-6 * rng.normal(size=6)
        jjt[...] = j @ j.T + rng.choice([1e-3, 1e-6, 1e-9]) * np.eye(6)
        tw[...] = rng.normal(size=(N_PLAN, 6)) * [1.5, 1.5, 1.5, 0.0, 0.0, 3.0]
        assert tk.plan_solve(fw, iw) == 0
        ref = np.linalg.solve(jjt, tw.T)
        differ += not np.array_equal(sol.view(np.int64), ref.view(np.int64))
    assert differ == 0


@needs_lapack
def test_kernel_reports_a_singular_system_as_numpy_does():
    fw, iw = _workspace(0)
    fw[tk.P_JJT:tk.P_JJT + 36] = np.diag([1.0, 2.0, 3.0, 0.0, 1.0, 1.0]).ravel()
    assert tk.plan_solve(fw, iw) == 4  # LAPACK's info: U[3, 3] is exactly zero
    with pytest.raises(np.linalg.LinAlgError, match="Singular matrix"):
        np.linalg.solve(fw[tk.P_JJT:tk.P_JJT + 36].reshape(6, 6), np.ones((6, N_PLAN)))


def _controller(model, **config):
    ids = scene_ids(model)
    data = mujoco.MjData(model)
    q = inverse_kinematics(model, mujoco.MjData(model), ids, np.array([0.2, -0.45, 1.15]),
                           -math.pi / 2, np.array([-2.3, -1.8, 2.1, -0.3, -3.9, 0.0]))
    data.qpos[ids.arm_qpos] = q
    data.ctrl[ids.gripper_act] = 255.0
    mujoco.mj_forward(model, data)
    place_object_in_gripper(model, data, ids)
    mujoco.mj_forward(model, data)
    c = ImpedanceController(model, ids, HandoverParams(stiffness=140.0, damping=10.0),
                            ControllerConfig(**config), rest_qpos=q)
    c.payload_mass = float(model.body_mass[ids.object_body])
    c.reset(data)
    return ids, data, c


def _run_jump(model, ticks: int = 150):
    """A fast far jump under the joint speed limit: many replans, some of them slowed."""
    ids, data, c = _controller(model, max_linear_speed=5.0, ref_omega=80.0,
                               joint_speed_limit=math.pi)
    c.set_target(np.array([0.5, -0.8, 1.36]), 0.0)
    for _ in range(ticks):
        data.ctrl[ids.arm_act] = c.compute(data)
        mujoco.mj_step(model, data, nstep=3)
    return c, data


@needs_lapack
def test_replan_in_one_call_equals_numpys_solve_between_two_kernels(model, monkeypatch):
    """The compiled replan and the Python path (numpy's solve between impedance_plan and
    impedance_plan_scale, as without numpy's LAPACK) leave the same controller, bit for bit."""
    fused, d_fused = _run_jump(model)
    monkeypatch.setattr(tk, "impedance_replan", None)
    plain, d_plain = _run_jump(model)
    assert fused.scaled_plans == plain.scaled_plans > 5
    keep = np.ones(fused._fw.shape[0], dtype=bool)  # all but the solve's own buffer
    keep[fused._iw[tk.I_SOLVE]:fused._iw[tk.I_SOLVE] + 36 + 6 * N_PLAN] = False
    assert np.array_equal(fused._fw[keep].view(np.int64), plain._fw[keep].view(np.int64))
    assert np.array_equal(d_fused.qpos, d_plain.qpos)
    # the last replan's solve in the controller's own workspace
    b = fused._iw[tk.I_SOLVE] + 36
    sol = fused._fw[b:b + 6 * N_PLAN].reshape(N_PLAN, 6).T
    ref = np.linalg.solve(fused._jjt, fused._plan_twist.T)
    assert np.array_equal(sol.view(np.int64), ref.view(np.int64))


@pytest.mark.parametrize("fused", [True, False])
def test_singular_undamped_replan_raises_numpys_error(model, monkeypatch, fused):
    """No damping and a zero Jacobian (an MjData never forwarded): the speed check's system is
    singular and the replan raises numpy's LinAlgError, on either path."""
    if not fused:
        monkeypatch.setattr(tk, "impedance_replan", None)
    ids = scene_ids(model)
    c = ImpedanceController(model, ids, HandoverParams(),
                            ControllerConfig(singular_damping=0.0, joint_speed_limit=math.pi))
    with pytest.raises(np.linalg.LinAlgError, match="Singular matrix"):
        c.reset(mujoco.MjData(model))


def test_nan_state_flows_through_the_replan_without_an_error(model, monkeypatch):
    """A NaN Jacobian is not singular to LAPACK: numpy's solve returns NaN and raises nothing;
    both paths give the same NaN-carrying workspace."""
    out = []
    for fused in (True, False):
        if not fused:
            monkeypatch.setattr(tk, "impedance_replan", None)
        ids, data, c = _controller(model, joint_speed_limit=math.pi)
        data.cdof[:] = np.nan
        c.set_target(np.array([0.3, -0.5, 1.2]), 0.1)
        keep = np.ones(c._fw.shape[0], dtype=bool)
        keep[c._iw[tk.I_SOLVE]:c._iw[tk.I_SOLVE] + 36 + 6 * N_PLAN] = False
        out.append(c._fw[keep])
    assert np.isnan(out[0]).any()
    assert np.array_equal(out[0], out[1], equal_nan=True)
