"""The agents of the closed-loop evaluation, their fold models, and the per-worker model cache.

Names (``--agents``): ``reactive``, ``static`` (in ``StaticHandover-v0``), ``ours`` (the SPGP
planner), ``iaal``, ``bc-mlp``, ``act``, ``giver-replay`` (replays only: the recorded giver's
object path), ``null`` (holds the object at the ready pose), ``lagging`` (the reactive agent
acting 0.5 s late), ``rl-residual`` and ``rl-scratch`` (RL policies of ``train.py rl``, loaded
from ``--rl-checkpoint`` folders by their form, or with ``--quick`` trained for a few hundred
steps into the cache; their model record's fold is -1, the folds they trained on are in the
checkpoint, and they refuse any receiver they trained on: :func:`check_rl_receivers`).

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
    "rl-residual",
    "rl-scratch",
)
#: closed-loop RL agent -> its policy form (``--rl-checkpoint``; ``--quick`` trains a tiny one).
RL_AGENTS: dict[str, str] = {"rl-residual": "residual", "rl-scratch": "scratch"}
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
    "rl-residual": "RL residual",
    "rl-scratch": "RL from scratch",
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


def default_agents(quick: bool, rl_checkpoints: tuple[str, ...] = ()) -> list[str]:
    """``--agents``' default: every agent; an RL one only with ``quick`` (trained on the spot) or
    an ``rl_checkpoints`` folder of its form."""
    forms = set()
    if rl_checkpoints:
        from baselines.rl.files import read_record

        forms = {read_record(f)[1].form for f in rl_checkpoints}
    return [a for a in AGENTS if a not in RL_AGENTS or quick or RL_AGENTS[a] in forms]


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
    records += prepare_rl(agents, options, cache_dir, progress)
    return sorted(records, key=lambda r: (r.agent, r.fold))


# ------------------------------------------------------------------------ RL policies
def rl_checkpoint(agent: str, options: MethodOptions, cache_dir: Path) -> Path:
    """The checkpoint folder of an RL agent: the ``--rl-checkpoint`` of its form, or with
    ``--quick`` the cache's quick one; a ValueError saying how to get one otherwise."""
    from baselines.rl.files import read_record

    form = RL_AGENTS[agent]
    for folder in options.rl_checkpoints:
        if read_record(folder)[1].form == form:
            return Path(folder)
    if options.quick:
        return Path(cache_dir) / f"rl-quick-{form}"
    raise ValueError(f"{agent} needs --rl-checkpoint DIR holding a {form} policy (train one with "
                     f"python train.py rl --form {form} --out DIR)")


def quick_rl_config(form: str, seed: int):
    """The tiny RL run of ``--quick`` (train.py rl --quick's budget, walkers only)."""
    from baselines.rl.config import QUICK, RLConfig

    return RLConfig(form=form, base="reactive" if form == "residual" else "", seed=seed, **QUICK)


def prepare_rl(agents: list[str], options: MethodOptions, cache_dir: Path,
               progress: bool) -> list[ModelRecord]:
    """Check each RL agent's checkpoint loads; with ``--quick`` train the missing quick ones."""
    from dataclasses import asdict

    from baselines.checkpoint_io import CheckpointError, remove_checkpoint
    from baselines.rl.files import read_checkpoint, read_record
    from baselines.rl.train import train_policy

    records = []
    for agent in (a for a in agents if a in RL_AGENTS):
        folder = rl_checkpoint(agent, options, cache_dir)
        t0, how = time.perf_counter(), "checkpoint"
        if options.quick and folder.name.startswith("rl-quick-"):
            want = quick_rl_config(RL_AGENTS[agent], options.seed)
            try:
                fresh = asdict(read_record(folder)[1]) != asdict(want)
            except CheckpointError:
                fresh = True
            if fresh:
                if folder.is_dir():
                    remove_checkpoint(folder, "rl")
                train_policy(want, folder, progress=progress)
                how = "trained"
        record = read_checkpoint(folder).record
        records.append(ModelRecord(agent, -1, how, time.perf_counter() - t0,
                                   int(record["training"].get("episodes", 0))))
    return records


def check_rl_receivers(agents: tuple[str, ...], receivers: list, options: MethodOptions,
                       cache_dir: Path) -> None:
    """A ValueError before any episode runs if an RL agent would meet a receiver it trained on
    (a replayed recording of its training folds, a walker seed of its training range)."""
    from baselines.rl.config import TRAIN_SEED_START
    from baselines.rl.files import read_record

    for agent in (a for a in agents if a in RL_AGENTS):
        folder = rl_checkpoint(agent, options, cache_dir)
        if not folder.is_dir():  # a --quick one not trained yet: walkers only, none of these
            continue
        trained = set(read_record(folder)[0]["receivers"]["replay_ids"])
        seen = sorted(s.key for s in receivers if s.set == "replay" and s.key in trained)
        high = sorted(s.key for s in receivers if s.set != "replay" and s.seed >= TRAIN_SEED_START)
        if seen or high:
            raise ValueError(
                f"{agent} ({folder}) trained on {len(seen) + len(high)} of these receivers "
                f"({', '.join((seen + high)[:3])}...): score it on held-out folds only "
                "(--replay-folds of the held-out half, the default)")


def rl_model(agent: str, dataset: HandoverDataset, options: MethodOptions, cache_dir: Path,
             token: str) -> tuple[Agent, ModelRecord | None]:
    """The RL agent's policy, loaded once per worker (a residual on ``ours`` refits its SPGP
    base on the training-fold episodes the checkpoint names)."""
    from baselines.rl.agent import RLAgent
    from baselines.rl.files import read_record

    if token != _TOKEN[0]:
        clear_models()
        _TOKEN[0] = token
    key = (agent, -1)
    if key in _MODELS:
        _MODELS.move_to_end(key)
        return _MODELS[key], None
    t0 = time.perf_counter()
    folder = rl_checkpoint(agent, options, cache_dir)
    saved, config = read_record(folder)
    fit = None
    if config.form == "residual" and config.base == "ours":
        if saved["receivers"]["dataset"] != dataset.name:
            raise ValueError(f"{agent} ({folder}): its SPGP base was fitted on "
                             f"{saved['receivers']['dataset']}; evaluate with that --data")
        ids = set(saved["receivers"]["base_fit_ids"])
        fit = dataset.subset(np.array([i for i, ep in enumerate(dataset) if ep.source_id in ids],
                                      dtype=np.int64))
    model = RLAgent.load(folder, fit_data=fit)
    _MODELS[key] = model
    while len(_MODELS) > MODEL_CACHE_SIZE:
        _MODELS.popitem(last=False)
    return model, ModelRecord(agent, -1, "loaded in worker", time.perf_counter() - t0, 0)


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
    if name in LEARNING or name in RL_AGENTS:
        assert model is not None, f"{name} needs its fold model or policy"
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
