"""Where a sweep's independent jobs run: a local process pool or a Ray cluster, behind one call.

Every sweep of the evaluations (Table I's and the sample-efficiency sweep's fold models and fold
scoring, closed-loop episode chunks, CoSpar participants) is a list of independent jobs mapped
through :func:`map_jobs`::

    results = map_jobs(fn, shared, jobs, workers=2, desc="table1", label=lambda j: f"fold {j.fold}")

``fn(shared, job)`` is a module-level function (pickled by reference); ``shared`` is the large
read-only input every job needs (the dataset), sent once: to each pool worker by its initialiser,
or put in Ray's object store once (``ray.put``) and passed by reference. Results come back in job
order. Every job runs on one torch thread. A job that raises (or whose worker dies) is retried
once; if it fails again, the other jobs still run to the end and then :class:`JobError` names
every failed job with its error. Whatever the finished jobs wrote to disk (checkpoints) stays, so
a rerun resumes through the checkpoint reuse.

The backend is chosen per command (``--backend process|ray``, ``--ray-address``, parsed in
``handover_eval/cli/args.py``) and made active with :func:`session`, which for Ray connects to
``ray.init(address=...)`` or starts a small local instance (``num_cpus`` = the workers asked for)
and shuts it down at the end, and measures that start-up on its own (:attr:`Session.startup_s`).
Ray tasks declare ``num_cpus=1`` and ``max_retries=1`` (``retry_exceptions=True``); the
scheduling is Ray's (``ray.remote``, ``ray.wait``, ``ray.get``).
"""

from __future__ import annotations

import multiprocessing
import os
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, TypeVar

from tqdm import tqdm

if TYPE_CHECKING:
    from handover_env.data.dataset import HandoverDataset

J = TypeVar("J")
R = TypeVar("R")

BACKENDS = ("process", "ray")
RETRIES = 1
INSTALL_HINT = (
    "--backend ray needs Ray: pip install 'handover_env[cluster]' (or pip install 'ray>=2.9')"
)
#: Set in every worker (pool initialiser, Ray runtime_env): one BLAS thread, offline hub.
WORKER_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
              "HF_HUB_OFFLINE": "1", "HF_DATASETS_OFFLINE": "1"}


class JobError(RuntimeError):
    """Jobs that failed after their retry; names each (``failed``: label -> error text).

    ``completed`` maps job index -> result of the jobs that did finish.
    """

    def __init__(
        self, desc: str, failed: dict[str, str], completed: dict[int, Any], total: int
    ) -> None:
        self.failed, self.completed = failed, completed
        names = "; ".join(f"{label}: {err}" for label, err in failed.items())
        super().__init__(f"{desc}: {len(failed)} of {total} job(s) failed after {RETRIES} retry "
                         f"({len(completed)} finished; their checkpoints are kept): {names}")


@dataclass(frozen=True)
class Backend:
    """Which executor runs the jobs: ``kind`` "process" or "ray"; ``address`` of a Ray cluster
    (None: a local instance started for the command, sized by the workers asked for)."""

    kind: str = "process"
    address: str | None = None

    def __post_init__(self) -> None:
        if self.kind not in BACKENDS:
            raise ValueError(f"--backend must be one of {list(BACKENDS)}, got {self.kind!r}")
        if self.address is not None and self.kind != "ray":
            raise ValueError("--ray-address needs --backend ray")


@dataclass
class Session:
    """The active backend; for Ray, whether this command started the instance and how long it
    took."""

    backend: Backend
    startup_s: float = 0.0
    started_here: bool = False
    cpus: float = 0.0


_ACTIVE: list[Session] = []


def active() -> Session:
    """The innermost :func:`session`, or the process backend when none is open."""
    return _ACTIVE[-1] if _ACTIVE else Session(Backend())


def import_ray() -> Any:
    """``ray``, or a one-line error naming the ``[cluster]`` extra."""
    os.environ.setdefault(
        "RAY_DEDUP_LOGS", "0"
    )  # read when ray is first imported: every worker's lines
    try:
        import ray
    except ImportError as exc:
        raise RuntimeError(INSTALL_HINT) from exc
    return ray


