"""The person's nominal motion: scripted and recorded sources, the static stop, the giver replay."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agents.giver_replay import GiverReplayAgent
from handover_env.person import motion as rm
from handover_env.person import trajectory
from handover_env.person.person import RATE, recorded_motion, resample, scripted_motion, stopped


def _track(frames=120, speed=0.9, y=-0.9):
    t = np.arange(frames) / RATE
    return np.stack([2.2 - speed * t, np.full_like(t, y)], axis=1)


def test_scripted_motion_is_the_shared_walker_model():
    a = scripted_motion(np.random.default_rng(4), "ood", height=1.8)
    b = scripted_motion(np.random.default_rng(4), "ood", height=1.8)
    np.testing.assert_array_equal(a.origin, b.origin)
    walker = rm.sample_walker(np.random.default_rng(4), "ood", height=1.8)
    traj = trajectory.base_trajectory(walker)
    np.testing.assert_allclose(a.origin[:, 0, :2], traj.xy, atol=1e-12)
    np.testing.assert_allclose(a.camera_xy, traj.xy, atol=1e-12)
    assert a.walker == walker and a.dims.height == 1.8 and not a.has_skeleton


def test_recorded_track_is_filtered_for_the_body_and_raw_for_the_camera():
    xy = _track()
    xy[60] += (0.0, 0.25)  # a tracker spike
    m = recorded_motion({"receiver_xy": xy, "source_id": "spiky"})
    np.testing.assert_array_equal(m.camera_xy, xy)  # the camera sees what was recorded
    assert abs(m.origin[60, 0, 1] - (-0.9)) < 0.03  # the body does not jump
    speed = np.linalg.norm(np.diff(m.origin[:, 0, :2], axis=0), axis=1) * RATE
    assert speed.max() < 1.3
    assert m.source_id == "spiky" and m.t_depart == 0.0
    with pytest.raises(ValueError, match="receiver_xy"):
        recorded_motion({"receiver_xy": np.zeros((4, 3))})
    with pytest.raises(ValueError, match="receiver_pose"):
        recorded_motion({"receiver_xy": _track(), "receiver_pose": np.zeros((5, 34, 3))})


def test_stopped_walks_to_the_line_decelerates_and_stands():
    m = recorded_motion({"receiver_xy": _track(frames=150)})
    s = stopped(m, 0.45)
    x = s.origin[:, 0, 0]
    v = np.abs(np.diff(x)) * RATE
    assert abs(x[int(s.rest_frame) + 5] - 0.45) < 0.03  # at rest on the stop line
    assert np.all(np.diff(x) <= 1e-9)  # never walks back
    assert v[: int(s.rest_frame) - 30].min() > 0.8 and v[int(s.rest_frame) + 1:].max() < 1e-6
    assert np.abs(np.diff(v)).max() * RATE < 3.0  # a smooth deceleration (< 3 m/s^2)


def test_resample_at_half_speed_doubles_the_duration():
    m = recorded_motion({"receiver_xy": _track()})
    slow = resample(m, np.arange(0, m.frames - 1, 0.5))
    assert slow.frames == 2 * (m.frames - 1)
    np.testing.assert_allclose(slow.origin[::2, 0], m.origin[:-1, 0], atol=1e-12)
    np.testing.assert_allclose(
        slow.speed[10:-10], m.speed[5:-6].repeat(2)[: slow.frames - 20] * 0.5, rtol=0.2
    )


def test_giver_replay_predicts_the_recorded_path():
    giver = np.stack([np.linspace(0.5, 0.0, 50), np.full(50, -0.5), np.full(50, 1.3)], axis=1)
    agent = GiverReplayAgent(giver)
    pred = agent.predict(np.zeros((11, 2)))
    np.testing.assert_allclose(pred, giver[10:40])
    end = agent.predict(np.zeros((45, 2)))
    np.testing.assert_allclose(end[-1], giver[-1])  # held at the last frame
    with pytest.raises(RuntimeError, match="set_episode"):
        GiverReplayAgent().predict(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="NaN"):
        agent.set_episode(np.full((5, 3), math.nan))
