"""The methods compared in Table I and the figures, built and fitted the same way for every run.

``ours`` is the paper's SPGP planner (inducing ratio 0.4 by default), ``iaal`` the same model with
exact GPs, ``bc_mlp`` and ``act`` the learned baselines. The learned baselines are trained once per
(method, configuration, training set, seed) and their checkpoints are reused when a matching one
exists under the cache folder; the nonparametric methods fit in seconds and are never cached.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from dataclasses import asdict, dataclass, is_dataclass
from pathlib import Path

import numpy as np

from agents.base import Agent
from handover_env.data.dataset import HandoverDataset

METHODS: tuple[str, ...] = ("ours", "iaal", "act", "bc_mlp")
LEARNED: frozenset[str] = frozenset({"act", "bc_mlp"})
_COMPLETE = "evaluate_complete.json"


@dataclass(frozen=True)
class MethodOptions:
    """How the compared methods are configured for one evaluation run.

    Args:
        seed: seeds the learned baselines (initialisation, shuffling, validation split).
        quick: tiny training budgets for tests (``--quick``); never used for reported numbers.
        inducing_ratio: the SPGP inducing ratio of ``ours`` (paper: 0.4).
        act_steps: ACT optimisation steps (None = the ACT agent's default).
        bc_epochs: BC-MLP maximum epochs (None = the BC-MLP agent's default).
        horizon: predicted frames (the protocol's horizon).
        giver_state: also give BC-MLP and ACT the giver's position at the query frame
            (``observation.state``). Off by default: the paper's modules all receive the
            receiver base pose alone (Sec. V-A), and the nonparametric methods never see it.
    """

    seed: int = 0
    quick: bool = False
    inducing_ratio: float = 0.4
    act_steps: int | None = None
    bc_epochs: int | None = None
    horizon: int = 30
    giver_state: bool = False


def check_methods(names: list[str] | tuple[str, ...]) -> list[str]:
    """Validate method names (clear error naming the unknown ones); keeps the given order."""
    unknown = [n for n in names if n not in METHODS]
    if unknown:
        raise ValueError(f"unknown method(s) {unknown}; choose from {list(METHODS)}")
    if not names:
        raise ValueError(f"no method selected; choose from {list(METHODS)}")
    return list(dict.fromkeys(names))


def build_agent(name: str, options: MethodOptions, inducing_ratio: float | None = None) -> Agent:
    """A fresh, unfitted agent for ``name``."""
    check_methods([name])
    if name in ("ours", "iaal"):
        from agents.nonparametric import NonparametricAgent, NonparametricConfig
        from baselines.iaal import IAALAgent

        ratio = options.inducing_ratio if inducing_ratio is None else inducing_ratio
        config = NonparametricConfig(inducing_ratio=ratio, horizon=options.horizon)
        return NonparametricAgent(config) if name == "ours" else IAALAgent(config)
    if name == "bc_mlp":
        from baselines.bc_mlp import BCMLPAgent, BCMLPConfig

        epochs = options.bc_epochs or (3 if options.quick else None)
        kwargs = {"seed": options.seed, "horizon": options.horizon, "use_giver_state": options.giver_state}
        if epochs:
            kwargs["max_epochs"] = epochs
        return BCMLPAgent(BCMLPConfig(**kwargs))
    from baselines.act import ACTAgent, ACTAgentConfig

    kwargs = {"seed": options.seed, "horizon": options.horizon, "use_giver_state": options.giver_state}
    steps = options.act_steps or (40 if options.quick else None)
    if steps:
        kwargs["steps"] = steps
        kwargs["eval_every"] = max(1, min(1000, steps // 4))
    if options.quick:
        kwargs.update(dim_model=32, dim_feedforward=64, n_heads=2, n_encoder_layers=1, batch_size=32)
    return ACTAgent(ACTAgentConfig(**kwargs))


def dataset_fingerprint(dataset: HandoverDataset) -> str:
    """A short hash of the episodes' ids and arrays (which training set a checkpoint saw)."""
    h = hashlib.sha1()
    for ep in dataset:
        h.update(ep.source_id.encode())
        h.update(np.ascontiguousarray(ep.receiver_xy).tobytes())
        h.update(np.ascontiguousarray(ep.giver_xyz).tobytes())
    return h.hexdigest()[:16]


def _config_dict(agent: Agent) -> dict:
    config = getattr(agent, "config", None)
    return asdict(config) if is_dataclass(config) else {}


def fit_agent(
    name: str,
    agent: Agent,
    train: HandoverDataset,
    cache_dir: str | os.PathLike | None = None,
    reuse: bool = True,
    progress: bool = False,
) -> tuple[Agent, bool]:
    """Fit ``agent`` on ``train``; learned baselines reuse a matching checkpoint under ``cache_dir``.

    Returns:
        ``(fitted agent, reused)`` where ``reused`` is True when a checkpoint was loaded.
    """
    if name not in LEARNED or cache_dir is None:
        kwargs = {"progress": progress} if name in LEARNED else {}
        return agent.fit(train, **kwargs), False
    key_src = json.dumps(
        {"method": name, "config": _config_dict(agent), "train": dataset_fingerprint(train)},
        sort_keys=True,
        default=str,
    )
    key = hashlib.sha1(key_src.encode()).hexdigest()[:16]
    folder = Path(cache_dir) / f"{name}-{key}"
    cls = type(agent)
    if reuse and (folder / _COMPLETE).is_file():
        try:
            return cls.load(folder), True  # type: ignore[attr-defined]
        except Exception as exc:  # an incompatible or damaged checkpoint is retrained, not trusted
            print(f"  checkpoint {folder} unusable ({exc}); retraining", flush=True)
    if folder.exists():
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    agent.fit(train, out_dir=folder, progress=progress)  # type: ignore[call-arg]
    agent.save(folder)  # type: ignore[attr-defined]
    (folder / _COMPLETE).write_text(key_src)
    return agent, False