@contextmanager
def session(
    backend: Backend, workers: int = 1, log: Callable[[str], None] | None = print
) -> Iterator[Session]:
    """Make ``backend`` active for the ``map_jobs`` calls inside; for Ray, init and shut down.

    With Ray already initialised in this process (a test fixture, a notebook) that instance is
    used and left running. Otherwise ``ray.init(address=...)`` connects to a cluster, or, without
    an address, starts a local instance with ``num_cpus=workers`` (no dashboard), which is shut
    down on exit. The start-up time is measured on its own and logged.
    """
    sess = Session(backend)
    if backend.kind == "ray":
        ray = import_ray()
        if not ray.is_initialized():
            t0 = time.perf_counter()
            kwargs: dict[str, Any] = {"include_dashboard": False, "log_to_driver": True,
                                      "runtime_env": {"env_vars": dict(WORKER_ENV)}}
            if backend.address is None:
                kwargs["num_cpus"] = max(1, int(workers))
            ray.init(address=backend.address, **kwargs)
            sess.startup_s, sess.started_here = time.perf_counter() - t0, True
        sess.cpus = float(ray.cluster_resources().get("CPU", 0.0))
        if log is not None:
            where = "local instance" if backend.address is None else f"cluster at {backend.address}"
            how = f"started in {sess.startup_s:.1f} s" if sess.started_here else "already running"
            log(f"ray: {where}, {sess.cpus:g} CPU(s), {how}")
    _ACTIVE.append(sess)
    try:
        yield sess
    finally:
        _ACTIVE.remove(sess)
        if sess.started_here:
            import_ray().shutdown()


# ------------------------------------------------------------------------------- the map
def map_jobs(
    fn: Callable[[Any, J], R],
    shared: Any,
    jobs: Sequence[J],
    workers: int = 1,
    progress: bool = True,
    desc: str = "jobs",
    label: Callable[[J], str] = str,
    weight: Callable[[J], int] | None = None,
    unit: str = "job",
    on_result: Callable[[J, R], None] | None = None,
) -> list[R]:
    """``[fn(shared, job) for job in jobs]`` on the active backend, in job order (module docstring).

    Process backend (the default, outside any :func:`session`): ``workers`` spawned processes
    (1 runs in this process, one torch thread); a script calling this needs the
    ``if __name__ == "__main__":`` guard. Ray backend (inside a Ray :func:`session`): one task per
    job, as many at a time as the instance has CPUs. The bar counts jobs, or ``weight(job)`` units;
    ``on_result(job, result)`` is called in this process as each job finishes.

    Raises:
        JobError: after every other job finished, naming the jobs that failed twice.
    """
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    size = weight or (lambda job: 1)
    bar = tqdm(total=sum(size(job) for job in jobs), desc=desc, unit=unit, disable=not progress)
    out: dict[int, R] = {}
    failed: dict[int, BaseException] = {}

    def done(i: int, result: R) -> None:
        out[i] = result
        bar.set_postfix_str(f"{label(jobs[i])} done")
        bar.update(size(jobs[i]))
        if on_result is not None:
            on_result(jobs[i], result)

    try:
        if active().backend.kind == "ray":
            _ray_map(fn, shared, jobs, done, failed)
        elif min(workers, len(jobs)) <= 1:
            _serial_map(fn, shared, jobs, done, failed)
        else:
            _pool_map(fn, shared, jobs, min(workers, len(jobs)), done, failed)
    finally:
        bar.close()
    if failed:
        first = failed[min(failed)]
        raise JobError(
            desc,
            {label(jobs[i]): _describe(exc) for i, exc in sorted(failed.items())},
            out,
            len(jobs),
        ) from first
    return [out[i] for i in range(len(jobs))]


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
    """:func:`map_jobs` with the dataset as the shared input: the evaluations' per-fold work.

    Table I's folds, the sample-efficiency cells, the trade-off fits and the closed-loop episode
    chunks are independent and seeded, so running them on ``workers`` processes (or as Ray tasks)
    returns exactly what the serial loop returns, in job order (``tests/eval/test_evaluate.py``
    checks the tables are identical with 1 and 2 workers, ``tests/eval/test_ray_backend.py`` with
    Ray).
    ``fn(dataset, job)`` must be a module-level function; a job that raises is retried once, then
    :class:`JobError` names it after the other jobs finished.
    """
    return map_jobs(fn, dataset, jobs, workers=workers, progress=progress, desc=desc, label=label,
                    weight=weight, unit=unit)


def _describe(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[-1] if text else ''}".rstrip(": ")


