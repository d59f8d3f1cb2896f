"""Aggregates of RL runs over seeds, as rliable reports them (Agarwal et al., "Deep
Reinforcement Learning at the Edge of the Statistical Precipice", NeurIPS 2021).

Scores are a (runs x tasks) matrix: one row per training seed, one column per task (for
example a receiver set, or a learning-curve point). The **interquartile mean** (IQM) is the mean
of the middle 50 % of all the matrix's scores (``scipy.stats.trim_mean`` with 25 % cut at each
end, rliable's ``aggregate_iqm``). Its **stratified bootstrap** confidence interval resamples the
runs with replacement within each task (column) independently, ``reps`` times, and takes the
percentile interval of the statistic over the resamples (rliable's ``StratifiedBootstrap`` and
``get_interval_estimates`` with ``method="percentile"``). With 3 seeds the interval is wide; that
is what 3 seeds can say.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.stats import trim_mean


def iqm(scores: np.ndarray) -> float:
    """The interquartile mean of every score (25 % trimmed at each end)."""
    x = np.asarray(scores, dtype=np.float64).ravel()
    if x.size == 0 or not np.all(np.isfinite(x)):
        raise ValueError("iqm needs at least one score, every one finite")
    return float(trim_mean(x, 0.25))


def stratified_bootstrap_ci(
    scores: np.ndarray, statistic: Callable[[np.ndarray], float] = iqm, reps: int = 2000,
    level: float = 0.95, seed: int = 0,
) -> tuple[float, float, float]:
    """``(point, low, high)``: ``statistic`` of the (runs x tasks) ``scores`` and its percentile
    interval of coverage ``level`` over ``reps`` stratified bootstrap resamples (runs resampled
    within each task; module docstring)."""
    x = np.asarray(scores, dtype=np.float64)
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2 or x.shape[0] < 1 or not 0 < level < 1 or reps < 1:
        raise ValueError("scores must be (runs x tasks) with a run, level in (0, 1), reps >= 1")
    runs, tasks = x.shape
    rng = np.random.default_rng(seed)
    rows = rng.integers(0, runs, size=(reps, runs, tasks))
    resampled = x[rows, np.arange(tasks)]  # (reps, runs, tasks)
    if statistic is iqm:  # the same trimmed mean, all resamples at once
        flat = np.sort(resampled.reshape(reps, -1), axis=1)
        cut = int(0.25 * flat.shape[1])
        stats = flat[:, cut:flat.shape[1] - cut].mean(axis=1)
    else:
        stats = np.array([statistic(r) for r in resampled])
    tail = 100.0 * (1.0 - level) / 2.0
    low, high = np.percentile(stats, [tail, 100.0 - tail])
    return statistic(x), float(low), float(high)


def curve_band(curves: list[list[float]], level: float = 0.95, reps: int = 2000,
               seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per learning-curve point, the IQM over seeds and its bootstrap interval: ``(iqm, low,
    high)`` arrays of the points the seeds share (``curves``: one list of scores per seed)."""
    n = min(len(c) for c in curves)
    x = np.array([c[:n] for c in curves], dtype=np.float64)  # (seeds, points)
    out = np.array([stratified_bootstrap_ci(x[:, j], iqm, reps, level, seed) for j in range(n)])
    return out[:, 0], out[:, 1], out[:, 2]
