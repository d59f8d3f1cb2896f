"""The planner's per-frame arithmetic compiled (:func:`handover_env.compiled.kernel`).

One streaming frame of the motion-flow planner (:mod:`agents.nonparametric`, Sec. IV-A) is, for
every demo k at once: the kernel row ``k(x, Z)`` against every inducing point, the stored
products ``[alpha^T; T] k`` (BLAS, :class:`agents.gp.FlowBank`), the flow's mean and latent
variance ``sigma2_k = s2 - |T k|^2``, Eq. d's summand ``kappa d_cos + sigma2_k`` added to the
running sums, and the top-K blend of Eq. xi_pred (each selected demo's closest frame and its
next H giver rows). The kernels below are those steps apart from the BLAS products and the
exponentials (``np.exp`` keeps numpy's own vectorised ``exp``), each the same IEEE operations in
the same order as the numpy expression it stands for, so a frame gives the same bits:

- :func:`exponent_kernel`: ``e = (-2c x) . z + log_base + c |x|^2``, capped at ``log s2``, as
  ``(-2c x) @ z_t`` (two products and one sum), ``+=`` and ``np.minimum`` do it;
- :func:`flow_kernel`: each demo's mean rows and its sum of squared ``T k`` rows, summed as
  ``np.add.reduceat`` sums a segment (its first element, then numpy's pairwise summation of the
  rest: :func:`pairwise_sum`), in the products' precision, then ``s2 - (top + bottom)`` in
  float64;
- :func:`terms_kernel`: the zero-velocity cosine distance and Eq. d's summand of each demo;
- :func:`blend_rows_kernel`: ``t_k = argmin_t |r_{k,t}|^2 - r_{k,t} . 2x`` (the dot product as
  numpy's stacked ``matmul`` computes it here: ``fma(r0, 2x0, r1 2x1)``) and the H giver rows
  from ``t_k`` on, each demo holding its last row.
"""

from __future__ import annotations

import numpy as np

from handover_env.compiled import kernel
from handover_env.kernel_math import fma


