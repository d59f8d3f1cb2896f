"""The reaching arm yields to the robot: touched, its targets stay within the human arm's maximal
push of its segments, and after the tactile latency they are held on them."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import handover_env  # noqa: F401 - registers the envs
from handover_env.person.arm_yield import ARM, MAX_ARM_PUSH, TACTILE_LATENCY
from handover_env.person.body_model import ARM_POSTURE_STIFFNESS
from handover_env.person.skeleton import SEG, SEGMENTS


def test_the_drive_is_bounded_then_the_push_stops() -> None:
    env = gym.make("handover_env/DynamicHandover-v0", person={"arm_yield": True}).unwrapped
    env.reset(seed=0, options={"receiver": "id"})
    d, rec = env.data, env.receiver
    arm = rec.targets.arm
    assert arm.reach == pytest.approx(MAX_ARM_PUSH / ARM_POSTURE_STIFFNESS)  # 0.107 m
    bodies = rec.body.bodies
    pos = np.zeros((len(SEGMENTS), 3))
    quat = np.tile([1.0, 0.0, 0.0, 0.0], (len(SEGMENTS), 1))
    far = d.xpos[bodies] + np.array([0.3, 0.0, 0.0])
    # untouched: the targets are the plan's
    pos[:] = far
    arm.limit(d, pos, quat)
    np.testing.assert_array_equal(pos, far)
    # the robot touches the forearm: the arm's targets come within the bound, the rest stay
    force = np.zeros(len(SEGMENTS))
    force[SEG["forearm_r"]] = 20.0
    t0 = float(d.time)
    rec.feel(force, t0)
    assert arm.blocked and arm.t_touch == t0
    arm.limit(d, pos, quat)
    lead = np.linalg.norm(pos - d.xpos[bodies], axis=1)
    for s in range(len(SEGMENTS)):
        if s in ARM:
            assert lead[s] == pytest.approx(arm.reach)
        else:
            assert lead[s] == pytest.approx(0.3)
    # after the tactile latency the arm's targets sit on their segments: no push
    d.time = t0 + TACTILE_LATENCY
    pos[:] = far
    arm.limit(d, pos, quat)
    for s in ARM:
        np.testing.assert_array_equal(pos[s], d.xpos[bodies[s]])
        np.testing.assert_array_equal(quat[s], d.xquat[bodies[s]])
    # a touch on another segment is not the arm's
    arm.reset()
    other = np.zeros(len(SEGMENTS))
    other[SEG["torso"]] = 50.0
    rec.feel(other, t0)
    assert not arm.blocked
    # the limit lasts to the end of the step of the last touch, and the reach re-plans
    rec.feel(force, t0)
    rec.feel(None, t0 + 0.005)
    assert arm.blocked and not arm.touching
    assert arm.end_step() is True and not arm.blocked and arm.touched_steps == 1
    assert arm.end_step() is False
    env.close()


def test_a_new_episode_starts_untouched() -> None:
    env = gym.make("handover_env/DynamicHandover-v0", person={"arm_yield": True}).unwrapped
    env.reset(seed=1, options={"receiver": "id"})
    arm = env.receiver.targets.arm
    force = np.zeros(len(SEGMENTS))
    force[SEG["hand_r"]] = 5.0
    env.receiver.feel(force, 0.5)
    assert arm.end_step() and arm.touched_steps == 1 and arm.blocked
    env.reset(seed=1, options={"receiver": "id"})
    assert arm.touched_steps == 0 and not arm.blocked and np.isnan(arm.t_touch)
    env.close()


def test_the_yield_is_on_by_default_and_can_be_switched_off() -> None:
    """On by default; switched off, a touch is not felt and the targets are never limited."""
    env = gym.make("handover_env/DynamicHandover-v0").unwrapped
    assert env.receiver.config.arm_yield is True and env.receiver.targets.arm.enabled is True
    env.close()
    env = gym.make("handover_env/DynamicHandover-v0", person={"arm_yield": False}).unwrapped
    env.reset(seed=0, options={"receiver": "id"})
    arm = env.receiver.targets.arm
    assert env.receiver.config.arm_yield is False and arm.enabled is False
    force = np.zeros(len(SEGMENTS))
    force[SEG["forearm_r"]] = 20.0
    env.receiver.feel(force, 0.1)
    assert not arm.blocked and arm.end_step() is False
    env.close()
    with pytest.raises(ValueError, match="arm_yield must be True or False"):
        gym.make("handover_env/DynamicHandover-v0", person={"arm_yield": 1})
