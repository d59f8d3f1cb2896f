"""CPU seconds per closed-loop episode for every agent of the closed-loop evaluation, one core.

Agents: ``reactive``, ``static`` (in ``StaticHandover-v0``), ``ours`` (SPGP planner, inducing
ratio 0.4), ``iaal`` (exact GP), ``bc-mlp``, ``act``, ``giver-replay`` and ``null``. The ones
that learn are fitted HERE ON SYNTHETIC DATA (``generate_synthetic``), the networks trained for
one epoch / a few steps at their default sizes: the figures are the cost of running them, not of
good models (a forward pass costs the same whatever the weights; the planners' cost grows with
the number of demos, ``--demos``). Their fitting time is printed but not counted.

Episodes: scripted ID walkers (seeds 0..n-1) for every agent except ``giver-replay``, which
needs a replayed recording (synthetic episodes replayed as the receiver, the agent following
their giver path). Per agent: CPU seconds per episode (``time.process_time``, torch and BLAS
on one thread), of which the agent's own ``act`` (``thread_time`` around it), and env steps
per episode. Episodes differ between agents (an agent that hands over early ends early), so
the per-step figure is printed too.

Usage: ``python bench/agent_episode_cost.py [--quick] [--episodes N] [--demos N]``
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("HF_DATASETS_OFFLINE", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

import gymnasium as gym  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import handover_env  # noqa: E402, F401
from agents.giver_replay import GiverReplayAgent  # noqa: E402
from agents.nonparametric import NonparametricAgent, NonparametricConfig  # noqa: E402
from agents.null import NullAgent  # noqa: E402
from agents.reactive import ReactiveAgent  # noqa: E402
from agents.static import StaticAgent  # noqa: E402
from handover_env.data.dataset import HandoverDataset  # noqa: E402
from handover_env.person.synthetic import generate_synthetic  # noqa: E402

DYNAMIC, STATIC = "handover_env/DynamicHandover-v0", "handover_env/StaticHandover-v0"
AGENTS = ("reactive", "static", "ours", "iaal", "bc-mlp", "act", "giver-replay", "null")


def _build(name: str, data: HandoverDataset, tmp: Path) -> Any:
    """The agent ``name``, fitted on ``data`` where it learns (tiny training, see the docstring)."""
    if name == "reactive":
        return ReactiveAgent()
    if name == "static":
        return StaticAgent()
    if name == "null":
        return NullAgent()
    if name == "giver-replay":
        return GiverReplayAgent()
    if name == "ours":
        return NonparametricAgent(NonparametricConfig(inducing_ratio=0.4)).fit(data)
    if name == "iaal":
        from baselines.iaal import IAALAgent

        return IAALAgent(NonparametricConfig()).fit(data)
    if name == "bc-mlp":
        from baselines.bc_mlp import BCMLPAgent, BCMLPConfig

        return BCMLPAgent(BCMLPConfig(max_epochs=1)).fit(data)
    if name == "act":
        from baselines.act import ACTAgent, ACTAgentConfig

        return ACTAgent(ACTAgentConfig(steps=2, eval_every=2)).fit(data, export_root=tmp / "act")
    raise ValueError(f"unknown agent {name!r}; choose from {list(AGENTS)}")


def _episodes(name: str, agent: Any, env: gym.Env, replays: HandoverDataset, n: int):
    """(CPU s, agent CPU s, env steps) of each of ``n`` closed-loop episodes."""
    out = []
    for i in range(n):
        if name == "giver-replay":
            ep = replays[i % len(replays)]
            agent.set_episode(ep)
            options: dict = {"receiver": "replay", "episode": ep}
        else:
            options = {"receiver": "id"}
        c0 = time.process_time()
        obs, _ = env.reset(seed=i, options=options)
        agent.reset()
        act_cpu, steps = 0.0, 0
        while True:
            a0 = time.thread_time()
            action = agent.act(obs)
            act_cpu += time.thread_time() - a0
            obs, _, term, trunc, _ = env.step(action)
            steps += 1
            if term or trunc:
                break
        out.append((time.process_time() - c0, act_cpu, steps))
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true", help="2 episodes per agent, 20 demos")
    parser.add_argument("--episodes", type=int, default=None, help="episodes per agent (default 5)")
    parser.add_argument("--demos", type=int, default=None,
                        help="synthetic demos the learned agents are fitted on (default 60)")
    parser.add_argument("--agents", nargs="*", default=list(AGENTS), choices=AGENTS,
                        help="agents to time (default: all)")
    args = parser.parse_args(argv)
    n_eps = args.episodes or (2 if args.quick else 5)
    n_demos = args.demos or (20 if args.quick else 60)
    if n_eps < 1 or n_demos < 2:
        parser.error("--episodes must be >= 1 and --demos >= 2")
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:  # the learned baselines then fail with their own message
        pass
    data = generate_synthetic(n=n_demos, ood_fraction=0.1, seed=0)
    replays = generate_synthetic(n=max(n_eps, 2), ood_fraction=0.0, seed=1)
    print(f"learned agents fitted on {n_demos} SYNTHETIC demos (tiny training: the cost of "
          f"running them, not good models); {n_eps} episodes per agent, one core", flush=True)
    print(f"{'agent':14s} {'fit s':>7s} {'CPU s/episode':>14s} {'of which act':>13s} "
          f"{'steps/ep':>9s} {'CPU ms/step':>12s}")
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.agents:
            t0 = time.perf_counter()
            agent = _build(name, data, Path(tmp))
            fit = time.perf_counter() - t0
            env = gym.make(STATIC if name == "static" else DYNAMIC)
            rows = _episodes(name, agent, env, replays, n_eps)
            env.close()
            cpu = sum(r[0] for r in rows) / n_eps
            act = sum(r[1] for r in rows) / n_eps
            steps = sum(r[2] for r in rows) / n_eps
            print(f"{name:14s} {fit:7.1f} {cpu:14.3f} {act:13.3f} {steps:9.0f} "
                  f"{1e3 * cpu / steps:12.3f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
