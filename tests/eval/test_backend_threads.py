"""Process-pool workers load BLAS with one thread, even when the caller did not set it.

Run as ``python evaluate.py ...`` (not through make, which exports OMP_NUM_THREADS=1), a 2-worker
pool on 2 cores used to give each worker's OpenBLAS one thread per core; the GP fits of the
closed-loop run then took 160 s instead of 2.5 s. The variables must be in the environment a
spawned worker inherits: its initialiser runs after numpy (and OpenBLAS) were loaded.
"""

from __future__ import annotations

import os

import pytest

from handover_eval.backend import WORKER_ENV, Backend, map_jobs, session

threadpoolctl = pytest.importorskip("threadpoolctl")


def _blas_threads(shared: None, job: int) -> list[int]:
    """The thread counts of every BLAS library loaded in this worker."""
    import numpy as np

    np.ones((64, 64)) @ np.ones((64, 64))  # make sure BLAS is loaded
    return [pool["num_threads"] for pool in threadpoolctl.threadpool_info()
            if pool["user_api"] == "blas"]


def test_pool_workers_get_one_blas_thread_and_the_callers_environment_is_restored(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    for key in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        monkeypatch.delenv(key, raising=False)
    with session(Backend("process"), workers=2, log=None):
        counts = map_jobs(_blas_threads, None, [0, 1], workers=2, progress=False)
    assert all(c and set(c) == {1} for c in counts), counts
    assert all(key not in os.environ for key in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS"))
    assert WORKER_ENV["OPENBLAS_NUM_THREADS"] == "1"
