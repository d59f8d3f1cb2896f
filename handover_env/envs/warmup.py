"""Compile every per-step kernel once, so that later processes load them from numba's cache.

A new process with an empty cache compiles the env's kernels (:mod:`handover_env.compiled`) at its
first ``gym.make``, ``reset`` and ``step``: about 20-40 s of CPU. ``make install`` runs
:func:`compile_kernels` once, so the test workers, the demo and the evaluation pools that start
afterwards all load the cached machine code instead of each compiling it. Running it again with a
warm cache costs a few seconds and changes nothing.
"""

from __future__ import annotations

import time

import gymnasium as gym
import numpy as np

#: every registered env with every sensing profile, so each kernel is compiled for what it meets
ENV_IDS = ("handover_env/DynamicHandover-v0", "handover_env/StaticHandover-v0")
SENSING = ("paper", "ideal", "randomized")


def compile_kernels(steps: int = 3) -> float:
    """Reset and step each env of :data:`ENV_IDS` with each profile of :data:`SENSING` ``steps``
    times (seed 0, the ready pose as the action); returns the wall seconds it took."""
    import handover_env  # noqa: F401  (registers the ids)

    start = time.perf_counter()
    for env_id in ENV_IDS:
        for sensing in SENSING:
            env = gym.make(env_id, sensing=sensing)
            try:
                obs, _ = env.reset(seed=0)
                action = np.zeros(env.action_space.shape, dtype=np.float64)
                action[:] = (env.action_space.low + env.action_space.high) / 2.0
                for _ in range(steps):
                    obs, _, terminated, truncated, _ = env.step(action)
                    if terminated or truncated:
                        break
            finally:
                env.close()
    return time.perf_counter() - start


if __name__ == "__main__":
    print(f"handover_env kernels compiled or loaded in {compile_kernels():.1f} s")
