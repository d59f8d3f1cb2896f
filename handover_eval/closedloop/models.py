"""The models of the closed-loop agents that learn: Table I's fold models, the RL policies, and
the per-worker model cache.

The agents that learn from data (the roster's ``learns`` entries: ours, iaal, bc-mlp, act) use
Table I's fold models: a replay of fold f runs with the model trained on the other folds (Table
I's fold-f training set); the scripted walkers use the fold-0 model. BC-MLP and ACT (the
``checkpoints`` entries) are loaded from Table I's checkpoint cache
(:func:`handover_eval.methods.fit_agent`; :func:`prepare_models` trains the missing ones first,
ACT through :func:`handover_eval.act_folds.pretrain_act`); ours and IAAL are fitted in each
worker (about a second each), at most once per worker and fold.

The RL agents (``rl-residual``, ``rl-scratch``: the roster's ``rl_form`` entries, policies of
``train.py rl``) are loaded from ``--rl-checkpoint`` folders by their form, or with ``--quick``
trained for a few hundred steps into the cache; their model record's fold is -1, the folds they
trained on are in the checkpoint, and they refuse any receiver they trained on
(:func:`check_rl_receivers`).
"""

from __future__ import annotations

import time
from collections import OrderedDict
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from agents.base import Agent, Policy
from handover_env.data.dataset import HandoverDataset
from handover_eval import roster
from handover_eval.methods import MethodOptions, build_agent, checkpoint_slot, fit_agent
from handover_eval.methods import is_complete as checkpoint_complete

MODEL_CACHE_SIZE = 4  # fitted fold models kept per worker (~150 MB each for ours / IAAL)


def rl_forms(rl_checkpoints: tuple[str, ...]) -> frozenset[str]:
    """The policy forms of the ``--rl-checkpoint`` folders."""
    if not rl_checkpoints:
        return frozenset()
    from baselines.rl.files import read_record

    return frozenset(read_record(f)[1].form for f in rl_checkpoints)



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
    """Make sure the checkpoints of ``folds_needed`` exist for the agents among ``agents`` that
    are trained into the checkpoint cache (BC-MLP, ACT), training the missing ones.

    ACT is trained as Table I trains it (one LeRobot export, ``options.workers`` processes);
    the others fold by fold (:func:`handover_eval.backend.map_folds`). Returns one record per
    (learned agent, fold), the agent as the closed-loop files spell it.
    """
    from handover_eval.backend import map_folds

    records: list[ModelRecord] = []
    cached = [e for e in dict.fromkeys(roster.entry(a) for a in agents) if e.checkpoints]
    if any(e.name == "act" for e in cached):
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
    for e in (e for e in cached if e.name != "act"):
        todo = []
        for f in folds_needed:
            train = dataset.subset(splits[f][0])
            folder, key = checkpoint_slot(e.name, build_agent(e.name, options), train, cache_dir)
            if checkpoint_complete(folder, key):
                records.append(ModelRecord(e.closedloop_name, f, "checkpoint", 0.0, len(train)))
            else:
                todo.append(_FitJob(e.name, f, splits[f][0], options, cache_dir))
        done = (
            map_folds(
                _fit_fold,
                dataset,
                todo,
                workers=options.workers,
                progress=progress,
                desc=f"{e.closedloop_name} folds",
                label=lambda job: f"fold {job.fold}",
            )
            if todo
            else []
        )
        records += [
            ModelRecord(e.closedloop_name, job.fold, "trained", s, len(job.train_idx))
            for job, s in zip(todo, done, strict=True)
        ]
    records += prepare_rl(agents, options, cache_dir, progress)
    return sorted(records, key=lambda r: (r.agent, r.fold))


# ------------------------------------------------------------------------ RL policies
def rl_checkpoint(agent: str, options: MethodOptions, cache_dir: Path) -> Path:
    """The checkpoint folder of an RL agent: the ``--rl-checkpoint`` of its form, or with
    ``--quick`` the cache's quick one; a ValueError saying how to get one otherwise."""
    from baselines.rl.files import read_record

    form = roster.entry(agent).rl_form
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
    for agent in (a for a in agents if roster.entry(a).rl_form):
        folder = rl_checkpoint(agent, options, cache_dir)
        t0, how = time.perf_counter(), "checkpoint"
        if options.quick and folder.name.startswith("rl-quick-"):
            want = quick_rl_config(roster.entry(agent).rl_form, options.seed)
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

    for agent in (a for a in agents if roster.entry(a).rl_form):
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
             token: str) -> tuple[Policy, ModelRecord | None]:
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
class _FitJob:
    method: str
    fold: int
    train_idx: np.ndarray
    options: MethodOptions
    cache_dir: Path


def _fit_fold(dataset: HandoverDataset, job: _FitJob) -> float:
    """Train one fold checkpoint into the cache (in a :func:`.backend.map_folds` worker);
    seconds."""
    t0 = time.perf_counter()
    fit_agent(job.method, build_agent(job.method, job.options), dataset.subset(job.train_idx),
              job.cache_dir)
    return time.perf_counter() - t0


# ------------------------------------------------------------------------ per-worker model cache
_MODELS: OrderedDict[tuple, Policy] = OrderedDict()
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
    e = roster.entry(agent)
    key = (e.name, fold)
    if key in _MODELS:
        _MODELS.move_to_end(key)
        return _MODELS[key], None  # type: ignore[return-value]
    t0 = time.perf_counter()
    train = dataset.subset(train_idx)
    model, reused = fit_agent(e.name, build_agent(e.name, options), train, cache_dir, reuse=True)
    how = "checkpoint" if reused else ("trained" if e.checkpoints else "fitted in worker")
    record = ModelRecord(agent, fold, how, time.perf_counter() - t0, len(train))
    _MODELS[key] = model
    while len(_MODELS) > MODEL_CACHE_SIZE:
        _MODELS.popitem(last=False)
    return model, record


def model_for(agent: str, dataset: HandoverDataset, model_fold: int | None,
              train_idx: np.ndarray | None, options: MethodOptions, cache_dir: Path,
              token: str) -> tuple[Policy | None, ModelRecord | None]:
    """What :func:`handover_eval.roster.make_agent` needs for ``agent``: its fold model (an agent
    that learns), its policy (an RL agent), or None; and the record when it was fitted or
    loaded just now."""
    e = roster.entry(agent)
    if e.learns:
        if model_fold is None or train_idx is None:
            raise ValueError(f"{agent} learns: its job needs a model fold and training indices")
        return fold_model(agent, model_fold, dataset, train_idx, options, cache_dir, token)
    if e.rl_form:
        return rl_model(agent, dataset, options, cache_dir, token)
    return None, None
