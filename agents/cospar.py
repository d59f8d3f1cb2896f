"""CoSpar preference learning of the handover parameters Theta = {K, B, t_f, f_r} (paper Sec. III-B,
IV-B).

The paper tunes Theta with CoSpar (Tucker et al., ICRA 2020) over 20 iterations within
K in [80, 140], B in [10, 20], t_f in [0, 1] and f_r in [5, 20]. CoSpar keeps a Gaussian-process
posterior over a latent utility f on a finite action set A (here a grid over those ranges) and
learns it from pairwise preferences:

* Likelihood of one preference x_k > x'_k (paper Eq. 2, after Chu & Ghahramani 2005):
  ``P(x_k > x'_k | f) = Phi((f(x_k) - f(x'_k)) / (sqrt(2) * sigma))``; the full likelihood is the
  product over the data (Eq. 3).
* Posterior ``P(f | D)`` by the Laplace approximation: Newton's method finds the MAP utility
  ``f_hat`` of ``log P(D | f) - 1/2 f^T K^-1 f``; the covariance is ``(K^-1 + W)^-1`` with W the
  negative Hessian of the log-likelihood at ``f_hat``.
* Each iteration draws ``n_samples`` utility functions from the posterior (Thompson sampling),
  tries the argmax action of each, and asks for the user's preferences among those actions and
  the ``buffer_size`` most recent earlier ones; every stated pair is added to D.

Nothing here knows about robots: the simulated participants of :mod:`agents.participants` judge
real handovers in the env and answer the queries (:mod:`handover_eval.preference` runs
the loop), standing in for the study's participants.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.special import log_ndtr

from handover_env.config import THETA_RANGES, HandoverParams

THETA_NAMES: tuple[str, ...] = ("stiffness", "damping", "forecast_time", "release_force")


@dataclass(frozen=True)
class CoSparConfig:
    """Settings of the preference learner.

    Args:
        points_per_dim: grid resolution per parameter, in the order K, B, t_f, f_r.
        ranges: (low, high) per parameter; the paper's ranges by default.
        lengthscale: squared-exponential lengthscale per parameter, as a fraction of its range.
        signal_variance: prior variance of the utility.
        preference_noise: sigma in Eq. 2 (in utility units).
        n_samples: actions tried per iteration (Thompson samples).
        buffer_size: earlier actions each new action is also compared with.
        jitter: added to the prior covariance diagonal for numerical stability.
        newton_iters: maximum Newton steps of the Laplace approximation.

    The defaults (lengthscale 0.4 of each range, noise 0.3, two Thompson samples plus a buffer of
    two) were chosen on simulated users: over 4 noiseless quadratic users on a 4x3x4x4 grid and 20
    iterations, the mean utility regret was 0.006 against 0.035-0.15 for lengthscale 0.25 and
    0.001-0.15 for 0.6 (sensitive to the buffer); see ``tests/agents/test_cospar.py``.
    """

    points_per_dim: tuple[int, int, int, int] = (7, 6, 6, 7)
    ranges: tuple[tuple[float, float], ...] = tuple(THETA_RANGES[name] for name in THETA_NAMES)
    lengthscale: tuple[float, float, float, float] = (0.4, 0.4, 0.4, 0.4)
    signal_variance: float = 1.0
    preference_noise: float = 0.3
    n_samples: int = 2
    buffer_size: int = 2
    jitter: float = 1e-6
    newton_iters: int = 50

    def __post_init__(self) -> None:
        if len(self.points_per_dim) != 4 or min(self.points_per_dim) < 2:
            raise ValueError(f"points_per_dim needs 4 entries >= 2, got {self.points_per_dim}")
        if len(self.ranges) != 4 or any(not (lo < hi) for lo, hi in self.ranges):
            raise ValueError(f"ranges need 4 (low, high) pairs with low < high, got {self.ranges}")
        if len(self.lengthscale) != 4 or min(self.lengthscale) <= 0:
            raise ValueError(f"lengthscale needs 4 positive entries, got {self.lengthscale}")
        if self.signal_variance <= 0 or self.preference_noise <= 0 or self.jitter <= 0:
            raise ValueError("signal_variance, preference_noise and jitter must be positive")
        if self.n_samples < 1 or self.buffer_size < 0 or self.n_samples + self.buffer_size < 2:
            raise ValueError(
                "need n_samples >= 1, buffer_size >= 0 and at least 2 actions to compare"
            )
        if int(np.prod(self.points_per_dim)) > 5000:
            raise ValueError("grid larger than 5000 actions: the dense posterior would be too slow")


def action_grid(config: CoSparConfig) -> np.ndarray:
    """(A, 4) grid of Theta values (K, B, t_f, f_r), C order over the four axes."""
    axes = [np.linspace(lo, hi, n) for (lo, hi), n in zip(config.ranges, config.points_per_dim)]
    return np.array(list(itertools.product(*axes)), dtype=np.float64)


def _prior_covariance(grid: np.ndarray, config: CoSparConfig) -> np.ndarray:
    """Squared-exponential kernel on range-normalised Theta."""
    lo = np.array([r[0] for r in config.ranges])
    span = np.array([r[1] - r[0] for r in config.ranges])
    z = (grid - lo) / span / np.asarray(config.lengthscale)
    sq = np.sum(z**2, axis=1)
    d2 = np.maximum(sq[:, None] + sq[None, :] - 2.0 * z @ z.T, 0.0)
    return config.signal_variance * np.exp(-0.5 * d2) + config.jitter * np.eye(len(grid))


def laplace_posterior(
    prior_cov: np.ndarray,
    preferences: np.ndarray,
    noise: float,
    max_iters: int = 50,
    tol: float = 1e-9,
) -> tuple[np.ndarray, np.ndarray]:
    """Laplace approximation of the preference posterior (Chu & Ghahramani 2005; paper Eqs. 2-3).

    The likelihood (Eq. 3) depends on the utilities of the compared actions S only, so the MAP is
    found by Newton's method on f_S under the prior K_SS (|S| is at most twice the number of
    preferences, far below the grid size), and then extended to every action exactly: at the MAP
    ``K^-1 f = grad log P(D|f)``, which is zero outside S, so ``f = K_{:,S} grad_S``; the covariance
    ``(K^-1 + W)^-1 = K - K_{:,S} (I + W_SS K_SS)^-1 W_SS K_{S,:}`` (W is zero outside S). The
    result
    equals the dense computation over all actions (:func:`laplace_posterior_dense`, kept for the
    tests) to round-off, at O(A |S|^2 + A^2 |S|) instead of O(A^3) per Newton step.

    Args:
        prior_cov: (A, A) GP prior covariance K of the utility at the actions.
        preferences: (N, 2) int array of (winner, loser) action indices.
        noise: sigma of Eq. 2.
        max_iters: Newton steps at most.
        tol: stop when the largest change of f is below this.

    Returns:
        ``(f_hat, cov)``: MAP utility (A,) and posterior covariance (K^-1 + W)^-1 (A, A).
    """
    n_actions = prior_cov.shape[0]
    prefs = np.asarray(preferences, dtype=np.int64).reshape(-1, 2)
    if prefs.size and (prefs.min() < 0 or prefs.max() >= n_actions):
        raise ValueError("preference indices out of range")
    if not prefs.size:
        return np.zeros(n_actions), prior_cov.copy()
    subset, local = np.unique(prefs, return_inverse=True)
    local = local.reshape(-1, 2)
    k_ss = prior_cov[np.ix_(subset, subset)]
    f_s, grad, hess_w = _newton_map(k_ss, local[:, 0], local[:, 1], noise, max_iters, tol)
    k_as = prior_cov[:, subset]
    f = k_as @ grad
    f[subset] = f_s
    eye = np.eye(len(subset))
    cov = prior_cov - k_as @ np.linalg.solve(eye + hess_w @ k_ss, hess_w @ k_as.T)
    return f, 0.5 * (cov + cov.T)


def laplace_posterior_dense(
    prior_cov: np.ndarray,
    preferences: np.ndarray,
    noise: float,
    max_iters: int = 50,
    tol: float = 1e-9,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`laplace_posterior` by Newton's method over every action at once (O(A^3) per step)."""
    n_actions = prior_cov.shape[0]
    prefs = np.asarray(preferences, dtype=np.int64).reshape(-1, 2)
    if not prefs.size:
        return np.zeros(n_actions), prior_cov.copy()
    f, _, hess_w = _newton_map(prior_cov, prefs[:, 0], prefs[:, 1], noise, max_iters, tol)
    eye = np.eye(n_actions)
    cov = prior_cov - prior_cov @ np.linalg.solve(eye + hess_w @ prior_cov, hess_w @ prior_cov)
    return f, 0.5 * (cov + cov.T)


