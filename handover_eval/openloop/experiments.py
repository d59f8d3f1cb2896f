"""The runs of the paper's simulation experiments (Sec. V-A): Table I, the sample-efficiency sweep
and the RMS / inference-time trade-off. Every run scores with the one open-loop protocol of
:mod:`.protocol` and returns an :class:`OpenLoopRun` of rows; the tables and figures are made by
:mod:`.report` and the files written by :mod:`.output`. ``out_dir`` is only the checkpoint cache
(``<out_dir>/checkpoints``) the learned baselines are fitted into and reused from.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from handover_env.data.dataset import HandoverDataset
from handover_eval.backend import map_folds
from handover_eval.methods import (
    MethodOptions,
    build_agent,
    check_methods,
    fit_agent,
    with_test_data,
)
from handover_eval.openloop.protocol import OpenLoopProtocol, evaluate_openloop, summarise
from handover_eval.reporting import PAPER_TABLE1

if TYPE_CHECKING:
    from handover_eval.act_folds import ACTRun

SQRT3 = math.sqrt(3.0)


@dataclass(frozen=True)
class OpenLoopRun:
    """What an open-loop run returns.

    Attributes:
        rows: one summary row per method (and ratio or inducing rate): mean ± std over folds.
        per_fold: one row per (method, fold[, ratio]).
        episodes: one row per (method, test episode) (Table I only; empty otherwise).
    """

    rows: list[dict]
    per_fold: list[dict]
    episodes: list[dict]


def _fold_stats(values: list[float]) -> tuple[float, float]:
    vals = np.asarray([v for v in values if np.isfinite(v)], dtype=np.float64)
    if vals.size == 0:
        return float("nan"), float("nan")
    return float(vals.mean()), float(vals.std(ddof=1)) if vals.size > 1 else 0.0


def _splits(dataset: HandoverDataset, folds: int, seed: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """The stratified folds; a clear ValueError when ``folds`` < 2 or the dataset is too small."""
    if folds < 2:
        raise ValueError(f"--folds must be >= 2, got {folds}")
    return dataset.stratified_kfold(folds, seed)


def _pretrain_act(
    dataset: HandoverDataset,
    methods: list[str],
    train_sets: list[np.ndarray],
    labels: list[str],
    options: MethodOptions,
    out_dir: Path,
    reuse: bool,
    workers: int | None,
    progress: bool,
) -> list[ACTRun] | None:
    """ACT's models for ``train_sets`` trained up front (None when ACT is not among ``methods``)."""
    if "act" not in methods:
        return None
    from handover_eval.act_folds import pretrain_act

    return pretrain_act(
        dataset,
        train_sets,
        options,
        out_dir / "checkpoints",
        reuse=reuse,
        workers=workers,
        labels=labels,
        progress=progress,
    )


@dataclass(frozen=True)
class _FoldJob:
    """What one fold job of :func:`map_folds` needs besides the dataset: its split and how to
    fit."""

    fold: int
    train_idx: np.ndarray  # training episodes, as indices of the dataset
    test_idx: np.ndarray
    methods: tuple[str, ...]
    options: MethodOptions
    protocol: OpenLoopProtocol
    cache_dir: Path
    reuse: bool


# ---------------------------------------------------------------------------------------- Table I
@dataclass(frozen=True)
class _Table1Fold(_FoldJob):
    """One fold of Table I."""

    act_fit_seconds: float | None  # ACT trained up front in this run: its training time, else None


def _table1_fold(dataset: HandoverDataset, job: _Table1Fold) -> tuple[list[dict], list[dict]]:
    """Fit every method on the fold's training episodes and score it on its test episodes.

    Returns ``(fold rows, episode rows)``. Runs in a :func:`map_folds` worker or in-process.
    """
    train, test = dataset.subset(job.train_idx), dataset.subset(job.test_idx)
    fold_rows: list[dict] = []
    episode_rows: list[dict] = []
    for name in job.methods:
        t0 = time.perf_counter()
        pretrained = name == "act" and job.act_fit_seconds is not None
        agent, reused = fit_agent(name, build_agent(name, job.options), train, job.cache_dir,
                                  job.reuse or pretrained)
        fit_s = time.perf_counter() - t0
        if pretrained:
            fit_s, reused = job.act_fit_seconds, False
        records = evaluate_openloop(agent, test, job.protocol, progress=False)
        summary = summarise(records)
        fold_rows.append(
            {
                "method": name,
                "fold": job.fold,
                "id_rms_3d_mm": summary["id"]["rms_3d_mm"],
                "ood_rms_3d_mm": summary["ood"]["rms_3d_mm"],
                "id_now_axis_mm": summary["id"]["rms_now_axis_mm"],
                "ood_now_axis_mm": summary["ood"]["rms_now_axis_mm"],
                "n_id": summary["id"]["n_episodes"],
                "n_ood": summary["ood"]["n_episodes"],
                "n_train": len(train),
                "train_fingerprint": train.fingerprint(),
                "fit_seconds": fit_s,
                "checkpoint_reused": reused,
            }
        )
        episode_rows += [
            {
                "method": name,
                "fold": job.fold,
                "source_id": r.source_id,
                "is_ood": r.is_ood,
                "rms_3d_mm": r.rms_3d_mm,
                "rms_axis_mm": r.rms_axis_mm,
                "rms_now_axis_mm": r.rms_now_axis_mm,
                "ade_05_mm": r.ade_05_mm,
                "fde_05_mm": r.fde_05_mm,
                "ade_10_mm": r.ade_10_mm,
                "fde_10_mm": r.fde_10_mm,
                "n_queries": r.n_queries,
            }
            for r in records
        ]
    return fold_rows, episode_rows


