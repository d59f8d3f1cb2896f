"""The reactive baseline agent: its handover point, its waiting and release behaviour, and closed
loop."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import handover_env  # noqa: F401
from agents.reactive import ReactiveAgent, ReactiveConfig
from handover_env.config import HandoverParams
from handover_env.envs.observation import ObsLayout

LAYOUT = ObsLayout()


def _obs(track: np.ndarray, released: bool = False, held: bool = True) -> np.ndarray:
    """A flat observation with the given receiver track (n <= W frames) and gripper state."""
    w = LAYOUT.history
    hist = np.repeat(track[:1], w, axis=0)
    hist[w - len(track):] = track[-w:]
    parts = {name: np.zeros(shape) for name, shape, _ in LAYOUT.fields}
    parts["receiver_xy_history"] = hist
    parts["receiver_frames_seen"] = np.array([len(track)])
    parts["gripper_open"] = np.array([1.0 if released else 0.0])
    parts["object_held"] = np.array([1.0 if held else 0.0])
    parts["robot_enabled"] = np.array([1.0])
    return LAYOUT.flatten(parts)


def _walk(x0: float, y: float, v: float, n: int) -> np.ndarray:
    t = np.arange(n) / 30.0
    return np.stack([x0 - v * t, np.full(n, y)], axis=1)


def test_handover_point_is_offset_and_extrapolated_by_tf():
    params = HandoverParams(forecast_time=0.3)
    cfg = ReactiveConfig()
    agent = ReactiveAgent(params, cfg)
    track = _walk(1.2, -0.95, 0.8, 20)  # last frame x = 1.2 - 0.8 * 19 / 30 = 0.693
    a = agent.act(_obs(track))
    x_last = track[-1, 0]
    expected_x = x_last - 0.8 * 0.3 - cfg.forward_offset
    assert a.dtype == np.float32 and a.shape == (4,)
    assert a[0] == pytest.approx(expected_x, abs=1e-4)
    assert a[1] == pytest.approx(-0.95 + cfg.lateral_offset, abs=1e-4)
    assert a[2] == pytest.approx(cfg.handover_height)
    # t_f = 0 points at the current offset position.
    a0 = ReactiveAgent(HandoverParams(forecast_time=0.0), cfg).act(_obs(track))
    assert a0[0] == pytest.approx(x_last - cfg.forward_offset, abs=1e-4)


def test_waits_at_ready_pose_when_receiver_far_and_clips_to_workspace():
    cfg = ReactiveConfig()
    agent = ReactiveAgent(config=cfg)
    far = agent.act(_obs(_walk(3.0, -0.9, 0.8, 10)))
    np.testing.assert_allclose(far, [*cfg.ready_pos, cfg.ready_yaw], atol=1e-6)
    near = agent.act(_obs(_walk(1.4, -1.6, 0.8, 10)))  # pelvis 1.6 m out: lateral point clipped
    assert near[1] == pytest.approx(cfg.y_range[0])
    assert cfg.x_range[0] <= near[0] <= cfg.x_range[1]
    assert abs(near[3] - cfg.ready_yaw) <= math.radians(20.0) + 1e-6


def test_holds_still_until_fingers_let_go_then_returns_to_ready():
    cfg = ReactiveConfig()
    agent = ReactiveAgent(config=cfg)
    track = _walk(0.9, -0.9, 0.8, 25)
    target = agent.act(_obs(track))
    later = _walk(0.9, -0.9, 0.8, 28)
    np.testing.assert_array_equal(agent.act(_obs(later, released=True, held=True)), target)
    np.testing.assert_allclose(
        agent.act(_obs(later, released=True, held=False)), [*cfg.ready_pos, cfg.ready_yaw]
    )
    agent.reset()
    np.testing.assert_allclose(
        agent.act(_obs(later, released=True, held=True)), [*cfg.ready_pos, cfg.ready_yaw]
    )


def test_predict_rows_step_by_one_frame():
    agent = ReactiveAgent(HandoverParams(forecast_time=0.14))
    track = _walk(0.8, -0.9, 0.9, 15)
    pred = agent.predict(track)
    assert pred.shape == (agent.horizon, 3)
    dx = np.diff(pred[:, 0])
    inside = (pred[1:, 0] > agent.config.x_range[0] + 1e-9) & (
        pred[:-1, 0] < agent.config.x_range[1] - 1e-9
    )
    np.testing.assert_allclose(dx[inside], -0.9 / 30.0, atol=1e-6)
    with pytest.raises(ValueError, match="shape"):
        agent.predict(np.zeros((5, 3)))


def test_config_validation():
    with pytest.raises(ValueError, match="x_range"):
        ReactiveConfig(x_range=(0.5, 0.1))
    with pytest.raises(ValueError, match="handover_height"):
        ReactiveConfig(handover_height=3.0)


def test_closed_loop_succeeds_on_seeded_id_walkers():
    env = gym.make("handover_env/DynamicHandover-v0")
    agent = ReactiveAgent()
    for seed in (1, 2, 3):
        obs, _ = env.reset(seed=seed, options={"receiver": "id"})
        agent.reset()
        while True:
            obs, _, term, trunc, info = env.step(agent.act(obs))
            if term or trunc:
                break
        assert info["outcome"] == "success", (seed, info)
        assert info["release_force"] > 7.1 and info["peak_contact_force"] < 60.0
