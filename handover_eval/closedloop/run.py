"""``evaluate.py closed-loop``: every agent hands the bottle to the same simulated receivers.

The run, top to bottom (:func:`run_closed_loop`):

1. **Receivers** (:mod:`.receivers`): N seeded scripted ID and OOD walkers, and the
   replayed episodes of the chosen folds of Table I's split (default: the held-out half).
2. **Fold models** (:mod:`.models`): BC-MLP / ACT checkpoints of the needed folds are
   loaded from Table I's cache, or trained first (the training time is reported apart).
3. **Episodes**: chunks of a few receivers for one agent are run in ``workers`` spawned
   processes (:func:`handover_eval.backend.map_folds`, the dataset sent once per
   worker; :mod:`.worker`). Each worker makes its own envs (one per env kind and Θ,
   never pickled: :func:`handover_eval.episodes.env_for`) and fits or loads each fold model
   once. Every episode is seeded and every
   agent reset, so the rows do not depend on the number of workers or on which worker ran what.
4. **Rows** (:func:`handover_eval.episodes.episode_row`): the final ``info`` flattened, ``outcome``
   "timeout" for a TimeLimit truncation, for replays the recorded transfer and Δt, Δx, and the
   number of MuJoCo instabilities (auto-resets) in the episode.

With ``--replay-data`` (``replay`` below) the replays are every episode of that other dataset,
none of them in ``--data``, and every learning agent meets every receiver (walkers and replays)
with one model fitted on all of ``--data`` (model fold
:data:`~handover_eval.receivers.FIT_ALL`); the workers receive ``--data`` followed by
the replays (:func:`handover_eval.methods.with_test_data`).

The tables and the plot are made by :mod:`.report`, :mod:`.markdown` and :mod:`.plot`; the
files are written by :mod:`.output`.
"""

from __future__ import annotations

import json
import os
import time
import uuid
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from handover_env.config import HandoverParams
from handover_env.data.dataset import HandoverDataset
from handover_env.person.settings import switch_tokens
from handover_env.sensors.profiles import PROFILES
from handover_eval import roster
from handover_eval.backend import map_folds
from handover_eval.closedloop.models import ModelRecord, check_rl_receivers, prepare_models
from handover_eval.closedloop.worker import EpisodeJob, clear_worker_state, run_job
from handover_eval.methods import MethodOptions, with_test_data
from handover_eval.receivers import (
    FIT_ALL,
    SETS,
    ReceiverSpec,
    fold_of,
    held_out_folds,
    other_replays,
    recording_paths,
    replays,
    walkers,
)


