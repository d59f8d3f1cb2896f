"""One closed-loop episode of an agent in a handover env: the loop every script and bench shares."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym


def run_episode(
    env: gym.Env,
    agent: Any,
    seed: int | None = None,
    options: dict | None = None,
    on_step: Callable[[int, dict], None] | None = None,
) -> dict:
    """Reset ``env`` and ``agent``, then step ``agent.act(obs)`` until the episode ends.

    Args:
        env: a handover env (or any Gymnasium env whose actions ``agent.act`` produces).
        agent: anything with ``reset()`` and ``act(obs)`` (an :class:`agents.base.Policy`).
        seed, options: passed to ``env.reset``.
        on_step: called after every step with the step index (0-based) and that step's ``info``.

    Returns:
        The final ``info`` (terminated or truncated).
    """
    obs, info = env.reset(seed=seed, options=options)
    agent.reset()
    step = 0
    while True:
        obs, _, terminated, truncated, info = env.step(agent.act(obs))
        if on_step is not None:
            on_step(step, info)
        step += 1
        if terminated or truncated:
            return info
