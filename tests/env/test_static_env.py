"""StaticHandover-v0: the robot waits for the detected hand (+ stabilisation delay), then
delivers."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import handover_env  # noqa: F401
from agents.static import StaticAgent
from handover_env.envs.base_handover import READY_POS
from handover_env.envs.static_handover_v0 import STOP_XY

ENV_ID = "handover_env/StaticHandover-v0"


def test_robot_does_not_move_before_hand_detection_and_delay():
    env = gym.make(ENV_ID, sensing="ideal")  # the timing, without sensor noise
    u = env.unwrapped
    sl = u.layout.slices()["robot_enabled"][0]
    obs, _ = env.reset(seed=0, options={"receiver": "id"})
    far = env.action_space.high.copy()  # an agent that wants to go far away at once
    max_dev, enabled_at = 0.0, None
    for _ in range(400):
        obs, _, term, trunc, info = env.step(far)
        t = u.data.time
        if obs[sl][0] < 0.5:
            assert t < u.t_enabled + 1e-9
            max_dev = max(
                max_dev, float(np.linalg.norm(u.data.site_xpos[u.ids.tcp_site] - READY_POS))
            )
        elif enabled_at is None:
            enabled_at = t
        if enabled_at is not None and t > enabled_at + 0.5:
            break
    assert max_dev < 0.01  # held at the ready pose whatever the action
    # Detection = the hand fully raised after the receiver stopped in the predefined area.
    rec = u.receiver
    assert rec.state == "presented" and not np.isnan(rec.t_hand_raised)
    assert rec.at_rest
    assert abs(rec.base()[0] - STOP_XY[0]) < 0.05  # stopped on the stop line
    assert u.t_detect == pytest.approx(rec.t_hand_raised)
    assert u.t_enabled == pytest.approx(rec.t_hand_raised + 2.0)
    assert enabled_at == pytest.approx(u.t_enabled, abs=1.5 / 30.0)
    # ... and afterwards it does move.
    assert np.linalg.norm(u.data.site_xpos[u.ids.tcp_site] - READY_POS) > 0.1
    assert not info["released"]  # the receiver never grabbed the object out of the ready pose


@pytest.mark.parametrize("delay", [2.0, 0.0])
def test_static_handover_succeeds_and_reports_both_times(delay):
    env = gym.make(ENV_ID, stabilisation_delay=delay)
    u = env.unwrapped
    agent = StaticAgent()
    obs, _ = env.reset(seed=1, options={"receiver": "id"})
    agent.reset()
    while True:
        obs, _, term, trunc, info = env.step(agent.act(obs))
        if term or trunc:
            break
    assert info["outcome"] == "success", info
    assert u.t_release > u.t_enabled and info["receiver_grasp_time"] > u.t_enabled
    assert info["release_force"] > 7.1
    assert info["handover_time_with_delay"] == pytest.approx(u.t_release - u.receiver.t_depart)
    assert info["handover_time_with_delay"] - info["handover_time"] == pytest.approx(delay)
    # The object went to the detected (raised) hand.
    assert (
        np.linalg.norm(u.data.xpos[u.ids.object_body] - u.data.site_xpos[u.ids.body.grip_site])
        < 0.12
    )
    assert 1.0 < info["handover_time"] < 10.0
