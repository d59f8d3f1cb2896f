"""The closed-loop track: the scored agent and the reactive reference meet the same receivers.

Receivers (:mod:`.protocol`): the test-seed scripted walkers (walker-id, walker-ood, far-pass)
and the replays. Models: an agent that learns meets a replay of fold f with the model fitted on
the other folds of ``--data`` and the walkers with the fold-0 model, or, with ``--replay-data``,
every receiver with one model fitted on all of ``--data``
(:data:`handover_eval.receivers.FIT_ALL`). Built-in agents are the roster's
(:mod:`handover_eval.roster`); those that learn use the closed loop's fold models
(:func:`handover_eval.closedloop.models.fold_model`, Table I's checkpoint cache); a plug-in is
built by its factory and fitted once per worker and model fold. Each job is a chunk of receivers
of one agent; each receiver is run by the one closed-loop episode runner
(:func:`handover_eval.episodes.run_receiver`: this process's env of the track's Θ on the
:data:`.protocol.SENSING` profile, the seeded episode, its row), so rows do not depend on the
workers. A row is the closed loop's episode row reduced to :data:`.files.CLOSEDLOOP_COLUMNS`,
with the first failure and the event flags of :mod:`.outcomes`. Every episode, and a plug-in's
``fit``, runs under
:func:`.guard.agent_guard`, with the scored agent's time limit for every agent of the run (the
reference too); an agent stopped by it stops its later episodes in the same process at once.
"""

from __future__ import annotations

import json
import math
import os
import uuid
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from agents.base import Agent, Policy
from handover_env.config import HandoverParams
from handover_env.data.dataset import HandoverDataset
from handover_eval import roster
from handover_eval.backend import map_folds
from handover_eval.benchmark.guard import AgentError, agent_guard, forget_stopped
from handover_eval.benchmark.outcomes import EVENTS, events, first_failure
from handover_eval.benchmark.plugin import AgentSource, fit_plugin
from handover_eval.benchmark.protocol import ENV_ID, PERSON, SENSING, BenchReceiver
from handover_eval.closedloop.models import fold_model, prepare_models
from handover_eval.episodes import ENV_IDS, Setting, clear_envs, env_for, run_receiver
from handover_eval.methods import MethodOptions
from handover_eval.receivers import FIT_ALL

FLOATS = (
    "handover_time", "transfer_time", "reach_onset_time", "release_time", "release_force",
    "peak_contact_force", "body_contact_force", "penetration", "time_lost", "reach_distance",
    "arm_extended_time", "pull_force", "robot_jerk_rms", "delta_t", "delta_x",
)
CHUNK = 4
#: The track's env: DynamicHandover-v0 (:data:`.protocol.ENV_ID`) on the :data:`.protocol.SENSING`
#: profile.
ENV_KIND = next(kind for kind, env_id in ENV_IDS.items() if env_id == ENV_ID)
ENV_KWARGS = json.dumps({"sensing": SENSING, "person": PERSON})


@dataclass(frozen=True)
class BenchJob:
    """A chunk of receivers for one agent and one model fold (None: the agent learns nothing)."""

    token: str
    source: AgentSource
    receivers: tuple[BenchReceiver, ...]
    params: HandoverParams
    options: MethodOptions
    cache_dir: Path
    model_fold: int | None = None
    train_idx: np.ndarray | None = None
    hand_mode: str = "reach"
    time_limit: float | None = None

    @property
    def guard_key(self) -> tuple[str, str]:
        """The key a stop of this job's agent is remembered under (this run, this agent)."""
        return (self.token, self.source.name)


def learns(source: AgentSource) -> bool:
    """True for agents fitted on data (the roster's learning entries and every plug-in)."""
    return source.kind == "plugin" or roster.entry(source.target).learns


_PLUGINS: OrderedDict[tuple, Agent] = OrderedDict()
CACHE_SIZE = 4


def track_env(params: HandoverParams) -> Any:
    """This process's env of the closed-loop track at Θ ``params`` (:data:`ENV_KIND` on
    :data:`ENV_KWARGS`, the env :func:`run_bench_job`'s episodes run in)."""
    return env_for(ENV_KIND, params, ENV_KWARGS)


def clear_state() -> None:
    """Close this process's envs and forget its plug-in models."""
    clear_envs()
    _PLUGINS.clear()


def _agent(dataset: HandoverDataset, job: BenchJob) -> Policy:
    src = job.source
    if src.kind != "plugin":
        model = None
        if roster.entry(src.target).learns:
            assert job.model_fold is not None and job.train_idx is not None
            model, _ = fold_model(src.target, job.model_fold, dataset, job.train_idx,
                                  job.options, job.cache_dir, job.token)
        return roster.make_agent(src.target, job.params, job.options, model)
    assert job.model_fold is not None and job.train_idx is not None
    key = (job.token, src, job.model_fold)
    if key not in _PLUGINS:
        _PLUGINS[key] = fit_plugin(src, dataset.subset(job.train_idx))
        while len(_PLUGINS) > CACHE_SIZE:
            _PLUGINS.popitem(last=False)
    return roster.make_agent(_PLUGINS[key], job.params, job.options)