@dataclass(frozen=True)
class ClosedLoopEvalConfig:
    """What ``evaluate.py closed-loop`` runs.

    Args:
        agents: agent names (default :func:`handover_eval.roster.compared_agents`).
        sets: receiver sets among "id", "ood", "replay".
        walkers: scripted walkers per set (ID, OOD).
        replay_folds: folds whose episodes are replayed (None: the held-out half).
        replays_per_fold: at most this many replays of each fold, spread evenly (None: all).
        hand_mode: "reach" (modelled hand) or "recorded" (the recorded arm) for replays.
        params: Θ = K, B, t_f, f_r.
        folds, seed: Table I's stratified split.
        walker_fold: the fold whose model the learning agents use on scripted walkers.
        chunk: receivers per worker job.
        workers: processes running episodes (1 = in this process).
        sensing: the env's sensor profile ("paper", "ideal", "randomized"; docs/sensing.md).
        person: the person switches set apart from their defaults, as tokens ``NAME``,
            ``NAME=on`` or ``NAME=off`` (:func:`handover_env.person.settings.switch_tokens`; ()
            for the default person).
        reference: the agent every other is paired against (``closed_loop_paired.csv``; no
            pairs when it is not among ``agents``).
    """

    agents: tuple[str, ...] = field(default_factory=roster.compared_agents)
    sets: tuple[str, ...] = SETS
    walkers: int = 50
    replay_folds: tuple[int, ...] | None = None
    replays_per_fold: int | None = None
    hand_mode: str = "reach"
    params: HandoverParams = field(default_factory=HandoverParams)
    folds: int = 10
    seed: int = 0
    walker_fold: int = 0
    chunk: int = 4
    workers: int = 2
    sensing: str = "paper"
    person: tuple[str, ...] = ()
    reference: str = "reactive"

    def __post_init__(self) -> None:
        object.__setattr__(self, "agents", tuple(roster.check_agents(list(self.agents))))
        if self.reference != "reactive" and self.reference not in self.agents:
            raise ValueError(f"--reference {self.reference!r} is not among --agents "
                             f"{list(self.agents)}")
        bad = [s for s in self.sets if s not in SETS]
        if bad or not self.sets:
            raise ValueError(f"unknown receiver set(s) {bad}; choose from {list(SETS)}")
        if self.hand_mode not in ("reach", "recorded"):
            raise ValueError(f"--hand-mode must be 'reach' or 'recorded', got {self.hand_mode!r}")
        if self.walkers < 0 or (self.replays_per_fold is not None and self.replays_per_fold < 1):
            raise ValueError("--walkers must be >= 0 and --replays-per-fold >= 1")
        if self.workers < 1 or self.chunk < 1:
            raise ValueError(f"workers must be >= 1, got {self.workers}")
        if self.sensing not in PROFILES:
            raise ValueError(f"--sensing must be one of {list(PROFILES)}, got {self.sensing!r}")
        if not 0 <= self.walker_fold < self.folds:
            raise ValueError(f"walker fold {self.walker_fold} is not a fold of {self.folds}")
        switch_tokens(self.person)  # one error naming every bad token

    def env_kwargs(self, **more: object) -> str:
        """The ``gym.make`` keywords of this run's env as JSON: the sensing profile, the person
        switches set apart from their defaults (none for the default person) and ``more``."""
        kwargs: dict[str, object] = {"sensing": self.sensing, **more}
        if self.person:
            kwargs["person"] = switch_tokens(self.person)
        return json.dumps(kwargs, sort_keys=True)


def plan_jobs(
    config: ClosedLoopEvalConfig,
    receivers: list[ReceiverSpec],
    splits: Mapping[int, tuple[np.ndarray, np.ndarray]] | list[tuple[np.ndarray, np.ndarray]],
    options: MethodOptions,
    cache_dir: Path,
    token: str,
) -> list[EpisodeJob]:
    """Chunks of receivers per agent; learning agents get the fold model each receiver needs.

    An agent of the roster's ``replays_only`` (giver replay) meets replays only. Jobs are
    ordered by model fold (so a worker's fold models are fitted once) and, within that, by
    agent in roster order. ``splits`` maps a model fold to its (train,
    test) indices; a replay without a fold (``--replay-data``) and every walker then meet
    :data:`FIT_ALL`, the model of all of ``--data``.
    """
    fit_all = FIT_ALL in (splits if isinstance(splits, Mapping) else {})
    jobs = []
    for agent in config.agents:
        groups: dict[tuple[str, int | None], list[ReceiverSpec]] = {}
        entry = roster.entry(agent)
        for spec in receivers:
            if entry.replays_only and spec.set != "replay":
                continue
            if not entry.learns:
                fold = None
            elif fit_all:
                fold = FIT_ALL
            else:
                fold = spec.fold if spec.set == "replay" else config.walker_fold
            groups.setdefault((spec.set, fold), []).append(spec)
        for (_, fold), specs in groups.items():
            for i in range(0, len(specs), config.chunk):
                jobs.append(
                    EpisodeJob(
                        token,
                        agent,
                        tuple(specs[i : i + config.chunk]),
                        config.params,
                        config.hand_mode,
                        options,
                        cache_dir,
                        fold,
                        None if fold is None else splits[fold][0],
                        env_kwargs=config.env_kwargs(),
                    )
                )
    return sorted(
        jobs, key=lambda j: (-1 if j.model_fold is None else j.model_fold, roster.rank(j.agent))
    )


