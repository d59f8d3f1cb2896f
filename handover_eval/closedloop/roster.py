"""The agents of the closed-loop evaluation, their fold models, and the per-worker model cache.

Names (``--agents``): ``reactive``, ``static`` (in ``StaticHandover-v0``), ``ours`` (the SPGP
planner), ``iaal``, ``bc-mlp``, ``act``, ``giver-replay`` (replays only: the recorded giver's
object path), ``null`` (holds the object at the ready pose) and ``lagging`` (the reactive agent
acting 0.5 s late).

The agents that learn from data (ours, iaal, bc-mlp, act) use Table I's fold models: a replay of
fold f runs with the model trained on the other folds (Table I's fold-f training set); the
scripted walkers use the fold-0 model. BC-MLP and ACT are loaded from Table I's checkpoint cache
(:func:`handover_eval.methods.fit_agent`; :func:`prepare_models` trains the missing
ones first, ACT through :func:`handover_eval.act_folds.pretrain_act`); ours and IAAL
are fitted in each worker (about a second each), at most once per worker and fold.
Θ: t_f goes to the agent (``agent.params``), K, B and f_r to the env.

Besides the names, :func:`make_agent` accepts any :class:`agents.base.Agent` object (an external
agent, e.g. one loaded by ``evaluate.py benchmark --agent``): it gets Θ's t_f when it has a
``params`` attribute, as the built-in predictive agents do.
"""

from __future__ import annotations

import time
from collections import OrderedDict
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from agents.base import Agent
from handover_env.config import HandoverParams
from handover_env.data.dataset import HandoverDataset
from handover_eval.methods import MethodOptions, build_agent, checkpoint_slot, fit_agent
from handover_eval.methods import is_complete as checkpoint_complete

AGENTS: tuple[str, ...] = (
    "reactive",
    "static",
    "ours",
    "iaal",
    "bc-mlp",
    "act",
    "giver-replay",
    "null",
    "lagging",
)
#: closed-loop agent name -> Table I method name, for the agents that learn from data.
LEARNING: dict[str, str] = {"ours": "ours", "iaal": "iaal", "bc-mlp": "bc_mlp", "act": "act"}
ALIASES = {"bc_mlp": "bc-mlp", "giver_replay": "giver-replay"}
LAG_SECONDS = 0.5
LABELS = {
    "reactive": "Reactive",
    "static": "Static (Meng et al.)",
    "ours": "Ours (SPGP)",
    "iaal": "IAAL",
    "bc-mlp": "BC-MLP",
    "act": "ACT",
    "giver-replay": "Giver replay (ref.)",
    "null": "Null (holds still)",
    "lagging": "Lagging (reactive +0.5 s)",
}
MODEL_CACHE_SIZE = 4  # fitted fold models kept per worker (~150 MB each for ours / IAAL)


def check_agents(names: list[str] | tuple[str, ...]) -> list[str]:
    """Validate agent names (accepting ``bc_mlp``); a clear ValueError naming the unknown ones."""
    names = [ALIASES.get(n, n) for n in names]
    unknown = [n for n in names if n not in AGENTS]
    if unknown:
        raise ValueError(f"unknown agent(s) {unknown}; choose from {list(AGENTS)}")
    if not names:
        raise ValueError(f"no agent selected; choose from {list(AGENTS)}")
    return list(dict.fromkeys(names))


def env_kind(agent: str) -> str:
    """``"static"`` for the static baseline (StaticHandover-v0), else ``"dynamic"``."""
    return "static" if agent == "static" else "dynamic"


@dataclass(frozen=True)
class ModelRecord:
    """How one fold model came to be: trained or loaded here, and how long that took."""

    agent: str
    fold: int
    how: str  # "trained", "checkpoint", "fitted in worker"
    seconds: float
    n_train: int