def bench_row(job: BenchJob, rec: BenchReceiver, row: dict) -> dict:
    """The benchmark's columns of one closed-loop episode row."""
    ev = events(row)
    ff = first_failure(str(row["outcome"]), ev)
    out: dict[str, Any] = {
        "agent": job.source.name,
        "set": rec.bench_set,
        "receiver": rec.spec.key,
        "seed": rec.spec.seed,
        "fold": "" if rec.spec.fold is None else rec.spec.fold,
        "model_fold": "" if job.model_fold is None else job.model_fold,
        "is_ood": rec.spec.is_ood,
        "pass_y": math.nan if rec.pass_y is None else rec.pass_y,
        "outcome": row["outcome"],
        "success": ff == "",
        "first_failure": ff,
        **{f"ev_{e}": ev[e] for e in EVENTS},
    }
    for c in FLOATS:
        v = row.get(c)
        out[c] = math.nan if v is None or isinstance(v, str) else float(v)
    out["sim_unstable"] = int(row.get("sim_unstable", 0))
    out["steps"] = int(row["steps"])
    return out


def run_bench_job(dataset: HandoverDataset, job: BenchJob) -> list[dict]:
    """Run ``job``'s episodes (in a worker or in-process); one benchmark row each.

    Each receiver runs through :func:`handover_eval.episodes.run_receiver` under
    :func:`.guard.agent_guard` (the job's time limit; a stopped episode closes this process's
    envs, so a later job builds fresh ones)."""
    name = job.source.name
    with agent_guard(name, "building and fitting", key=job.guard_key):
        agent = _agent(dataset, job)
    setting = Setting(name, job.params, ENV_KIND, ENV_KWARGS, job.hand_mode, job.model_fold)
    builtin = None if job.source.kind == "plugin" else roster.entry(job.source.target)
    rows = []
    for rec in job.receivers:
        spec = rec.spec
        if rec.kind != spec.set:
            raise ValueError(f"{rec.bench_set}/{spec.key}: receiver kind {rec.kind!r} is not "
                             f"its spec's set {spec.set!r}")
        walker = {"pass_y": rec.pass_y} if rec.pass_y is not None else None
        what = f"closed-loop episode {rec.bench_set}/{spec.key} (seed {spec.seed})"
        try:
            with agent_guard(name, what, job.time_limit, job.guard_key):
                row = run_receiver(setting, agent, spec, dataset, builtin, walker)
        except (AgentError, KeyboardInterrupt):
            clear_state()  # the env may have stopped mid-step: a later job builds a fresh one
            raise
        rows.append(bench_row(job, rec, row))
    return rows


def plan(
    sources: list[AgentSource],
    receivers: list[BenchReceiver],
    splits: dict[int, tuple[np.ndarray, np.ndarray]],
    params: HandoverParams,
    options: MethodOptions,
    cache_dir: Path,
    token: str,
) -> list[BenchJob]:
    """Chunks of :data:`CHUNK` receivers per agent and model fold, agents in ``sources`` order;
    every job has the time limit of the scored agent, ``sources[0]``."""
    fit_all = FIT_ALL in splits
    limit = sources[0].episode_limit_s if sources else None
    jobs = []
    for src in sources:
        groups: dict[tuple[str, int | None], list[BenchReceiver]] = {}
        for rec in receivers:
            fold = None
            if learns(src):
                fold = FIT_ALL if fit_all else (rec.spec.fold if rec.kind == "replay" else 0)
            groups.setdefault((rec.bench_set, fold), []).append(rec)
        for (_, fold), recs in groups.items():
            for i in range(0, len(recs), CHUNK):
                jobs.append(BenchJob(token, src, tuple(recs[i:i + CHUNK]), params, options,
                                     cache_dir, fold, None if fold is None else splits[fold][0],
                                     time_limit=limit))
    return jobs


def run_closedloop(
    sources: list[AgentSource],
    receivers: list[BenchReceiver],
    dataset: HandoverDataset,
    shared: HandoverDataset,
    splits: dict[int, tuple[np.ndarray, np.ndarray]],
    params: HandoverParams,
    options: MethodOptions,
    cache_dir: Path,
    progress: bool = True,
) -> list[dict]:
    """Every episode row of every agent of ``sources`` (module docstring).

    ``dataset`` is ``--data`` (the learned built-ins' checkpoints are prepared on it first);
    ``shared`` what the workers receive (``dataset``, then any ``--replay-data`` episodes).
    """
    token = f"{os.getpid()}-{uuid.uuid4().hex}"
    jobs = plan(sources, receivers, splits, params, options, cache_dir, token)
    needed = sorted({j.model_fold for j in jobs if j.model_fold is not None})
    learned = [s.target for s in sources
               if s.kind != "plugin" and roster.entry(s.target).checkpoints]
    if learned:
        prepare_models(dataset, learned, splits, needed, options, cache_dir, progress)
    try:
        import torch

        threads = torch.get_num_threads()
        torch.set_num_threads(1)  # as in a worker: rows must not depend on where they ran
    except ImportError:  # the [baselines] extra is optional for plug-ins and built-ins w/o torch
        torch, threads = None, 0
    try:
        results = map_folds(run_bench_job, shared, jobs, workers=options.workers,
                            progress=progress, desc="closed-loop track",
                            label=lambda j: f"{j.source.name} {j.receivers[0].bench_set}",
                            weight=lambda j: len(j.receivers), unit="episode")
    finally:
        if torch is not None:
            torch.set_num_threads(threads)
        clear_state()
        forget_stopped()
    return [row for rows in results for row in rows]
