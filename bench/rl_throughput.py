"""Agent steps per second per core: what a reinforcement-learning loop gets out of the env.

Loops over ``DynamicHandover-v0`` (scripted ID walkers, episodes reset as they end):

* ``reactive``: one env stepped by the reactive agent (``agents/reactive.py``), agent included;
* ``random``: one env stepped by random actions (the env alone);
* ``2 processes``: two independent processes, each one env with random actions (the ceiling of
  any two-env vector env);
* ``vec sync x2``: ``gym.make_vec(..., num_envs=2, vectorization_mode="sync")``;
* ``vec async x2``: the same with ``vectorization_mode="async"`` (one worker process per env);
* ``SB3 Dummy x2`` / ``SB3 Subproc x2``: stable-baselines3's ``DummyVecEnv`` and
  ``SubprocVecEnv`` (the vector envs ``train.py rl`` uses; skipped without the ``rl`` extra);
* ``..., lean info``: async and Subproc over the env whose mid-episode info holds only the
  three reward terms, whose episode-ending step the whole info and whose reset info only the
  receiver (:class:`handover_env.envs.end_info.EndInfo`, the rule of ``train.py rl``'s training env,
  ``baselines/rl/envs.py``).

Every loop is measured the same way. The random actions are one table drawn before any loop
from the action space (seed 0): every env of every loop takes its actions from it, so no loop
pays for drawing them, and a vector env's main process does not draw its sub-envs' actions one
after the other while two independent processes draw theirs at once. Every env is built,
reset and stepped ``WARMUP`` untimed steps in its own process before any timing (the first step
of a fresh process loads the compiled kernels from numba's cache: about 50 ms, 8 % of a
``--quick`` loop). All loops stay alive and are timed in ``--rounds`` interleaved rounds (the
order reversed every other round), each round's rates taken as shares of the same round's two
independent processes; the share printed is the median over rounds, with its range. Wall time
on a shared machine mostly measures the other processes; steps per CPU second (this process
plus its workers, read from ``/proc``) is the per-core figure.

Where a lock-step vector env loses against two independent processes (printed after the table):
every sub-env step is stamped inside its worker (:class:`_Timed`, ``time.perf_counter`` is one
clock for all processes), and every vector step in the main process, so each vector step splits
exactly into the dispatch (main process to the worker's step: pickling, the pipe, the worker's
wake-up), the env's step (mean of the sub-envs), the wait for the slower sub-env and the return
(the slower worker's step end to the main process holding the results: the worker's pickling,
the pipe, the main's wake-up and unpickling, gymnasium's info merge). The bytes each step sends
through the pipe and the time to pickle and unpickle them are measured on the messages
themselves (SB3: ``(obs, reward, done, info, reset_info)``; gymnasium async: ``(reward,
terminated, truncated, info)``, the observation going through shared memory).

Usage: ``python bench/rl_throughput.py [--quick] [--steps N] [--rounds R]``
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
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import handover_env  # noqa: E402, F401
from agents.reactive import ReactiveAgent  # noqa: E402
from handover_env.envs.end_info import EndInfo  # noqa: E402

ENV_ID = "handover_env/DynamicHandover-v0"
OPTIONS = {"receiver": "id"}
#: untimed steps of every env after its first reset (kernel loading, first-call costs)
WARMUP = 20

Rate = tuple[int, float, float]  # (env steps, wall s, CPU s)


def _proc_cpu(pid: int) -> float:
    """CPU seconds (user + system) of process ``pid`` from /proc (0 where /proc is absent)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def action_table(n: int, n_envs: int = 2, seed: int = 0) -> np.ndarray:
    """``(n, n_envs, 4)`` random actions drawn from the env's action space (``seed``); row ``i``
    column ``k`` is the ``i``-th action of the ``k``-th env of a loop, cycled past ``n``."""
    env = gym.make(ENV_ID)
    space = env.action_space
    env.close()
    space.seed(seed)
    return np.stack([[space.sample() for _ in range(n_envs)] for _ in range(n)])


