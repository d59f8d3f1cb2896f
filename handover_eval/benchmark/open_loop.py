"""The open-loop track: the scored agent's predictions on Table I's folds (or on other data).

For each fold of the stratified split of ``--data`` (:data:`.protocol.OPENLOOP_FOLDS`, seed 0) a
fresh agent is fitted on the training folds and every test episode is scored with the metrics of
:func:`handover_eval.openloop.protocol.episode_metrics`. With ``test_data`` (``--replay-data``)
there is one fit on all of ``--data`` and every episode of ``test_data`` is scored (fold 0).
The folds run as :func:`handover_eval.backend.map_folds` jobs; a plug-in is loaded again in each
worker. Returns one row per (agent, test episode): :data:`.files.OPENLOOP_COLUMNS`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from agents.base import Agent
from handover_env.data.dataset import HandoverDataset
from handover_eval.backend import map_folds
from handover_eval.benchmark.guard import agent_guard
from handover_eval.benchmark.plugin import AgentSource, fit_plugin
from handover_eval.benchmark.protocol import OPENLOOP_METRICS, OPENLOOP_SEED
from handover_eval.methods import MethodOptions, build_agent, fit_agent, with_test_data
from handover_eval.openloop.protocol import OpenLoopProtocol, episode_metrics, query_times


@dataclass(frozen=True)
class OpenLoopJob:
    """One fold: fit on ``train_idx``, score ``test_idx`` (indices of the shared dataset)."""

    fold: int
    train_idx: np.ndarray
    test_idx: np.ndarray
    source: AgentSource
    options: MethodOptions
    protocol: OpenLoopProtocol
    cache_dir: Path


def fitted_agent(
    source: AgentSource, train: HandoverDataset, options: MethodOptions, cache_dir: Path
) -> Agent:
    """A fresh agent of ``source`` fitted on ``train`` (built-in learned methods reuse Table I's
    checkpoint cache)."""
    if source.kind == "method":
        agent, _ = fit_agent(source.target, build_agent(source.target, options), train, cache_dir)
        return agent
    if source.kind == "plugin":
        return fit_plugin(source, train)
    raise ValueError(
        f"{source.name} is a closed-loop-only agent: it has no open-loop predictor "
        "(its extrapolation is the 'cv' method)"
    )


def run_fold(dataset: HandoverDataset, job: OpenLoopJob) -> list[dict]:
    """Fit one fold's agent and score its test episodes (in a worker or in-process)."""
    agent = fitted_agent(job.source, dataset.subset(job.train_idx), job.options, job.cache_dir)
    rows = []
    for i in job.test_idx:
        ep = dataset[int(i)]
        with agent_guard(job.source.name, f"open-loop episode {ep.source_id} (fold {job.fold})",
                         job.source.episode_limit_s, job.source.guard_key):
            m = episode_metrics(agent, ep, job.protocol)
        if m["n_rows"] == 0:
            continue
        rows.append(
            {
                "agent": job.source.name,
                "fold": job.fold,
                "source_id": ep.source_id,
                "is_ood": ep.is_ood,
                "n_queries": int(query_times(ep.length, job.protocol).size),
                **{k: m[k] for k in OPENLOOP_METRICS},
            }
        )
    return rows


def run_openloop(
    source: AgentSource,
    dataset: HandoverDataset,
    folds: int,
    protocol: OpenLoopProtocol,
    options: MethodOptions,
    cache_dir: Path,
    test_data: HandoverDataset | None = None,
    progress: bool = True,
) -> list[dict]:
    """Every test episode's row (module docstring), in fold order."""
    if test_data is None:
        shared = dataset
        splits = dataset.stratified_kfold(folds, OPENLOOP_SEED)
    else:
        shared = with_test_data(dataset, test_data)
        n, m = len(dataset), len(test_data)
        splits = [(np.arange(n, dtype=np.int64), np.arange(n, n + m, dtype=np.int64))]
    if source.kind == "method" and source.target == "act":
        from handover_eval.act_folds import pretrain_act

        pretrain_act(dataset, [tr for tr, _ in splits], options, cache_dir,
                     labels=[f"fold {f}" for f in range(len(splits))], progress=progress)
    jobs = [
        OpenLoopJob(f, tr, te, source, options, protocol, cache_dir)
        for f, (tr, te) in enumerate(splits)
    ]
    results = map_folds(run_fold, shared, jobs, workers=options.workers, progress=progress,
                        desc="open-loop track", label=lambda j: f"fold {j.fold}")
    return [row for rows in results for row in rows]