def _serial_map(
    fn: Callable, shared: Any, jobs: Sequence, done: Callable, failed: dict[int, BaseException]
) -> None:
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # as in a worker; restored afterwards
    try:
        for i, job in enumerate(jobs):
            for attempt in range(RETRIES + 1):
                try:
                    result = fn(shared, job)
                except Exception as exc:  # noqa: BLE001 - retried, then reported by name
                    if attempt == RETRIES:
                        failed[i] = exc
                else:
                    done(i, result)
                    break
    finally:
        torch.set_num_threads(threads)


# --------------------------------------------------------------------------- process pool
_SHARED: list[Any] = [None]  # the pool worker's copy of ``shared``, set once by _init_worker


@contextmanager
def _worker_environment() -> Iterator[None]:
    """Put :data:`WORKER_ENV` (where unset) in this process's environment while workers spawn.

    A spawned worker imports numpy, and with it OpenBLAS, while it unpickles its initialiser's
    arguments, before the initialiser runs; OpenBLAS reads its thread count once, at load. So
    the variables must already be in the environment the worker inherits, so that each worker
    runs one BLAS thread rather than one per core (which oversubscribes the cores). The caller's
    environment is restored afterwards (no process-wide side effect).
    """
    added = {k: v for k, v in WORKER_ENV.items() if k not in os.environ}
    os.environ.update(added)
    try:
        yield
    finally:
        for key in added:
            os.environ.pop(key, None)


def _init_worker(shared: Any) -> None:
    """Pool worker start-up: keep ``shared``, one torch thread (the BLAS and offline-hub variables
    were inherited: :func:`_worker_environment`)."""
    _SHARED[0] = shared
    import torch

    torch.set_num_threads(1)


def _pool_call(fn: Callable, job: Any) -> Any:
    return fn(_SHARED[0], job)


def _pool_map(fn: Callable, shared: Any, jobs: Sequence, n_proc: int, done: Callable,
              failed: dict[int, BaseException]) -> None:
    """A spawn pool; a job that raises is resubmitted once (a crashed worker breaks the pool, and
    every job still pending is then reported as failed)."""
    ctx = multiprocessing.get_context("spawn")
    with _worker_environment(), ProcessPoolExecutor(
            max_workers=n_proc, mp_context=ctx, initializer=_init_worker,
            initargs=(shared,)) as pool:
        pending = {pool.submit(_pool_call, fn, job): (i, 0) for i, job in enumerate(jobs)}
        while pending:
            finished, _ = wait(set(pending), return_when=FIRST_COMPLETED)
            for fut in finished:
                i, attempt = pending.pop(fut)
                exc = fut.exception()
                if exc is None:
                    done(i, fut.result())
                elif attempt < RETRIES:
                    try:
                        pending[pool.submit(_pool_call, fn, jobs[i])] = (i, attempt + 1)
                    except RuntimeError as broken:  # BrokenProcessPool: no retry possible
                        failed[i] = broken
                else:
                    failed[i] = exc


# ------------------------------------------------------------------------------------- Ray
_RAY_SHARED: dict[str, Any] = {}  # the Ray worker's copy of ``shared``, by object id (latest only)
_RAY_TASK: list[Any] = [None]


def _ray_call(fn: Callable, shared_ref: list, job: Any) -> Any:
    """Body of the Ray task: fetch ``shared`` once per worker process, one torch thread, run."""
    import ray
    import torch

    torch.set_num_threads(1)
    key = shared_ref[0].hex()
    if key not in _RAY_SHARED:
        _RAY_SHARED.clear()
        _RAY_SHARED[key] = ray.get(shared_ref[0])
    return fn(_RAY_SHARED[key], job)


def _ray_map(
    fn: Callable, shared: Any, jobs: Sequence, done: Callable, failed: dict[int, BaseException]
) -> None:
    """One task per job (``num_cpus=1``, ``max_retries=1`` with ``retry_exceptions``); ``ray.wait``
    reports them as they finish."""
    ray = import_ray()
    if _RAY_TASK[0] is None:
        _RAY_TASK[0] = ray.remote(num_cpus=1, max_retries=RETRIES, retry_exceptions=True)(_ray_call)
    ref = ray.put(shared)  # once; each task gets the reference (in a list: not resolved by Ray)
    pending = {_RAY_TASK[0].remote(fn, [ref], job): i for i, job in enumerate(jobs)}
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1)
        for obj in ready:
            i = pending.pop(obj)
            try:
                result = ray.get(obj)
            except Exception as exc:  # noqa: BLE001 - RayTaskError / WorkerCrashedError after the retry
                failed[i] = getattr(exc, "cause", None) or exc
            else:
                done(i, result)