@kernel
def _block_sum(a: np.ndarray, lo: int, n: int) -> float:
    """``a[lo:lo + n]`` summed as numpy's ``pairwise_sum`` sums a block of n <= 128: a plain
    loop below 8 elements, else 8 interleaved partial sums, in ``a``'s precision."""
    if n < 8:
        res = a[lo]  # numpy starts from 0.0; 0.0 + a[lo] == a[lo] for the sums here
        for i in range(1, n):
            res += a[lo + i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    stop = n - n % 8
    while i < stop:
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@kernel
def pairwise_sum(a: np.ndarray, lo: int, n: int) -> float:
    """``a[lo:lo + n]`` (n >= 1) summed as numpy's ``sum`` of a contiguous array does: in chunks
    of 8192 (numpy's buffer), added one after the other, each in the pairwise order of
    :func:`_pairwise_chunk`, in ``a``'s precision."""
    if n <= 128:
        return _block_sum(a, lo, n)
    return _long_sum(a, lo, n)


@kernel
def _long_sum(a: np.ndarray, lo: int, n: int) -> float:
    """:func:`pairwise_sum` above 128 elements (out of line, so that the short sums inline)."""
    res = _pairwise_chunk(a, lo, min(n, 8192))
    for start in range(8192, n, 8192):
        res += _pairwise_chunk(a, lo + start, min(8192, n - start))
    return res


@kernel
def _pairwise_chunk(a: np.ndarray, lo: int, n: int) -> float:
    """numpy's ``pairwise_sum`` of its ``add`` reduction: :func:`_block_sum` up to 128
    elements, above that the sum of the two halves, the first half rounded down to a multiple
    of 8. The halving is walked with an explicit stack, not by recursion (numba cannot link a
    cached recursive kernel into a caller compiled in another process)."""
    if n <= 128:
        return _block_sum(a, lo, n)
    s_lo = np.empty(64, dtype=np.int64)  # the pending ranges, root first
    s_n = np.empty(64, dtype=np.int64)
    s_left = np.empty(64, dtype=a.dtype)  # each range's left-half sum, once known
    s_has_left = np.zeros(64, dtype=np.bool_)
    sp = 0
    s_lo[0], s_n[0] = lo, n
    res = a[lo]
    while sp >= 0:
        m = s_n[sp]
        if m > 128:  # descend into the left half
            half = m // 2
            half -= half % 8
            s_lo[sp + 1], s_n[sp + 1], s_has_left[sp + 1] = s_lo[sp], half, False
            sp += 1
            continue
        res = _block_sum(a, s_lo[sp], m)
        sp -= 1
        while sp >= 0:  # hand the finished sum up: a left half waits, a right half completes
            if s_has_left[sp]:
                res = s_left[sp] + res
                sp -= 1
            else:
                s_left[sp], s_has_left[sp] = res, True
                half = s_n[sp] // 2
                half -= half % 8
                s_lo[sp + 1], s_n[sp + 1] = s_lo[sp] + half, s_n[sp] - half
                s_has_left[sp + 1] = False
                sp += 1
                break
    return res


@kernel
def exponent_kernel(xq: np.ndarray, c: float, z_t: np.ndarray, log_base: np.ndarray,
                    log_s2: float, out: np.ndarray) -> None:
    """``out[q, p] = min((-2c x0) z0_p + (-2c x1) z1_p + log_base_p + c (x0^2 + x1^2), log s2)``
    for every query ``x = xq[q]`` and inducing point p (the exponent of ``k(x, z_p)``), stored in
    ``out``'s precision."""
    for q in range(xq.shape[0]):
        x0, x1 = xq[q, 0], xq[q, 1]
        a0 = -2.0 * c * x0
        a1 = -2.0 * c * x1
        cx = c * (x0 * x0 + x1 * x1)
        for p in range(z_t.shape[1]):
            e = a0 * z_t[0, p] + a1 * z_t[1, p]
            e += log_base[p]
            e += cx
            if e > log_s2:
                e = log_s2
            out[q, p] = e


@kernel
def flow_kernel(top: np.ndarray, bot: np.ndarray, seg: np.ndarray, signal_var: float,
                mean: np.ndarray, var: np.ndarray) -> None:
    """Every demo's flow at Q queries from the products' columns.

    Args:
        top: (rows, Q) ``[alpha^T; T[:h]] k`` of every demo, stacked.
        bot: (rows, Q) ``T[h:, h:] k[h:]`` of every demo, stacked.
        seg: (N, 4 + D) int64, per demo: its ``[start, stop)`` rows of ``T k`` in ``top``, the
            same in ``bot``, then the D rows of ``top`` holding its mean.
        signal_var: s2.
        mean: out, (Q, N, D) float64.
        var: out, (Q, N) float64: ``s2 - (|T[:h] k|^2 + |T[h:] k|^2)``.
    """
    n_q = top.shape[1]
    n_demos, d = mean.shape[1], mean.shape[2]
    col = np.empty(max(top.shape[0], bot.shape[0]), dtype=top.dtype)
    for q in range(n_q):
        for n in range(n_demos):
            for j in range(d):
                mean[q, n, j] = top[seg[n, 4 + j], q]
        for i in range(top.shape[0]):
            col[i] = top[i, q] * top[i, q]
        for n in range(n_demos):
            lo, hi = seg[n, 0], seg[n, 1]
            if 1 < hi - lo <= 129:  # the short sum called directly: the compiler inlines it
                var[q, n] = np.float64(col[lo] + _block_sum(col, lo + 1, hi - lo - 1))
            elif hi - lo > 1:
                var[q, n] = np.float64(col[lo] + pairwise_sum(col, lo + 1, hi - lo - 1))
            elif hi - lo == 1:
                var[q, n] = np.float64(col[lo])
            else:
                var[q, n] = 0.0
        for i in range(bot.shape[0]):
            col[i] = bot[i, q] * bot[i, q]
        for n in range(n_demos):
            lo, hi = seg[n, 2], seg[n, 3]
            if 1 < hi - lo <= 129:
                var[q, n] += np.float64(col[lo] + _block_sum(col, lo + 1, hi - lo - 1))
            elif hi - lo > 1:
                var[q, n] += np.float64(col[lo] + pairwise_sum(col, lo + 1, hi - lo - 1))
            elif hi - lo == 1:
                var[q, n] += np.float64(col[lo])
            var[q, n] = signal_var - var[q, n]


@kernel
def cosine_distance_kernel(a0: float, a1: float, b0: float, b1: float, min_speed: float) -> float:
    """``1 - a.b / (max(|a|, v0) max(|b|, v0))`` of two 2D velocities (the zero-velocity rule of
    :mod:`agents.nonparametric`; ``v0 = min_speed``)."""
    na = max(np.sqrt(a0 * a0 + a1 * a1), min_speed)
    nb = max(np.sqrt(b0 * b0 + b1 * b1), min_speed)
    return 1.0 - (a0 * b0 + a1 * b1) / (na * nb)


@kernel
def cosine_rows_kernel(a: np.ndarray, b: np.ndarray, min_speed: float, out: np.ndarray) -> None:
    """``out[i]`` = the cosine distance of rows ``a[i]`` and ``b[i]`` ((M, 2) each)."""
    for i in range(out.shape[0]):
        out[i] = cosine_distance_kernel(a[i, 0], a[i, 1], b[i, 0], b[i, 1], min_speed)


@kernel
def terms_kernel(vel: np.ndarray, mean: np.ndarray, var: np.ndarray, output_scale: float,
                 min_speed: float, kappa: float, out: np.ndarray) -> None:
    """Eq. d's summands of F frames against N demos: ``out[f, n] = kappa d_cos(vel_f,
    mu_n(x_f) output_scale) + sigma2_n(x_f)`` (vel (F, 2), mean (F, N, 2), var and out (F, N))."""
    for f in range(out.shape[0]):
        v0, v1 = vel[f, 0], vel[f, 1]
        for n in range(out.shape[1]):
            d = cosine_distance_kernel(v0, v1, mean[f, n, 0] * output_scale,
                                       mean[f, n, 1] * output_scale, min_speed)
            out[f, n] = kappa * d + var[f, n]


#: ``stream_frame_kernel``'s settings, in ``par``: s2, rate (Hz), output scale, v0, kappa
STREAM_PAR = ("signal_var", "rate_hz", "output_scale", "min_speed", "kappa")
#: ``stream_frame_kernel``'s ``state``: frames seen, whether a last frame exists, its x and y; then
#: the running sums (N) and the distances ``sums / count`` (N)
STATE_HEAD = 4


@kernel
def stream_frame_kernel(top: np.ndarray, bot: np.ndarray, seg: np.ndarray, par: np.ndarray,
                        x0: float, x1: float, state: np.ndarray) -> None:
    """One streamed frame at receiver position ``(x0, x1)`` (m, dataset frame): every demo's
    flow from the products (:func:`flow_kernel`, Q = 1), the backward velocity ``(x - x_last)
    rate`` (zero at the first frame), Eq. d's summand of each demo (:func:`terms_kernel`) added
    to the running sums, and the distances ``d = sums / count``, all in ``state`` (see
    :data:`STATE_HEAD`; ``par`` as :data:`STREAM_PAR`)."""
    n = seg.shape[0]
    mean = np.empty((1, n, seg.shape[1] - 4))
    var = np.empty((1, n))
    flow_kernel(top, bot, seg, par[0], mean, var)
    if state[1] == 0.0:
        v0 = v1 = 0.0
    else:
        v0 = (x0 - state[2]) * par[1]
        v1 = (x1 - state[3]) * par[1]
    terms = np.empty((1, n))
    vel = np.empty((1, 2))
    vel[0, 0], vel[0, 1] = v0, v1
    terms_kernel(vel, mean, var, par[2], par[3], par[4], terms)
    count = state[0] + 1.0
    state[0], state[1], state[2], state[3] = count, 1.0, x0, x1
    for i in range(n):
        state[STATE_HEAD + i] += terms[0, i]
        state[STATE_HEAD + n + i] = state[STATE_HEAD + i] / count


@kernel
def blend_rows_kernel(sel: np.ndarray, search: np.ndarray, x0: float, x1: float,
                      lengths: np.ndarray, givers: np.ndarray, rows: np.ndarray) -> None:
    """The giver rows Eq. xi_pred blends: for each selected demo k, ``t_k`` = its frame closest
    to ``x`` (the first of equals) among its ``L_k`` frames, by ``|r_{k,t}|^2 - r_{k,t} . 2x``
    (the dot product as numpy's stacked ``matmul`` computes it here: ``fma(r0, 2x0, r1 2x1)``;
    ``search[k, t] = (|r|^2, r0, r1)``), and ``rows[i] = givers[k, min(t_k + h, L_k - 1)]`` for
    h < H (``rows`` (K, H * 3), row-major as ``givers[k, t]`` are)."""
    v0 = 2.0 * x0
    v1 = 2.0 * x1
    horizon = rows.shape[1] // 3
    for i in range(sel.shape[0]):
        k = sel[i]
        best = search[k, 0, 0] - fma(search[k, 0, 1], v0, search[k, 0, 2] * v1)
        t_k = 0
        for t in range(1, lengths[k]):
            val = search[k, t, 0] - fma(search[k, t, 1], v0, search[k, t, 2] * v1)
            if val < best:
                best = val
                t_k = t
        last = lengths[k] - 1
        for h in range(horizon):
            t = min(t_k + h, last)
            for j in range(3):
                rows[i, 3 * h + j] = givers[k, t, j]


@kernel
def blend_weights_kernel(sel: np.ndarray, d: np.ndarray, w: np.ndarray) -> None:
    """Eq. xi_pred's weights of the selected demos: ``w_i = exp(-(d_i - min d)) / sum``, the sum
    in numpy's pairwise order (``w.sum()``)."""
    lo = d[sel[0]]
    for i in range(1, sel.shape[0]):
        lo = min(lo, d[sel[i]])
    for i in range(sel.shape[0]):
        w[i] = np.exp(-(d[sel[i]] - lo))
    total = pairwise_sum(w, 0, w.shape[0])
    for i in range(sel.shape[0]):
        w[i] /= total


@kernel
def blend_kernel(sel: np.ndarray, d: np.ndarray, search: np.ndarray, x0: float, x1: float,
                 lengths: np.ndarray, givers: np.ndarray, w: np.ndarray,
                 rows: np.ndarray) -> None:
    """The weights (:func:`blend_weights_kernel`) and giver rows (:func:`blend_rows_kernel`)
    of the selected demos ``sel`` at distances ``d`` and receiver position ``x``, in one call;
    the chunk is ``w @ rows``."""
    blend_weights_kernel(sel, d, w)
    blend_rows_kernel(sel, search, x0, x1, lengths, givers, rows)
