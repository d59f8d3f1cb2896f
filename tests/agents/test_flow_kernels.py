"""The planner's compiled frame (agents/flow_kernels.py) gives numpy's bits."""

from __future__ import annotations

import numpy as np
import pytest

from agents.flow_kernels import (
    STATE_HEAD,
    STREAM_PAR,
    blend_kernel,
    blend_rows_kernel,
    blend_weights_kernel,
    exponent_kernel,
    flow_kernel,
    pairwise_sum,
    stream_frame_kernel,
)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_segment_sum_is_numpy_reduceat(dtype: type) -> None:
    rng = np.random.default_rng(0)
    a = rng.random(2000).astype(dtype) ** 2
    for n in list(range(2, 140)) + [255, 256, 257, 300, 1000, 1999]:
        lo = int(rng.integers(0, a.size - n + 1))
        expected = np.add.reduceat(a[lo : lo + n], [0])[0]
        got = a[lo] + pairwise_sum(a, lo + 1, n - 1)
        assert got == expected, n


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_pairwise_sum_is_numpy_sum_short_and_long(dtype: type) -> None:
    rng = np.random.default_rng(5)
    a = rng.random(40_000).astype(dtype)
    for n in [1, 2, 7, 8, 20, 129, 1000, 8191, 8192, 8193, 16385, 39_990]:
        lo = int(rng.integers(0, a.size - n + 1))
        assert pairwise_sum(a, lo, n) == np.sum(a[lo : lo + n]), n


def _segments(rng: np.random.Generator, n: int, d: int) -> tuple[np.ndarray, np.ndarray,
                                                                  np.ndarray]:
    """A bank-like layout: per demo d mean rows then its T rows in ``top``, its rows in ``bot``."""
    lt, lb = rng.integers(0, 140, n), rng.integers(0, 60, n)
    t0 = np.concatenate([[0], np.cumsum(lt + d)])
    b0 = np.concatenate([[0], np.cumsum(lb)])
    seg = np.column_stack([t0[:-1] + d, t0[1:], b0[:-1], b0[1:],
                           t0[:-1, None] + np.arange(d)[None, :]])
    return np.ascontiguousarray(seg, dtype=np.int64), t0, b0


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_flow_kernel_is_the_numpy_segment_sums(dtype: type) -> None:
    rng = np.random.default_rng(6)
    n, d, q = 40, 2, 3
    seg, t0, b0 = _segments(rng, n, d)
    top = rng.normal(size=(t0[-1], q)).astype(dtype)
    bot = rng.normal(size=(max(b0[-1], 1), q)).astype(dtype)
    mean, var = np.empty((q, n, d)), np.empty((q, n))
    flow_kernel(top, bot, seg, 1.5, mean, var)
    for j in range(q):
        for k in range(n):
            assert np.array_equal(mean[j, k], top[seg[k, 4:], j])
            sq_t = top[seg[k, 0] : seg[k, 1], j] ** 2
            sq_b = bot[seg[k, 2] : seg[k, 3], j] ** 2
            parts = [np.add.reduceat(sq, [0])[0] if sq.size else dtype(0) for sq in (sq_t, sq_b)]
            assert var[j, k] == 1.5 - (np.float64(parts[0]) + np.float64(parts[1]))


def test_blend_weights_are_numpy_normalised_exponentials() -> None:
    rng = np.random.default_rng(7)
    for n, k in [(875, 20), (50, 7), (30, 30), (12, 1)]:
        d = rng.random(n) * 3.0
        sel = np.argpartition(d, k - 1)[:k] if k < n else np.arange(n)
        w = np.empty(k)
        blend_weights_kernel(sel, d, w)
        ds = d[sel]
        expected = np.exp(-(ds - ds.min()))
        expected /= expected.sum()
        assert np.array_equal(w, expected)
        assert abs(w.sum() - 1.0) < 1e-12 and w.max() <= 1.0


def test_stream_frame_adds_eq_d_terms_to_the_running_sums() -> None:
    rng = np.random.default_rng(8)
    n, d = 25, 2
    seg, t0, b0 = _segments(rng, n, d)
    top = rng.normal(size=(t0[-1], 1))
    bot = rng.normal(size=(max(b0[-1], 1), 1))
    s2, rate, scale, v0, kappa = 1.0, 30.0, 0.7, 0.05, 1.3
    par = np.array([s2, rate, scale, v0, kappa])
    assert len(STREAM_PAR) == par.size
    state = np.zeros(STATE_HEAD + 2 * n)
    mean = top[seg[:, 4:], 0]  # (N, 2)
    var = s2 - np.array([np.sum(top[a:b, 0] ** 2) + np.sum(bot[c:e, 0] ** 2)
                         for a, b, c, e in seg[:, :4]])
    sums = np.zeros(n)
    last = None
    for count, (x0, x1) in enumerate(rng.normal(size=(4, 2)), start=1):
        stream_frame_kernel(top, bot, seg, par, float(x0), float(x1), state)
        vel = np.zeros(2) if last is None else (np.array([x0, x1]) - last) * rate
        mu = mean * scale
        cos = 1.0 - (mu @ vel) / (np.maximum(np.linalg.norm(mu, axis=1), v0)
                                  * max(np.linalg.norm(vel), v0))
        sums += kappa * cos + var
        last = np.array([x0, x1])
        np.testing.assert_allclose(state[STATE_HEAD : STATE_HEAD + n], sums, rtol=1e-12)
        np.testing.assert_allclose(state[STATE_HEAD + n :], sums / count, rtol=1e-12)
        assert state[0] == count and state[1] == 1.0 and np.array_equal(state[2:4], last)
    # at the first frame the velocity is zero: every demo's cosine term is kappa * 1
    state[:] = 0.0
    stream_frame_kernel(top, bot, seg, par, 0.1, 0.2, state)
    np.testing.assert_allclose(state[STATE_HEAD : STATE_HEAD + n], kappa + var, rtol=1e-12)


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
    search = np.ascontiguousarray(np.concatenate([rr[..., None], receivers], axis=2))
    sel, xy = np.array([4, 1, 5, 0], dtype=np.int64), np.array([0.3, -0.2])
    rows = np.empty((sel.size, 3 * horizon))
    blend_rows_kernel(sel, search, float(xy[0]), float(xy[1]), lengths, givers, rows)
    t_k = np.argmin(rr[sel] - receivers[sel] @ (2.0 * xy), axis=1)
    assert np.array_equal(t_k, np.argmin(np.sum((receivers[sel] - xy) ** 2, axis=2), axis=1))
    for i, k in enumerate(sel):
        idx = np.minimum(t_k[i] + np.arange(horizon), lengths[k] - 1)
        assert np.array_equal(rows[i].reshape(horizon, 3), givers[k, idx])
    assert np.array_equal(rows[2].reshape(horizon, 3), np.repeat(givers[5, :1], horizon, 0))
    # the one-call blend gives the same rows and numpy's weights
    d = rng.random(n)
    w, rows2 = np.empty(sel.size), np.empty_like(rows)
    blend_kernel(sel, d, search, float(xy[0]), float(xy[1]), lengths, givers, w, rows2)
    expected = np.exp(-(d[sel] - d[sel].min()))
    assert np.array_equal(rows2, rows) and np.array_equal(w, expected / expected.sum())
