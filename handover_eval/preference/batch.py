"""The walks one CoSpar turn needs, run as parallel Ray tasks (``--backend ray``).

CoSpar pools its participants into one posterior: each participant's turn proposes from the
posterior the previous turn updated, so turns are sequential. What a turn can run in parallel is
its new actions' walks (Thompson samples x walks episodes). :func:`prefetch` runs those as
backend jobs on the active Ray backend (:mod:`.backend`) and fills the runner's episode cache,
from which :meth:`.tuning.EpisodeRunner.run` then reads them. Every walk is seeded, so the
episodes, and the run, are those of the serial loop. On the process backend it does nothing: a
process pool per turn would cost more than the few episodes it parallelises.
"""

from __future__ import annotations

import copy
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from agents.participants import Participant
from handover_env.config import HandoverParams
from handover_eval.backend import active, map_jobs


@dataclass(frozen=True)
class WalkJob:
    """One episode: ``participant`` walks ``seed`` with the planner at ``theta``."""

    participant: Participant
    theta: HandoverParams
    seed: int


def _walk(runner: Any, job: WalkJob) -> tuple[dict[str, Any], float]:
    """Run one walk on the worker's copy of the runner (its planner already fitted); the kept
    info."""
    t0 = time.perf_counter()
    info = runner.run(job.participant, job.theta, [job.seed])[0]
    return info, time.perf_counter() - t0


def prefetch(
    runner: Any, participant: Participant, thetas: Sequence[HandoverParams], seeds: Sequence[int]
) -> int:
    """Run the uncached walks of ``participant`` under ``thetas`` in parallel (Ray backend only).

    Returns the number of episodes run here (0 on the process backend or when all are cached).
    """
    if active().backend.kind != "ray":
        return 0
    jobs = [WalkJob(participant, theta, int(seed)) for theta in thetas for seed in seeds
            if runner.cache_key(participant, theta, seed) not in runner.cache]
    if len(jobs) < 2:
        return 0
    runner.planner(jobs[0].theta)  # fit once here, so every task gets the fitted planner
    portable = copy.copy(runner)  # no env (the runner holds none), and no episode cache
    portable.cache = {}
    results = map_jobs(_walk, portable, jobs, progress=False, desc="CoSpar walks",
                       label=lambda j: f"participant {j.participant.pid} seed {j.seed}")
    for job, (info, seconds) in zip(jobs, results, strict=True):
        runner.cache[runner.cache_key(job.participant, job.theta, job.seed)] = info
        runner.episodes_run += 1
        runner.seconds += seconds
    return len(jobs)