def run_table1(
    dataset: HandoverDataset,
    methods: Sequence[str],
    folds: int,
    seed: int,
    options: MethodOptions,
    protocol: OpenLoopProtocol,
    out_dir: Path,
    reuse: bool = True,
    progress: bool = True,
    workers: int | None = None,
    test_data: HandoverDataset | None = None,
) -> OpenLoopRun:
    """Stratified k-fold open-loop RMS of every method (paper Table I).

    ACT's fold models are trained first, all from one LeRobot export of ``dataset`` and in
    ``workers`` processes (default ``options.workers``), into the checkpoint cache the fold loop
    then loads from (:func:`handover_eval.act_folds.pretrain_act`). ACT's
    ``fit_seconds`` is that training time (measured in its worker, beside the other workers).

    With ``test_data`` (``--replay-data``) there is one "fold" (0): every method fits on all of
    ``dataset`` and is scored on every episode of ``test_data``
    (:func:`handover_eval.methods.with_test_data`); the ±
    of a row is then the standard deviation over the test episodes, not over folds.
    """
    methods = check_methods(list(methods))
    if test_data is None:
        shared, splits = dataset, _splits(dataset, folds, seed)
    else:
        shared = with_test_data(dataset, test_data)
        n, m = len(dataset), len(test_data)
        splits = [(np.arange(n, dtype=np.int64), np.arange(n, n + m, dtype=np.int64))]
    act_runs = _pretrain_act(
        dataset,
        methods,
        [tr for tr, _ in splits],
        [f"fold {f}" for f in range(len(splits))],
        options,
        out_dir,
        reuse,
        workers,
        progress,
    )
    n_workers = options.workers if workers is None else int(workers)
    jobs = [
        _Table1Fold(
            f,
            train_idx,
            test_idx,
            tuple(methods),
            options,
            protocol,
            out_dir / "checkpoints",
            reuse,
            None if act_runs is None or not act_runs[f].trained else act_runs[f].fit_seconds,
        )
        for f, (train_idx, test_idx) in enumerate(splits)
    ]
    results = map_folds(
        _table1_fold,
        shared,
        jobs,
        workers=n_workers,
        progress=progress,
        desc="table1",
        label=lambda job: f"fold {job.fold}",
    )
    fold_rows = [row for fold, _ in results for row in fold]
    episode_rows = [row for _, eps in results for row in eps]
    rows = []
    nan_pair = {"id": (math.nan, math.nan), "ood": (math.nan, math.nan)}
    for name in methods:
        mine = [r for r in fold_rows if r["method"] == name]
        if test_data is None:  # mean ± std over the folds of the per-fold means
            id_m, id_s = _fold_stats([r["id_rms_3d_mm"] for r in mine])
            ood_m, ood_s = _fold_stats([r["ood_rms_3d_mm"] for r in mine])
            id_now_m, id_now_s = _fold_stats([r["id_now_axis_mm"] for r in mine])
            ood_now_m, ood_now_s = _fold_stats([r["ood_now_axis_mm"] for r in mine])
        else:  # one fit: mean ± std over the test episodes
            eps = [r for r in episode_rows if r["method"] == name]

            def over(key: str, ood: bool, eps: list[dict] = eps) -> tuple[float, float]:
                return _fold_stats([r[key] for r in eps if r["is_ood"] == ood])

            (id_m, id_s), (ood_m, ood_s) = over("rms_3d_mm", False), over("rms_3d_mm", True)
            id_now_m, id_now_s = over("rms_now_axis_mm", False)
            ood_now_m, ood_now_s = over("rms_now_axis_mm", True)
        paper = PAPER_TABLE1.get(name, nan_pair)
        rows.append(
            {
                "method": name,
                "id_rms_3d_mm": id_m, "id_std_3d_mm": id_s,
                "ood_rms_3d_mm": ood_m, "ood_std_3d_mm": ood_s,
                "id_rms_axis_mm": id_m / SQRT3, "id_std_axis_mm": id_s / SQRT3,
                "ood_rms_axis_mm": ood_m / SQRT3, "ood_std_axis_mm": ood_s / SQRT3,
                "id_now_axis_mm": id_now_m, "id_now_axis_std_mm": id_now_s,
                "ood_now_axis_mm": ood_now_m, "ood_now_axis_std_mm": ood_now_s,
                "paper_id_mm": paper["id"][0], "paper_id_std_mm": paper["id"][1],
                "paper_ood_mm": paper["ood"][0], "paper_ood_std_mm": paper["ood"][1],
                "fit_seconds_mean": float(np.mean([r["fit_seconds"] for r in mine])),
            }
        )
    return OpenLoopRun(rows, fold_rows, episode_rows)


