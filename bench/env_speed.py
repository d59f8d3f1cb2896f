"""Env real-time factor and its ratio to raw ``mj_step`` throughput of the same model (one core).

Both are measured in the same run, interleaved step by step, as CPU time of this thread
(``time.thread_time``: on a shared machine wall time mostly measures the other processes; the wall
clock figures are printed too): the env stepped by the reactive agent through whole episodes (agent
time excluded),
and ``mj_step`` on the env's own ``MjModel``/``MjData`` from the same states. Target: env cost
<= 2x raw physics.

Usage: ``python bench/env_speed.py [--quick]``
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import mujoco
import numpy as np

import handover_env  # noqa: F401
from agents.reactive import ReactiveAgent
from handover_env.envs.base_handover import FRAME_SKIP


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args(argv)
    rounds = 3 if args.quick else 10
    env = gym.make("handover_env/DynamicHandover-v0").unwrapped
    agent = ReactiveAgent()
    m = env.model
    scratch = mujoco.MjData(m)
    state = np.empty(mujoco.mj_stateSize(m, mujoco.mjtState.mjSTATE_INTEGRATION))
    env_time = raw_time = env_wall = raw_wall = 0.0
    env_steps = 0
    for r in range(rounds):
        obs, _ = env.reset(seed=r, options={"receiver": "id"})
        while True:
            action = agent.act(obs)
            mujoco.mj_getState(m, env.data, state, mujoco.mjtState.mjSTATE_INTEGRATION)
            w, t = time.perf_counter(), time.thread_time()
            obs, _, term, trunc, _ = env.step(action)
            env_time += time.thread_time() - t
            env_wall += time.perf_counter() - w
            env_steps += 1
            # Raw physics from the same state, same number of steps.
            mujoco.mj_setState(m, scratch, state, mujoco.mjtState.mjSTATE_INTEGRATION)
            w, t = time.perf_counter(), time.thread_time()
            mujoco.mj_step(m, scratch, nstep=FRAME_SKIP)
            raw_time += time.thread_time() - t
            raw_wall += time.perf_counter() - w
            if term or trunc or env_steps % 400 == 0:
                break
    sim = env_steps * env.dt
    print(f"env steps: {env_steps} ({sim:.1f} simulated s, {FRAME_SKIP} physics steps each)")
    print(
        f"env real-time factor:      {sim / env_time:8.1f}x  ({1e3 * env_time / env_steps:.3f} ms "
        "per env step)"
    )
    print(
        f"raw mj_step real-time fac: {sim / raw_time:8.1f}x  ({1e3 * raw_time / env_steps:.3f} ms "
        "per 20 steps)"
    )
    print(f"env cost / raw physics:    {env_time / raw_time:8.2f}x  (target <= 2x; CPU time)")
    print(
        f"  (wall clock: env {sim / env_wall:.1f}x real time, raw {sim / raw_wall:.1f}x, ratio "
        f"{env_wall / raw_wall:.2f}x)"
    )


if __name__ == "__main__":
    main()
