"""Cross-check of the hand-written Laplace preference posterior (agents/cospar.py) against BoTorch.

BoTorch's ``PairwiseGP`` with its ``PairwiseProbitLikelihood`` is the same model as the paper's
Eqs. 2-3 (Chu & Ghahramani 2005) with two differences in parametrisation, mapped here:

* **Noise.** BoTorch fixes sigma = 1: P(a > b) = Phi((g_a - g_b) / sqrt(2)). Ours has sigma in
  utility units. With g = f / sigma the likelihoods are equal, so ours with prior covariance K and
  noise sigma equals BoTorch with covariance K / sigma^2 (``outputscale = s^2 / sigma^2``), and
  f_ours = sigma * g_botorch.
* **Kernel.** Ours: s^2 exp(-|z - z'|^2 / 2) with z = x / lengthscale per dimension; BoTorch's
  ``ScaleKernel(RBFKernel(ard_num_dims=4))`` is the same function. Both add 1e-6 jitter.
* **Clamping.** BoTorch clamps z = (g_a - g_b) / sqrt(2) to [-3, 3] for numerical stability; where
  the MAP has |z| > 3 the two MAPs differ by design. The data below keep |z| < 3 (asserted).

BoTorch only models the compared points; ours the whole grid. Restricted to the compared points
the Laplace MAP is the same (the likelihood depends on those points only). Tolerance: 1e-4 in
utility units (BoTorch solves the MAP with scipy's fsolve, xtol ~1e-6).
"""

from __future__ import annotations

import numpy as np
import pytest

from agents.cospar import CoSpar, CoSparConfig, laplace_posterior, laplace_posterior_dense

torch = pytest.importorskip("torch")
botorch_models = pytest.importorskip("botorch.models")
kernels = pytest.importorskip("gpytorch.kernels")


def _botorch_map(
    x: np.ndarray, prefs: np.ndarray, lengthscale: np.ndarray, s2: float, sigma: float
) -> np.ndarray:
    cov = kernels.ScaleKernel(kernels.RBFKernel(ard_num_dims=x.shape[1])).double()
    cov.base_kernel.lengthscale = torch.tensor(lengthscale, dtype=torch.float64)
    cov.outputscale = torch.tensor(s2 / sigma**2, dtype=torch.float64)
    model = botorch_models.PairwiseGP(
        torch.tensor(x, dtype=torch.float64), torch.tensor(prefs), covar_module=cov
    )
    return model.utility.detach().numpy() * sigma


@pytest.mark.parametrize("seed, sigma", [(0, 0.6), (1, 0.5), (2, 1.0), (3, 0.8)])
def test_laplace_map_matches_botorch_pairwise_gp(seed: int, sigma: float) -> None:
    rng = np.random.default_rng(seed)
    n = 14
    x = rng.random((n, 4))
    lengthscale = np.array([0.4, 0.3, 0.5, 0.4])
    z = x / lengthscale
    k = np.exp(-0.5 * ((z[:, None, :] - z[None, :, :]) ** 2).sum(-1)) + 1e-6 * np.eye(n)
    # comparisons from a hidden utility with probit noise (some inconsistent answers)
    hidden = np.sin(3 * x[:, 0]) + x[:, 1] - x[:, 3]
    pairs = rng.choice(n, size=(20, 2))
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    noisy = hidden[pairs[:, 0]] - hidden[pairs[:, 1]] + 0.3 * rng.standard_normal(len(pairs))
    prefs = np.where(noisy[:, None] > 0, pairs, pairs[:, ::-1])
    ours, _ = laplace_posterior(k, prefs, sigma)
    z_map = (ours[prefs[:, 0]] - ours[prefs[:, 1]]) / (np.sqrt(2) * sigma)
    assert np.abs(z_map).max() < 3.0  # inside BoTorch's clamp (see the module docstring)
    theirs = _botorch_map(x, prefs, lengthscale, 1.0, sigma)
    np.testing.assert_allclose(ours, theirs, atol=1e-4)


def test_subset_laplace_equals_dense_on_the_cospar_grid() -> None:
    learner = CoSpar(CoSparConfig(points_per_dim=(4, 3, 4, 4)), seed=0)
    rng = np.random.default_rng(5)
    prefs = rng.integers(0, len(learner.grid), size=(60, 2))
    prefs = prefs[prefs[:, 0] != prefs[:, 1]]
    f1, c1 = laplace_posterior(learner.prior_cov, prefs, 0.3)
    f2, c2 = laplace_posterior_dense(learner.prior_cov, prefs, 0.3)
    np.testing.assert_allclose(f1, f2, atol=1e-9)
    np.testing.assert_allclose(c1, c2, atol=1e-9)