# ------------------------------------------------------------------------------ sample efficiency
@dataclass(frozen=True)
class _RatioJob(_FoldJob):
    """One (fold, training ratio) cell of the sample-efficiency sweep; ``train_idx`` is
    subsampled."""

    ratio: float


def _ratio_job(dataset: HandoverDataset, job: _RatioJob) -> list[dict]:
    """Fit every method on the cell's training episodes; one per-fold row per method.

    ACT always loads the model :func:`_pretrain_act` just trained or found.
    """
    train, test = dataset.subset(job.train_idx), dataset.subset(job.test_idx)
    rows = []
    for name in job.methods:
        agent, _ = fit_agent(
            name, build_agent(name, job.options), train, job.cache_dir, job.reuse or name == "act"
        )
        s = summarise(evaluate_openloop(agent, test, job.protocol, progress=False))
        rows.append({"method": name, "ratio": job.ratio, "fold": job.fold, "n_train": len(train),
                     **{f"{k}_rms_3d_mm": s[k]["rms_3d_mm"] for k in ("all", "id", "ood")},
                     **{f"{k}_now_axis_mm": s[k]["rms_now_axis_mm"] for k in ("all", "id", "ood")}})
    return rows


def run_sample_efficiency(
    dataset: HandoverDataset,
    methods: Sequence[str],
    ratios: Sequence[float],
    folds: int,
    seed: int,
    options: MethodOptions,
    protocol: OpenLoopProtocol,
    out_dir: Path,
    reuse: bool = True,
    progress: bool = True,
    workers: int | None = None,
) -> OpenLoopRun:
    """RMS vs training-data ratio (paper Fig. "Sample efficiency").

    ACT's (fold, ratio) models are trained first, in parallel, as in :func:`run_table1`.
    """
    methods = check_methods(list(methods))
    ratios = [float(r) for r in ratios]
    if not ratios or any(not 0.0 < r <= 1.0 for r in ratios):
        raise ValueError(f"ratios must lie in (0, 1], got {ratios}")
    splits = _splits(dataset, folds, seed)
    train_sets = {(f, ratio): dataset.subset(train_idx).subsample(ratio, seed=seed + f)
                  for f, (train_idx, _) in enumerate(splits) for ratio in ratios}
    from handover_eval.act_folds import episode_indices

    train_idx = {key: episode_indices(dataset, t) for key, t in train_sets.items()}
    _pretrain_act(
        dataset,
        methods,
        list(train_idx.values()),
        [f"fold {f} ratio {r:g}" for f, r in train_sets],
        options,
        out_dir,
        reuse,
        workers,
        progress,
    )
    jobs = [_RatioJob(f, train_idx[(f, ratio)], test_idx, tuple(methods), options, protocol,
                      out_dir / "checkpoints", reuse, ratio)
            for f, (_, test_idx) in enumerate(splits) for ratio in ratios]
    results = map_folds(
        _ratio_job,
        dataset,
        jobs,
        workers=options.workers if workers is None else int(workers),
        progress=progress,
        desc="sample-efficiency",
        label=lambda job: f"fold {job.fold} ratio {job.ratio:g}",
    )
    per_fold = [row for rows_ in results for row in rows_]
    rows = []
    for name in methods:
        for ratio in ratios:
            mine = [r for r in per_fold if r["method"] == name and r["ratio"] == ratio]
            row = {
                "method": name,
                "ratio": ratio,
                "n_train_mean": float(np.mean([r["n_train"] for r in mine])),
            }
            for k in ("all", "id", "ood"):
                m, s = _fold_stats([r[f"{k}_rms_3d_mm"] for r in mine])
                row[f"{k}_rms_3d_mm"], row[f"{k}_std_3d_mm"] = m, s
                m, s = _fold_stats([r[f"{k}_now_axis_mm"] for r in mine])
                row[f"{k}_now_axis_mm"], row[f"{k}_now_axis_std_mm"] = m, s
            rows.append(row)
    return OpenLoopRun(rows, per_fold, [])


