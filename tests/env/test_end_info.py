"""EndInfo: the lean per-step info changes no number and keeps the episode's facts at its end."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import handover_env  # noqa: F401  (registers the envs)
from agents.reactive import ReactiveAgent
from handover_env.envs.end_info import REWARD_KEYS, EndInfo

ENV = "handover_env/DynamicHandover-v0"


def _episode(lean: bool, seed: int, max_steps: int | None = None) -> tuple[dict, list[tuple]]:
    env = gym.make(ENV, **({} if max_steps is None else {"max_episode_steps": max_steps}))
    if lean:
        env = EndInfo(env)
    obs, reset_info = env.reset(seed=seed)
    agent = ReactiveAgent()
    agent.reset()
    out, done = [], False
    while not done:
        obs, reward, terminated, truncated, info = env.step(agent.act(obs))
        out.append((obs.copy(), reward, terminated, truncated, info))
        done = terminated or truncated
    env.close()
    return reset_info, out


@pytest.mark.parametrize("max_steps", [None, 12])
def test_lean_info_has_the_reward_terms_and_the_whole_info_at_the_end(max_steps) -> None:
    full_reset, full = _episode(False, 3, max_steps)
    lean_reset, lean = _episode(True, 3, max_steps)
    assert lean_reset == {"receiver_id": full_reset["receiver_id"]}
    assert len(full) == len(lean) > 1
    for (o1, r1, te1, tr1, i1), (o2, r2, te2, tr2, i2) in zip(full, lean, strict=True):
        assert np.array_equal(o1, o2) and r1 == r2 and (te1, tr1) == (te2, tr2)
        assert {k: i1[k] for k in REWARD_KEYS} == {k: i2[k] for k in REWARD_KEYS}
    for _, _, _, _, info in lean[:-1]:
        assert set(info) == set(REWARD_KEYS)
    assert lean[-1][4] == full[-1][4]  # the episode's facts at its last step
    assert "outcome" in lean[-1][4] and "handover_time" in lean[-1][4]
    if max_steps is not None:
        assert lean[-1][3] and not lean[-1][2]  # truncated by the TimeLimit: the whole info too


def test_a_vector_env_runs_with_the_wrapper() -> None:
    envs = gym.make_vec(ENV, 2, vectorization_mode="sync", wrappers=[EndInfo])
    envs.reset(seed=0)
    _, rewards, _, _, info = envs.step(np.tile(envs.single_action_space.sample(), (2, 1)))
    assert rewards.shape == (2,) and set(info) >= set(REWARD_KEYS)
    assert "outcome" not in info  # no episode ended on the first step
    envs.close()
