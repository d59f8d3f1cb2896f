"""The planner's compiled frame (agents/flow_kernels.py) gives numpy's bits."""

from __future__ import annotations

import numpy as np
import pytest

from agents.flow_kernels import blend_rows_kernel, exponent_kernel, pairwise_sum


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_segment_sum_is_numpy_reduceat(dtype: type) -> None:
    rng = np.random.default_rng(0)
    a = rng.random(2000).astype(dtype) ** 2
    for n in list(range(2, 140)) + [255, 256, 257, 300, 1000, 1999]:
        lo = int(rng.integers(0, a.size - n + 1))
        expected = np.add.reduceat(a[lo : lo + n], [0])[0]
        got = a[lo] + pairwise_sum(a, lo + 1, n - 1)
        assert got == expected, n


def test_exponent_is_numpy_expansion_of_one_query() -> None:
    rng = np.random.default_rng(1)
    z_t = np.ascontiguousarray(rng.normal(size=(2, 500)))
    log_base = rng.normal(size=500) - 2.0
    log_base[::7] = -np.inf  # padding
    c, xq = -0.5 / 0.15**2, rng.normal(size=(1, 2))
    e = (-2.0 * c * xq) @ z_t
    e += log_base
    e += (c * np.sum(xq**2, axis=1))[:, None]
    np.minimum(e, 0.0, out=e)
    out = np.empty((1, 500), dtype=np.float32)
    exponent_kernel(xq, c, z_t, log_base, 0.0, out)
    assert np.array_equal(out, e.astype(np.float32))
    assert np.all(out <= 0.0) and np.sum(np.isneginf(out)) == 72


def test_blend_rows_are_the_closest_frames_next_rows() -> None:
    rng = np.random.default_rng(2)
    n, lmax, horizon = 6, 40, 5
    receivers = rng.normal(size=(n, lmax, 2))
    lengths = np.array([40, 3, 25, 40, 10, 1], dtype=np.int64)
    for k, length in enumerate(lengths):
        receivers[k, length:] = 1e6
    givers = rng.normal(size=(n, lmax, 3))
    rr = np.sum(receivers**2, axis=2)
    sel, xy = np.array([4, 1, 5, 0], dtype=np.int64), np.array([0.3, -0.2])
    rows = np.empty((sel.size, 3 * horizon))
    blend_rows_kernel(sel, rr, receivers, float(xy[0]), float(xy[1]), lengths, givers, rows)
    t_k = np.argmin(rr[sel] - receivers[sel] @ (2.0 * xy), axis=1)
    assert np.array_equal(t_k, np.argmin(np.sum((receivers[sel] - xy) ** 2, axis=2), axis=1))
    for i, k in enumerate(sel):
        idx = np.minimum(t_k[i] + np.arange(horizon), lengths[k] - 1)
        assert np.array_equal(rows[i].reshape(horizon, 3), givers[k, idx])
    assert np.array_equal(rows[2].reshape(horizon, 3), np.repeat(givers[5, :1], horizon, 0))