class _Timed(gym.Wrapper):
    """The env with the (start, end) ``perf_counter`` stamps of every vector step's work in it,
    and the reset options of the other loops as its default. SB3's workers reset right after the
    step that ended an episode (the reset counts with that step); gymnasium's vector envs reset
    in the next vector step instead of stepping (``reset_own_step``: the reset is its entry)."""

    def __init__(self, env: gym.Env, reset_own_step: bool = False) -> None:
        super().__init__(env)
        self.stamps: list[tuple[float, float]] = []
        self.reset_own_step = reset_own_step

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        t0 = time.perf_counter()
        out = self.env.reset(seed=seed, options=OPTIONS if options is None else options)
        if self.reset_own_step:
            self.stamps.append((t0, time.perf_counter()))
        elif self.stamps:
            self.stamps[-1] = (self.stamps[-1][0], time.perf_counter())
        return out

    def step(self, action):
        t0 = time.perf_counter()
        out = self.env.step(action)
        self.stamps.append((t0, time.perf_counter()))
        return out

    def n_stamps(self) -> int:
        """How many steps have been stamped."""
        return len(self.stamps)

    def timings(self, start: int = 0) -> list[tuple[float, float]]:
        """The (start, end) stamps of every step from the ``start``-th on (with its reset)."""
        return self.stamps[start:]


def _timed_env(lean: bool = False) -> gym.Env:
    env = gym.make(ENV_ID)
    return _Timed(EndInfo(env) if lean else env)


class _Single:
    """One env in this process, stepped by the reactive agent or by the action table."""

    def __init__(self, policy: str, actions: np.ndarray) -> None:
        self.env, self.agent, self.actions = gym.make(ENV_ID), ReactiveAgent(), actions[:, 0]
        self.policy, self.i, self.episode = policy, 0, 0
        self.obs, _ = self.env.reset(seed=0, options=OPTIONS)
        self.agent.reset()
        self.run(WARMUP)

    def run(self, n: int) -> Rate:
        env, agent, acts, obs = self.env, self.agent, self.actions, self.obs
        reactive = self.policy == "reactive"
        w0, c0 = time.perf_counter(), time.process_time()
        for _ in range(n):
            a = agent.act(obs) if reactive else acts[self.i % len(acts)]
            self.i += 1
            obs, _, term, trunc, _ = env.step(a)
            if term or trunc:
                self.episode += 1
                obs, _ = env.reset(seed=self.episode, options=OPTIONS)
                agent.reset()
        self.obs = obs
        return n, time.perf_counter() - w0, time.process_time() - c0

    def close(self) -> None:
        self.env.close()


def _serve_independent(conn: Any, actions: np.ndarray) -> None:
    """One of the independent processes: build, reset and warm its env, then for every ``n``
    received step ``n`` times and send back (n, CPU s)."""
    env = gym.make(ENV_ID)
    env.reset(seed=0, options=OPTIONS)
    i = episode = 0

    def steps(n: int) -> None:
        nonlocal i, episode
        for _ in range(n):
            _, _, term, trunc, _ = env.step(actions[i % len(actions)])
            i += 1
            if term or trunc:
                episode += 1
                env.reset(seed=episode, options=OPTIONS)

    steps(WARMUP)
    conn.send("ready")
    while (n := conn.recv()) is not None:
        c0 = time.process_time()
        steps(n)
        conn.send((n, time.process_time() - c0))
    env.close()


