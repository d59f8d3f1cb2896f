"""Run the experiments' per-fold work in parallel, the dataset sent to each worker once.

After ACT's fold models are trained (:mod:`.act_folds`), Table I's fold loop fits the
nonparametric methods and BC-MLP and scores all four methods, fold after fold, on one torch
thread: on the 2-core box this left a core idle for ~13 min of the 10-fold run. The folds are
independent and every method is seeded, so :func:`map_folds` runs them in ``workers`` spawned
processes, or as Ray tasks (``--backend ray``, :mod:`.backend`), and returns exactly what the
serial loop returns, in job order (``tests/test_evaluate.py`` checks the tables are identical
with 1 and 2 workers, ``tests/test_ray_backend.py`` with Ray).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TypeVar

from handover_env.data.dataset import HandoverDataset
from handover_eval.backend import map_jobs

J = TypeVar("J")
R = TypeVar("R")


def map_folds(
    fn: Callable[[HandoverDataset, J], R],
    dataset: HandoverDataset,
    jobs: Sequence[J],
    workers: int = 1,
    progress: bool = True,
    desc: str = "folds",
    label: Callable[[J], str] = str,
    weight: Callable[[J], int] | None = None,
    unit: str = "job",
) -> list[R]:
    """``[fn(dataset, job) for job in jobs]`` on the active backend (:func:`.backend.map_jobs`).

    ``fn`` must be a module-level function (it is pickled by reference). With more than one
    process worker the pool uses the ``spawn`` start method, so a script that calls this needs the
    usual ``if __name__ == "__main__":`` guard. A job that raises is retried once; then, after the
    other jobs finished, :class:`.backend.JobError` names it. The progress bar counts jobs, or
    ``weight(job)`` units per job (e.g. the episodes a job runs) with ``weight``.
    """
    return map_jobs(fn, dataset, jobs, workers=workers, progress=progress, desc=desc, label=label,
                    weight=weight, unit=unit)
