"""The compiled grip spring (person/grip.py: grip_kernel) gives the bits of its formula written with
numpy and MuJoCo's bindings (mj_objectVelocity, mju_mat2Quat, mj_applyFT), and MuJoCo's C
functions called from a kernel (handover_env.mujoco_calls) give the bindings' bits."""

from __future__ import annotations

import math

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import handover_env  # noqa: F401
from handover_env.person.grip import ArmGrip

_SITE, _BODY = int(mujoco.mjtObj.mjOBJ_SITE), int(mujoco.mjtObj.mjOBJ_BODY)


def _reference(grip: ArmGrip, m: mujoco.MjModel, d: mujoco.MjData) -> tuple[np.ndarray, ...]:
    """The grip's wrench by its formula (module docstring of person/grip.py) in numpy."""
    c = grip.config
    r_obj, r_hand = d.xmat[grip.obj].reshape(3, 3), d.xmat[grip.hand].reshape(3, 3)
    grasp = d.xpos[grip.obj] + r_obj @ grip.offset_local
    v_site, v_obj = np.zeros(6), np.zeros(6)
    mujoco.mj_objectVelocity(m, d, _SITE, grip.site, v_site, 0)
    mujoco.mj_objectVelocity(m, d, _BODY, grip.obj, v_obj, 0)
    u = v_obj[3:] + np.cross(v_obj[:3], grasp - d.xpos[grip.obj])
    force = c.stiffness * (d.site_xpos[grip.site] - grasp) + c.damping * (v_site[3:] - u)
    q = np.empty(4)
    mujoco.mju_mat2Quat(q, ((r_hand @ grip._rel_rot) @ r_obj.T).reshape(9))
    q = -q if q[0] < 0 else q
    s = math.sqrt(q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    rotvec = np.zeros(3) if s < 1e-12 else q[1:] * (2.0 * math.atan2(s, q[0]) / s)
    torque_local = c.rot_stiffness * (r_obj.T @ rotvec) + grip._rot_damping * (
        r_obj.T @ (v_site[:3] - v_obj[:3]))
    torque_local[2] = 0.0
    torque = r_obj @ torque_local
    qfrc = np.zeros(m.nv)
    mujoco.mj_applyFT(m, d, force, torque, grasp, grip.obj, qfrc)
    mujoco.mj_applyFT(m, d, -force, -torque, d.site_xpos[grip.site].copy(), grip.hand, qfrc)
    return force, qfrc


def test_grip_kernel_is_its_formula_bit_for_bit() -> None:
    env = gym.make("handover_env/DynamicHandover-v0").unwrapped
    env.reset(seed=0)
    m, d = env.model, env.data
    grip = env.receiver.grip
    rng = np.random.default_rng(4)
    for trial in range(30):
        d.qvel[:] = rng.normal(scale=0.5, size=m.nv)
        d.qpos[:] = d.qpos + rng.normal(scale=0.02, size=m.nq) * (trial > 0)
        mujoco.mj_forward(m, d)
        grip.close(d, rng.normal(scale=0.03, size=3))
        # a rotation away from the grasp's, so the spring's torque is not zero
        mujoco.mj_forward(m, d)
        d.xmat[grip.obj] = (d.xmat[grip.obj].reshape(3, 3)
                            @ _rot_z(rng.uniform(-1, 1)) @ _rot_x(rng.uniform(-1, 1))).ravel()
        force, qfrc = _reference(grip, m, d)
        grip.apply(d)
        assert np.array_equal(grip.force, force)
        assert np.array_equal(d.qfrc_applied, qfrc)
        assert np.abs(qfrc).max() > 0.0
        grip.open(d)
        assert not d.qfrc_applied.any() and not grip.force.any()


def test_grip_checks_its_ids() -> None:
    env = gym.make("handover_env/DynamicHandover-v0").unwrapped
    with pytest.raises(ValueError, match="object_body"):
        ArmGrip(env.model, 1, 0, env.model.nbody)


def _rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
