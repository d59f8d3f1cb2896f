"""Issue 16, items 16-19: the env refuses bad input before touching its state, and says so."""

from __future__ import annotations

import copy
import pickle

import gymnasium as gym
import numpy as np
import pytest

import handover_env  # noqa: F401

ENV_ID = "handover_env/DynamicHandover-v0"


def test_step_before_reset_and_after_a_failed_reset_raise_clearly():
    env = gym.make(ENV_ID).unwrapped
    with pytest.raises(RuntimeError, match="before reset"):
        env.step(np.array([0.3, -0.4, 1.15, 0.0], dtype=np.float32))
    env.reset(seed=0)
    env.step(np.array([0.3, -0.4, 1.15, 0.0], dtype=np.float32))
    clock = env.data.time
    with pytest.raises(ValueError, match="height"):
        env.reset(seed=0, options={"height": 9.0})
    assert env.data.time == clock  # the failed reset touched nothing ...
    with pytest.raises(RuntimeError, match="reset"):
        env.step(
            np.array([0.3, -0.4, 1.15, 0.0], dtype=np.float32)
        )  # ... but the env must be reset


def test_a_copy_of_a_running_env_is_a_fresh_env_that_says_so():
    env = gym.make(ENV_ID).unwrapped
    env.reset(seed=0)
    env.step(np.array([0.3, -0.4, 1.15, 0.0], dtype=np.float32))
    for twin in (copy.deepcopy(env), pickle.loads(pickle.dumps(env))):
        with pytest.raises(RuntimeError, match="fresh"):
            twin.step(np.array([0.3, -0.4, 1.15, 0.0], dtype=np.float32))
        obs, _ = twin.reset(seed=0)
        assert twin.observation_space.contains(obs)


@pytest.mark.parametrize(
    "action",
    [
        np.zeros((2, 2), dtype=np.float32),
        np.zeros((1, 4), dtype=np.float32),
        np.zeros((4, 1), dtype=np.float32),
        np.array(["0.3", "-0.4", "1.1", "0"]),
        np.array([0.3, -0.4, 1.1, 1j]),
        np.array([0.3, np.inf, 1.1, 0.0]),
    ],
)
def test_malformed_actions_are_refused(action):
    env = gym.make(ENV_ID).unwrapped
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        env.step(action)


def test_constructor_checks():
    gym.make(
        ENV_ID, stiffness=np.float32(100.0), damping=np.float64(15.0)
    )  # numpy numbers are numbers
    with pytest.raises(ValueError, match="history"):
        gym.make(ENV_ID, history=2.5)
    for kw in ({"width": 0}, {"height": -1}, {"width": 12.5}):
        with pytest.raises(ValueError, match="pixels"):
            gym.make(ENV_ID, render_mode="rgb_array", **kw)


def test_human_rendering_without_a_display_is_a_python_error(monkeypatch, tmp_path):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.chdir(tmp_path)
    with pytest.raises(RuntimeError, match="display"):
        gym.make(ENV_ID, render_mode="human")
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()


def test_unknown_reset_options_warn_by_name():
    env = gym.make(ENV_ID)
    with pytest.warns(UserWarning, match="reciever"):
        env.reset(seed=0, options={"reciever": "ood"})


def test_a_diverging_simulation_ends_the_episode_as_unstable():
    env = gym.make(ENV_ID).unwrapped
    env.reset(seed=0)
    env.data.qvel[env.ids.object_dof:env.ids.object_dof + 3] = 1e30  # blow it up
    *_, terminated, _, info = env.step(np.array([0.3, -0.4, 1.15, 0.0], dtype=np.float32))
    assert terminated and info["outcome"] == "unstable" and not info["is_success"]
