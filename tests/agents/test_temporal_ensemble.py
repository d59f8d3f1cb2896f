"""ACT-style temporal ensembling (agents/temporal_ensemble.py) and the closed-loop wrapper."""

from __future__ import annotations

import numpy as np
import pytest

from agents.predictive import ClosedLoopConfig, PredictiveAgent
from agents.temporal_ensemble import TemporalEnsembler
from handover_env.envs.observation import ObsLayout


def test_weights_follow_act_direction_oldest_first():
    ens = TemporalEnsembler(horizon=4, m=0.5, dim=1)
    ens.add(np.full((4, 1), 10.0), 0)  # oldest chunk, i = 0, weight 1
    ens.add(np.full((4, 1), 20.0), 1)  # i = 1, weight exp(-0.5)
    ens.add(np.full((4, 1), 30.0), 2)  # i = 2, weight exp(-1)
    w = np.exp(-0.5 * np.arange(3))
    np.testing.assert_allclose(ens.at_frame(2), [(w @ [10, 20, 30]) / w.sum()])
    np.testing.assert_allclose(ens.at_frame(1), [(w[:2] @ [10, 20]) / w[:2].sum()])
    np.testing.assert_allclose(ens.at_frame(0), [10.0])
    # m < 0 favours the newest chunk.
    neg = TemporalEnsembler(horizon=4, m=-50.0, dim=1)
    neg.add(np.full((4, 1), 10.0), 0)
    neg.add(np.full((4, 1), 20.0), 1)
    assert abs(neg.at_frame(1)[0] - 20.0) < 1e-9


def test_old_chunks_expire_and_interpolation():
    ens = TemporalEnsembler(horizon=3, m=0.0, dim=1)
    ens.add(np.array([[0.0], [1.0], [2.0]]), 0)
    ens.add(np.array([[10.0], [11.0], [12.0]]), 5)  # chunk 0 no longer covers frames >= 3
    assert ens.at_frame(5)[0] == 10.0 and ens.at_frame(3) is None
    np.testing.assert_allclose(ens.at(5.25), [10.25])
    np.testing.assert_allclose(ens.at(9.0), [12.0])  # past the newest chunk: hold its last row
    np.testing.assert_allclose(ens.at(1.5), [1.5])
    with pytest.raises(ValueError, match="start frames must not decrease: 4 after 5"):
        ens.add(np.zeros((3, 1)), 4)  # start frames must not decrease
    with pytest.raises(ValueError, match=r"chunk must have shape \(3, 1\), got \(2, 1\)"):
        ens.add(np.zeros((2, 1)), 6)
    with pytest.raises(ValueError, match="chunk contains NaN or inf"):
        ens.add(np.full((3, 1), np.nan), 6)
    ens.reset()
    assert ens.empty and ens.at(0.0) is None


def test_uniform_weights_average_overlapping_chunks():
    ens = TemporalEnsembler(horizon=30, m=0.0, dim=3)
    rng = np.random.default_rng(0)
    chunks = [rng.normal(size=(30, 3)) for _ in range(5)]
    for s, c in enumerate(chunks):
        ens.add(c, s)
    np.testing.assert_allclose(
        ens.at_frame(6), np.mean([c[6 - s] for s, c in enumerate(chunks)], axis=0)
    )


class _ConstantVelocity(PredictiveAgent):
    """A minimal PredictiveAgent: the giver follows the receiver 0.5 m to its side (+y)."""

    horizon = 10

    def predict(self, receiver_history: np.ndarray) -> np.ndarray:
        h = np.asarray(receiver_history)
        v = (h[-1] - h[-2]) * 30.0 if len(h) > 1 else np.zeros(2)
        xy = h[-1] + np.outer(np.arange(self.horizon) / 30.0, v) + np.array([0.0, 0.5])
        return np.column_stack([xy, np.full(self.horizon, 1.2)])


def _obs(layout: ObsLayout, track: np.ndarray, released: bool = False) -> np.ndarray:
    sl = layout.slices()
    obs = np.zeros(layout.size, dtype=np.float32)
    hist = track[-layout.history :]
    full = np.vstack([np.repeat(hist[:1], layout.history - len(hist), axis=0), hist])
    obs[sl["receiver_xy_history"][0]] = full.reshape(-1)
    obs[sl["receiver_frames_seen"][0]] = len(track)
    obs[sl["gripper_open"][0]] = float(released)
    return obs


def test_predictive_agent_streams_forecasts_and_resets():
    layout = ObsLayout()
    agent = _ConstantVelocity(
        closed_loop=ClosedLoopConfig(ensemble_m=0.0, min_frames=2), layout=layout
    )
    walk = np.column_stack([2.0 - 0.9 * np.arange(60) / 30.0, np.full(60, -0.9)])
    out = [agent.act(_obs(layout, walk[: n + 1])) for n in range(40)]
    ready = np.array([*agent.closed_loop.ready_pos, agent.closed_loop.ready_yaw], dtype=np.float32)
    np.testing.assert_allclose(out[0], ready)
    # Constant velocity: every chunk agrees, so the target is the walk at t + t_f, offset by 0.5 m.
    t_f = agent.params.forecast_time
    np.testing.assert_allclose(out[30][:3], [walk[30, 0] - 0.9 * t_f, -0.4, 1.2], atol=1e-5)
    # Yaw faces the receiver's current position from the target (within the allowed turn).
    assert abs(out[30][3] - np.arctan2(-0.5, 0.9 * t_f)) < 1e-5
    assert len(agent._history) == 40  # one streamed frame per new camera frame
    # A repeated observation (no new camera frame) streams nothing new.
    agent.act(_obs(layout, walk[:40]))
    assert len(agent._history) == 40
    # frames_seen going down = a new episode: the agent resets itself.
    np.testing.assert_allclose(agent.act(_obs(layout, walk[:1])), ready)
    assert len(agent._history) == 1
    # After the release: ready pose.
    np.testing.assert_allclose(agent.act(_obs(layout, walk[:2], released=True)), ready)


def test_closed_loop_config_validation():
    for kwargs, match in (({"min_frames": 0}, "min_frames must be an integer >= 1"),
                          ({"ensemble_m": float("nan")}, "ClosedLoopConfig values must be finite"),
                          ({"ready_pos": (0.0, 0.0)}, r"ready_pos must be \(x, y, z\)"),
                          ({"max_yaw_turn": -1.0}, "max_yaw_turn must be >= 0")):
        with pytest.raises(ValueError, match=match):
            ClosedLoopConfig(**kwargs)
    with pytest.raises(ValueError, match="horizon must be an integer >= 1"):
        TemporalEnsembler(horizon=0)
    agent = _ConstantVelocity()
    with pytest.raises(ValueError, match=r"observation must have shape \(90,\)"):
        agent.act(np.zeros(3))