class _Independent:
    """``n_procs`` independent one-env processes stepping at once; the wall time is this
    process's from telling them to start to the last one's answer."""

    def __init__(self, n_procs: int, actions: np.ndarray) -> None:
        ctx = mp.get_context("forkserver")
        self.conns, self.procs = [], []
        for k in range(n_procs):
            here, there = ctx.Pipe()
            proc = ctx.Process(target=_serve_independent,
                               args=(there, np.ascontiguousarray(actions[:, k])))
            proc.start()
            self.conns.append(here)
            self.procs.append(proc)
        for conn in self.conns:
            if conn.recv() != "ready":
                raise RuntimeError("an independent env process failed to start")

    def run(self, n: int) -> Rate:
        w0 = time.perf_counter()
        for conn in self.conns:
            conn.send(n // len(self.conns))
        results = [conn.recv() for conn in self.conns]
        return (sum(r[0] for r in results), time.perf_counter() - w0, sum(r[1] for r in results))

    def close(self) -> None:
        for conn in self.conns:
            conn.send(None)
        for proc in self.procs:
            proc.join()


class _Vector:
    """A two-env vector env (``mode``: sync / async (gymnasium), sb3-dummy / sb3-subproc), over
    the env or with ``lean`` over :class:`EndInfo`; every vector step stamped (module
    docstring), the splits summed over rounds in :attr:`loss`."""

    def __init__(self, mode: str, actions: np.ndarray, lean: bool = False) -> None:
        self.mode, self.actions, self.i = mode, actions, 0
        n_envs = actions.shape[1]
        if mode.startswith("sb3"):
            from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

            cls = SubprocVecEnv if mode == "sb3-subproc" else DummyVecEnv
            self.envs = cls([functools.partial(_timed_env, lean)] * n_envs)
            self.envs.seed(0)
            self.envs.reset()
            self._call = self.envs.env_method
        else:
            wrappers = ([EndInfo] if lean else []) + [
                functools.partial(_Timed, reset_own_step=True)]
            self.envs = gym.make_vec(ENV_ID, num_envs=n_envs, vectorization_mode=mode,
                                     wrappers=wrappers)
            self.envs.reset(seed=0, options=OPTIONS)
            self._call = self.envs.call
        self.workers = [p.pid for p in getattr(self.envs, "processes", [])]
        self.loss = dict.fromkeys(("dispatch", "env", "wait", "return"), 0.0)
        self.main_cpu, self.vector_steps = 0.0, 0
        self._step(WARMUP)

    def _timings(self, starts: list[int]) -> list[list[tuple[float, float]]]:
        """Every sub-env's step stamps from its ``starts[k]``-th on."""
        m = min(starts)
        return [t[s - m:] for t, s in zip(self._call("timings", m), starts)]

    def _step(self, n_vec: int) -> list[tuple[float, float]]:
        envs, acts, stamps = self.envs, self.actions, []
        for _ in range(n_vec):
            a = acts[self.i % len(acts)]
            self.i += 1
            t0 = time.perf_counter()
            envs.step(a)
            stamps.append((t0, time.perf_counter()))
        return stamps

    def run(self, n: int) -> Rate:
        n_envs = self.actions.shape[1]
        n_vec = max(1, n // n_envs)
        starts = list(self._call("n_stamps"))
        w0, c0 = time.perf_counter(), time.process_time()
        k0 = sum(_proc_cpu(p) for p in self.workers)
        main = self._step(n_vec)
        wall, cpu_main = time.perf_counter() - w0, time.process_time() - c0
        cpu = cpu_main + sum(_proc_cpu(p) for p in self.workers) - k0
        if self.workers:
            sub = np.array([t[:n_vec] for t in self._timings(starts)])  # (envs, n_vec, 2)
            vec = np.array(main)  # (n_vec, 2)
            mean_end, max_end = sub[:, :, 1].mean(axis=0), sub[:, :, 1].max(axis=0)
            env = (sub[:, :, 1] - sub[:, :, 0]).mean(axis=0)
            self.loss["env"] += float(env.sum())
            self.loss["dispatch"] += float((mean_end - env - vec[:, 0]).sum())
            self.loss["wait"] += float((max_end - mean_end).sum())
            self.loss["return"] += float((vec[:, 1] - max_end).sum())
            self.main_cpu += cpu_main
            self.vector_steps += n_vec
        return n_vec * n_envs, wall, cpu

    def close(self) -> None:
        self.envs.close()


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
    sends through its pipe: SB3's SubprocVecEnv over the env, the lean-info env and ``train.py
    rl``'s training env (scratch form), gymnasium's AsyncVectorEnv (observation in shared
    memory) over the env and the lean-info env."""
    sb3 = _sb3_messages(_timed_env(), n_steps)
    lean = _sb3_messages(_timed_env(lean=True), n_steps)
    out = {"SB3 Subproc, env": _pickle_cost(sb3, 3),
           "SB3 Subproc, lean info": _pickle_cost(lean, 3),
           "gym async, env": _pickle_cost([(m[1], m[2], False, m[3]) for m in sb3], 3),
           "gym async, lean info": _pickle_cost([(m[1], m[2], False, m[3]) for m in lean], 3)}
    try:
        from baselines.rl.config import RLConfig
        from baselines.rl.envs import training_env
    except ImportError:  # the rl extra
        return out
    env = training_env(RLConfig(form="scratch", n_envs=2), 0, None, [])
    out["SB3 Subproc, training env"] = _pickle_cost(_sb3_messages(env, n_steps), 3)
    return out


def _loops(actions: np.ndarray) -> dict[str, Any]:
    """Every loop of the module docstring, built, reset and warmed up."""
    loops: dict[str, Any] = {
        "reactive (1 env)": _Single("reactive", actions),
        "random (1 env)": _Single("random", actions),
        "2 processes": _Independent(2, actions),
        "vec sync x2": _Vector("sync", actions),
        "vec async x2": _Vector("async", actions),
        "vec async x2, lean info": _Vector("async", actions, lean=True),
    }
    try:
        import stable_baselines3  # noqa: F401
    except ImportError:
        print("stable-baselines3 not installed (the rl extra): its vector envs are skipped")
        return loops
    loops["SB3 Dummy x2"] = _Vector("sb3-dummy", actions)
    loops["SB3 Subproc x2"] = _Vector("sb3-subproc", actions)
    loops["SB3 Subproc x2, lean info"] = _Vector("sb3-subproc", actions, lean=True)
    return loops


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true", help="300 env steps per loop and round")
    parser.add_argument("--steps", type=int, default=None,
                        help="env steps per loop and round (default 2000)")
    parser.add_argument("--rounds", type=int, default=3, help="interleaved rounds (default 3)")
    args = parser.parse_args(argv)
    n = args.steps or (300 if args.quick else 2000)
    if n < 2:
        parser.error("--steps must be >= 2")
    if args.rounds < 1:
        parser.error("--rounds must be >= 1")
    loops = _loops(action_table(max(n, WARMUP) + WARMUP))
    rates: dict[str, list[Rate]] = {name: [] for name in loops}
    try:
        for r in range(args.rounds):
            order = list(loops) if r % 2 == 0 else list(loops)[::-1]
            for name in order:
                rates[name].append(loops[name].run(n))
    finally:
        for loop in loops.values():
            loop.close()
    ceiling = [s / w for s, w, _ in rates["2 processes"]]
    print(f"{ENV_ID}, {n} env steps per loop and round, {args.rounds} interleaved rounds, "
          f"{WARMUP} warm-up steps per env (1 env step = 1/30 s simulated)")
    print(f"{'loop':26s} {'steps/s wall':>13s} {'steps/s per core':>17s} {'real time/core':>15s}"
          f" {'of 2 processes (range)':>24s}")
    for name, rs in rates.items():
        wall = [s / w for s, w, _ in rs]
        per_core = sum(s for s, _, _ in rs) / max(sum(c for _, _, c in rs), 1e-9)
        share = [w / c for w, c in zip(wall, ceiling)]
        print(f"{name:26s} {np.median(wall):13.1f} {per_core:17.1f} {per_core / 30.0:14.1f}x"
              f" {np.median(share):9.0%} ({min(share):.0%}-{max(share):.0%})")
    print("\nwhere a process vector env's step goes (share of the summed vector step times):")
    print(f"{'vector env':26s} {'dispatch':>9s} {'env step':>9s} {'wait slower':>12s} "
          f"{'return':>8s} {'main CPU/vector step':>21s}")
    for name, loop in loops.items():
        if not (isinstance(loop, _Vector) and loop.workers):
            continue  # one process steps the envs in turn: nothing waits, nothing is sent
        parts = loop.loss
        total = sum(parts.values())
        print(f"{name:26s} {parts['dispatch'] / total:9.1%} {parts['env'] / total:9.1%} "
              f"{parts['wait'] / total:12.1%} {parts['return'] / total:8.1%} "
              f"{1e6 * loop.main_cpu / loop.vector_steps:18.0f} us")
    print("\nper env step through a worker's pipe (the message as the worker sends it):")
    for name, (size, us, keys) in _messages(min(n, 500)).items():
        print(f"  {name:27s} {size:6.0f} bytes, pickle + unpickle {us:6.1f} us, "
              f"{keys:4.1f} info keys (mean)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