def run_jobs(
    dataset: HandoverDataset,
    jobs: list[EpisodeJob],
    workers: int,
    progress: bool,
    desc: str = "episodes",
) -> tuple[list[dict], list[ModelRecord]]:
    """All jobs' rows (in job order) and model records, in ``workers`` processes (or in-process)."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # as in a worker: results must not depend on where an episode ran
    try:
        results = map_folds(
            run_job,
            dataset,
            jobs,
            workers=workers,
            progress=progress,
            desc=desc,
            label=lambda j: f"{j.agent} {j.receivers[0].set}",
            weight=lambda j: len(j.receivers),
            unit="episode",
        )
    finally:
        torch.set_num_threads(threads)
        clear_worker_state()
    return [r for rows, _ in results for r in rows], [f for _, fits in results for f in fits]


@dataclass
class ClosedLoopRun:
    """What :func:`run_closed_loop` returns: the rows, the models and the timings."""

    rows: list[dict]
    receivers: list[ReceiverSpec]
    models: list[ModelRecord]
    prepare_seconds: float
    episode_seconds: float
    replay_folds: tuple[int, ...]


def build_receivers(
    config: ClosedLoopEvalConfig,
    dataset: HandoverDataset,
    data: str | None,
    replay: HandoverDataset | None = None,
    replay_data: str | None = None,
) -> tuple[list[ReceiverSpec], tuple[int, ...]]:
    """The walkers and replays of ``config`` (replays of recordings when ``data`` is a folder).

    With ``replay`` (loaded from ``replay_data``) the replays are every episode of it
    (``config.replays_per_fold`` caps their number), indexed after ``dataset``'s episodes.
    """
    specs = walkers(config.walkers, tuple(s for s in config.sets if s != "replay"))
    folds: tuple[int, ...] = ()
    if "replay" in config.sets and replay is not None:
        paths = recording_paths(replay_data, replay)
        if config.hand_mode == "recorded" and not paths:
            raise ValueError(
                "--hand-mode recorded needs recordings with the skeleton: "
                "--replay-data a public-dataset folder (whole_motions/)"
            )
        specs += other_replays(replay, len(dataset), paths, config.replays_per_fold)
    elif "replay" in config.sets:
        fold_ids = fold_of(dataset, config.folds, config.seed)
        folds = (
            held_out_folds(config.folds)
            if config.replay_folds is None
            else tuple(config.replay_folds)
        )
        paths = recording_paths(data, dataset)
        if config.hand_mode == "recorded" and not paths:
            raise ValueError(
                "--hand-mode recorded needs recordings with the skeleton: "
                "--data a public-dataset folder (whole_motions/)"
            )
        specs += replays(dataset, fold_ids, folds, paths, config.replays_per_fold)
    if not specs:
        raise ValueError("no receivers: use --walkers > 0 or the replay set")
    return specs, folds


def run_closed_loop(
    config: ClosedLoopEvalConfig,
    dataset: HandoverDataset,
    data: str | None,
    options: MethodOptions,
    cache_dir: Path,
    progress: bool = True,
    replay: HandoverDataset | None = None,
    replay_data: str | None = None,
) -> ClosedLoopRun:
    """Receivers, fold models, then every agent's episodes (module docstring).

    ``replay`` (loaded from ``replay_data``): score on every episode of it, with the models
    fitted on all of ``dataset`` (``--replay-data``).
    """
    specs, replay_folds = build_receivers(config, dataset, data, replay, replay_data)
    check_rl_receivers(config.agents, specs, options, cache_dir)
    splits: dict[int, tuple[np.ndarray, np.ndarray]]
    if replay is None:
        splits = dict(enumerate(dataset.stratified_kfold(config.folds, config.seed)))
        walker_folds = {config.walker_fold} if any(s.set != "replay" for s in specs) else set()
        needed = sorted(walker_folds | {s.fold for s in specs if s.fold is not None})
        shared = dataset
    else:
        n = len(dataset)
        splits = {FIT_ALL: (np.arange(n, dtype=np.int64), np.arange(n, n + len(replay)))}
        needed = [FIT_ALL]
        shared = with_test_data(dataset, replay)
    token = f"{os.getpid()}-{uuid.uuid4().hex}"
    jobs = plan_jobs(config, specs, splits, options, cache_dir, token)
    if not jobs:
        raise ValueError("nothing to run: giver-replay meets replays only (add --sets replay)")
    t0 = time.perf_counter()
    models = prepare_models(
        dataset, list(config.agents), splits, needed, options, cache_dir, progress
    )
    prepared = time.perf_counter() - t0
    t0 = time.perf_counter()
    rows, fits = run_jobs(shared, jobs, config.workers, progress)
    return ClosedLoopRun(
        rows, specs, models + fits, prepared, time.perf_counter() - t0, replay_folds
    )
