"""The methods compared in Table I and the figures, configured, fitted and cached the same way for
every run.

The methods are the open-loop entries of :mod:`handover_eval.roster` (which builds them):
``ours`` is the paper's SPGP planner (inducing ratio 0.4 by default), ``iaal`` the same model with
exact GPs, ``bc_mlp`` and ``act`` the learned baselines, and ``cv`` the constant-velocity predictor
(:mod:`agents.constant_velocity`: the reactive agent's extrapolation, nothing learned), the simple
baseline that learned trajectory predictors are held against. The learned baselines are trained
once per (method, configuration, training set, seed) and their checkpoints are reused when a
matching one exists under the cache folder; the nonparametric methods fit in seconds and are
never cached. The experiments pre-train ACT's models for all folds in parallel worker processes
into that same cache (:mod:`handover_eval.act_folds`), so :func:`fit_agent` then only loads them.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from dataclasses import asdict, dataclass, field, is_dataclass
from pathlib import Path

import numpy as np

from agents.base import Agent
from handover_env.data.dataset import HandoverDataset
from handover_eval import roster
from handover_eval.reporting import write_text

#: The open-loop methods in Table I's row order, read from the roster.
METHODS: tuple[str, ...] = roster.openloop_methods()
COMPLETE = "evaluate_complete.json"

ACT_EVAL_STEPS = 3_000
"""ACT optimisation steps of the k-fold evaluations (``MethodOptions.act_steps=None``); see
MethodOptions."""
QUICK_ACT_STEPS = 40


def default_workers() -> int:
    """Processes for the ACT fold pre-training: one per core, at most 2."""
    return max(1, min(2, os.cpu_count() or 1))


@dataclass(frozen=True)
class MethodOptions:
    """How the compared methods are configured for one evaluation run.

    Args:
        seed: seeds the learned baselines (initialisation, shuffling, validation split).
        quick: tiny training budgets for tests (``--quick``); never used for reported numbers.
        inducing_ratio: the SPGP inducing ratio of ``ours`` (paper: 0.4).
        act_steps: ACT optimisation steps. None = :data:`ACT_EVAL_STEPS` (3000; 40 with ``quick``),
            the k-fold budget, not ``train.py``'s 8000, so that 10 ACT folds train within the
            make-test-sized machine's budget (2 cores, one torch thread per fold). On a
            787-episode training set the validation L1 after 3000 steps is within ~1% of the
            value after 5000; the held-out current-frame RMS still gains from more steps
            (docs/results.md, Sample efficiency).
        bc_epochs: BC-MLP maximum epochs (None = the BC-MLP agent's default).
        horizon: predicted frames (the protocol's horizon).
        giver_state: also give BC-MLP and ACT the giver's position at the query frame
            (``observation.state``). Off by default: the paper's modules all receive the
            receiver base pose alone (Sec. V-A), and the nonparametric methods never see it.
        workers: processes that pre-train the ACT fold models in parallel (each with one torch
            thread) and then run the folds (:func:`handover_eval.backend.map_folds`); default
            one per core, at most 2. 1 runs everything in this process. Either way every ACT
            fold trains on its episodes of one shared LeRobot export
            (:mod:`handover_eval.act_folds`), and the results are the same.
        rl_checkpoints: RL checkpoint folders (``train.py rl``) of the ``rl-*`` closed-loop
            agents, matched to them by their policy form.
    """

    seed: int = 0
    quick: bool = False
    inducing_ratio: float = 0.4
    act_steps: int | None = None
    bc_epochs: int | None = None
    horizon: int = 30
    giver_state: bool = False
    workers: int = field(default_factory=default_workers)
    rl_checkpoints: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.workers, (int, np.integer)) or self.workers < 1:
            raise ValueError(f"workers must be a positive integer, got {self.workers!r}")
        if self.act_steps is not None and self.act_steps < 1:
            raise ValueError(f"act_steps must be positive, got {self.act_steps!r}")

    @property
    def act_budget(self) -> int:
        """ACT's optimisation steps: ``act_steps``, else :data:`ACT_EVAL_STEPS` (40 with
        ``quick``)."""
        return self.act_steps or (QUICK_ACT_STEPS if self.quick else ACT_EVAL_STEPS)


def check_methods(names: list[str] | tuple[str, ...]) -> list[str]:
    """Validate method names (:func:`handover_eval.roster.check_methods`: a clear error naming the
    unknown ones, other spellings as the entry's name); keeps the given order."""
    return roster.check_methods(names)


def build_agent(name: str, options: MethodOptions, inducing_ratio: float | None = None) -> Agent:
    """A fresh, unfitted open-loop method ``name`` (its roster entry's builder)."""
    (name,) = check_methods([name])
    agent = roster.build(name, options, inducing_ratio=inducing_ratio)
    assert isinstance(agent, Agent), f"{name} is an open-loop method, so it predicts"
    return agent


def dataset_fingerprint(dataset: HandoverDataset) -> str:
    """A short hash of the episodes' ids and arrays (which training set a checkpoint saw)."""
    h = hashlib.sha1()
    for ep in dataset:
        h.update(ep.source_id.encode())
        h.update(np.ascontiguousarray(ep.receiver_xy).tobytes())
        h.update(np.ascontiguousarray(ep.giver_xyz).tobytes())
    return h.hexdigest()[:16]


def with_test_data(dataset: HandoverDataset, test_data: HandoverDataset) -> HandoverDataset:
    """``dataset``'s episodes, then ``test_data``'s, in one dataset (``--replay-data``).

    The models fit on indices ``0 .. len(dataset) - 1`` (all of ``dataset``) and are scored on the
    rest. A clear ValueError when the rates differ, ``test_data`` is empty, or it shares an
    episode (the same source id or the same arrays) with ``dataset``: the recordings scored on
    must not be in the data the models fit on.
    """
    if float(test_data.rate_hz) != float(dataset.rate_hz):
        raise ValueError(
            f"--replay-data is at {test_data.rate_hz:g} Hz, --data at {dataset.rate_hz:g} Hz"
        )
    if len(test_data) == 0:
        raise ValueError("--replay-data holds no episode")
    ids = {ep.source_id for ep in dataset}
    prints = {dataset.subset([i]).fingerprint() for i in range(len(dataset))}
    shared = [
        ep.source_id
        for i, ep in enumerate(test_data)
        if ep.source_id in ids or test_data.subset([i]).fingerprint() in prints
    ]
    if shared:
        raise ValueError(
            f"--replay-data shares {len(shared)} episode(s) with --data (e.g. {shared[0]!r}): "
            "the recordings scored on must not be in the data the models fit on"
        )
    return HandoverDataset(
        list(dataset) + list(test_data),
        rate_hz=dataset.rate_hz,
        name=f"{dataset.name or 'data'} (models fit on all {len(dataset)} episodes) + "
        f"{test_data.name or 'other data'} ({len(test_data)} episodes scored)",
    )


def _config_dict(agent: Agent) -> dict:
    """The agent's config as it keys its checkpoints (ACT: the format-1 layout where it can, so
    checkpoints trained before ACT's config wrapped LeRobot's ``ACTConfig`` are reused)."""
    config = getattr(agent, "config", None)
    legacy = getattr(config, "legacy_dict", None)
    if callable(legacy) and legacy() is not None:
        return legacy()
    return asdict(config) if is_dataclass(config) else {}


def checkpoint_slot(
    name: str, agent: Agent, train: HandoverDataset, cache_dir: str | os.PathLike
) -> tuple[Path, str]:
    """``(folder, key source)`` of ``agent``'s checkpoint for ``train`` under ``cache_dir``.

    The folder is ``<cache_dir>/<name>-<key>`` with the key a hash of (method, configuration,
    training-set fingerprint); the key source (JSON) is what :func:`mark_complete` writes.
    """
    key_src = json.dumps(
        {"method": name, "config": _config_dict(agent), "train": dataset_fingerprint(train)},
        sort_keys=True,
        default=str,
    )
    key = hashlib.sha1(key_src.encode()).hexdigest()[:16]
    return Path(cache_dir) / f"{name}-{key}", key_src


def is_complete(folder: str | os.PathLike, key_src: str) -> bool:
    """True when ``folder`` holds a finished checkpoint written for ``key_src``."""
    marker = Path(folder) / COMPLETE
    return marker.is_file() and marker.read_text() == key_src


def mark_complete(folder: str | os.PathLike, key_src: str) -> None:
    """Mark a checkpoint folder finished (written last, after the checkpoint itself)."""
    write_text(key_src, Path(folder) / COMPLETE)


def fresh_folder(folder: str | os.PathLike) -> Path:
    """Empty ``folder`` (deleting an old or unfinished checkpoint there)."""
    folder = Path(folder)
    if folder.exists():
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    return folder


def fit_agent(
    name: str,
    agent: Agent,
    train: HandoverDataset,
    cache_dir: str | os.PathLike | None = None,
    reuse: bool = True,
    progress: bool = False,
) -> tuple[Agent, bool]:
    """Fit ``agent`` on ``train``; learned baselines reuse a matching checkpoint under
    ``cache_dir``.

    Returns:
        ``(fitted agent, reused)`` where ``reused`` is True when a checkpoint was loaded.
    """
    cached = roster.entry(name).checkpoints
    if not cached or cache_dir is None:
        kwargs = {"progress": progress} if cached else {}
        return agent.fit(train, **kwargs), False
    folder, key_src = checkpoint_slot(name, agent, train, cache_dir)
    cls = type(agent)
    if reuse and is_complete(folder, key_src):
        try:
            return cls.load(folder), True  # type: ignore[attr-defined]
        except Exception as exc:  # an incompatible or damaged checkpoint is retrained, not trusted
            print(f"  checkpoint {folder} unusable ({exc}); retraining", flush=True)
    fresh_folder(folder)
    agent.fit(train, out_dir=folder, progress=progress)  # type: ignore[call-arg]
    agent.save(folder)  # type: ignore[attr-defined]
    mark_complete(folder, key_src)
    return agent, False
