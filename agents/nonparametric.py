"""The paper's nonparametric trajectory generator g(xi^r_o; D) (Sec. IV-A), with SPGP motion flows.

**Motion flow per demo k** (Sec. IV-A, "Trajectory Similarity Measure"): f_k: x -> xdot, from
the receiver base position x (m) to its velocity (m/s). Velocities are *backward* finite
differences at the dataset rate, ``xdot_t = (x_t - x_{t-1}) * 30`` (the only difference
available online at the newest frame; the demos use the same convention so that query and demo
velocities lag alike; a demo's frame 0 copies frame 1's velocity). f_k is an SPGP/FITC
(:mod:`agents.gp`) whose inducing inputs are the fraction ``inducing_ratio`` of demo k's own
samples, evenly spaced in time; IAAL (:mod:`baselines.iaal`) is the same model with the exact
GP. Hyperparameters follow one fixed rule for all demos and both models
(:meth:`agents.gp.GPHyperparameters.from_velocities`): outputs scaled by the pooled RMS
velocity (s2 = 1), noise from successive velocity differences, lengthscale a setting.

**Distance and similarity** (Eqs. d and sim)::

    d(xi_o; xi_k) = 1/t_c * sum_{t=1..t_c} [ kappa * d_cos(xdot_{o,t}, mu_k(x_{o,t})) +
    sigma2_k(x_{o,t}) ]
    sim_k = exp(-d)

sigma2_k is the latent variance in the scaled units (0 on demo k's path, 1 far from it).
**Zero velocity rule:** ``d_cos(a, b) = 1 - a.b / (max(|a|, v0) * max(|b|, v0))`` with
``v0 = min_speed`` (0.05 m/s). It equals the paper's cosine distance whenever both speeds are at
least v0, is continuous, never NaN, and tends to 1 ("no directional evidence") when either
velocity vanishes: a pausing receiver adds the same kappa to every demo's sum (no demo is
preferred by direction), and a demo whose flow is ~0 at x (x far from it) gets no directional
credit. The observed frame 0 has no backward difference and counts as zero velocity.

**Prediction** (Eq. xi_pred): the K demos of largest sim form S; for each, t_k is the frame
where demo k's receiver was closest (Euclidean, over its whole recording) to the current
receiver position; ``xi_pred = sum_{k in S} w_k xi^g_{k, t_k : t_k + H}`` with
``w_k = sim_k / sum_S sim``, computed as ``exp(-(d_k - min_S d))`` normalised (identical, and
no underflow when every d is large, i.e. a query far from every demo). The paper truncates the
blend at the shortest remaining selected demo (T = min L_k); the agent interface needs H rows,
so a demo that runs out before H rows holds its last row (the blend equals the paper's on the
rows the paper defines).

**Streaming:** :meth:`NonparametricAgent.stream_update` adds one frame's terms for all demos at
once to running sums (one batched kernel evaluation of the new point against every inducing
point, batched mat-vecs); the history is never recomputed. ``predict_sequence`` uses cumulative
sums of the same per-frame terms, evaluated in batches of frames.

**Defaults and how they were chosen** (open-loop protocol, fold 0 of the stratified 10-fold
split with seed 0 of the 875-episode development copy: 787 demos, 88 test episodes; 3D RMS of
the ID test episodes):

* top_k K: 1 -> ~154 mm, 3 -> ~125, 5 -> ~118, 10 -> ~112, 20 -> ~111, 40 -> ~111.5; K = 20.
  Blending many demos helps because the receiver track says little about the giver's own
  timing (the object starts to move ~13 frames into every recording, wherever the receiver is).
* kappa in {0, 0.3, 1, 3, 10} at K = 20: 110.7 to 113.3 mm (0 = variance term only is the
  worst); kappa = 1 (both terms of Eq. d on their natural [0, 2] and [0, 1] scales).
* lengthscale in {0.1, 0.2, 0.4} m at K = 20, kappa = 1: 111.4, 110.9, 111.2 mm (flat); 0.15 m is
  used: short enough that K_mm stays representable, so FITC at ratio 1.0 equals the exact GP to
  1e-8 on synthetic 30 Hz walks (tests/agents/test_gp.py) and to 2e-8 median / 1.3e-6 worst on real
  recordings (pauses make K_mm numerically singular; see agents/gp.py).
* precision float32: per-frame cost ~halved, flows within 1e-4 of float64, RMS unchanged (see
  the 10-fold figures in docs/results.md).

Far from every demo all flows revert to their prior (mu = 0, sigma2 = 1), every d tends to
kappa + 1 and the blend becomes an (arbitrary but deterministic) K-demo average at each demo's
nearest frame: finite and inside the recorded giver workspace, but no longer informative (ID
test tracks shifted 0.25 / 0.5 / 1 / 2 m away: 3D RMS 106 -> 142 / 200 / 352 / 409 mm).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agents.base import validate_history
from agents.flow_kernels import (
    STATE_HEAD,
    blend_kernel,
    cosine_rows_kernel,
    stream_frame_kernel,
    terms_kernel,
)
from agents.gp import DEFAULT_RCOND, FlowBank, GPHyperparameters, build_bank
from agents.predictive import ClosedLoopConfig, PredictiveAgent
from handover_env.config import HandoverParams
from handover_env.data.dataset import HandoverDataset
from handover_env.envs.observation import ObsLayout

_FAR = 1e6  # padding position of receiver frames past a demo's end (never the closest frame)


@dataclass(frozen=True)
class NonparametricConfig:
    """Settings of the nonparametric planner (paper defaults where the paper gives one).

    Args:
        inducing_ratio: fraction of each demo's samples used as FITC inducing points, in (0, 1]
            (paper: 0.4). Ignored when ``exact``.
        exact: use the exact GP per demo (IAAL) instead of FITC.
        lengthscale: kernel lengthscale l, m (chosen on the open-loop protocol; docs/results.md).
        kappa: weight of the cosine distance against the variance term in Eq. d.
        top_k: K, the number of most similar demos blended (Eq. xi_pred).
        horizon: H, predicted frames (30 = 1 s at 30 Hz, the paper's chunk).
        min_speed: v0 of the zero-velocity rule, m/s.
        rate_hz: dataset / camera rate.
        n_buckets: size groups of the padded GP tensors (speed only).
        precision: "float64" or "float32" for the per-frame mat-vecs (speed; see FlowBank).
        rcond: relative eigenvalue cut-off of K_mm (numerics only; see agents.gp).
        frame_batch: frames per batched GP evaluation in ``predict``/``predict_sequence``.
    """

    inducing_ratio: float = 0.4
    exact: bool = False
    lengthscale: float = 0.15
    kappa: float = 1.0
    top_k: int = 20
    horizon: int = 30
    min_speed: float = 0.05
    rate_hz: float = 30.0
    n_buckets: int = 12
    precision: str = "float32"
    rcond: float = DEFAULT_RCOND
    frame_batch: int = 32

    def __post_init__(self) -> None:
        if not (0.0 < float(self.inducing_ratio) <= 1.0):
            raise ValueError(f"inducing_ratio must be in (0, 1], got {self.inducing_ratio!r}")
        for name in ("lengthscale", "min_speed", "rate_hz"):
            v = float(getattr(self, name))
            if not np.isfinite(v) or v <= 0:
                raise ValueError(f"{name} must be positive and finite, got {getattr(self, name)!r}")
        if not np.isfinite(float(self.kappa)) or self.kappa < 0:
            raise ValueError(f"kappa must be finite and >= 0, got {self.kappa!r}")
        for name in ("top_k", "horizon", "n_buckets", "frame_batch"):
            v = getattr(self, name)
            if not isinstance(v, (int, np.integer)) or v < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {v!r}")
        if self.precision not in ("float32", "float64"):
            raise ValueError(f"precision must be 'float32' or 'float64', got {self.precision!r}")
        if not (0.0 <= float(self.rcond) < 1.0):
            raise ValueError(f"rcond must be in [0, 1), got {self.rcond!r}")


def backward_velocity(xy: np.ndarray, rate_hz: float) -> np.ndarray:
    """(T, 2) backward differences ``(x_t - x_{t-1}) * rate``; frame 0 copies frame 1 (T >= 2)."""
    v = np.diff(xy, axis=0) * rate_hz
    return np.vstack([v[:1], v])


def cosine_distance(a: np.ndarray, b: np.ndarray, min_speed: float) -> np.ndarray:
    """``1 - a.b / (max(|a|, v0) max(|b|, v0))`` over the last axis (2D; the zero-velocity rule),
    ``a`` and ``b`` broadcast against each other."""
    a, b = np.broadcast_arrays(np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64))
    if a.shape[-1:] != (2,):
        raise ValueError(f"cosine_distance takes 2D velocities (..., 2), got {a.shape}")
    out = np.empty(a.shape[:-1])
    cosine_rows_kernel(np.ascontiguousarray(a.reshape(-1, 2)),
                       np.ascontiguousarray(b.reshape(-1, 2)), float(min_speed), out.reshape(-1))
    return out


class _Stream:
    """Running state of one observed receiver trajectory, in the one array the compiled frame
    (:func:`agents.flow_kernels.stream_frame_kernel`) updates: frames seen, whether there is a
    last frame and its xy, the running sums of kappa * d_cos + sigma2 (N) and ``d = sums /
    count`` (N)."""

    def __init__(self, n_demos: int) -> None:
        self.n_demos = n_demos
        self.state = np.zeros(STATE_HEAD + 2 * n_demos)

    @property
    def sums(self) -> np.ndarray:
        """The running sums (a view of ``state``; views made on access survive a pickle)."""
        return self.state[STATE_HEAD : STATE_HEAD + self.n_demos]

    @property
    def d(self) -> np.ndarray:
        """The distances ``sums / count`` (a view of ``state``)."""
        return self.state[STATE_HEAD + self.n_demos :]

    @property
    def count(self) -> int:
        return int(self.state[0])

    @property
    def last(self) -> np.ndarray | None:
        """The newest receiver xy (m, dataset frame), or None before the first frame."""
        return self.state[2:4].copy() if self.state[1] else None


class NonparametricAgent(PredictiveAgent):
    """SPGP motion-flow similarity planner (paper Sec. IV-A); IAAL with ``exact=True``.

    Args:
        config: model settings (:class:`NonparametricConfig`).
        params: Theta; ``forecast_time`` is used in closed loop.
        closed_loop: ensembling, ready pose and yaw (see :mod:`agents.predictive`).
        layout: the env's observation layout.
    """

    def __init__(
        self,
        config: NonparametricConfig | None = None,
        params: HandoverParams | None = None,
        closed_loop: ClosedLoopConfig | None = None,
        layout: ObsLayout | None = None,
    ) -> None:
        super().__init__(params=params, closed_loop=closed_loop, layout=layout)
        self.config = config or NonparametricConfig()
        self.horizon = self.config.horizon
        self.bank: FlowBank | None = None
        self._state: _Stream | None = None

    # ------------------------------------------------------------------ fitting
    def fit(self, dataset: HandoverDataset) -> NonparametricAgent:
        """Precompute every demo's flow (FITC or exact) and the padded demo tensors."""
        c = self.config
        if not isinstance(dataset, HandoverDataset) or len(dataset) == 0:
            raise ValueError("fit needs a non-empty HandoverDataset")
        if abs(dataset.rate_hz - c.rate_hz) > 1e-6:
            raise ValueError(
                f"dataset rate is {dataset.rate_hz} Hz, the planner is set to {c.rate_hz} Hz"
            )
        xs = [ep.receiver_xy for ep in dataset]
        vels = [backward_velocity(x, c.rate_hz) for x in xs]
        allv = np.concatenate(vels)
        self.output_scale = float(np.sqrt(np.mean(allv**2)))
        if not self.output_scale > 0:
            raise ValueError("every training receiver is motionless; the flows are undefined")
        self.hyp = GPHyperparameters.from_velocities(vels, c.lengthscale, self.output_scale)
        # Centre positions (translation-invariant kernel; better float32 round-off).
        self.origin = np.concatenate(xs).mean(axis=0)
        self._origin = tuple(self.origin.tolist())
        self.bank = build_bank(
            [x - self.origin for x in xs],
            [v / self.output_scale for v in vels],
            self.hyp,
            ratio=None if c.exact else c.inducing_ratio,
            n_buckets=c.n_buckets,
            rcond=c.rcond,
            dtype=c.precision,
        )
        lengths = dataset.lengths
        n, lmax = len(dataset), int(lengths.max())
        self.lengths = np.ascontiguousarray(lengths, dtype=np.int64)
        self.receivers = np.full((n, lmax, 2), _FAR)
        self.givers = np.zeros((n, lmax, 3))
        for k, ep in enumerate(dataset):  # fit time only
            self.receivers[k, : ep.length] = ep.receiver_xy
            self.givers[k, : ep.length] = ep.giver_xyz
            self.givers[k, ep.length :] = ep.giver_xyz[-1]  # hold the last row (see module doc)
        # (N, Lmax, 3) (|r|^2, r) of every frame: the closest-frame search's one array
        self._search = np.ascontiguousarray(
            np.concatenate([np.sum(self.receivers**2, axis=2)[..., None], self.receivers], axis=2)
        )
        self.n_demos = n
        self._top_k = min(c.top_k, n)
        self._all = np.arange(n, dtype=np.int64)
        self._w = np.empty(self._top_k)
        self._rows = np.empty((self._top_k, 3 * c.horizon))
        self._seg = self.bank.segments()
        self._par = np.array([self.hyp.signal_var, c.rate_hz, self.output_scale, c.min_speed,
                              c.kappa], dtype=np.float64)  # flow_kernels.STREAM_PAR
        self.reset()
        return self

    def _check_fitted(self) -> None:
        if self.bank is None:
            raise RuntimeError("call fit(dataset) first")

    # ------------------------------------------------------------------ per-frame terms
    def frame_terms(self, xy: np.ndarray, vel: np.ndarray) -> np.ndarray:
        """Eq. d summands ``kappa * d_cos + sigma2`` of frames (F, 2) with velocities (F, 2): (F,
        N)."""
        self._check_fitted()
        mean, var = self.bank.predict(np.asarray(xy) - self.origin)  # (F, N, 2), (F, N)
        c = self.config
        terms = np.empty_like(var)
        terms_kernel(np.ascontiguousarray(vel, dtype=np.float64).reshape(-1, 2), mean, var,
                     self.output_scale, c.min_speed, c.kappa, terms)
        return terms

    def _terms_batched(self, hist: np.ndarray) -> np.ndarray:
        """Summands of every frame of a history (T, 2): (T, N), in batches of frames."""
        vel = np.zeros_like(hist)
        vel[1:] = np.diff(hist, axis=0) * self.config.rate_hz
        fb = self.config.frame_batch
        return np.concatenate(
            [self.frame_terms(hist[i : i + fb], vel[i : i + fb]) for i in range(0, len(hist), fb)]
        )

    def distances(self, receiver_history: np.ndarray) -> np.ndarray:
        """Eq. d of a whole observed history against every demo, recomputed from scratch: (N,)."""
        hist = validate_history(receiver_history)
        return self._terms_batched(hist).mean(axis=0)

    def similarities(self, receiver_history: np.ndarray) -> np.ndarray:
        """Eq. sim, exp(-d), for every demo: (N,)."""
        return np.exp(-self.distances(receiver_history))

    # ------------------------------------------------------------------ prediction (Eq. xi_pred)
    def _blend(self, d: np.ndarray, xy: np.ndarray) -> np.ndarray:
        """Eq. xi_pred at distances ``d`` (N,) and receiver position ``xy``: the K closest demos
        (numpy's ``argpartition``), their weights and giver rows (flow_kernels.blend_kernel:
        t_k = argmin_t |r_{k,t} - x|^2 = argmin_t (|r_{k,t}|^2 - 2 r_{k,t}.x) and the H rows
        from t_k on), then ``w @ rows`` (numpy's BLAS product)."""
        k = self._top_k
        sel = np.argpartition(d, k - 1)[:k] if k < d.size else self._all
        blend_kernel(sel, d, self._search, xy[0], xy[1], self.lengths, self.givers, self._w,
                     self._rows)
        return (self._w @ self._rows).reshape(-1, 3)

    def predict(self, receiver_history: np.ndarray) -> np.ndarray:
        """(H, 3) predicted giver trajectory; row 0 is the current frame (open-loop use)."""
        self._check_fitted()
        hist = validate_history(receiver_history)
        return self._blend(self._terms_batched(hist).mean(axis=0), hist[-1])

    def predict_sequence(self, receiver_xy: np.ndarray, query_times: np.ndarray) -> np.ndarray:
        """Open-loop predictions at many times of one episode: (Q, H, 3), via running sums.

        Equal to ``predict(receiver_xy[: t + 1])`` for each t (tested); each frame's terms are
        computed once and accumulated.
        """
        self._check_fitted()
        receiver_xy = validate_history(receiver_xy)
        times = np.asarray(query_times, dtype=np.int64).reshape(-1)
        if times.size == 0:
            return np.zeros((0, self.horizon, 3))
        if times.min() < 0 or times.max() >= receiver_xy.shape[0]:
            raise ValueError(f"query times must lie in [0, {receiver_xy.shape[0] - 1}]")
        hist = receiver_xy[: times.max() + 1]
        csum = np.cumsum(self._terms_batched(hist), axis=0)  # (T, N)
        return np.stack([self._blend(csum[t] / (t + 1), hist[t]) for t in times])

    # ------------------------------------------------------------------ streaming hooks
    def stream_reset(self) -> None:
        """Start a new observed trajectory (O(N))."""
        self._state = _Stream(self.n_demos) if self.bank is not None else None

    def stream_update(self, receiver_xy: np.ndarray) -> None:
        """Add one new 30 Hz frame: only its own terms, for all demos at once."""
        self._check_fitted()
        arr = np.asarray(receiver_xy, dtype=np.float64)
        if arr.size != 2:
            validate_history(arr)  # a clear error for a bad shape, NaN or no frame
            raise ValueError(f"stream_update takes one frame (2,), got {np.shape(receiver_xy)}")
        x0, x1 = arr.reshape(-1).tolist()
        if not (math.isfinite(x0) and math.isfinite(x1)):
            raise ValueError("receiver_history contains NaN or inf")
        # frame_terms(xy, vel) of one frame, in the same float64 operations, added to the sums
        o0, o1 = self._origin
        top, bot = self.bank.point_products(x0 - o0, x1 - o1)
        stream_frame_kernel(top, bot, self._seg, self._par, x0, x1, self._state.state)

    def stream_distances(self) -> np.ndarray:
        """Eq. d from the running sums: (N,)."""
        self._check_fitted()
        if self._state.count == 0:
            raise ValueError("no receiver frame streamed yet")
        return self._state.d.copy()

    def stream_predict(self) -> np.ndarray:
        """(H, 3) chunk for the newest streamed frame."""
        s = self._state
        if s is None or s.state[0] == 0.0:
            self.stream_distances()  # the clear error
        return self._blend(s.d, s.state[2:4])
