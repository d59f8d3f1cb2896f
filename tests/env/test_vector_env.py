"""``gym.make_vec`` on the handover env: sync and async vector envs, autoreset and per-env info.

Every env holds the object at the ready pose (the null agent's action), so the walkers take it
and episodes end and restart inside 300 steps. Gymnasium's default autoreset mode is NEXT_STEP:
the step after an episode ends returns the new episode's first observation with reward 0.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import handover_env  # noqa: F401

ENV_ID = "handover_env/DynamicHandover-v0"
READY = np.array([0.3, -0.4, 1.15, -math.pi / 2], dtype=np.float32)
N_ENVS, N_STEPS = 2, 300


def _rollout(mode: str) -> tuple[np.ndarray, list[tuple[int, int, str, bool]], list[np.ndarray]]:
    envs = gym.make_vec(ENV_ID, num_envs=N_ENVS, vectorization_mode=mode)
    try:
        assert envs.metadata["autoreset_mode"] == gym.vector.AutoresetMode.NEXT_STEP
        obs, _ = envs.reset(seed=[0, 1])
        actions = np.tile(READY, (N_ENVS, 1))
        ended, first_obs = [], []
        rewards = np.zeros((N_STEPS, N_ENVS))
        done_prev = np.zeros(N_ENVS, dtype=bool)
        for t in range(N_STEPS):
            obs, reward, terminated, truncated, info = envs.step(actions)
            rewards[t] = reward
            for j in np.flatnonzero(done_prev):  # autoreset step: a new episode's first obs
                assert reward[j] == 0.0 and not terminated[j] and not truncated[j]
                first_obs.append(obs[j].copy())
            done = terminated | truncated
            for j in np.flatnonzero(done):
                assert info["_outcome"][j] and info["_is_success"][j]
                outcome, success = str(info["outcome"][j]), bool(info["is_success"][j])
                assert outcome != "running"
                assert success == (outcome == "success")
                ended.append((t, int(j), outcome, success))
            done_prev = done
        assert np.all(np.isfinite(obs))
        return rewards, ended, first_obs
    finally:
        envs.close()


@pytest.fixture(scope="module")
def rollouts() -> dict[str, tuple]:
    return {mode: _rollout(mode) for mode in ("sync", "async")}


def test_vector_envs_autoreset_and_report_outcomes_per_env(rollouts):
    rewards, ended, first_obs = rollouts["sync"]
    assert len(ended) >= N_ENVS  # every env finished at least one episode in 300 steps
    assert {j for _, j, _, _ in ended} == set(range(N_ENVS))
    assert any(success for *_, success in ended)  # the walkers take the held object
    assert len(first_obs) >= N_ENVS - 1  # and the env restarted after it


def test_sync_and_async_vector_envs_agree_exactly(rollouts):
    sync, async_ = rollouts["sync"], rollouts["async"]
    np.testing.assert_array_equal(sync[0], async_[0])
    assert sync[1] == async_[1]
    for a, b in zip(sync[2], async_[2]):
        np.testing.assert_array_equal(a, b)
