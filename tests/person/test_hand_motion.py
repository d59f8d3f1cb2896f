"""The hand's minimum-jerk reach and the arm-spring grip, against their closed forms."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from handover_env.person.grip import ArmGrip, GripConfig
from handover_env.person.min_jerk import min_jerk_coefficients, min_jerk_step


def test_min_jerk_meets_its_boundary_conditions():
    x0, v0, a0 = np.array([0.1, -0.2, 0.3]), np.array([0.5, 0.0, -0.1]), np.array([0.0, 1.0, 0.0])
    x1, v1, d = np.array([0.6, 0.1, 0.9]), np.array([-0.2, 0.3, 0.0]), 0.7
    c = min_jerk_coefficients(x0, v0, a0, x1, v1, d)
    s = np.array([d**k for k in range(6)])
    ds = np.array([k * d ** (k - 1) if k else 0.0 for k in range(6)])
    dds = np.array([k * (k - 1) * d ** (k - 2) if k > 1 else 0.0 for k in range(6)])
    np.testing.assert_allclose(s @ c, x1, atol=1e-12)
    np.testing.assert_allclose(ds @ c, v1, atol=1e-12)
    np.testing.assert_allclose(dds @ c, 0.0, atol=1e-10)
    x, v, a = min_jerk_step(x0, v0, a0, x1, v1, d, 0.0)
    np.testing.assert_allclose((x, v, a), (x0, v0, a0), atol=1e-12)
    x, v, a = min_jerk_step(x0, v0, a0, x1, v1, d, 1.0)  # beyond the end: the target state
    np.testing.assert_allclose((x, v, a), (x1, v1, np.zeros(3)), atol=1e-12)


def test_a_rest_to_rest_reach_is_the_flash_hogan_profile():
    x, v, a = np.zeros(1), np.zeros(1), np.zeros(1)
    d, n = 0.6, 60
    traj = []
    for k in range(n):  # re-planned every step with the shrinking remaining time
        x, v, a = min_jerk_step(x, v, a, np.ones(1), np.zeros(1), d - k * d / n, d / n)
        traj.append(x[0])
    tau = np.arange(1, n + 1) / n
    np.testing.assert_allclose(traj, 10 * tau**3 - 15 * tau**4 + 6 * tau**5, atol=1e-9)
    with pytest.raises(ValueError, match="duration"):
        min_jerk_coefficients(0.0, 0.0, 0.0, 1.0, 0.0, 0.0)


def _two_bodies():
    xml = """<mujoco><option gravity="0 0 0"/><worldbody>
      <body name="hand" pos="0 0 1" mocap="true"><site name="grip"/></body>
      <body name="obj" pos="0.02 0 1"><freejoint/>
        <geom type="cylinder" size="0.033 0.1" mass="0.4"/></body>
    </worldbody></mujoco>"""
    m = mujoco.MjModel.from_xml_string(xml)
    return m, mujoco.MjData(m)


def test_the_grip_pulls_like_the_arm_spring():
    m, d = _two_bodies()
    mujoco.mj_forward(m, d)
    hand = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "hand")
    obj = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "obj")
    site = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, "grip")
    cfg = GripConfig(stiffness=500.0, damping=0.0, rot_stiffness=5.0, rot_damping=0.0)
    grip = ArmGrip(m, hand, site, obj, cfg)
    grip.close(d, np.zeros(3))  # holds the object's centre where it is now (2 cm from the grip)
    grip.apply(d)
    # F = K (p_grip - p_grasp): 500 N/m x -2 cm along x, applied at the object's centre.
    np.testing.assert_allclose(grip.force, [-10.0, 0.0, 0.0], atol=1e-9)
    dof = m.jnt_dofadr[m.body_jntadr[obj]]
    np.testing.assert_allclose(d.qfrc_applied[dof:dof + 3], [-10.0, 0.0, 0.0], atol=1e-9)
    grip.open(d)
    assert not grip.active and not d.qfrc_applied.any()
    with pytest.raises(ValueError, match="stiffness"):
        GripConfig(stiffness=-1.0)