def prepare_models(
    dataset: HandoverDataset,
    agents: list[str],
    splits: Mapping[int, tuple[np.ndarray, np.ndarray]] | list[tuple[np.ndarray, np.ndarray]],
    folds_needed: list[int],
    options: MethodOptions,
    cache_dir: Path,
    progress: bool = True,
) -> list[ModelRecord]:
    """Make sure the BC-MLP / ACT checkpoints of ``folds_needed`` exist (training the missing ones).

    ACT is trained as Table I trains it (one LeRobot export, ``options.workers`` processes);
    BC-MLP fold by fold in this process. Returns one record per (learned agent, fold).
    """
    from handover_eval.backend import map_folds

    records: list[ModelRecord] = []
    if "act" in agents:
        from handover_eval.act_folds import pretrain_act

        runs = pretrain_act(
            dataset,
            [splits[f][0] for f in folds_needed],
            options,
            cache_dir,
            reuse=True,
            labels=[f"fold {f}" for f in folds_needed],
            progress=progress,
        )
        records += [
            ModelRecord(
                "act",
                f,
                "trained" if run.trained else "checkpoint",
                run.fit_seconds if run.trained and run.fit_seconds else 0.0,
                len(splits[f][0]),
            )
            for f, run in zip(folds_needed, runs, strict=True)
        ]
    if "bc-mlp" in agents:
        todo = []
        for f in folds_needed:
            train = dataset.subset(splits[f][0])
            folder, key = checkpoint_slot(
                "bc_mlp", build_agent("bc_mlp", options), train, cache_dir
            )
            if checkpoint_complete(folder, key):
                records.append(ModelRecord("bc-mlp", f, "checkpoint", 0.0, len(train)))
            else:
                todo.append(_BCJob(f, splits[f][0], options, cache_dir))
        done = (
            map_folds(
                _fit_bc,
                dataset,
                todo,
                workers=options.workers,
                progress=progress,
                desc="bc-mlp folds",
                label=lambda job: f"fold {job.fold}",
            )
            if todo
            else []
        )
        records += [
            ModelRecord("bc-mlp", job.fold, "trained", s, len(job.train_idx))
            for job, s in zip(todo, done, strict=True)
        ]
    return sorted(records, key=lambda r: (r.agent, r.fold))


@dataclass(frozen=True)
class _BCJob:
    fold: int
    train_idx: np.ndarray
    options: MethodOptions
    cache_dir: Path


def _fit_bc(dataset: HandoverDataset, job: _BCJob) -> float:
    """Train one BC-MLP fold checkpoint into the cache (in a :func:`.backend.map_folds` worker);
    seconds."""
    t0 = time.perf_counter()
    fit_agent(
        "bc_mlp", build_agent("bc_mlp", job.options), dataset.subset(job.train_idx), job.cache_dir
    )
    return time.perf_counter() - t0


# ------------------------------------------------------------------------ per-worker model cache
_MODELS: OrderedDict[tuple, Agent] = OrderedDict()
_TOKEN: list[str] = [""]


def clear_models() -> None:
    """Forget the fitted models (between runs; the workers' copies die with the pool)."""
    _MODELS.clear()
    _TOKEN[0] = ""


def fold_model(
    agent: str,
    fold: int,
    dataset: HandoverDataset,
    train_idx: np.ndarray,
    options: MethodOptions,
    cache_dir: Path,
    token: str,
) -> tuple[Agent, ModelRecord | None]:
    """The fitted model of a learning agent for ``fold``, fitted or loaded once per worker.

    ``token`` identifies the run: a new token empties the cache. Returns the model and, when it
    was fitted or loaded just now, a record of that.
    """
    if token != _TOKEN[0]:
        clear_models()
        _TOKEN[0] = token
    key = (agent, fold)
    if key in _MODELS:
        _MODELS.move_to_end(key)
        return _MODELS[key], None
    method = LEARNING[agent]
    t0 = time.perf_counter()
    train = dataset.subset(train_idx)
    model, reused = fit_agent(method, build_agent(method, options), train, cache_dir, reuse=True)
    how = (
        "checkpoint"
        if reused
        else ("fitted in worker" if method in ("ours", "iaal") else "trained")
    )
    record = ModelRecord(agent, fold, how, time.perf_counter() - t0, len(train))
    _MODELS[key] = model
    while len(_MODELS) > MODEL_CACHE_SIZE:
        _MODELS.popitem(last=False)
    return model, record


def make_agent(name: str | Agent, params: HandoverParams, model: Agent | None = None) -> Agent:
    """A ready agent for one chunk of episodes (Θ's t_f set on it; K, B, f_r are the env's).

    ``name`` is a built-in name, or an external :class:`Agent` object, returned as it is with
    ``params`` set when it has that attribute (a :class:`agents.predictive.PredictiveAgent`).
    """
    if isinstance(name, Agent):
        if isinstance(getattr(name, "params", None), HandoverParams):
            name.params = params  # type: ignore[attr-defined]
        return name
    if name in LEARNING:
        assert model is not None, f"{name} needs its fold model"
        model.params = params  # type: ignore[attr-defined]
        return model
    if name == "reactive":
        from agents.reactive import ReactiveAgent

        return ReactiveAgent(params)
    if name == "lagging":
        from agents.null import DelayedAgent
        from agents.reactive import ReactiveAgent

        return DelayedAgent(ReactiveAgent(params), LAG_SECONDS)
    if name == "null":
        from agents.null import NullAgent

        return NullAgent()
    if name == "static":
        from agents.static import StaticAgent

        return StaticAgent()
    if name == "giver-replay":
        from agents.giver_replay import GiverReplayAgent

        return GiverReplayAgent(params=params)
    raise ValueError(f"unknown agent {name!r}")
