"""The constant-velocity predictor (method ``cv``): the reactive agent's extrapolation, row 0 the
current frame, in the predictive wrapper; its Table I row."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agents.constant_velocity import ConstantVelocityAgent
from agents.predictive import PredictiveAgent
from agents.reactive import ReactiveAgent, ReactiveConfig
from handover_env.config import HandoverParams
from handover_env.envs.observation import ObsLayout
from handover_env.person.synthetic import generate_synthetic
from handover_eval.methods import METHODS, MethodOptions, build_agent
from handover_eval.openloop.protocol import episode_metrics, evaluate_openloop, summarise


def _walk(x0: float, y: float, vx: float, vy: float, n: int) -> np.ndarray:
    t = np.arange(n) / 30.0
    return np.stack([x0 - vx * t, y + vy * t], axis=1)


def test_rows_are_the_extrapolated_offset_point_k_frames_ahead() -> None:
    cfg = ReactiveConfig()
    agent = ConstantVelocityAgent(cfg)
    track = _walk(1.6, -0.95, 0.9, 0.05, 20)  # x leaves the workspace clip within the 1 s
    pred = agent.predict(track)
    assert pred.shape == (30, 3)
    x, y = track[-1]
    for k in (0, 10, 29):
        ex = min(max(x - 0.9 * k / 30 - cfg.forward_offset, cfg.x_range[0]), cfg.x_range[1])
        ey = min(max(y + 0.05 * k / 30 + cfg.lateral_offset, cfg.y_range[0]), cfg.y_range[1])
        assert pred[k, 0] == pytest.approx(ex, abs=1e-9)
        assert pred[k, 1] == pytest.approx(ey, abs=1e-9)
        assert pred[k, 2] == pytest.approx(cfg.handover_height)
    # ... the reactive agent's own predict at t_f = 0, whatever Θ's t_f is.
    agent.params = HandoverParams(forecast_time=0.5)
    reactive = ReactiveAgent(HandoverParams(forecast_time=0.0), cfg)
    np.testing.assert_array_equal(agent.predict(track), reactive.predict(track))
    shifted = ReactiveAgent(HandoverParams(forecast_time=0.5), cfg).predict(track)
    assert not np.allclose(shifted, pred)  # the reactive agent's forecast is not in the rows


def test_is_a_method_with_no_learned_parameter() -> None:
    assert "cv" in METHODS
    agent = build_agent("cv", MethodOptions(quick=True, workers=1, horizon=20))
    assert isinstance(agent, ConstantVelocityAgent) and isinstance(agent, PredictiveAgent)
    assert agent.horizon == 20
    data = generate_synthetic(n=6, ood_fraction=0.0, seed=1)
    before = agent.predict(data[0].receiver_xy[:10])
    assert agent.fit(data) is agent
    np.testing.assert_array_equal(agent.predict(data[0].receiver_xy[:10]), before)


def test_open_loop_metrics_are_finite_and_ordered() -> None:
    """A constant velocity drifts from the walk it extrapolates: the further ahead, the larger
    the error. In every episode the mean error over 0.5 s is below that over 1 s and below the
    error at 0.5 s, which is below the error at 1 s; the current frame's error is below the
    horizon's."""
    data = generate_synthetic(n=8, ood_fraction=0.25, seed=2)
    agent = build_agent("cv", MethodOptions(workers=1))
    for ep in data:
        m = episode_metrics(agent, ep)
        for key in ("rms_3d_mm", "rms_now_axis_mm", "ade_05_mm", "fde_05_mm", "ade_10_mm",
                    "fde_10_mm"):
            assert math.isfinite(m[key]) and m[key] > 0, key
        assert m["ade_05_mm"] < m["ade_10_mm"] < m["fde_10_mm"], m
        assert m["ade_05_mm"] < m["fde_05_mm"] < m["fde_10_mm"], m
    summary = summarise(evaluate_openloop(agent, data, progress=False))
    assert summary["id"]["n_episodes"] == 6 and summary["ood"]["n_episodes"] == 2
    for part in ("id", "ood", "all"):
        assert summary[part]["rms_now_axis_mm"] < summary[part]["rms_axis_mm"], part


def test_closed_loop_act_holds_ready_then_tracks_the_receiver() -> None:
    layout = ObsLayout()
    agent = ConstantVelocityAgent()
    agent.reset()
    track = _walk(1.0, -0.9, 0.8, 0.0, 12)
    w = layout.history
    parts = {name: np.zeros(shape) for name, shape, _ in layout.fields}
    for seen in (1, 12):
        hist = np.repeat(track[:1], w, axis=0)
        hist[w - seen:] = track[:seen][-w:]
        parts["receiver_xy_history"] = hist
        parts["receiver_frames_seen"] = np.array([seen])
        a = agent.act(layout.flatten(parts))
        assert a.shape == (4,) and a.dtype == np.float32 and np.all(np.isfinite(a))
        if seen == 1:  # fewer than min_frames: the ready pose
            np.testing.assert_allclose(a[:3], agent.closed_loop.ready_pos, atol=1e-6)
    assert a[1] == pytest.approx(-0.9 + ReactiveConfig().lateral_offset, abs=0.02)
