"""Inference cost per 30 Hz step of the learned baselines (BC-MLP, ACT), on one core.

One step = ``agent.act(obs)``: the closed-loop call the env makes every 30 Hz frame (feature
encoding, the network, temporal ensembling, the target at t_f). Also timed: one open-loop
``predict`` (the network alone, batch 1). Recorded receiver tracks are replayed as env
observations (receiver history, frames seen, the giver position as ``ee_pos``); the agents
alternate step by step so both see the same machine load.

Checkpoints: ``--bc-mlp DIR`` / ``--act DIR`` (default ``runs/bc_mlp`` and ``runs/act`` when they
exist). Without one, a default-size model is fitted for a moment on a few episodes: the cost of a
forward pass does not depend on the weights.

Printed: median and p99 wall and CPU (``thread_time``) milliseconds per step, the ratio ACT/BC-MLP
and the share of the 33.3 ms frame budget.

Usage: ``python bench/baseline_latency.py [--quick] [--data PATH] [--bc-mlp DIR] [--act DIR]``
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

import numpy as np  # noqa: E402
import torch  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from baselines.act import ACTAgent, ACTAgentConfig  # noqa: E402
from baselines.bc_mlp import BCMLPAgent, BCMLPConfig  # noqa: E402
from handover_env.data.dataset import Episode  # noqa: E402
from handover_env.person.demos import load_any  # noqa: E402

DEV_COPY = ROOT / ".." / "shared" / "data" / "dynamic_handover_dataset" / "whole_motions"


def _pin_one_core() -> str:
    try:
        cores = sorted(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {cores[0]})
        return f"pinned to core {cores[0]} of {len(cores)} available"
    except (AttributeError, OSError):
        return "not pinned (no sched_setaffinity)"


def _observations(agent, ep: Episode) -> list[np.ndarray]:
    """Env observations replaying ``ep``: receiver history, frames seen, ee_pos = the giver."""
    layout = agent.layout
    parts = {name: np.zeros(shape) for name, shape, _ in layout.fields}
    obs = []
    for t in range(ep.length):
        idx = np.clip(np.arange(t - layout.history + 1, t + 1), 0, None)
        parts["receiver_xy_history"] = ep.receiver_xy[idx]
        parts["receiver_frames_seen"] = np.array([t + 1.0])
        parts["ee_pos"] = ep.giver_xyz[t]
        parts["time"] = np.array([t / 30.0])
        obs.append(layout.flatten(parts))
    return obs


def _agents(args, data) -> dict:
    small = data.subset(np.arange(min(len(data), 12)))
    bc_dir = Path(args.bc_mlp) if args.bc_mlp else ROOT / "runs" / "bc_mlp"
    act_dir = Path(args.act) if args.act else ROOT / "runs" / "act"
    out = {}
    try:
        out["BC-MLP"] = (BCMLPAgent.load(bc_dir), f"checkpoint {bc_dir}")
    except Exception:  # noqa: BLE001 - no usable checkpoint: a default-size model
        out["BC-MLP"] = (
            BCMLPAgent(BCMLPConfig(max_epochs=1)).fit(small),
            "default size, untrained weights",
        )
    try:
        out["ACT"] = (ACTAgent.load(act_dir), f"checkpoint {act_dir}")
    except Exception:  # noqa: BLE001
        with tempfile.TemporaryDirectory() as tmp:
            agent = ACTAgent(ACTAgentConfig(steps=1, eval_every=1)).fit(
                small, export_root=Path(tmp) / "lr"
            )
        out["ACT"] = (agent, "default size, untrained weights")
    return out


def _fmt(x: np.ndarray) -> str:
    return f"median {np.median(x) * 1e3:7.3f} ms  p99 {np.percentile(x, 99) * 1e3:7.3f} ms"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--quick", action="store_true", help="few episodes (for CI)")
    parser.add_argument(
        "--data",
        default=None,
        help="dataset for the replayed tracks (default: the dev copy "
        "if present, else the synthetic default)",
    )
    parser.add_argument(
        "--bc-mlp", default=None, help="BC-MLP checkpoint folder (default runs/bc_mlp)"
    )
    parser.add_argument("--act", default=None, help="ACT checkpoint folder (default runs/act)")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    print(_pin_one_core(), "| torch threads 1", flush=True)
    path = args.data or (str(DEV_COPY) if DEV_COPY.is_dir() else None)
    data = load_any(path)
    print(
        f"data: {len(data)} episodes, {data.n_frames} frames ({path or 'synthetic default'})",
        flush=True,
    )
    agents = _agents(args, data)
    for name, (_, origin) in agents.items():
        print(f"{name}: {origin}")
    n_eps = 3 if args.quick else 20
    episodes = [data[i] for i in np.linspace(0, len(data) - 1, n_eps).round().astype(int)]

    wall = {n: [] for n in agents}
    cpu = {n: [] for n in agents}
    pred_wall = {n: [] for n in agents}
    for ep in episodes:
        streams = {n: _observations(a, ep) for n, (a, _) in agents.items()}
        for a, _ in agents.values():
            a.reset()
        for t in range(ep.length):
            for n, (a, _) in agents.items():
                w0, c0 = time.perf_counter(), time.thread_time()
                a.act(streams[n][t])
                wall[n].append(time.perf_counter() - w0)
                cpu[n].append(time.thread_time() - c0)
        for n, (a, _) in agents.items():
            for t in range(5, ep.length, 10):
                w0 = time.perf_counter()
                a.predict(ep.receiver_xy[: t + 1], ep.giver_xyz[t])
                pred_wall[n].append(time.perf_counter() - w0)
    steps = len(wall["BC-MLP"])
    print(f"\none 30 Hz step = act(obs), {steps} steps over {n_eps} replayed episodes:")
    for n in agents:
        print(f"  {n:6s} wall {_fmt(np.array(wall[n]))}   cpu {_fmt(np.array(cpu[n]))}")
    print("\none open-loop predict (batch 1):")
    for n in agents:
        print(f"  {n:6s} wall {_fmt(np.array(pred_wall[n]))}")
    ratio = np.median(wall["ACT"]) / np.median(wall["BC-MLP"])
    print(f"\nratio ACT/BC-MLP per step: {ratio:.1f}x (wall medians)")
    for n in agents:
        print(
            f"  {n}: {np.median(wall[n]) / (1 / 30):.1%} of the 33.3 ms frame budget (wall median)"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
