"""The held object leaves the gripper by its open side (person switch ``avoid_gripper``, on by
default): a real handover in the physics, with and without the switch."""

from __future__ import annotations

import math
import warnings

import gymnasium as gym
import numpy as np
import pytest

import handover_env  # noqa: F401
from agents.reactive import ReactiveAgent

#: An ID walker whose walk, without the switch, carries the held object 2 cm back into the
#: gripper in the 0.2 s after the release (with it: 4.6 cm out).
SEED = 0


def _depth_after_release(avoid: bool) -> tuple[float, float, dict, object]:
    """The object's depth along the gripper's approach axis (from the TCP, the axis as it last
    held) 0.2 s after the release, the same at the release, the final info and the receiver."""
    env = gym.make("handover_env/DynamicHandover-v0", person={"avoid_gripper": avoid}).unwrapped
    agent = ReactiveAgent()
    agent.reset()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        obs, info = env.reset(seed=SEED, options={"receiver": "id"})
    axis, at_release, after, done = None, math.nan, math.nan, False
    while not done:
        if env.receiver.state == "holding" and not env.released:
            axis = env._tcp_axis_v.copy()  # noqa: SLF001 - the gripper's approach axis
        obs, _, terminated, truncated, info = env.step(agent.act(obs))
        done = terminated or truncated
        if env.released and axis is not None:
            depth = float((env.data.body("object").xpos - env._tcp_pos_v) @ axis)  # noqa: SLF001
            if math.isnan(at_release):
                at_release = depth
            if env.data.time <= env.t_release + 0.2 + 1e-9:
                after = depth
    receiver = env.receiver
    env.close()
    return at_release, after, info, receiver


def test_the_object_is_drawn_out_by_the_open_side() -> None:
    on_release, on_after, on_info, on = _depth_after_release(True)
    off_release, off_after, off_info, off = _depth_after_release(False)
    assert on_info["outcome"] == off_info["outcome"] == "success"
    # the draw-out starts at the first step that sees the gripper open, and only with the switch
    assert on._t_out == pytest.approx(on_info["release_time"], abs=1.0 / 30 + 1e-9)
    assert math.isinf(off._t_out)
    # with it the object comes out along the gripper's axis, without it less (or inward)
    assert on_after - on_release > off_after - off_release + 0.01
    assert np.isfinite([on_after, off_after]).all()
