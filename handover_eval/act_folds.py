"""ACT for the k-fold evaluations: one LeRobot export, fold models trained in parallel processes.

Every fold's model trains from one shared export, in parallel:

1. The whole dataset is exported once per (dataset fingerprint, W, H) to
   ``<cache>/act-export-<key>/`` (:func:`ensure_export`), written to a temporary sibling and
   renamed when finished, so a folder under the final name is always complete; it is reused by
   later runs (and by Table I and the sample-efficiency sweep alike).
2. Each training set is a list of episode indices of that export:
   ``ACTAgent.fit_lerobot(export, episodes=...)`` splits train/validation and computes the
   normalisation statistics from those episodes only, and trains exactly the model that exporting
   just those episodes would give (``tests/baselines/test_act_folds.py``).
3. :func:`pretrain_act` trains the missing fold models in ``workers`` spawned processes, or as
   Ray tasks (:mod:`.backend`), with one torch thread each and writes them to the same checkpoint
   folders, with the same completion
   marker, that :func:`handover_eval.methods.fit_agent` looks up, so the fold loop of
   the experiments only loads them.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from handover_env.data.dataset import HandoverDataset
from handover_eval.backend import active, map_jobs
from handover_eval.methods import (
    MethodOptions,
    build_agent,
    checkpoint_slot,
    dataset_fingerprint,
    fresh_folder,
    is_complete,
    mark_complete,
)

EXPORT_PREFIX = "act-export-"


@dataclass(frozen=True)
class ACTJob:
    """One ACT model to train: a training set given as episode indices of the shared export.

    Attributes:
        label: human-readable name (``fold 3``, ``fold 3 ratio 0.5``).
        config: ``asdict(ACTAgentConfig)`` of the model.
        episodes: export episode indices of the training set (in training-set order).
        folder: the checkpoint folder ``fit_agent`` reuses.
        key_src: the checkpoint key source written to the completion marker.
        export_root: the LeRobot export of the whole dataset.
        progress: show the per-step tqdm bar of the training (the in-process path; other
            workers write their validation passes to the checkpoint's ``train_log.jsonl`` only).
    """

    label: str
    config: dict
    episodes: tuple[int, ...]
    folder: str
    key_src: str
    export_root: str
    progress: bool = False


@dataclass(frozen=True)
class ACTRun:
    """What :func:`pretrain_act` did for one training set.

    Attributes:
        folder: its checkpoint folder.
        trained: True if trained in this call, False if a complete checkpoint was already there.
        fit_seconds: training wall time (in its worker, with the other workers running), or None.
        best_step, best_val: the validation pass that picked the kept weights (None if reused).
    """

    folder: Path
    trained: bool
    fit_seconds: float | None = None
    best_step: int | None = None
    best_val: float | None = None


def episode_indices(dataset: HandoverDataset, part: HandoverDataset) -> np.ndarray:
    """Indices in ``dataset`` of the episodes of ``part`` (a ``subset`` / ``subsample`` of it), in
    order."""
    where = {id(ep): i for i, ep in enumerate(dataset.episodes)}
    try:
        return np.array([where[id(ep)] for ep in part.episodes], dtype=np.int64)
    except KeyError as exc:
        raise ValueError(
            "the training set holds episodes that are not in the dataset being exported"
        ) from exc


def export_key(dataset: HandoverDataset, history: int, horizon: int) -> str:
    """Cache key of a whole-dataset export: dataset fingerprint, W, H and the export format."""
    from handover_env.data.lerobot_export import EXPORT_FORMAT

    src = json.dumps(
        {
            "train": dataset_fingerprint(dataset),
            "n": len(dataset),
            "history": int(history),
            "horizon": int(horizon),
            "rate_hz": float(dataset.rate_hz),
            "format": EXPORT_FORMAT,
        },
        sort_keys=True,
    )
    return hashlib.sha1(src.encode()).hexdigest()[:16]


def _export_matches(root: Path, dataset: HandoverDataset, history: int, horizon: int) -> bool:
    from handover_env.data.lerobot_export import read_sidecar

    try:
        meta = read_sidecar(root)
    except (OSError, ValueError):
        return False
    return (
        (root / "meta" / "info.json").is_file()
        and meta.get("history") == history
        and meta.get("horizon") == horizon
        and meta.get("n_frames") == dataset.n_frames
        and meta.get("source_id") == [ep.source_id for ep in dataset]
    )


def ensure_export(
    dataset: HandoverDataset,
    cache_dir: str | os.PathLike,
    history: int,
    horizon: int,
    progress: bool = False,
) -> tuple[Path, bool]:
    """The whole-dataset LeRobot export under ``cache_dir``; returns ``(root, reused)``.

    An existing ``act-export-<key>`` folder is reused when its sidecar matches the dataset
    (episode ids, frame count, W, H); otherwise it is rebuilt. The export is written to a
    temporary folder and renamed into place, so an interrupted export is never mistaken for one.
    """
    from handover_env.data.lerobot_export import export_lerobot

    root = Path(cache_dir) / f"{EXPORT_PREFIX}{export_key(dataset, history, horizon)}"
    if root.is_dir() and _export_matches(root, dataset, history, horizon):
        return root, True
    if root.exists():
        shutil.rmtree(root)
    tmp = root.with_name(f"{root.name}.partial-{os.getpid()}")
    if tmp.exists():
        shutil.rmtree(tmp)
    tmp.parent.mkdir(parents=True, exist_ok=True)
    try:
        export_lerobot(dataset, tmp, history=history, horizon=horizon, progress=progress)
        tmp.rename(root)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp)
    return root, False


def train_job(job: ACTJob) -> dict:
    """Train one ACT model on its export episodes into its checkpoint folder (runs in a worker).

    Writes the folder exactly as ``fit_agent`` would (training checkpoints, final ``save``, then
    the completion marker) and returns a summary.
    """
    from baselines.act import ACTAgent, ACTAgentConfig

    folder = fresh_folder(job.folder)
    t0 = time.perf_counter()
    agent = ACTAgent(ACTAgentConfig.from_dict(job.config))
    agent.fit_lerobot(
        job.export_root,
        out_dir=folder,
        episodes=np.asarray(job.episodes, dtype=np.int64),
        progress=job.progress,
    )
    agent.save(folder)
    mark_complete(folder, job.key_src)
    return {
        "label": job.label,
        "folder": str(folder),
        "seconds": time.perf_counter() - t0,
        "best_step": int(agent.train_log["best_step"]),
        "best_val": float(agent.train_log["best_val"]),
    }


def pretrain_act(
    dataset: HandoverDataset,
    train_sets: Sequence[np.ndarray],
    options: MethodOptions,
    cache_dir: str | os.PathLike,
    reuse: bool = True,
    workers: int | None = None,
    labels: Sequence[str] | None = None,
    progress: bool = True,
    log: Callable[[str], None] | None = None,
) -> list[ACTRun]:
    """Train the ACT checkpoints of ``train_sets`` (episode indices of ``dataset``) before the fold
    loop.

    Checkpoints already complete under ``cache_dir`` are kept when ``reuse``; the others are
    trained on the shared whole-dataset export, in ``workers`` spawned processes (default
    ``options.workers``; 1 trains in this process). Identical training sets share one checkpoint.

    With ``workers`` > 1 the pool uses the ``spawn`` start method: a script that calls this
    (directly or through ``run_table1``) needs the usual ``if __name__ == "__main__":`` guard.

    Returns:
        one :class:`ACTRun` per training set, aligned with ``train_sets``.
    """
    workers = options.workers if workers is None else int(workers)
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    labels = list(labels) if labels is not None else [f"set {i}" for i in range(len(train_sets))]
    agent = build_agent("act", options)
    config = asdict(agent.config)
    slots = []
    for idx in train_sets:
        idx = np.asarray(idx, dtype=np.int64)
        folder, key_src = checkpoint_slot("act", agent, dataset.subset(idx), cache_dir)
        slots.append((idx, folder, key_src))
    todo: dict[Path, tuple[str, np.ndarray, str]] = {}
    for (idx, folder, key_src), label in zip(slots, labels, strict=True):
        if folder in todo or (reuse and is_complete(folder, key_src)):
            continue
        todo[folder] = (label, idx, key_src)
    done: dict[Path, dict] = {}
    if todo:
        export_root, _ = ensure_export(
            dataset, cache_dir, agent.config.history, agent.config.horizon, progress
        )
        jobs = [
            ACTJob(
                label, config, tuple(int(i) for i in idx), str(folder), key_src, str(export_root)
            )
            for folder, (label, idx, key_src) in todo.items()
        ]
        done = run_act_jobs(jobs, workers, progress, log)
    return [
        ACTRun(
            folder,
            True,
            done[folder]["seconds"],
            done[folder]["best_step"],
            done[folder]["best_val"],
        )
        if folder in done
        else ACTRun(folder, False)
        for _, folder, _ in slots
    ]


def _train(_: None, job: ACTJob) -> dict:
    """:func:`train_job` in the ``fn(shared, job)`` form of :func:`.backend.map_jobs`."""
    return train_job(job)


def run_act_jobs(
    jobs: list[ACTJob], workers: int, progress: bool, log: Callable[[str], None] | None
) -> dict[Path, dict]:
    """Run ``jobs`` on the active backend (:func:`.backend.map_jobs`: in this process for one
    process worker, else a spawn pool or Ray tasks); results by folder."""
    kind = active().backend.kind
    n_proc = 1 if workers == 1 or len(jobs) == 1 else min(workers, len(jobs))
    where = f"{n_proc} process(es)" if kind == "process" else "Ray tasks of one CPU"
    start = f"  act: training {len(jobs)} model(s) in {where}, one torch thread each"
    if log is not None:
        log(start)
    elif progress:
        tqdm.write(start)

    def report(job: ACTJob, res: dict) -> None:
        line = (f"  act {res['label']}: {res['seconds']:.0f} s, best val L1 {res['best_val']:.4f} "
                f"@ step {res['best_step']}")
        if log is not None:
            log(line)
        elif progress:
            tqdm.write(line)

    if kind == "process" and n_proc == 1:  # in this process: the training's own step bar too
        jobs = [replace(job, progress=progress) for job in jobs]
    done = map_jobs(_train, None, jobs, workers=n_proc, progress=progress,
                    desc=f"act x{n_proc}" if kind == "process" else "act (ray)", unit="model",
                    label=lambda job: job.label, on_result=report)
    return {Path(res["folder"]): res for res in done}
