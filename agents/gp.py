"""Gaussian-process motion flows, exact and sparse (FITC/SPGP), batched over demonstrations.

The paper (Sec. IV-A, "Trajectory Similarity Measure") models, for every demo k, a flow function
f_k: x -> xdot from the receiver base position (2D) to its velocity (2D) with a Sparse
Pseudo-input GP (SPGP, Snelson & Ghahramani 2006, whose approximation is called FITC in
Quinonero-Candela & Rasmussen 2005). IAAL (Choi et al. 2018) uses the exact GP instead. Both
velocity components share one kernel, so they share every matrix below and differ only in
their weight vectors.

Kernel: squared exponential ``k(a, b) = s2 * exp(-|a - b|^2 / (2 l^2))``.

**Exact GP** on inputs X (N, 2), outputs Y (N, 2), noise variance sn2::

    mu(x)     = k_x^T (K_nn + sn2 I)^-1 Y
    sigma2(x) = s2 - k_x^T (K_nn + sn2 I)^-1 k_x                     (latent f, no noise)

**FITC / SPGP** with inducing inputs Z (M, 2) (Snelson & Ghahramani 2006, Eqs. 8-9)::

    Lambda    = diag(K_nn - Q_nn) + sn2 I,   Q_nn = K_nm K_mm^-1 K_mn
    Q         = K_mm + K_mn Lambda^-1 K_nm
    mu(x)     = k_x^T Q^-1 K_mn Lambda^-1 Y
    sigma2(x) = s2 - k_x^T (K_mm^-1 - Q^-1) k_x

computed in feature space: K_mm is inverted on its numerically non-singular eigen-space,
``K_mm^+ = P P^T`` (eigenvalues below ``rcond * max`` dropped instead of adding jitter, which
costs ~sqrt(jitter) in accuracy), ``Phi = K_nm P``, ``A = I + Phi^T Lambda^-1 Phi`` (eigenvalues
>= 1). When Z = X (inducing ratio 1.0) Q_nn = K_nn, Lambda = sn2 I and both formulas agree with
the exact GP (tests/agents/test_gp.py: 1e-8 on synthetic 30 Hz walks with l <= 0.15 m). On 59 real
recordings at l = 0.15 m the largest difference in mean or variance is 2e-8 (median), 3e-7
(90th percentile), 1.3e-6 (worst): where the receiver pauses or samples are dense, K_mm is
numerically singular and float64 cannot represent K_mm^-1 any better.

Both models therefore reduce to one *predictive form* per demo,
``mu(x) = k(x, Z)^T alpha`` and ``sigma2(x) = s2 - |R k(x, Z)|^2`` (``R^T R = W``, the variance
matrix: ``(K_nn + sn2 I)^-1`` exact, ``K_mm^-1 - Q^-1`` FITC; summing squares avoids the
cancellation of ``k^T W k``), with everything query-independent (Z, alpha, R) precomputed at
fit time. :class:`FlowBank` stacks the predictive forms of all demos into padded tensors
(grouped into buckets of similar size so padding wastes little; R made upper-triangular by a
QR so a quarter of it need not be streamed) and evaluates every demo's flow at a query with one
kernel evaluation against all inducing points of all demos plus batched mat-vecs: per query
O(M_k) for the kernel and mean and O(M_k^2) for the variance, against O(N_k) and O(N_k^2) for
the exact GP.

**Hyperparameters** are not fitted per demo: one shared triple (l, s2, sn2) is set by the
documented rule in :meth:`GPHyperparameters.from_velocities`. The similarity compares the
variance sigma2_k across demos, so all flows must share one prior scale; per-demo
marginal-likelihood fits would make a demo with small fitted s2 look "close" everywhere.
The same triple is used by the exact GP (IAAL), so FITC and exact differ only by the sparse
approximation.

The module is over 500 lines because the two models, their textbook forms (for the tests) and
the bank that batches them share the formulas above; the per-frame arithmetic is compiled
apart in :mod:`agents.flow_kernels`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.linalg import cho_solve, cholesky, eigh, solve_triangular

from agents.flow_kernels import exponent_kernel, flow_kernel

DEFAULT_RCOND = (
    1e-14  # eigenvalues of K_mm below rcond * max are treated as zero (float64 round-off)
)


@dataclass(frozen=True)
class GPHyperparameters:
    """Shared squared-exponential kernel hyperparameters of every flow GP.

    Args:
        lengthscale: l in metres (receiver base positions are in metres).
        signal_var: s2, prior variance of each velocity component (in the GP's output units).
        noise_var: sn2, observation noise variance of each velocity component (same units).
    """

    lengthscale: float
    signal_var: float = 1.0
    noise_var: float = 0.05

    def __post_init__(self) -> None:
        for name in ("lengthscale", "signal_var", "noise_var"):
            value = float(getattr(self, name))
            if not np.isfinite(value) or value <= 0:
                raise ValueError(f"{name} must be positive and finite, got {getattr(self, name)!r}")
            object.__setattr__(self, name, value)

    @classmethod
    def from_velocities(
        cls, velocities: Sequence[np.ndarray], lengthscale: float, output_scale: float
    ) -> GPHyperparameters:
        """The fixed rule used by both the SPGP planner and IAAL.

        Velocities are divided by ``output_scale`` before they enter the GP (the caller uses the
        pooled standard deviation of all training velocity components, so the outputs have unit
        variance and ``s2 = 1``: far from a demo sigma2 -> 1, on its path sigma2 -> ~0).
        The noise variance is the classic difference-based estimate: if v_t = v*_t + e_t with
        white e and a smooth v*, then Var(v_t - v_{t-1}) ~= 2 Var(e), so
        ``sn2 = mean((v_t - v_{t-1})^2) / 2 / output_scale^2``, pooled over demos and axes and
        floored at 1e-4. The lengthscale is a planner setting (metres) chosen on the open-loop
        protocol.
        """
        diffs = [np.diff(np.asarray(v, dtype=np.float64), axis=0) for v in velocities if len(v) > 1]
        if not diffs:
            raise ValueError("need at least one velocity sequence with 2 or more frames")
        d = np.concatenate(diffs)
        sn2 = 0.5 * float(np.mean(d**2)) / float(output_scale) ** 2
        return cls(lengthscale=lengthscale, signal_var=1.0, noise_var=max(sn2, 1e-4))


def se_kernel(a: np.ndarray, b: np.ndarray, hyp: GPHyperparameters) -> np.ndarray:
    """Squared-exponential kernel matrix between (..., n, 2) and (..., m, 2): (..., n, m)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    d2 = np.sum((a[..., :, None, :] - b[..., None, :, :]) ** 2, axis=-1)
    return hyp.signal_var * np.exp(-0.5 / hyp.lengthscale**2 * d2)


def inducing_indices(n: int, ratio: float) -> np.ndarray:
    """Indices of the inducing samples: ``max(1, round(ratio * n))`` samples uniformly in time.

    The paper picks "the proportion of actual data points used as inducing points ... ensuring
    a uniform distribution across time"; we take evenly spaced indices from the first to the
    last sample (ratio 1.0 gives every sample).
    """
    if not (0.0 < float(ratio) <= 1.0):
        raise ValueError(f"inducing ratio must be in (0, 1], got {ratio!r}")
    if n < 1:
        raise ValueError(f"need at least one sample, got {n}")
    m = min(n, max(1, int(round(ratio * n))))
    return np.unique(np.round(np.linspace(0, n - 1, m)).astype(np.int64))


def _check_xy(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != 2 or y.ndim != 2 or y.shape[0] != x.shape[0]:
        raise ValueError(f"expected X (N, 2) and Y (N, D), got {x.shape} and {y.shape}")
    if x.shape[0] < 1 or not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise ValueError("X and Y must be non-empty and finite")
    return x, y


@dataclass(frozen=True)
class PredictiveForm:
    """mu(x) = k(x, Z)^T alpha and sigma2(x) = s2 - |R k(x, Z)|^2 for one demo.

    ``W = R^T R`` is the variance matrix ((K + sn2 I)^-1 exact, K_mm^-1 - Q^-1 FITC); keeping the
    factor R and summing squares avoids the cancellation of ``k^T W k`` when W has large entries.
    """

    z: np.ndarray  # (M, 2) inducing (FITC) or training (exact) inputs
    alpha: np.ndarray  # (M, D) mean weights
    r: np.ndarray  # (r, M) variance factor, r <= M

    def predict(self, x: np.ndarray, hyp: GPHyperparameters) -> tuple[np.ndarray, np.ndarray]:
        """Mean (Q, D) and latent variance (Q,) at query points x (Q, 2)."""
        k = se_kernel(np.atleast_2d(x), self.z, hyp)
        return k @ self.alpha, hyp.signal_var - np.sum((k @ self.r.T) ** 2, axis=1)


def exact_gp(x: np.ndarray, y: np.ndarray, hyp: GPHyperparameters) -> PredictiveForm:
    """Exact GP regression (IAAL's flow model): Z = X, alpha = (K + sn2 I)^-1 Y, R = L^-1.

    ``L = chol(K + sn2 I)`` is well conditioned (eigenvalues >= sn2), so ``R = L^-1`` is exact.
    """
    x, y = _check_xy(x, y)
    k = se_kernel(x, x, hyp)
    k[np.diag_indices_from(k)] += hyp.noise_var
    c = cholesky(k, lower=True)
    r = solve_triangular(c, np.eye(x.shape[0]), lower=True)
    return PredictiveForm(z=x, alpha=cho_solve((c, True), y), r=r)


def exact_gp_reference(
    x: np.ndarray, y: np.ndarray, xq: np.ndarray, hyp: GPHyperparameters
) -> tuple[np.ndarray, np.ndarray]:
    """Textbook exact GP prediction by triangular solves (Rasmussen & Williams Alg. 2.1), for
    tests."""
    x, y = _check_xy(x, y)
    k = se_kernel(x, x, hyp) + hyp.noise_var * np.eye(x.shape[0])
    c = cholesky(k, lower=True)
    ks = se_kernel(np.atleast_2d(xq), x, hyp)
    v = solve_triangular(c, ks.T, lower=True)
    return ks @ cho_solve((c, True), y), hyp.signal_var - np.sum(v**2, axis=0)


def _fitc_parts(
    x: np.ndarray, y: np.ndarray, z: np.ndarray, hyp: GPHyperparameters, rcond: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Feature-space FITC: P (M, r), Lambda (N,), eigen-decomposition (a, E) of A, and A^-1 Phi^T
    Lambda^-1 Y."""
    x, y = _check_xy(x, y)
    z = np.asarray(z, dtype=np.float64)
    if z.ndim != 2 or z.shape[1] != 2 or z.shape[0] < 1 or not np.all(np.isfinite(z)):
        raise ValueError(f"inducing inputs must be finite with shape (M, 2), got {z.shape}")
    lam, u = eigh(se_kernel(z, z, hyp))
    keep = lam > rcond * lam[-1]
    p = u[:, keep] / np.sqrt(lam[keep])  # K_mm^+ = P P^T on the kept eigen-space
    phi = se_kernel(x, z, hyp) @ p  # (N, r): Q_nn = Phi Phi^T
    # Lambda = diag(K_nn - Q_nn) + sn2; the clip only removes round-off below zero.
    lam_n = np.maximum(hyp.signal_var - np.sum(phi**2, axis=1), 0.0) + hyp.noise_var
    a_val, a_vec = eigh(np.eye(p.shape[1]) + (phi / lam_n[:, None]).T @ phi)  # A, eigenvalues >= 1
    beta = a_vec @ ((a_vec.T @ (phi.T @ (y / lam_n[:, None]))) / a_val[:, None])
    return p, a_val, a_vec, beta


def fitc_gp(
    x: np.ndarray,
    y: np.ndarray,
    z: np.ndarray,
    hyp: GPHyperparameters,
    rcond: float = DEFAULT_RCOND,
) -> PredictiveForm:
    """FITC / SPGP (Snelson & Ghahramani 2006) in predictive form, inducing inputs ``z``.

    K_mm is inverted on its numerically non-singular eigen-space (eigenvalues above
    ``rcond * max``), ``K_mm^+ = P P^T`` with ``P = U_r diag(lambda_r)^-1/2``. With the features
    ``Phi = K_nm P`` (so Q_nn = Phi Phi^T) and ``A = I + Phi^T Lambda^-1 Phi``::

        alpha = P A^-1 Phi^T Lambda^-1 Y
        R     = diag(sqrt(1 - 1/a)) E^T P^T          (A = E diag(a) E^T)

    so that ``k^T R^T R k = k^T (K_mm^-1 - Q^-1) k``. Truncating the spectrum (instead of adding
    jitter to K_mm, which perturbs every direction and costs ~sqrt(jitter) in accuracy) keeps
    FITC at Z = X equal to the exact GP as far as float64 can represent K_mm^-1.
    """
    p, a_val, a_vec, beta = _fitc_parts(x, y, z, hyp, rcond)
    r = (np.sqrt(np.maximum(1.0 - 1.0 / a_val, 0.0))[:, None] * a_vec.T) @ p.T
    return PredictiveForm(z=np.asarray(z, dtype=np.float64), alpha=p @ beta, r=r)


def fitc_gp_reference(
    x: np.ndarray,
    y: np.ndarray,
    z: np.ndarray,
    xq: np.ndarray,
    hyp: GPHyperparameters,
    rcond: float = DEFAULT_RCOND,
) -> tuple[np.ndarray, np.ndarray]:
    """FITC prediction by the textbook feature-space formulas evaluated at query time, for tests.

    ``mu = phi_*^T A^-1 Phi^T Lambda^-1 Y`` and ``sigma2 = s2 - phi_*^T phi_* + phi_*^T A^-1 phi_*``
    with ``phi_* = P^T k_*`` (Snelson & Ghahramani 2006, Eqs. 8-9, written with Q = K_mm + ...
    factored through K_mm^+ = P P^T).
    """
    p, a_val, a_vec, beta = _fitc_parts(x, y, z, hyp, rcond)
    phis = se_kernel(np.atleast_2d(xq), np.asarray(z, dtype=np.float64), hyp) @ p  # (Q, r)
    proj = phis @ a_vec
    var = hyp.signal_var - np.sum(phis**2, axis=1) + np.sum(proj**2 / a_val, axis=1)
    return phis @ beta, var


@dataclass
class _Bucket:
    """Demos of similar size, padded to a common M, R; their rows of the bank's flat arrays.

    The variance factor is stored upper-triangular (``T`` from ``R = Q T``; ``|T k| = |R k|``)
    and split in two row blocks: rows ``[0, h)`` need every column, rows ``[h, R)`` only
    columns ``[h, M)``, so 3/4 of the square is streamed per query. The D mean-weight rows are
    stacked on top of the first block (one product gives the mean and the first half of T k).
    """

    start: int  # first row of this bucket in the bank's flat inducing-point arrays
    n_demos: int  # B
    m: int  # padded M
    h: int  # split row
    top: np.ndarray  # (B, D + h, M): [alpha^T; T[:h, :]]
    bottom: np.ndarray  # (B, R - h, M - h): T[h:, h:]


def _split_buckets(order: np.ndarray, sizes: np.ndarray, ranks: np.ndarray, max_buckets: int,
                   overhead_entries: float = 4e4) -> list[np.ndarray]:
    """Split demos (``order`` sorts them by size) into <= ``max_buckets`` contiguous groups.

    Minimises ``sum over buckets (overhead_entries + B * R_max * M_max)``: the padded entries
    streamed per query plus a fixed cost per bucket (one more set of numpy calls), by dynamic
    programming over the sorted sizes (fit time only).
    """
    n = order.size
    m_sorted = sizes[order].astype(np.float64)
    r_sorted = np.maximum.accumulate(ranks[order].astype(np.float64))
    max_buckets = max(1, min(max_buckets, n))
    cost = np.full((max_buckets + 1, n + 1), np.inf)
    back = np.zeros((max_buckets + 1, n + 1), dtype=np.int64)
    cost[0, 0] = 0.0
    j = np.arange(n)
    for b in range(1, max_buckets + 1):
        for i in range(1, n + 1):
            # last bucket = sorted demos j..i-1, padded to the largest (the (i-1)-th) M and R
            cand = (
                cost[b - 1, :i] + overhead_entries + (i - j[:i]) * m_sorted[i - 1] * r_sorted[i - 1]
            )
            k = int(np.argmin(cand))
            cost[b, i], back[b, i] = cand[k], k
    b = int(np.argmin(cost[1:, n])) + 1
    cuts, i = [], n
    while b > 0:
        cuts.append((back[b, i], i))
        i, b = back[b, i], b - 1
    return [order[lo:hi] for lo, hi in reversed(cuts) if hi > lo]


class FlowBank:
    """The predictive forms of many demos stacked for batched evaluation.

    Args:
        forms: one :class:`PredictiveForm` per demo (all with the same output width D).
        hyp: the shared hyperparameters they were built with.
        n_buckets: the most groups of similar size the demos are split into, each padded to its
            own largest M; the split minimises padded entries plus a per-group overhead.
        dtype: precision of the per-query mat-vecs. Kernel values are computed in float64 and
            then cast. float32 halves the memory streamed per query (the cost is memory-bound)
            at an absolute error of ~1e-4 in sigma2 (K_mm is ill-conditioned, so R has large
            entries); float64 reproduces :meth:`PredictiveForm.predict` to round-off.
    """

    def __init__(
        self,
        forms: Sequence[PredictiveForm],
        hyp: GPHyperparameters,
        n_buckets: int = 12,
        dtype: type | str = np.float64,
    ) -> None:
        if len(forms) == 0:
            raise ValueError("FlowBank needs at least one demo")
        if not isinstance(n_buckets, (int, np.integer)) or n_buckets < 1:
            raise ValueError(f"n_buckets must be an integer >= 1, got {n_buckets!r}")
        self.dtype = np.dtype(dtype)
        if self.dtype not in (np.dtype(np.float32), np.dtype(np.float64)):
            raise ValueError(f"dtype must be float32 or float64, got {dtype!r}")
        self.hyp = hyp
        self.n_demos = len(forms)
        self.sizes = np.array([f.z.shape[0] for f in forms], dtype=np.int64)
        ranks = np.array([min(f.r.shape) for f in forms], dtype=np.int64)
        out_dim = {f.alpha.shape[1] for f in forms}
        if len(out_dim) != 1:
            raise ValueError(f"all demos need the same output width, got {sorted(out_dim)}")
        d = self.out_dim = out_dim.pop()
        order = np.argsort(self.sizes, kind="stable")
        groups = _split_buckets(order, self.sizes, ranks, int(n_buckets))
        self.order = np.concatenate(groups)  # bank row b*M.. holds demo order[...]
        self._unsort = np.argsort(self.order)
        z_all, mask_all, self.buckets = [], [], []
        start = 0
        for idx in groups:
            m, nr, b = int(self.sizes[idx].max()), int(ranks[idx].max()), idx.size
            h = nr // 2
            z = np.zeros((b, m, 2))
            mask = np.zeros((b, m))
            full = np.zeros((b, d + nr, m))
            for j, k in enumerate(idx):  # fit time only
                mk = self.sizes[k]
                z[j, :mk] = forms[k].z
                mask[j, :mk] = 1.0
                full[j, :d, :mk] = forms[k].alpha.T
                tri = np.linalg.qr(forms[k].r, mode="r")  # upper-trapezoidal, |T k| = |R k|
                full[j, d : d + tri.shape[0], :mk] = tri
            self.buckets.append(
                _Bucket(start, b, m, h, full[:, : d + h].astype(self.dtype),
                        np.ascontiguousarray(full[:, d + h :, h:]).astype(self.dtype))
            )
            z_all.append(z.reshape(-1, 2))
            mask_all.append(mask.reshape(-1))
            start += b * m
        # Flat output buffers of the per-bucket products and the segment starts of every demo in
        # them (bucket-sorted order): rows [D mean | h of T] in "top", [R - h of T] in "bottom".
        top_sizes = [bk.n_demos * bk.top.shape[1] for bk in self.buckets]
        bot_sizes = [bk.n_demos * bk.bottom.shape[1] for bk in self.buckets]
        self._top_off = np.concatenate([[0], np.cumsum(top_sizes)])
        self._bot_off = np.concatenate([[0], np.cumsum(bot_sizes)])
        seg_top, seg_bot, mean_idx = [], [], []
        for bk, t0, b0 in zip(self.buckets, self._top_off, self._bot_off):
            rows_top, rows_bot = bk.top.shape[1], bk.bottom.shape[1]
            starts = t0 + rows_top * np.arange(bk.n_demos)
            seg_top.append(np.column_stack([starts, starts + d]).reshape(-1))
            seg_bot.append(b0 + rows_bot * np.arange(bk.n_demos))
            mean_idx.append(starts[:, None] + np.arange(d)[None, :])
        self._seg_top = np.concatenate(seg_top)  # 2 per demo: mean rows start, T rows start
        self._seg_bot = np.concatenate(seg_bot)
        self._mean_idx = np.concatenate(mean_idx)[self._unsort]  # (N, D) in the caller's order
        self.z_all = np.concatenate(z_all)  # (P, 2) every (padded) inducing point of every demo
        c = -0.5 / hyp.lengthscale**2
        self._c = c
        # k(x, z) = exp(c |z|^2 + log s2 - 2c z.x + c |x|^2); padding gets -inf, i.e. k = 0.
        mask = np.concatenate(mask_all) > 0
        self._log_base = np.where(
            mask, c * np.sum(self.z_all**2, axis=1) + np.log(hyp.signal_var), -np.inf
        )
        self._z_t = np.ascontiguousarray(self.z_all.T)  # (2, P)
        self._single: tuple | None = None  # buffers of a one-point query, built on first use
        self._segs: tuple | None = None  # per-demo rows of the products, built on first use

    def __getstate__(self) -> dict:
        # The one-point buffers hold views of each other, which a copy would not keep: a copy
        # (pickle, deepcopy, a worker process) builds its own on first use.
        return {**self.__dict__, "_single": None, "_segs": None}

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update({**state, "_single": None, "_segs": None})

    def _segments(self) -> tuple[np.ndarray, float]:
        """Per demo (the caller's order), as :func:`agents.flow_kernels.flow_kernel` takes them:
        its ``[start, stop)`` rows of ``T k`` in ``top`` and in ``bottom``, then its mean rows in
        ``top`` ((N, 4 + D) int64); and log s2 (built once)."""
        if self._segs is None:
            stops = (np.append(self._seg_top[1:], self._top_off[-1])[1::2],
                     np.append(self._seg_bot[1:], self._bot_off[-1]))
            segs = [np.column_stack([lo, hi])[self._unsort]
                    for lo, hi in zip((self._seg_top[1::2], self._seg_bot), stops)]
            seg = np.ascontiguousarray(np.hstack([*segs, self._mean_idx]), dtype=np.int64)
            self._segs = (seg, float(np.log(self.hyp.signal_var)))
        return self._segs

    def _bucket_views(self, kt: np.ndarray, top: np.ndarray, bot: np.ndarray) -> list:
        """Per stored block: the block, the kernel columns (of ``kt`` (P, Q)) it multiplies and
        the rows of ``top`` / ``bot`` (rows, Q) the product goes to (two per bucket, the second
        left out when it is empty)."""
        q, views = kt.shape[1], []
        for b, t0, t1, b0, b1 in zip(
            self.buckets, self._top_off, self._top_off[1:], self._bot_off, self._bot_off[1:]
        ):
            kb = kt[b.start : b.start + b.n_demos * b.m].reshape(b.n_demos, b.m, q)
            views.append((b.top, kb, top[t0:t1].reshape(b.n_demos, -1, q)))
            if b1 > b0:
                views.append((b.bottom, kb[:, b.h :], bot[b0:b1].reshape(b.n_demos, -1, q)))
        return views

    def _single_query(self) -> tuple:
        """Buffers of a one-point query (the streaming frame), built once: the query, the
        exponent and kernel rows, the product outputs, their per-block views and the flows."""
        if self._single is None:
            p, n = self.z_all.shape[0], self.n_demos
            e, k = np.empty((1, p), dtype=self.dtype), np.empty((1, p), dtype=self.dtype)
            top = np.empty((self._top_off[-1], 1), dtype=self.dtype)
            bot = np.empty((max(self._bot_off[-1], 1), 1), dtype=self.dtype)
            self._single = (np.empty((1, 2)), e, k, top, bot, self._bucket_views(k.T, top, bot),
                            np.empty((1, n, self.out_dim)), np.empty((1, n)))
        return self._single

    def _products(self, xq: np.ndarray, e: np.ndarray, k: np.ndarray,
                  views: list) -> None:
        """The products at queries ``xq`` (Q, 2): the kernel's exponent (``e`` (Q, P)), ``k =
        exp(e)`` (numpy's own exp), then every stored block times its kernel columns (``views``,
        built on ``k``)."""
        exponent_kernel(xq, self._c, self._z_t, self._log_base, self._segments()[1], e)
        np.exp(e, out=k)
        for block, kb, out in views:
            np.matmul(block, kb, out=out)

    def point_products(self, x0: float, x1: float) -> tuple[np.ndarray, np.ndarray]:
        """The products ``[alpha^T; T[:h]] k`` and ``T[h:, h:] k[h:]`` of every demo at one
        query point, (rows, 1) each, in buffers the next call overwrites; their rows per demo are
        :meth:`segments` (``flow_kernel`` turns them into the flows)."""
        xq, e, k, top, bot, views, _, _ = self._single_query()
        xq[0, 0], xq[0, 1] = x0, x1
        self._products(xq, e, k, views)
        return top, bot

    def segments(self) -> np.ndarray:
        """(N, 4 + D) int64: each demo's rows in :meth:`point_products`' outputs (see
        :func:`agents.flow_kernels.flow_kernel`)."""
        return self._segments()[0]

    def predict_point(self, x0: float, x1: float) -> tuple[np.ndarray, np.ndarray]:
        """Every demo's flow at one query point (the streaming frame): mean (1, N, D) and latent
        variance (1, N), as :meth:`predict` gives them, in buffers the next call overwrites."""
        top, bot = self.point_products(x0, x1)
        mean, var = self._single_query()[6:]
        flow_kernel(top, bot, self._segments()[0], self.hyp.signal_var, mean, var)
        return mean, var

    @property
    def n_stored(self) -> int:
        """Stored mean and variance-factor entries including padding: the per-query mat-vec work."""
        return int(sum(b.top.size + b.bottom.size for b in self.buckets))

    def predict(self, xq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every demo's flow at query points: mean (Q, K, D) and latent variance (Q, K).

        One kernel evaluation of the Q queries against all (padded) inducing points of all
        demos, ``k (P, Q)``, then per bucket of similar-size demos two batched products with
        the stored ``[alpha^T; T]`` blocks; no loop over demos. Padding has k = 0.
        """
        xq = np.asarray(xq, dtype=np.float64).reshape(-1, 2)
        q = xq.shape[0]
        if q == 1:
            mean, var = self.predict_point(float(xq[0, 0]), float(xq[0, 1]))
            return mean.copy(), var.copy()
        top = np.empty((self._top_off[-1], q), dtype=self.dtype)
        bot = np.empty((max(self._bot_off[-1], 1), q), dtype=self.dtype)
        e = np.empty((q, self.z_all.shape[0]), dtype=self.dtype)
        self._products(np.ascontiguousarray(xq), e, e, self._bucket_views(e.T, top, bot))
        mean, var = np.empty((q, self.n_demos, self.out_dim)), np.empty((q, self.n_demos))
        flow_kernel(top, bot, self._segments()[0], self.hyp.signal_var, mean, var)
        return mean, var


def build_bank(
    inputs: Sequence[np.ndarray],
    outputs: Sequence[np.ndarray],
    hyp: GPHyperparameters,
    ratio: float | None,
    n_buckets: int = 12,
    rcond: float = DEFAULT_RCOND,
    dtype: type | str = np.float64,
) -> FlowBank:
    """Fit one flow per demo and stack them: FITC with ``ratio`` in (0, 1], or exact when ``None``.

    The loop over demos here runs once, at fit time.
    """
    if len(inputs) != len(outputs):
        raise ValueError(f"{len(inputs)} input and {len(outputs)} output sequences")
    forms = []
    for x, y in zip(inputs, outputs):
        if ratio is None:
            forms.append(exact_gp(x, y, hyp))
        else:
            x = np.asarray(x, dtype=np.float64)
            forms.append(fitc_gp(x, y, x[inducing_indices(len(x), ratio)], hyp, rcond))
    return FlowBank(forms, hyp, n_buckets=n_buckets, dtype=dtype)
