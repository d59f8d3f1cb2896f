"""Run the experiments' per-fold work in parallel processes, the dataset sent to each worker once.

After ACT's fold models are trained (:mod:`.act_folds`), Table I's fold loop fits the
nonparametric methods and BC-MLP and scores all four methods, fold after fold, on one torch
thread: on the 2-core box this left a core idle for ~13 min of the 10-fold run. The folds are
independent and every method is seeded, so :func:`map_folds` runs them in ``workers`` spawned
processes and returns exactly what the serial loop returns, in job order
(``tests/test_evaluate.py`` checks the tables are identical with 1 and 2 workers).
"""

from __future__ import annotations

import multiprocessing
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Any, TypeVar

from tqdm import tqdm

from handover_env.data.dataset import HandoverDataset

J = TypeVar("J")
R = TypeVar("R")

_DATASET: HandoverDataset | None = None  # the worker's copy, set once by _init_worker


def _init_worker(dataset: HandoverDataset) -> None:
    """Worker start-up: keep the dataset, one torch thread per process (the environment, and so
    the entry point's Hugging Face offline setting, is inherited from the parent)."""
    global _DATASET
    _DATASET = dataset
    import torch

    torch.set_num_threads(1)


def _call(fn: Callable[[HandoverDataset, Any], Any], job: Any) -> Any:
    assert _DATASET is not None, "fold_pool worker used before its initialiser ran"
    return fn(_DATASET, job)


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
    """``[fn(dataset, job) for job in jobs]``, in ``workers`` spawned processes when ``workers`` >
    1.

    ``fn`` must be a module-level function (it is pickled by reference). With more than one
    worker the pool uses the ``spawn`` start method, so a script that calls this needs the usual
    ``if __name__ == "__main__":`` guard. The first job that raises stops the pool (queued jobs
    are dropped) and its exception is re-raised here. The progress bar counts jobs, or
    ``weight(job)`` units per job (e.g. the episodes a job runs) with ``weight``.
    """
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    size = weight or (lambda job: 1)
    bar = tqdm(total=sum(size(job) for job in jobs), desc=desc, unit=unit, disable=not progress)
    try:
        n_proc = min(workers, len(jobs))
        if n_proc <= 1:
            results = []
            for job in jobs:
                bar.set_postfix_str(label(job))
                results.append(fn(dataset, job))
                bar.update(size(job))
            return results
        ctx = multiprocessing.get_context("spawn")
        out: dict[int, R] = {}
        with ProcessPoolExecutor(max_workers=n_proc, mp_context=ctx, initializer=_init_worker,
                                 initargs=(dataset,)) as pool:
            pending = {pool.submit(_call, fn, job): i for i, job in enumerate(jobs)}
            waiting = set(pending)
            while waiting:
                finished, waiting = wait(waiting, return_when=FIRST_COMPLETED)
                for fut in finished:
                    if fut.exception() is not None:
                        pool.shutdown(wait=True, cancel_futures=True)
                        raise fut.exception()
                    out[pending[fut]] = fut.result()
                    bar.set_postfix_str(f"{label(jobs[pending[fut]])} done")
                    bar.update(size(jobs[pending[fut]]))
        return [out[i] for i in range(len(jobs))]
    finally:
        bar.close()
