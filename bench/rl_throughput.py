"""Agent steps per second per core: what a reinforcement-learning loop gets out of the env.

Loops over ``DynamicHandover-v0`` (scripted ID walkers, episodes reset as they end):

* ``reactive``: one env stepped by the reactive agent (``agents/reactive.py``), agent included;
* ``random``: one env stepped by ``action_space.sample()`` (the env alone, almost);
* ``2 processes``: two independent processes, each one env with random actions (the ceiling of
  any two-env vector env);
* ``vec sync x2``: ``gym.make_vec(..., num_envs=2, vectorization_mode="sync")``, random actions;
* ``vec async x2``: the same with ``vectorization_mode="async"`` (one worker process per env);
* ``SB3 Dummy x2`` / ``SB3 Subproc x2``: stable-baselines3's ``DummyVecEnv`` and
  ``SubprocVecEnv`` (the vector envs ``train.py rl`` uses), random actions (skipped without the
  ``rl`` extra).

For each: env steps (summed over the sub-envs) per second of wall time and per CPU second (the
CPU time of this process plus that of its worker processes, read from ``/proc``), and the wall
rate as a share of the two independent processes'. Steps per CPU second is the per-core figure;
wall time on a shared machine mostly measures the other processes. Random actions end episodes
early or late; every loop runs the same number of env steps.

Where a lock-step vector env loses against two independent processes (printed after the table,
from the SB3 ``SubprocVecEnv`` and gymnasium async runs): every sub-env step is timed inside its
worker (:class:`_Timed`), so the wall time of the vector steps splits into the slower sub-env's
step (``max``: the env's own work plus the wait for the slower one, against the mean of the
two), and the rest (the pipe, pickling, the main process's own work per step). The bytes each
step sends through the pipe and the time to pickle and unpickle them are measured on the
messages themselves (SB3: ``(obs, reward, done, info, reset_info)``; gymnasium async: ``(reward,
terminated, truncated, info)``, the observation going through shared memory).

Usage: ``python bench/rl_throughput.py [--quick] [--steps N]``
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import functools  # noqa: E402
import multiprocessing as mp  # noqa: E402
import pickle  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from pathlib import Path  # noqa: E402

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import handover_env  # noqa: E402, F401
from agents.reactive import ReactiveAgent  # noqa: E402

ENV_ID = "handover_env/DynamicHandover-v0"
OPTIONS = {"receiver": "id"}


def _proc_cpu(pid: int) -> float:
    """CPU seconds (user + system) of process ``pid`` from /proc (0 where /proc is absent)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _single(policy: str, n_steps: int) -> tuple[int, float, float]:
    """(env steps, wall s, CPU s) of one env stepped by ``policy`` for ``n_steps`` steps."""
    env = gym.make(ENV_ID)
    env.action_space.seed(0)
    agent = ReactiveAgent()
    obs, _ = env.reset(seed=0, options=OPTIONS)
    agent.reset()
    episode = 0
    act: Callable[[np.ndarray], np.ndarray] = (
        agent.act if policy == "reactive" else (lambda _obs: env.action_space.sample())
    )
    w0, c0 = time.perf_counter(), time.process_time()
    for _ in range(n_steps):
        obs, _, term, trunc, _ = env.step(act(obs))
        if term or trunc:
            episode += 1
            obs, _ = env.reset(seed=episode, options=OPTIONS)
            agent.reset()
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    env.close()
    return n_steps, wall, cpu


class _Timed(gym.Wrapper):
    """The env with the wall time of every vector step's work in it, and the reset options of
    the other loops as its default. SB3's workers reset right after the step that ended an
    episode (the reset counts with that step); gymnasium's vector envs reset in the next vector
    step instead of stepping (``reset_own_step``: the reset is that step's entry)."""

    def __init__(self, env: gym.Env, reset_own_step: bool = False) -> None:
        super().__init__(env)
        self.durations: list[float] = []
        self.reset_own_step = reset_own_step

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        t0 = time.perf_counter()
        out = self.env.reset(seed=seed, options=OPTIONS if options is None else options)
        if self.reset_own_step:
            self.durations.append(time.perf_counter() - t0)
        elif self.durations:
            self.durations[-1] += time.perf_counter() - t0
        return out

    def step(self, action):
        t0 = time.perf_counter()
        out = self.env.step(action)
        self.durations.append(time.perf_counter() - t0)
        return out

    def timings(self) -> list[float]:
        """Wall seconds of every step so far (with its reset)."""
        return self.durations


