"""Env real-time factor and its ratio to raw ``mj_step`` throughput of the same model (one core).

Both are measured in the same run, interleaved step by step, as CPU time of this thread
(``time.thread_time``: on a shared machine wall time mostly measures the other processes; the wall
clock figures are printed too): the env stepped by the reactive agent through whole episodes (agent
time excluded),
and ``mj_step`` on the env's own ``MjModel``/``MjData`` from the same states. Target: env cost
<= 2x raw physics.

Usage: ``python bench/env_speed.py [--quick] [--sensing both|paper|ideal|randomized]``: by default
the "paper" and "ideal" sensor profiles side by side (issue 24: the camera, wrist F/T and controller
models run in the step).
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


def measure(sensing: str, rounds: int) -> dict[str, float]:
    """CPU and wall time of env steps and of raw ``mj_step`` from the same states."""
    env = gym.make("handover_env/DynamicHandover-v0", sensing=sensing).unwrapped
    agent = ReactiveAgent()
    m = env.model
    scratch = mujoco.MjData(m)
    state = np.empty(mujoco.mj_stateSize(m, mujoco.mjtState.mjSTATE_INTEGRATION))
    env_time = raw_time = env_wall = raw_wall = 0.0
    env_steps = 0
    for r in range(rounds):
        obs, _ = env.reset(seed=r, options={"receiver": "id"})
        agent.reset()
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
    return {"steps": env_steps, "sim": env_steps * env.dt, "env": env_time, "raw": raw_time,
            "env_wall": env_wall, "raw_wall": raw_wall}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true", help="3 episodes per profile, not 10")
    parser.add_argument(
        "--sensing", choices=("both", "paper", "ideal", "randomized"), default="both",
        help="sensor profile of the env (gym.make(..., sensing=...)); 'both': paper and ideal "
        "side by side (default)",
    )
    args = parser.parse_args(argv)
    rounds = 3 if args.quick else 10
    names = ["paper", "ideal"] if args.sensing == "both" else [args.sensing]
    res = {name: measure(name, rounds) for name in names}
    print("profile       " + "".join(f"{n:>14}" for n in names))
    rows = [
        ("env steps", lambda r: f"{r['steps']:d}"),
        ("simulated s", lambda r: f"{r['sim']:.1f}"),
        ("env RTF", lambda r: f"{r['sim'] / r['env']:.1f}x"),
        ("env ms/step", lambda r: f"{1e3 * r['env'] / r['steps']:.3f}"),
        ("raw RTF", lambda r: f"{r['sim'] / r['raw']:.1f}x"),
        ("raw ms/20 st", lambda r: f"{1e3 * r['raw'] / r['steps']:.3f}"),
        ("env / raw", lambda r: f"{r['env'] / r['raw']:.2f}x"),
        ("wall env/raw", lambda r: f"{r['env_wall'] / r['raw_wall']:.2f}x"),
    ]
    for label, fmt in rows:
        print(f"{label:<14}" + "".join(f"{fmt(res[n]):>14}" for n in names))
    print("target: env / raw <= 2x (CPU time of this thread; the wall clock row for reference)")


if __name__ == "__main__":
    main()
