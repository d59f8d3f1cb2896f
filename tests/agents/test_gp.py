"""Exact GP and FITC/SPGP (agents/gp.py): FITC at inducing ratio 1.0 is the exact GP, batching is
exact."""

from __future__ import annotations

import numpy as np
import pytest

from agents.gp import (
    FlowBank,
    GPHyperparameters,
    build_bank,
    exact_gp,
    exact_gp_reference,
    fitc_gp,
    fitc_gp_reference,
    inducing_indices,
)


def _walk(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    """A 30 Hz receiver-like walk (curving, ~0.8 m/s) and its noisy backward-difference velocity."""
    t = np.arange(n) / 30.0
    x = np.column_stack([2.5 - 0.8 * t, -0.8 + 0.3 * np.sin(0.9 * t + rng.uniform(0, 3))])
    x += rng.normal(0, 0.004, x.shape)
    v = np.diff(x, axis=0, prepend=x[:1] - (x[1] - x[0])) * 30.0
    return x, v / 0.8


@pytest.fixture()
def demos() -> list[tuple[np.ndarray, np.ndarray]]:
    rng = np.random.default_rng(0)
    return [_walk(rng, n) for n in (40, 75, 120, 97)]


def _queries(x: np.ndarray) -> np.ndarray:
    return np.vstack([x[::7] + 0.03, x[::11] + np.array([0.4, -0.3]), [[10.0, 10.0]]])


@pytest.mark.parametrize("lengthscale", [0.1, 0.15])
def test_fitc_at_ratio_one_equals_exact_gp(demos, lengthscale):
    vels = [v for _, v in demos]
    hyp = GPHyperparameters.from_velocities(vels, lengthscale, 1.0)
    for x, y in demos:
        xq = _queries(x)
        mean_ref, var_ref = exact_gp_reference(x, y, xq, hyp)
        z = x[inducing_indices(len(x), 1.0)]
        np.testing.assert_array_equal(z, x)
        for mean, var in (
            fitc_gp_reference(x, y, z, xq, hyp),
            fitc_gp(x, y, z, hyp).predict(xq, hyp),
            exact_gp(x, y, hyp).predict(xq, hyp),
        ):
            np.testing.assert_allclose(mean, mean_ref, rtol=0, atol=1e-8)
            np.testing.assert_allclose(var, var_ref, rtol=0, atol=1e-8)


def test_fitc_predictive_form_matches_feature_space_formulas(demos):
    hyp = GPHyperparameters(lengthscale=0.15, noise_var=0.03)
    for x, y in demos:
        z = x[inducing_indices(len(x), 0.4)]
        xq = _queries(x)
        mean_ref, var_ref = fitc_gp_reference(x, y, z, xq, hyp)
        mean, var = fitc_gp(x, y, z, hyp).predict(xq, hyp)
        np.testing.assert_allclose(mean, mean_ref, atol=1e-8)
        np.testing.assert_allclose(var, var_ref, atol=1e-8)
        # Far from the demo the flow reverts to the prior: mean 0, variance s2.
        assert abs(var[-1] - hyp.signal_var) < 1e-12 and np.all(np.abs(mean[-1]) < 1e-12)
        # Variance is a variance: within [0, s2] up to round-off.
        assert np.all(var > -1e-9) and np.all(var <= hyp.signal_var + 1e-9)


def test_sparse_is_an_approximation_that_improves_with_ratio(demos):
    hyp = GPHyperparameters(lengthscale=0.15, noise_var=0.03)
    x, y = demos[2]
    xq = _queries(x)
    mean_ex, _ = exact_gp_reference(x, y, xq, hyp)
    errs = [
        np.abs(
            fitc_gp(x, y, x[inducing_indices(len(x), r)], hyp).predict(xq, hyp)[0] - mean_ex
        ).max()
        for r in (0.05, 0.4, 1.0)
    ]
    assert errs[0] > errs[1] > errs[2] and errs[2] < 1e-8


@pytest.mark.parametrize("ratio", [0.02, 0.4, None])
@pytest.mark.parametrize("n_buckets", [1, 3])
def test_bank_batches_every_demo_exactly(demos, ratio, n_buckets):
    hyp = GPHyperparameters(lengthscale=0.15, noise_var=0.03)
    xs, ys = [d[0] for d in demos], [d[1] for d in demos]
    bank = build_bank(xs, ys, hyp, ratio, n_buckets=n_buckets)
    xq = np.vstack([xs[0][::9], xs[3][::13] + 0.05])
    mean, var = bank.predict(xq)
    assert mean.shape == (len(xq), len(demos), 2) and var.shape == (len(xq), len(demos))
    for k, (x, y) in enumerate(demos):
        form = (
            exact_gp(x, y, hyp)
            if ratio is None
            else fitc_gp(x, y, x[inducing_indices(len(x), ratio)], hyp)
        )
        m, v = form.predict(xq, hyp)
        np.testing.assert_allclose(mean[:, k], m, atol=1e-9)
        np.testing.assert_allclose(var[:, k], v, atol=1e-9)
    # float32 mat-vecs: same flows to ~1e-3 (documented trade-off).
    m32, v32 = build_bank(xs, ys, hyp, ratio, n_buckets=n_buckets, dtype=np.float32).predict(xq)
    assert np.abs(m32 - mean).max() < 1e-3 and np.abs(v32 - var).max() < 1e-3


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_one_point_queries_are_exact_and_keep_their_results(demos, dtype):
    # The streaming frame (one query point) runs on buffers built once; each result stays what
    # it was when a later query reuses them, equals the per-demo form, and a copy of the bank
    # (pickle, deepcopy) builds buffers of its own.
    import copy
    import pickle

    hyp = GPHyperparameters(lengthscale=0.15, noise_var=0.03)
    xs, ys = [d[0] for d in demos], [d[1] for d in demos]
    bank = build_bank(xs, ys, hyp, 0.4, n_buckets=3, dtype=dtype)
    points = [xs[1][5], xs[2][60] + 0.02, np.array([10.0, 10.0])]
    first = [bank.predict(p[None]) for p in points]
    kept = [(m.copy(), v.copy()) for m, v in first]
    for (m, v), (m0, v0) in zip(first, kept):  # later queries did not overwrite earlier results
        assert np.array_equal(m, m0) and np.array_equal(v, v0)
    for p, (m, v) in zip(points, first):
        for k, (x, y) in enumerate(demos):
            mk, vk = fitc_gp(x, y, x[inducing_indices(len(x), 0.4)], hyp).predict(p[None], hyp)
            tol = 1e-9 if dtype == np.float64 else 1e-3
            np.testing.assert_allclose(m[0, k], mk[0], atol=tol)
            np.testing.assert_allclose(v[0, k], vk[0], atol=tol)
    for twin in (pickle.loads(pickle.dumps(bank)), copy.deepcopy(bank)):
        for p, (m, v) in zip(points, kept):
            m2, v2 = twin.predict(p[None])
            assert np.array_equal(m2, m) and np.array_equal(v2, v)


def test_inducing_indices_uniform_in_time():
    idx = inducing_indices(100, 0.4)
    assert idx.size == 40 and idx[0] == 0 and idx[-1] == 99
    assert np.ptp(np.diff(idx)) <= 1  # evenly spaced
    assert inducing_indices(3, 0.01).tolist() == [0]
    np.testing.assert_array_equal(inducing_indices(7, 1.0), np.arange(7))
    for bad in (0.0, -0.1, 1.5, float("nan")):
        with pytest.raises(ValueError, match=r"inducing ratio must be in \(0, 1\]"):
            inducing_indices(10, bad)


def test_bad_inputs_raise():
    with pytest.raises(ValueError, match="lengthscale must be positive and finite"):
        GPHyperparameters(lengthscale=0.0)
    with pytest.raises(ValueError, match="noise_var must be positive and finite"):
        GPHyperparameters(lengthscale=0.1, noise_var=float("nan"))
    hyp = GPHyperparameters(lengthscale=0.1)
    with pytest.raises(ValueError, match=r"expected X \(N, 2\) and Y \(N, D\)"):
        exact_gp(np.zeros((3, 3)), np.zeros((3, 2)), hyp)
    with pytest.raises(ValueError, match="X and Y must be non-empty and finite"):
        exact_gp(np.full((3, 2), np.nan), np.zeros((3, 2)), hyp)
    with pytest.raises(ValueError, match="FlowBank needs at least one demo"):
        FlowBank([], hyp)
    with pytest.raises(ValueError, match="1 input and 0 output sequences"):
        build_bank([np.zeros((3, 2))], [], hyp, 0.4)
