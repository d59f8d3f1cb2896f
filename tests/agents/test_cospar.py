"""CoSpar preference learning: the Laplace posterior against its defining equations, and
learning."""

from __future__ import annotations

import numpy as np
import pytest
from quadratic_users import QuadraticUser, sample_users
from scipy.special import log_ndtr
from scipy.stats import norm

from agents.cospar import CoSpar, CoSparConfig, action_grid, laplace_posterior
from handover_env.config import THETA_RANGES

SMALL = CoSparConfig(points_per_dim=(4, 3, 4, 4))


def _rand_spd(n: int, seed: int) -> np.ndarray:
    a = np.random.default_rng(seed).standard_normal((n, n))
    return a @ a.T / n + 0.5 * np.eye(n)


def test_laplace_map_is_stationary_point_of_log_posterior() -> None:
    k = _rand_spd(6, 0)
    prefs = np.array([[0, 1], [1, 2], [0, 2], [3, 4], [5, 0]])
    sigma = 0.3
    f, cov = laplace_posterior(k, prefs, sigma)
    scale = 1 / (np.sqrt(2) * sigma)
    z = scale * (f[prefs[:, 0]] - f[prefs[:, 1]])
    ratio = norm.pdf(z) / norm.cdf(z)
    grad = np.zeros(6)
    np.add.at(grad, prefs[:, 0], scale * ratio)
    np.add.at(grad, prefs[:, 1], -scale * ratio)
    # MAP: d/df [log P(D|f) - f^T K^-1 f / 2] = 0  <=>  K^-1 f = grad log P(D|f).
    np.testing.assert_allclose(np.linalg.solve(k, f), grad, atol=1e-8)
    # Covariance equals (K^-1 + W)^-1 with W the negative Hessian of the log likelihood.
    c = scale**2 * ratio * (z + ratio)
    w = np.zeros((6, 6))
    for (a, b), ck in zip(prefs, c):
        e = np.zeros(6)
        e[a], e[b] = 1, -1
        w += ck * np.outer(e, e)
    np.testing.assert_allclose(cov, np.linalg.inv(np.linalg.inv(k) + w), atol=1e-8)
    assert f[0] > f[1] > f[2] and f[3] > f[4]


def test_laplace_map_matches_brute_force_optimum_for_two_actions() -> None:
    k = np.eye(2)
    sigma = 0.5
    f, _ = laplace_posterior(k, np.array([[0, 1]]), sigma)
    # By symmetry f = (a, -a) with a maximising log Phi(2a / (sqrt2 sigma)) - a^2.
    grid = np.linspace(0, 2, 200001)
    best = grid[np.argmax(log_ndtr(2 * grid / (np.sqrt(2) * sigma)) - grid**2)]
    assert f[0] == pytest.approx(best, abs=1e-4) and f[1] == pytest.approx(-best, abs=1e-4)


def test_no_preferences_gives_prior() -> None:
    k = _rand_spd(4, 1)
    f, cov = laplace_posterior(k, np.zeros((0, 2), dtype=int), 0.1)
    assert np.all(f == 0) and np.allclose(cov, k)


def test_bad_indices_rejected() -> None:
    with pytest.raises(ValueError, match="out of range"):
        laplace_posterior(np.eye(3), np.array([[0, 3]]), 0.1)


def test_grid_spans_paper_ranges() -> None:
    grid = action_grid(SMALL)
    assert grid.shape == (4 * 3 * 4 * 4, 4)
    for j, name in enumerate(("stiffness", "damping", "forecast_time", "release_force")):
        assert (
            grid[:, j].min() == THETA_RANGES[name][0] and grid[:, j].max() == THETA_RANGES[name][1]
        )


def test_config_validation() -> None:
    with pytest.raises(ValueError, match="points_per_dim needs 4 entries >= 2"):
        CoSparConfig(points_per_dim=(1, 3, 3, 3))
    with pytest.raises(ValueError, match="need n_samples >= 1"):
        CoSparConfig(n_samples=1, buffer_size=0)


def test_cospar_finds_a_noiseless_users_ideal() -> None:
    user = QuadraticUser(ideal=[120.0, 16.0, 0.2, 8.0], sensitivity=[1, 1, 1, 1], noise=0.0)
    learner = CoSpar(SMALL, seed=0)
    theta = np.array(learner.run(user.prefers, iterations=20).as_array())
    grid = action_grid(SMALL)
    best_on_grid = max(user.utility(g) for g in grid)
    # The learned Theta is among the best few percent of the grid for this user.
    utilities = np.sort([user.utility(g) for g in grid])
    assert user.utility(theta) >= utilities[int(0.95 * len(utilities))]
    assert best_on_grid - user.utility(theta) < 0.05


def test_cospar_beats_random_parameters_for_simulated_participants() -> None:
    users = sample_users(4, seed=3)
    rng = np.random.default_rng(0)
    lows = np.array(
        [THETA_RANGES[n][0] for n in ("stiffness", "damping", "forecast_time", "release_force")]
    )
    highs = np.array(
        [THETA_RANGES[n][1] for n in ("stiffness", "damping", "forecast_time", "release_force")]
    )
    wins = 0
    for i, user in enumerate(users):
        learned = np.array(CoSpar(SMALL, seed=i).run(user.prefers, iterations=15).as_array())
        random_theta = rng.uniform(lows, highs)
        wins += user.utility(learned) > user.utility(random_theta)
    assert wins == len(users)


def test_cospar_is_deterministic_under_a_seed() -> None:
    runs = []
    for _ in range(2):
        user = QuadraticUser(
            ideal=np.array([100.0, 12.0, 0.6, 15.0]), sensitivity=np.ones(4), noise=0.05, seed=7
        )
        runs.append(CoSpar(SMALL, seed=1).run(user.prefers, iterations=5))
    assert runs[0] == runs[1]