def _newton_map(
    prior_cov: np.ndarray,
    win: np.ndarray,
    lose: np.ndarray,
    noise: float,
    max_iters: int,
    tol: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """MAP of ``log P(D|f) - f^T K^-1 f / 2`` by Newton's method: (f, grad log P(D|f), W) at the
    MAP."""
    n = prior_cov.shape[0]
    scale = 1.0 / (np.sqrt(2.0) * noise)
    eye = np.eye(n)
    f = np.zeros(n)
    for _ in range(max_iters):
        grad, hess_w = _likelihood_derivatives(f, win, lose, scale, n)
        # Newton step in the stable form f_new = K (I + W K)^-1 (W f + grad).
        f_new = prior_cov @ np.linalg.solve(eye + hess_w @ prior_cov, hess_w @ f + grad)
        done = np.max(np.abs(f_new - f)) < tol
        f = f_new
        if done:
            break
    grad, hess_w = _likelihood_derivatives(f, win, lose, scale, n)
    return f, grad, hess_w


def _likelihood_derivatives(
    f: np.ndarray, win: np.ndarray, lose: np.ndarray, scale: float, n_actions: int
) -> tuple[np.ndarray, np.ndarray]:
    """Gradient of log P(D|f) and W = -Hessian, for z_k = scale * (f_win - f_lose)."""
    z = scale * (f[win] - f[lose])
    ratio = np.exp(-0.5 * z**2 - 0.5 * np.log(2.0 * np.pi) - log_ndtr(z))  # phi(z) / Phi(z), stable
    curvature = ratio * (z + ratio)  # -d^2/dz^2 log Phi(z) >= 0
    grad = np.zeros(n_actions)
    np.add.at(grad, win, scale * ratio)
    np.add.at(grad, lose, -scale * ratio)
    hess_w = np.zeros((n_actions, n_actions))
    c = scale**2 * curvature
    np.add.at(hess_w, (win, win), c)
    np.add.at(hess_w, (lose, lose), c)
    np.add.at(hess_w, (win, lose), -c)
    np.add.at(hess_w, (lose, win), -c)
    return grad, hess_w


Preference = Callable[[np.ndarray, np.ndarray], bool]
"""A user: given two Theta vectors (4,), True when the first is preferred."""


@dataclass
class CoSpar:
    """The CoSpar loop (Tucker et al. 2020) over a grid of Theta.

    Args:
        config: :class:`CoSparConfig`.
        seed: seeds the Thompson samples.
    """

    config: CoSparConfig = field(default_factory=CoSparConfig)
    seed: int = 0

    def __post_init__(self) -> None:
        self.grid = action_grid(self.config)
        self.prior_cov = _prior_covariance(self.grid, self.config)
        self.rng = np.random.default_rng(self.seed)
        self.preferences: list[tuple[int, int]] = []
        self.history: list[int] = []
        self.f_hat = np.zeros(len(self.grid))
        self.cov = self.prior_cov.copy()

    def propose(self) -> list[int]:
        """Action indices to try this iteration: the argmax of ``n_samples`` posterior draws."""
        chol = np.linalg.cholesky(self.cov + self.config.jitter * np.eye(len(self.grid)))
        draws = (
            self.f_hat[None, :]
            + self.rng.standard_normal((self.config.n_samples, len(self.grid))) @ chol.T
        )
        return [int(i) for i in np.argmax(draws, axis=1)]

    def add_preference(self, winner: int, loser: int) -> None:
        """Record that action ``winner`` was preferred to ``loser`` (indices into :attr:`grid`)."""
        if winner == loser:
            return
        for idx in (winner, loser):
            if not 0 <= idx < len(self.grid):
                raise ValueError(f"action index {idx} outside the grid of {len(self.grid)}")
        self.preferences.append((int(winner), int(loser)))

    def update_posterior(self) -> None:
        """Recompute the Laplace posterior from every preference so far."""
        self.f_hat, self.cov = laplace_posterior(
            self.prior_cov,
            np.array(self.preferences),
            self.config.preference_noise,
            self.config.newton_iters,
        )

    def step(self, prefers: Preference) -> list[int]:
        """One CoSpar iteration: propose, query ``prefers`` on all new pairs and the buffer, update.

        Returns:
            The action indices tried in this iteration.
        """
        tried = self.propose()
        buffer = self.history[-self.config.buffer_size :] if self.config.buffer_size else []
        compared = tried + [b for b in buffer if b not in tried]
        for i, j in itertools.combinations(range(len(compared)), 2):
            a, b = compared[i], compared[j]
            if a == b:
                continue
            if prefers(self.grid[a], self.grid[b]):
                self.add_preference(a, b)
            else:
                self.add_preference(b, a)
        self.history.extend(tried)
        self.update_posterior()
        return tried

    def run(
        self, prefers: Preference, iterations: int = 20, progress: bool = False
    ) -> HandoverParams:
        """Run ``iterations`` CoSpar steps (the paper: 20) and return the learned Theta-hat."""
        steps: Sequence[int] = range(iterations)
        if progress:
            from tqdm import tqdm

            steps = tqdm(steps, desc="CoSpar", unit="iter")
        for _ in steps:
            self.step(prefers)
        return self.best()

    def best_index(self, tried_only: bool = True) -> int:
        """Grid index of the posterior-mean maximiser, among the actions tried so far (default;
        the whole grid when nothing was tried) or over the whole grid (``tried_only=False``)."""
        tried = np.unique(self.history) if self.history else np.arange(len(self.grid))
        candidates = tried if tried_only else np.arange(len(self.grid))
        return int(candidates[np.argmax(self.f_hat[candidates])])

    def best(self, tried_only: bool = True) -> HandoverParams:
        """Theta-hat: Theta at :meth:`best_index`."""
        return HandoverParams(*(float(v) for v in self.grid[self.best_index(tried_only)]))
