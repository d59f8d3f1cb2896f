"""Statistics of the closed-loop tables: Wilson intervals, bootstrap CIs, paired differences.

Everything here is plain numpy and deterministic for a given seed:

* :func:`wilson_interval`: the 95 % Wilson score interval of a success rate k / n (it stays inside
  [0, 1] and is sensible at k = 0 or k = n, where the normal interval collapses).
* :func:`bootstrap_ci`: a percentile bootstrap CI of a statistic (median or mean) of one sample,
  the resamples drawn as a (B, n) index matrix in blocks of rows of at most
  :data:`BOOTSTRAP_BLOCK` indices, so memory stays bounded for any n; numpy's generator draws
  the same integers in the same order whatever the blocks, so the CI is that of one (B, n) draw,
  bit for bit (``tests/security/test_security_results.py``).
* :func:`pair_up`: aligns two agents' per-episode values on the same receivers (by key, never
  by row order) and drops receivers where either value is undefined.
* :func:`paired_difference`: the median (or mean) of the paired differences agent - reference,
  with a bootstrap CI over receivers (resampling pairs), and whether the CI excludes 0.
* :func:`cell_float`: one cell of an episode row (CSV text as read back, or the live value) as
  a float, NaN where it holds no number.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Hashable, Mapping
from dataclasses import dataclass

import numpy as np

Z95 = 1.959963984540054  # the standard normal's 97.5 % quantile
N_BOOTSTRAP = 2000
#: Most indices (rows x n) of one block of bootstrap resamples: 32 MiB of int64 indices and as
#: much for the values they pick, whatever the sample size.
BOOTSTRAP_BLOCK = 1 << 22


def wilson_interval(k: int, n: int, z: float = Z95) -> tuple[float, float]:
    """The Wilson score interval of a binomial proportion k / n (95 % for the default ``z``).

    ``(nan, nan)`` when n = 0.
    """
    if n < 0 or k < 0 or k > n:
        raise ValueError(f"need 0 <= k <= n, got k={k}, n={n}")
    if n == 0:
        return math.nan, math.nan
    p = k / n
    z2 = z * z
    centre = (p + z2 / (2 * n)) / (1 + z2 / n)
    half = z / (1 + z2 / n) * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n))
    return max(0.0, centre - half), min(1.0, centre + half)


def stable_seed(*parts: object, base: int = 0) -> int:
    """A seed that depends only on ``parts`` (not on the order the tables are computed in)."""
    return (base * 1_000_003 + zlib.crc32(repr(parts).encode())) % (2**32)


def _statistic(values: np.ndarray, stat: str, axis: int | None = None) -> np.ndarray:
    if stat == "median":
        return np.median(values, axis=axis)
    if stat == "mean":
        return np.mean(values, axis=axis)
    raise ValueError(f"stat must be 'median' or 'mean', got {stat!r}")


def bootstrap_ci(
    values: np.ndarray,
    stat: str = "median",
    n_boot: int = N_BOOTSTRAP,
    seed: int = 0,
    level: float = 0.95,
) -> tuple[float, float, float]:
    """``(statistic, low, high)``: the statistic of ``values`` and its percentile bootstrap CI.

    NaNs are dropped first. With no values all three are NaN; with one value the CI is that value.
    """
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return math.nan, math.nan, math.nan
    est = float(_statistic(v, stat))
    if v.size == 1:
        return est, est, est
    if n_boot < 1 or not 0 < level < 1:
        raise ValueError(f"need n_boot >= 1 and 0 < level < 1, got {n_boot}, {level}")
    rng = np.random.default_rng(seed)
    rows = max(1, BOOTSTRAP_BLOCK // v.size)
    boot = np.empty(n_boot, dtype=np.float64)
    for start in range(0, n_boot, rows):
        idx = rng.integers(0, v.size, size=(min(rows, n_boot - start), v.size))
        boot[start : start + idx.shape[0]] = _statistic(v[idx], stat, axis=1)
        del idx
    alpha = (1.0 - level) / 2.0
    lo, hi = np.quantile(boot, [alpha, 1.0 - alpha])
    return est, float(lo), float(hi)


def cell_float(value: object) -> float:
    """An episode-row cell as a float: a number, its CSV text or a bool (as 0 / 1); NaN for None,
    a blank or any text that is not a number."""
    try:
        return float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return math.nan


def pair_up(
    agent: Mapping[Hashable, float | None],
    reference: Mapping[Hashable, float | None],
) -> tuple[list[Hashable], np.ndarray, np.ndarray]:
    """Values of the receivers both mappings hold with a finite value, in the reference's key order.

    Returns ``(keys, agent values, reference values)``.
    """
    keys, a, r = [], [], []
    for key, ref in reference.items():
        if key not in agent:
            continue
        x, y = agent[key], ref
        if x is None or y is None or not (math.isfinite(float(x)) and math.isfinite(float(y))):
            continue
        keys.append(key)
        a.append(float(x))
        r.append(float(y))
    return keys, np.asarray(a, dtype=np.float64), np.asarray(r, dtype=np.float64)


@dataclass(frozen=True)
class PairedDifference:
    """A paired comparison agent - reference over the same receivers.

    Attributes:
        n: number of pairs.
        agent, reference: the statistic of each side over the pairs.
        diff, low, high: the statistic of the differences and its bootstrap CI.
        stat: "median" or "mean" (a success-rate difference is a mean of 0/1 differences).
    """

    n: int
    agent: float
    reference: float
    diff: float
    low: float
    high: float
    stat: str

    @property
    def excludes_zero(self) -> bool:
        """True when the CI lies entirely above or below 0."""
        return self.n > 0 and ci_excludes_zero(self.low, self.high)


def ci_excludes_zero(low: float, high: float) -> bool:
    """True when the interval [low, high] lies entirely above or below 0 (the tables' star)."""
    return low > 0 or high < 0


def paired_difference(
    agent: np.ndarray,
    reference: np.ndarray,
    stat: str = "median",
    n_boot: int = N_BOOTSTRAP,
    seed: int = 0,
    level: float = 0.95,
) -> PairedDifference:
    """The ``stat`` of ``agent - reference`` (aligned arrays), bootstrap CI resampling pairs."""
    a = np.asarray(agent, dtype=np.float64).reshape(-1)
    r = np.asarray(reference, dtype=np.float64).reshape(-1)
    if a.shape != r.shape:
        raise ValueError(f"paired arrays differ in length: {a.size} vs {r.size}")
    if a.size == 0:
        return PairedDifference(0, math.nan, math.nan, math.nan, math.nan, math.nan, stat)
    est, lo, hi = bootstrap_ci(a - r, stat, n_boot, seed, level)
    return PairedDifference(
        int(a.size), float(_statistic(a, stat)), float(_statistic(r, stat)), est, lo, hi, stat
    )


def median_iqr(values: np.ndarray) -> tuple[float, float, float]:
    """``(median, 25 %, 75 %)`` of the finite values (NaNs when there are none)."""
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return math.nan, math.nan, math.nan
    q25, med, q75 = np.quantile(v, [0.25, 0.5, 0.75])
    return float(med), float(q25), float(q75)


def quantiles(values: np.ndarray, qs: tuple[float, ...] = (0.5, 0.9, 0.99, 1.0)) -> list[float]:
    """Quantiles of the finite values (NaNs when there are none)."""
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return [math.nan] * len(qs)
    return [float(x) for x in np.quantile(v, qs)]
