"""The closed-loop track: the scored agent and the reactive reference meet the same receivers.

Receivers (:mod:`.protocol`): the test-seed scripted walkers (walker-id, walker-ood, far-pass)
and the replays. Models: an agent that learns meets a replay of fold f with the model fitted on
the other folds of ``--data`` and the walkers with the fold-0 model, or, with ``--replay-data``,
every receiver with one model fitted on all of ``--data``
(:data:`handover_eval.closedloop.receivers.FIT_ALL`). Built-in learning agents use the closed
loop's fold models (:func:`handover_eval.closedloop.roster.fold_model`, Table I's checkpoint
cache); a plug-in is built by its factory and fitted once per worker and model fold. Each job is
a chunk of receivers of one agent; its episodes are seeded and the agent reset, so rows do not
depend on the workers. A row is the closed loop's episode row
(:func:`handover_eval.closedloop.worker.episode_row`) reduced to
:data:`.files.CLOSEDLOOP_COLUMNS`, with the first failure and the event flags of
:mod:`.outcomes`. Every episode, and a plug-in's ``fit``, runs under
:func:`.guard.agent_guard`, with the scored agent's time limit for every agent of the run (the
reference too); an agent stopped by it stops its later episodes in the same process at once.
"""

from __future__ import annotations

import math
import os
import time
import uuid
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from agents.base import Agent
from handover_env.config import HandoverParams
from handover_env.data.dataset import HandoverDataset
from handover_eval.backend import map_folds
from handover_eval.benchmark.guard import AgentError, agent_guard, forget_stopped
from handover_eval.benchmark.outcomes import EVENTS, events, first_failure
from handover_eval.benchmark.plugin import ROSTER_NAME, AgentSource, fit_plugin
from handover_eval.benchmark.protocol import ENV_ID, SENSING, BenchReceiver
from handover_eval.closedloop.receivers import FIT_ALL, replay_source
from handover_eval.closedloop.roster import fold_model, make_agent, prepare_models
from handover_eval.closedloop.worker import EpisodeJob, episode_row, instabilities
from handover_eval.methods import MethodOptions, build_agent

FLOATS = (
    "handover_time", "transfer_time", "reach_onset_time", "release_time", "release_force",
    "peak_contact_force", "body_contact_force", "penetration", "time_lost", "reach_distance",
    "arm_extended_time", "pull_force", "robot_jerk_rms", "delta_t", "delta_x",
)
CHUNK = 4


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
    """True for agents fitted on data (built-in learned methods and every plug-in)."""
    return source.kind == "plugin" or (source.kind == "method" and source.target != "cv")


_ENVS: OrderedDict[tuple, Any] = OrderedDict()
_PLUGINS: OrderedDict[tuple, Agent] = OrderedDict()
CACHE_SIZE = 4


def track_env(params: HandoverParams):
    """This process's env of the closed-loop track at Θ ``params`` (cached, on :data:`SENSING`)."""
    key = params.as_array()
    if key not in _ENVS:
        import gymnasium as gym

        import handover_env  # noqa: F401 - registers the envs

        _ENVS[key] = gym.make(ENV_ID, stiffness=params.stiffness, damping=params.damping,
                              forecast_time=params.forecast_time,
                              release_force=params.release_force, sensing=SENSING)
        while len(_ENVS) > CACHE_SIZE:
            _ENVS.popitem(last=False)[1].close()
    return _ENVS[key]


def clear_state() -> None:
    """Close this process's envs and forget its plug-in models."""
    while _ENVS:
        _ENVS.popitem()[1].close()
    _PLUGINS.clear()


def _agent(dataset: HandoverDataset, job: BenchJob) -> Agent:
    src = job.source
    if src.kind == "roster":
        return make_agent(src.target, job.params)
    if src.kind == "method" and src.target == "cv":
        return make_agent(build_agent("cv", job.options), job.params)
    assert job.model_fold is not None and job.train_idx is not None
    if src.kind == "method":
        name = ROSTER_NAME[src.target]
        model, _ = fold_model(name, job.model_fold, dataset, job.train_idx, job.options,
                              job.cache_dir, job.token)
        return make_agent(name, job.params, model)
    key = (job.token, src, job.model_fold)
    if key not in _PLUGINS:
        _PLUGINS[key] = fit_plugin(src, dataset.subset(job.train_idx))
        while len(_PLUGINS) > CACHE_SIZE:
            _PLUGINS.popitem(last=False)
    return make_agent(_PLUGINS[key], job.params)


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
    """Run ``job``'s episodes (in a worker or in-process); one benchmark row each."""
    from handover_env.rollout import run_episode

    name = job.source.name
    with agent_guard(name, "building and fitting", key=job.guard_key):
        agent = _agent(dataset, job)
    env = track_env(job.params)
    rows = []
    for rec in job.receivers:
        spec = rec.spec
        if rec.kind == "replay":
            options: dict[str, Any] = {"receiver": "replay", "hand_mode": job.hand_mode,
                                       "episode": replay_source(spec, dataset)}
        else:
            options = {"receiver": rec.kind}
            if rec.pass_y is not None:
                options["walker"] = {"pass_y": rec.pass_y}
        steps = [0]

        def count(step: int, info: dict, steps: list[int] = steps) -> None:
            steps[0] = step + 1

        t0 = time.perf_counter()
        what = f"closed-loop episode {rec.bench_set}/{spec.key} (seed {spec.seed})"
        try:
            with agent_guard(name, what, job.time_limit, job.guard_key):
                info = run_episode(env, agent, seed=spec.seed, options=options, on_step=count)
        except (AgentError, KeyboardInterrupt):
            clear_state()  # the env may have stopped mid-step: a later job builds a fresh one
            raise
        ep_job = EpisodeJob(job.token, job.source.name, (spec,), job.params, job.hand_mode,
                            job.options, job.cache_dir, job.model_fold, job.train_idx)
        row = episode_row(ep_job, spec, info, steps[0], time.perf_counter() - t0)
        row["sim_unstable"] = instabilities(env.unwrapped.data)
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
    learned = [ROSTER_NAME[s.target] for s in sources
               if s.kind == "method" and s.target in ("act", "bc_mlp")]
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