def _timed_env() -> gym.Env:
    return _Timed(gym.make(ENV_ID))


def _worker_loop(n_steps: int, barrier, queue) -> None:
    """One of the two independent processes: build the env, wait for the other, step."""
    env = gym.make(ENV_ID)
    env.action_space.seed(0)
    env.reset(seed=0, options=OPTIONS)
    barrier.wait()
    w0, c0 = time.perf_counter(), time.process_time()
    for episode in range(1, n_steps + 1):
        _, _, term, trunc, _ = env.step(env.action_space.sample())
        if term or trunc:
            env.reset(seed=episode, options=OPTIONS)
    queue.put((n_steps, time.perf_counter() - w0, time.process_time() - c0))


def _independent(n_procs: int, n_steps: int) -> tuple[int, float, float]:
    """(env steps, wall s, CPU s) of ``n_procs`` independent one-env processes stepping at once
    (``n_steps`` in all; the wall time is the slowest process's)."""
    ctx = mp.get_context("forkserver")
    barrier, queue = ctx.Barrier(n_procs), ctx.Queue()
    procs = [ctx.Process(target=_worker_loop, args=(n_steps // n_procs, barrier, queue))
             for _ in range(n_procs)]
    for p in procs:
        p.start()
    results = [queue.get() for _ in procs]
    for p in procs:
        p.join()
    return (sum(r[0] for r in results), max(r[1] for r in results),
            sum(r[2] for r in results))


#: where each lock-step vector env's wall time went (module docstring), filled by _vector
LOSS: dict[str, dict[str, float]] = {}


def _vector(mode: str, n_envs: int, n_steps: int) -> tuple[int, float, float]:
    """(env steps summed over sub-envs, wall s, CPU s incl. workers) of a random-action vec env:
    ``mode`` sync / async (gymnasium) or sb3-dummy / sb3-subproc."""
    if mode.startswith("sb3"):
        from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

        cls = SubprocVecEnv if mode == "sb3-subproc" else DummyVecEnv
        envs = cls([_timed_env] * n_envs)
        envs.seed(0)
        envs.reset()
        workers = [p.pid for p in getattr(envs, "processes", [])]
        space = envs.action_space
        space.seed(0)

        def sample() -> np.ndarray:
            return np.stack([space.sample() for _ in range(n_envs)])

        def timings() -> list[list[float]]:
            return envs.env_method("timings")
    else:
        envs = gym.make_vec(ENV_ID, num_envs=n_envs, vectorization_mode=mode,
                            wrappers=[functools.partial(_Timed, reset_own_step=True)])
        envs.action_space.seed(0)
        envs.reset(seed=0, options=OPTIONS)
        workers = [p.pid for p in getattr(envs, "processes", [])]
        sample = envs.action_space.sample

        def timings() -> list[list[float]]:
            return list(envs.call("timings"))
    n_vec = max(1, n_steps // n_envs)
    before = [len(t) for t in timings()]
    w0, c0 = time.perf_counter(), time.process_time()
    k0 = sum(_proc_cpu(p) for p in workers)
    main_cpu = 0.0
    for _ in range(n_vec):
        m0 = time.process_time()
        envs.step(sample())
        main_cpu += time.process_time() - m0
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    cpu += sum(_proc_cpu(p) for p in workers) - k0
    per_env = np.array([t[b : b + n_vec] for t, b in zip(timings(), before)])  # (envs, n_vec)
    envs.close()
    LOSS[mode] = {
        "wall": wall,
        "max": float(per_env.max(axis=0).sum()),
        "mean": float(per_env.mean(axis=0).sum()),
        "main_cpu_us": 1e6 * main_cpu / n_vec,
    }
    return n_vec * n_envs, wall, cpu


def _sb3_messages(env: gym.Env, n_steps: int) -> list[tuple]:
    """The messages an SB3 ``SubprocVecEnv`` worker sends for ``n_steps`` random steps of
    ``env``: ``(obs, reward, done, info, reset_info)``, the last reset's info in every one."""
    env.action_space.seed(0)
    obs, reset_info = env.reset(seed=0)
    out = []
    for _ in range(n_steps):
        obs, reward, term, trunc, info = env.step(env.action_space.sample())
        done = term or trunc
        info["TimeLimit.truncated"] = trunc and not term
        if done:
            info["terminal_observation"] = obs
            obs, reset_info = env.reset()
        out.append((obs, reward, done, info, reset_info))
    return out


def _pickle_cost(msgs: list[tuple], info_at: int) -> tuple[float, float, float]:
    """(mean bytes, pickle + unpickle microseconds (best of 5 passes), mean info keys)."""
    blobs = [pickle.dumps(m, protocol=pickle.HIGHEST_PROTOCOL) for m in msgs]
    best = float("inf")
    for _ in range(5):
        t0 = time.perf_counter()
        for m in msgs:
            pickle.loads(pickle.dumps(m, protocol=pickle.HIGHEST_PROTOCOL))
        best = min(best, time.perf_counter() - t0)
    return (float(np.mean([len(b) for b in blobs])), 1e6 * best / len(msgs),
            float(np.mean([len(m[info_at]) for m in msgs])))


def _messages(n_steps: int) -> dict[str, tuple[float, float, float]]:
    """Per env step: (bytes, pickle + unpickle microseconds, info keys) of the message a worker
    sends through its pipe: SB3's SubprocVecEnv over the env and over ``train.py rl``'s training
    env (scratch form), gymnasium's AsyncVectorEnv (observation in shared memory)."""
    sb3 = _sb3_messages(_Timed(gym.make(ENV_ID)), n_steps)
    out = {"SB3 Subproc, env": _pickle_cost(sb3, 3),
           "gym async, env": _pickle_cost([(m[1], m[2], False, m[3]) for m in sb3], 3)}
    try:
        from baselines.rl.config import RLConfig
        from baselines.rl.envs import training_env
    except ImportError:  # the rl extra
        return out
    env = training_env(RLConfig(form="scratch", n_envs=2), 0, None, [])
    out["SB3 Subproc, training env"] = _pickle_cost(_sb3_messages(env, n_steps), 3)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true", help="300 env steps per loop")
    parser.add_argument("--steps", type=int, default=None, help="env steps per loop (default 2000)")
    args = parser.parse_args(argv)
    n = args.steps or (300 if args.quick else 2000)
    if n < 2:
        parser.error("--steps must be >= 2")
    rows = [
        ("reactive (1 env)", _single("reactive", n)),
        ("random (1 env)", _single("random", n)),
        ("2 processes, random", _independent(2, n)),
        ("vec sync x2, random", _vector("sync", 2, n)),
        ("vec async x2, random", _vector("async", 2, n)),
    ]
    try:
        import stable_baselines3  # noqa: F401
    except ImportError:
        print("stable-baselines3 not installed (the rl extra): its vector envs are skipped")
    else:
        rows += [("SB3 Dummy x2, random", _vector("sb3-dummy", 2, n)),
                 ("SB3 Subproc x2, random", _vector("sb3-subproc", 2, n))]
    ceiling = rows[2][1][0] / rows[2][1][1]
    print(f"{ENV_ID}, {n} env steps per loop (1 env step = 1/30 s simulated)")
    print(f"{'loop':24s} {'steps/s wall':>13s} {'steps/s per core':>17s} {'real time/core':>15s}"
          f" {'of 2 processes':>15s}")
    for name, (steps, wall, cpu) in rows:
        per_core = steps / cpu if cpu > 0 else float("nan")
        print(f"{name:24s} {steps / wall:13.1f} {per_core:17.1f} {per_core / 30.0:14.1f}x"
              f" {steps / wall / ceiling:14.0%}")
    print("\nwhere a vector step's wall time goes (sums over the loop's vector steps):")
    print(f"{'vector env':12s} {'wall s':>8s} {'slower env':>11s} {'mean env':>9s} "
          f"{'wait for slower':>16s} {'rest (IPC, main)':>17s} {'main CPU/step':>14s}")
    for mode, r in LOSS.items():
        if mode in ("sync", "sb3-dummy"):
            continue  # one process steps both envs in turn: nothing waits
        wait, rest = (r["max"] - r["mean"]) / r["wall"], (r["wall"] - r["max"]) / r["wall"]
        print(f"{mode:12s} {r['wall']:8.2f} {r['max']:11.2f} {r['mean']:9.2f} "
              f"{wait:16.1%} {rest:17.1%} {r['main_cpu_us']:11.0f} us")
    print("\nper env step through a worker's pipe (the message as the worker sends it):")
    for name, (size, us, keys) in _messages(min(n, 500)).items():
        print(f"  {name:27s} {size:6.0f} bytes, pickle + unpickle {us:6.1f} us, "
              f"{keys:4.1f} info keys (mean)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
