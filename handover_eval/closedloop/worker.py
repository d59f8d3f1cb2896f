"""The worker side of the closed-loop runs: one chunk of episodes of one agent, and its rows.

A job (:class:`EpisodeJob`) is a chunk of receivers for one agent, Θ and model fold. A worker
gets the job's model once (:func:`handover_eval.closedloop.models.model_for`: fitted or loaded
once per worker and fold), makes the agent (:func:`handover_eval.roster.make_agent`) and runs
each receiver through :func:`handover_eval.episodes.run_receiver`, the one closed-loop episode
runner (this process's Θ-keyed envs, the episode, its row).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from handover_env.config import HandoverParams
from handover_env.data.dataset import HandoverDataset
from handover_eval import roster
from handover_eval.closedloop.models import ModelRecord, clear_models, model_for
from handover_eval.episodes import clear_envs, run_receiver
from handover_eval.methods import MethodOptions
from handover_eval.receivers import ReceiverSpec


@dataclass(frozen=True)
class EpisodeJob:
    """A chunk of receivers for one agent, Θ and model, run by :func:`run_job` in a worker.

    ``agent`` is spelled as the closed-loop files spell it (:func:`handover_eval.roster.
    check_agents`). ``extra`` columns are copied into every row (the Θ sweep's parameter and
    value); ``env_kwargs`` (a JSON object, "" for none) are further ``gym.make`` keyword
    arguments (the sensing profile, the sensing sweep's ``sensors``).
    """

    token: str
    agent: str
    receivers: tuple[ReceiverSpec, ...]
    params: HandoverParams
    hand_mode: str
    options: MethodOptions
    cache_dir: Path
    model_fold: int | None = None
    train_idx: np.ndarray | None = None
    extra: tuple[tuple[str, Any], ...] = ()
    env_kwargs: str = ""

    @property
    def env(self) -> str:
        """The env kind of the job's agent (the roster's; ``"dynamic"`` for a name it lacks)."""
        return roster.env_kind(self.agent)


def clear_worker_state() -> None:
    """Close this process's envs and forget its fold models (end of an in-process run)."""
    clear_envs()
    clear_models()


def run_job(dataset: HandoverDataset, job: EpisodeJob) -> tuple[list[dict], list[ModelRecord]]:
    """Run ``job``'s episodes; returns the rows and the fold models fitted or loaded for it."""
    model, record = model_for(job.agent, dataset, job.model_fold, job.train_idx, job.options,
                              job.cache_dir, job.token)
    agent = roster.make_agent(job.agent, job.params, job.options, model)
    builtin = roster.entry(job.agent)
    rows = [run_receiver(job, agent, spec, dataset, builtin) for spec in job.receivers]
    return rows, [record] if record is not None else []