# ---------------------------------------------------------------------------------------- trade-off
@contextmanager
def _one_core():
    """Pin this process to one core while timing (restores the previous affinity)."""
    if not hasattr(os, "sched_getaffinity"):
        yield None
        return
    before = os.sched_getaffinity(0)
    core = min(before)
    os.sched_setaffinity(0, {core})
    try:
        yield core
    finally:
        os.sched_setaffinity(0, before)


def time_streaming_frames(agent, episodes: Sequence, warmup: int = 3) -> np.ndarray:
    """Seconds per 30 Hz frame (stream_update + stream_predict) of a streaming planner, all
    frames."""
    times = []
    for ep in episodes:
        agent.stream_reset()
        for t, xy in enumerate(ep.receiver_xy):
            t0 = time.perf_counter()
            agent.stream_update(xy)
            agent.stream_predict()
            if t >= warmup:
                times.append(time.perf_counter() - t0)
    return np.asarray(times)


@dataclass(frozen=True)
class _TradeoffJob:
    """One (variant, fold) fit of the trade-off sweep."""

    method: str
    rate: float
    fold: int
    train_idx: np.ndarray
    test_idx: np.ndarray
    options: MethodOptions
    protocol: OpenLoopProtocol


def _tradeoff_fit(
    dataset: HandoverDataset, job: _TradeoffJob
) -> tuple[dict[str, float], object | None]:
    """Fit one variant on one fold and score it: (RMS by subset, the fitted agent for fold 0 only,
    which is timed afterwards in the main process)."""
    agent = build_agent(job.method, job.options, inducing_ratio=job.rate).fit(
        dataset.subset(job.train_idx)
    )
    s = summarise(
        evaluate_openloop(agent, dataset.subset(job.test_idx), job.protocol, progress=False)
    )
    return {k: s[k]["rms_3d_mm"] for k in ("all", "id", "ood")}, agent if job.fold == 0 else None


def run_tradeoff(
    dataset: HandoverDataset,
    rates: Sequence[float],
    folds: int,
    seed: int,
    options: MethodOptions,
    protocol: OpenLoopProtocol,
    out_dir: Path,
    timing_episodes: int = 20,
    include_iaal: bool = True,
    progress: bool = True,
) -> OpenLoopRun:
    """RMS vs per-frame inference time for ours at several inducing rates and IAAL.

    The (variant, fold) fits run as backend jobs (:func:`map_folds`); each variant's fold-0 model
    is then timed here, one variant after another, pinned to one core, with no job running.
    """
    rates = [float(r) for r in rates]
    if not rates or any(not 0.0 < r <= 1.0 for r in rates):
        raise ValueError(f"inducing rates must lie in (0, 1], got {rates}")
    splits = _splits(dataset, folds, seed)
    variants = [("ours", r) for r in rates] + ([("iaal", 1.0)] if include_iaal else [])
    jobs = [_TradeoffJob(name, rate, f, train_idx, test_idx, options, protocol)
            for name, rate in variants for f, (train_idx, test_idx) in enumerate(splits)]
    fits = map_folds(
        _tradeoff_fit,
        dataset,
        jobs,
        workers=options.workers,
        progress=progress,
        desc="tradeoff",
        label=lambda job: f"{job.method} {job.rate:g} fold {job.fold}",
        unit="fit",
    )
    rows = []
    for name, rate in variants:  # timed here, one variant after another, on one pinned core
        mine = [
            (job, fit)
            for job, fit in zip(jobs, fits, strict=True)
            if (job.method, job.rate) == (name, rate)
        ]
        fold0_job, (_, agent) = mine[0]
        with _one_core():
            frame_times = time_streaming_frames(
                agent, list(dataset.subset(fold0_job.test_idx))[:timing_episodes]
            )
        row = {"method": name, "inducing_rate": rate if name == "ours" else None,
               "frame_ms_median": float(np.median(frame_times) * 1e3),
               "frame_ms_p99": float(np.percentile(frame_times, 99) * 1e3),
               "n_timed_frames": int(frame_times.size), "cores": os.cpu_count()}
        for k in ("all", "id", "ood"):
            row[f"{k}_rms_3d_mm"], row[f"{k}_std_3d_mm"] = _fold_stats(
                [rms[k] for _, (rms, _) in mine]
            )
        rows.append(row)
    iaal = next((r for r in rows if r["method"] == "iaal"), None)
    for r in rows:
        if iaal is not None:
            r["speedup_vs_iaal"] = iaal["frame_ms_median"] / r["frame_ms_median"]
            r["rms_cost_vs_iaal_pct"] = 100.0 * (r["all_rms_3d_mm"] / iaal["all_rms_3d_mm"] - 1.0)
    return OpenLoopRun(rows, [], [])
