"""ObsLayout's named views read the flat observation as the offsets of its table say."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import handover_env  # noqa: F401  (registers the envs)
from agents.reactive import ReactiveAgent
from handover_env.envs.observation import ObsLayout

LAYOUT = ObsLayout()


def _by_offset(obs: np.ndarray, name: str) -> np.ndarray:
    sl, shape = LAYOUT.slices()[name]
    return np.asarray(obs)[sl].reshape(shape)


@pytest.fixture(scope="module")
def observations() -> list[np.ndarray]:
    env = gym.make("handover_env/DynamicHandover-v0")
    agent = ReactiveAgent()
    obs, _ = env.reset(seed=2)
    out = [obs]
    for _ in range(20):
        obs, *_ = env.step(agent.act(obs))
        out.append(obs)
    env.close()
    return out


def test_views_equal_the_offsets_on_env_observations(observations):
    for obs in observations:
        parts = LAYOUT.unflatten(obs)
        for name in parts:
            view = LAYOUT.part(obs, name)
            assert view.dtype == obs.dtype and np.array_equal(view, _by_offset(obs, name))
        assert LAYOUT.object_held(obs) == bool(_by_offset(obs, "object_held")[0] > 0.5)
        assert LAYOUT.gripper_open(obs) == bool(_by_offset(obs, "gripper_open")[0] > 0.5)
        assert LAYOUT.robot_enabled(obs) == bool(_by_offset(obs, "robot_enabled")[0] > 0.5)
        seen = int(round(float(_by_offset(obs, "receiver_frames_seen")[0])))
        assert LAYOUT.frames_seen(obs) == seen
        n = min(LAYOUT.history, max(1, seen))
        track = LAYOUT.receiver_track(obs)
        assert track.dtype == np.float32 and track.shape == (n, 2)
        assert np.array_equal(track, _by_offset(obs, "receiver_xy_history")[-n:])
    assert LAYOUT.frames_seen(observations[-1]) > LAYOUT.frames_seen(observations[0])


def test_flags_and_track_on_a_crafted_observation():
    parts = {name: np.zeros(shape) for name, shape, _ in LAYOUT.fields}
    parts["object_held"][0], parts["gripper_open"][0] = 1.0, 1.0
    parts["receiver_frames_seen"][0] = 3.0
    parts["receiver_xy_history"][:] = 0.125 * np.arange(2 * LAYOUT.history).reshape(-1, 2)
    obs = LAYOUT.flatten(parts)
    assert LAYOUT.object_held(obs) and LAYOUT.gripper_open(obs) and not LAYOUT.robot_enabled(obs)
    assert LAYOUT.receiver_track(obs).tolist() == [[6.75, 6.875], [7.0, 7.125], [7.25, 7.375]]
    view = LAYOUT.receiver_track(obs)
    view[:] = -1.0
    assert LAYOUT.receiver_track(obs)[0, 0] == 6.75  # a copy, not a view into obs


def test_views_refuse_a_wrong_observation():
    with pytest.raises(ValueError, match=r"observation must have shape \(90,\)"):
        LAYOUT.gripper_open(np.zeros(89, dtype=np.float32))
    with pytest.raises(KeyError, match="no observation part 'gripper'"):
        LAYOUT.part(np.zeros(LAYOUT.size, dtype=np.float32), "gripper")
