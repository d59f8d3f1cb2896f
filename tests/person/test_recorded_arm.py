"""The arm of the person of protocol v3: the hand on the object's lower part (``grasp_below``),
the elbow held as the recorded receivers held it (``recorded_elbow``) and no passive joint
damping (``joint_damping`` off): numbers against the calibration, a closed-form pose and a real
handover in the physics."""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import handover_env  # noqa: F401
from agents.reactive import ReactiveAgent
from handover_env.person.body_model import PASSIVE_JOINT_DAMPING
from handover_env.person.posing import (
    ELBOW_POLE_OUT,
    ELBOW_POLE_RECORDED,
    POLE,
    arm_constants,
    arm_kernel,
)
from handover_env.person.skeleton import SEG, BodyDims, J

CALIBRATION = Path(__file__).resolve().parents[2] / "docs" / "calibration" / "grasp_height.json"


def test_the_elbow_pole_is_the_calibration_half_s_direction() -> None:
    got = json.loads(CALIBRATION.read_text())["elbow_pole"]["calibration"]["pooled"]["direction"]
    assert np.allclose(ELBOW_POLE_RECORDED, got, atol=5e-4)
    assert ELBOW_POLE_RECORDED[0] < 0 and ELBOW_POLE_RECORDED[2] < 0  # down and back
    io = arm_constants(np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3), pole=ELBOW_POLE_OUT)
    assert tuple(io[POLE:POLE + 3]) == ELBOW_POLE_OUT


def _elbow(pole: tuple[float, float, float], grip: np.ndarray) -> np.ndarray:
    """The IK's elbow (wrist straight) for a torso facing +x (identity rotation), shoulder at
    the origin."""
    dims = BodyDims.from_height(1.725)
    elbow_local = dims.local(J["RIGHT_ELBOW"], SEG["upper_arm_r"])
    io = arm_constants(dims.local(J["RIGHT_SHOULDER"], SEG["torso"]), elbow_local,
                       dims.local(J["RIGHT_WRIST"], SEG["forearm_r"]), dims.grip("r"), pole=pole)
    upper, _, _ = arm_kernel(io, (0.0, 0.0, 0.0), tuple(np.eye(3).ravel()), tuple(grip), False,
                             (0.0, 0.0, 0.0))
    return np.array(upper).reshape(3, 3) @ elbow_local


def test_a_folded_arm_keeps_its_elbow_down_and_back_not_out_to_the_side() -> None:
    """An object taken low in front, close to the body (0.32 m from the shoulder): the recorded
    pole keeps the elbow below and behind, 4 cm to the right; the old one swung it 12 cm out to
    the right (toward a robot on the person's right, past its gripper)."""
    grip = np.array([0.2, 0.0, -0.25])
    new, old = _elbow(ELBOW_POLE_RECORDED, grip), _elbow(ELBOW_POLE_OUT, grip)
    assert -0.05 < new[1] < 0.0 and old[1] < -0.1  # y: left, so -y is out to the right
    assert new[0] < old[0] < 0.0 and new[2] < 0.0  # behind the shoulder, below it
    # same arm either way: the elbow is on the sphere of the upper arm
    assert np.linalg.norm(new) == pytest.approx(np.linalg.norm(old), abs=1e-9)


def _damping(env) -> np.ndarray:
    u = env.unwrapped
    dofs = u.receiver.body.dofs
    return u.model.dof_damping[dofs.start + 6:dofs.stop]


def test_joint_damping_is_a_switch_off_by_default() -> None:
    plain = gym.make("handover_env/DynamicHandover-v0")
    damped = gym.make("handover_env/DynamicHandover-v0", person={"joint_damping": True})
    assert np.all(_damping(plain) == 0.0)
    assert np.all(_damping(damped) == PASSIVE_JOINT_DAMPING) and _damping(damped).size == 36
    plain.close()
    damped.close()


def _handover(person: dict) -> tuple[dict, float]:
    """A reactive handover to an ID walker: the final info and the grip point's height above the
    object's centre at the grasp."""
    env = gym.make("handover_env/DynamicHandover-v0", sensing="ideal", person=person).unwrapped
    agent = ReactiveAgent()
    agent.reset()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        obs, info = env.reset(seed=2, options={"receiver": "id"})
    dz, done = math.nan, False
    while not done:
        obs, _, term, trunc, info = env.step(agent.act(obs))
        done = term or trunc
        r = env.receiver
        if math.isnan(dz) and r.state == "holding":
            d = env.data
            dz = float(d.site_xpos[r.body.grip_site][2] - d.xpos[env.ids.object_body][2])
    env.close()
    return info, dz


def test_the_hand_takes_the_lower_part_in_the_physics() -> None:
    info, dz = _handover({})
    assert info["outcome"] == "success"
    assert -0.1 < dz < -0.04  # held 7.5 cm below the centre, below the pads (within 3.5 cm)
    top, dz_top = _handover({"grasp_below": False})
    assert top["outcome"] == "success" and 0.04 < dz_top < 0.1


def test_the_switches_are_checked() -> None:
    for name in ("grasp_below", "recorded_elbow", "joint_damping"):
        with pytest.raises(ValueError, match=f"{name} must be True or False"):
            gym.make("handover_env/DynamicHandover-v0", person={name: 1})
