"""An info a vector training loop can afford: the episode's facts at its end, the reward terms
before.

A handover env's step info holds about 50 episode facts (outcome, times, forces, effort,
contact per segment: :meth:`handover_env.envs.base_handover.HandoverEnvBase._info`). A process
vector env (gymnasium's ``AsyncVectorEnv``, SB3's ``SubprocVecEnv``) pickles every step's info
through its pipe and merges it in the main process, about half of the main process's CPU per
vector step (``bench/rl_throughput.py``: gymnasium async 0.83-0.89 ms -> 0.44-0.51 ms, 1,363 ->
161 bytes per step). :class:`EndInfo` keeps what a training loop reads: mid-episode only the
reward terms (``reward_<term>``: the default task's ``reward_time``, ``reward_force``,
``reward_outcome`` of :class:`~handover_env.envs.tasks.base.HandoverReward`, and any term a
custom task adds), the whole info at the step that ends the
episode (terminated, or truncated by the TimeLimit), and at a reset only the receiver drawn.
It changes no observation, reward or flag.

Usage: ``gym.make_vec(ENV_ID, 2, vectorization_mode="async", wrappers=[EndInfo])``, or
``EndInfo(gym.make(ENV_ID))`` in an SB3 env factory.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym

from handover_env.envs.tasks.base import TERMS

#: the mid-episode info of the default task: its reward terms
REWARD_KEYS = tuple(f"reward_{term}" for term in TERMS)


def reward_info(info: dict[str, Any]) -> dict[str, Any]:
    """The reward terms of a step's info (every ``reward_<term>`` the env's task reports)."""
    return {k: v for k, v in info.items() if k.startswith("reward_")}


class EndInfo(gym.Wrapper):
    """The env with the episode's facts in the info of its last step only (module docstring)."""

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        return obs, {"receiver_id": info["receiver_id"]}

    def step(self, action: Any):
        obs, reward, terminated, truncated, info = self.env.step(action)
        if not (terminated or truncated):
            info = reward_info(info)
        return obs, reward, terminated, truncated, info


__all__ = ["REWARD_KEYS", "EndInfo", "reward_info"]
