"""The SPGP planner and IAAL (agents/nonparametric.py, baselines/iaal.py) on toy data with known
answers."""

from __future__ import annotations

import numpy as np
import pytest

from agents.base import Agent
from agents.nonparametric import (
    NonparametricAgent,
    NonparametricConfig,
    backward_velocity,
    cosine_distance,
)
from baselines.iaal import IAALAgent
from handover_env.data.dataset import Episode, HandoverDataset
from handover_env.envs.observation import ObsLayout


def _episode(i: int, receiver: np.ndarray, giver: np.ndarray, ood: bool = False) -> Episode:
    n = len(receiver)
    return Episode(receiver_xy=receiver, receiver_hand_xyz=np.zeros((n, 3)), giver_xyz=giver,
                   object_quat=np.tile([1.0, 0, 0, 0], (n, 1)), is_ood=ood, source_id=f"toy_{i}")


def toy_dataset(n_demos: int = 6, length: int = 70) -> HandoverDataset:
    """Receivers on well separated straight lanes (different y and headings); each giver
    trajectory is a distinct known function of time, so the right answer is known."""
    eps = []
    t = np.arange(length) / 30.0
    for j in range(n_demos):
        heading = np.pi + 0.25 * (j - n_demos / 2)  # walking toward -x, fanned out
        y0 = -1.5 + 0.5 * j
        rec = np.column_stack([2.5 + 0.8 * t * np.cos(heading), y0 + 0.8 * t * np.sin(heading)])
        giv = np.column_stack(
            [0.1 * j + 0.2 * t, -0.3 - 0.05 * j + 0.0 * t, 1.0 + 0.03 * j + 0.1 * np.sin(t + j)]
        )
        eps.append(_episode(j, rec, giv, ood=(j == n_demos - 1)))
    return HandoverDataset(eps, name="toy")


CONFIG = NonparametricConfig(lengthscale=0.15, top_k=1, horizon=30, precision="float64")


@pytest.fixture(scope="module")
def toy() -> HandoverDataset:
    return toy_dataset()


@pytest.fixture(scope="module", params=["spgp", "iaal"])
def agent(request, toy) -> NonparametricAgent:
    cls = NonparametricAgent if request.param == "spgp" else IAALAgent
    return cls(CONFIG).fit(toy)


def test_replaying_demo_j_predicts_demo_j(agent, toy):
    for j, ep in enumerate(toy):
        for t_c in (5, 20, 39):
            pred = agent.predict(ep.receiver_xy[: t_c + 1])
            np.testing.assert_allclose(pred, ep.giver_xyz[t_c : t_c + 30], atol=1e-12)
            d = agent.distances(ep.receiver_xy[: t_c + 1])
            assert int(np.argmin(d)) == j
        # Near the end the demo runs out: its last row is held.
        pred = agent.predict(ep.receiver_xy[:60])
        np.testing.assert_allclose(pred[:11], ep.giver_xyz[59:70], atol=1e-12)
        np.testing.assert_allclose(pred[11:], np.repeat(ep.giver_xyz[-1:], 19, axis=0), atol=1e-12)


def test_streaming_equals_batch_recomputation(agent, toy):
    ep = toy[2]
    noisy = ep.receiver_xy + np.random.default_rng(1).normal(0, 0.01, ep.receiver_xy.shape)
    agent.stream_reset()
    for t in range(len(noisy)):
        agent.stream_update(noisy[t])
        if t in (0, 1, 7, 33, len(noisy) - 1):
            np.testing.assert_allclose(
                agent.stream_distances(), agent.distances(noisy[: t + 1]), atol=1e-12
            )
            np.testing.assert_allclose(
                agent.stream_predict(), agent.predict(noisy[: t + 1]), atol=1e-12
            )


def test_a_pickled_stream_continues_as_the_original(agent, toy):
    import pickle

    noisy = toy[2].receiver_xy + np.random.default_rng(3).normal(0, 0.01, toy[2].receiver_xy.shape)
    agent.stream_reset()
    for xy in noisy[:10]:
        agent.stream_update(xy)
    copy = pickle.loads(pickle.dumps(agent))
    for xy in noisy[10:20]:
        agent.stream_update(xy)
        copy.stream_update(xy)
        assert np.array_equal(copy.stream_distances(), agent.stream_distances())
        assert np.array_equal(copy.stream_predict(), agent.stream_predict())
    assert copy._state.count == 20 and np.array_equal(copy._state.last, noisy[19])


def test_float32_default_agrees_with_float64(toy):
    from dataclasses import replace

    ep = toy[2]
    noisy = ep.receiver_xy + np.random.default_rng(2).normal(0, 0.02, ep.receiver_xy.shape)
    f64 = NonparametricAgent(replace(CONFIG, top_k=3)).fit(toy)
    f32 = NonparametricAgent(replace(CONFIG, top_k=3, precision="float32")).fit(toy)
    assert NonparametricConfig().precision == "float32"
    np.testing.assert_allclose(f32.distances(noisy), f64.distances(noisy), atol=1e-4)
    f32.stream_reset()
    for xy in noisy[:30]:
        f32.stream_update(xy)
    np.testing.assert_allclose(f32.stream_distances(), f64.distances(noisy[:30]), atol=1e-4)
    np.testing.assert_allclose(f32.stream_predict(), f64.predict(noisy[:30]), atol=1e-4)


def test_predict_sequence_equals_loop_over_predict(agent, toy):
    ep = toy[4]
    times = np.array([0, 3, 10, 11, 40, 68])
    fast = agent.predict_sequence(ep.receiver_xy, times)
    slow = Agent.predict_sequence(agent, ep.receiver_xy, times)  # the base-class loop over predict
    np.testing.assert_allclose(fast, slow, atol=1e-12)
    assert agent.predict_sequence(ep.receiver_xy, np.array([], dtype=int)).shape == (0, 30, 3)


def test_blend_weights_are_normalised_similarities(toy):
    agent = NonparametricAgent(
        NonparametricConfig(lengthscale=0.15, top_k=3, precision="float64")
    ).fit(toy)
    hist = toy[1].receiver_xy[:25] + np.array([0.0, 0.25])  # between lanes 1 and 2
    d = agent.distances(hist)
    sel = np.argsort(d)[:3]
    w = np.exp(-d[sel]) / np.exp(-d[sel]).sum()
    expected = np.zeros((30, 3))
    for wk, k in zip(w, sel):
        t_k = int(np.argmin(np.sum((agent.receivers[k] - hist[-1]) ** 2, axis=1)))
        rows = np.minimum(t_k + np.arange(30), agent.lengths[k] - 1)
        expected += wk * agent.givers[k, rows]
    np.testing.assert_allclose(agent.predict(hist), expected, atol=1e-12)
    np.testing.assert_allclose(agent.similarities(hist), np.exp(-d))


def test_zero_velocity_is_neutral_and_finite(toy):
    agent = NonparametricAgent(CONFIG).fit(toy)
    pause = np.repeat(toy[3].receiver_xy[10:11], 15, axis=0)  # a receiver standing still
    d = agent.distances(pause)
    assert np.all(np.isfinite(d)) and np.all(np.isfinite(agent.predict(pause)))
    # Standing still gives no directional evidence: d_cos = 1 for every frame and demo.
    np.testing.assert_allclose(cosine_distance(np.zeros((4, 2)), np.ones((4, 2)), 0.05), 1.0)
    np.testing.assert_allclose(cosine_distance(np.array([1.0, 0]), np.array([-2.0, 0]), 0.05), 2.0)
    np.testing.assert_allclose(cosine_distance(np.array([1.0, 0]), np.array([0.0, 0]), 0.05), 1.0)
    np.testing.assert_allclose(
        backward_velocity(np.array([[0.0, 0], [1, 0], [3, 0]]), 30.0)[:, 0], [30, 30, 60]
    )


def test_far_query_is_finite_and_sensible(toy):
    agent = NonparametricAgent(
        NonparametricConfig(lengthscale=0.15, top_k=3, precision="float64")
    ).fit(toy)
    far = toy[0].receiver_xy[:20] + np.array([50.0, 50.0])
    d = agent.distances(far)
    # Every flow reverts to its prior: sigma2 = 1, d_cos = 1, so d = kappa + 1 for every demo.
    np.testing.assert_allclose(d, CONFIG.kappa + 1.0, atol=1e-9)
    pred = agent.predict(far)
    assert pred.shape == (30, 3) and np.all(np.isfinite(pred))
    lo, hi = (
        np.min([ep.giver_xyz.min(0) for ep in toy], 0),
        np.max([ep.giver_xyz.max(0) for ep in toy], 0),
    )
    assert np.all(pred >= lo - 1e-9) and np.all(
        pred <= hi + 1e-9
    )  # a convex blend of recorded givers


def test_bad_input_raises(agent):
    for bad, match in ((np.zeros((0, 2)), "at least 1 frame"),
                       (np.zeros((5, 3)), r"shape \(T, 2\)"),
                       (np.array([[0.0, np.nan]]), "NaN or inf"),
                       (np.zeros(4), r"shape \(T, 2\)")):
        with pytest.raises(ValueError, match=match):
            agent.predict(bad)
    with pytest.raises(ValueError, match=r"query times must lie in \[0, 4\]"):
        agent.predict_sequence(np.zeros((5, 2)), np.array([7]))
    agent.stream_reset()
    with pytest.raises(ValueError, match="no receiver frame streamed yet"):
        agent.stream_predict()
    with pytest.raises(ValueError, match="NaN or inf"):
        agent.stream_update(np.array([np.inf, 0.0]))
    agent.stream_update([0.5, -0.8])
    sums, last = agent.stream_distances().copy(), agent._state.last.copy()
    for bad, match in ((np.zeros((3, 2)), "takes one frame"), (np.zeros((5, 3)), "shape"),
                       ([[np.nan, 0.0]], "NaN or inf"), (np.zeros((0, 2)), "at least 1"),
                       (["a", "b"], "could not convert")):
        with pytest.raises(ValueError, match=match):
            agent.stream_update(bad)
    # a refused frame changes nothing
    assert np.array_equal(agent.stream_distances(), sums)
    assert np.array_equal(agent._state.last, last) and agent._state.count == 1
    with pytest.raises(RuntimeError, match=r"call fit\(dataset\) first"):
        NonparametricAgent().predict(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="fit needs a non-empty HandoverDataset"):
        NonparametricAgent().fit(HandoverDataset([]))
    for kwargs in ({"inducing_ratio": 0.0}, {"inducing_ratio": 1.2}, {"kappa": -1.0}, {"top_k": 0},
                   {"lengthscale": 0.0}, {"precision": "float16"}, {"horizon": 2.5}):
        with pytest.raises(ValueError, match=f"^{next(iter(kwargs))} must be"):
            NonparametricConfig(**kwargs)


def test_one_episode_and_short_episodes_work(toy):
    one = HandoverDataset([toy[0]])
    agent = NonparametricAgent(
        NonparametricConfig(lengthscale=0.15, top_k=10, precision="float64")
    ).fit(one)
    np.testing.assert_allclose(
        agent.predict(toy[0].receiver_xy[:10]), toy[0].giver_xyz[9:39], atol=1e-12
    )
    short = HandoverDataset([_episode(0, toy[0].receiver_xy[:8], toy[0].giver_xyz[:8]), toy[1]])
    agent = NonparametricAgent(
        NonparametricConfig(lengthscale=0.15, top_k=1, precision="float64")
    ).fit(short)
    pred = agent.predict(toy[0].receiver_xy[:4])
    np.testing.assert_allclose(pred[:5], toy[0].giver_xyz[3:8], atol=1e-12)
    np.testing.assert_allclose(pred[5:], np.repeat(toy[0].giver_xyz[7:8], 25, axis=0), atol=1e-12)


def test_act_follows_the_forecast_with_ready_pose_first(toy):
    layout = ObsLayout()
    agent = NonparametricAgent(CONFIG).fit(toy)
    agent.reset()
    ep = toy[2]
    sl = layout.slices()
    targets = []
    for n in range(1, 40):
        obs = np.zeros(layout.size, dtype=np.float32)
        hist = ep.receiver_xy[max(0, n - layout.history) : n]
        full = np.vstack([np.repeat(hist[:1], layout.history - len(hist), axis=0), hist])
        obs[sl["receiver_xy_history"][0]] = full.reshape(-1)
        obs[sl["receiver_frames_seen"][0]] = n
        targets.append(agent.act(obs))
    targets = np.array(targets)
    ready = np.array([*agent.closed_loop.ready_pos, agent.closed_loop.ready_yaw], dtype=np.float32)
    np.testing.assert_allclose(targets[0], ready)  # fewer than min_frames = 3 frames seen
    np.testing.assert_allclose(targets[1], ready)
    # Later the target is demo 2's giver at frame (n - 1) + t_f * 30 = n - 1 + 4.2 (interpolated).
    for n in (10, 25, 39):
        f = n - 1 + agent.params.forecast_time * 30.0
        lo = int(np.floor(f))
        exp = (1 - (f - lo)) * ep.giver_xyz[lo] + (f - lo) * ep.giver_xyz[lo + 1]
        np.testing.assert_allclose(targets[n - 1][:3], exp, atol=1e-5)
        assert abs(targets[n - 1][3] - ready[3]) <= agent.closed_loop.max_yaw_turn + 1e-6


REAL = (
    __import__("pathlib").Path(__file__).resolve().parents[2]
    / ".."
    / "shared"
    / "data"
    / "dynamic_handover_dataset"
    / "whole_motions"
)


@pytest.mark.skipif(not REAL.is_dir(), reason="development copy of the public dataset not present")
def test_real_recordings_sparse_matches_iaal():
    from agents.gp import GPHyperparameters, exact_gp_reference, fitc_gp
    from handover_env.person.demos import load_any
    from handover_eval import OpenLoopProtocol, evaluate_openloop, summarise

    ds = load_any(str(REAL))
    train, test = ds.subset(np.arange(0, len(ds), 12)), ds.subset(np.arange(3, len(ds), 120))
    ours = NonparametricAgent().fit(train)
    iaal = IAALAgent().fit(train)
    # FITC at ratio 1.0 vs the exact GP on real recordings (pauses make K_mm near singular).
    hyp: GPHyperparameters = ours.hyp
    for ep in list(train)[:3]:
        x = ep.receiver_xy - ours.origin
        y = backward_velocity(ep.receiver_xy, 30.0) / ours.output_scale
        xq = x[::4] + 0.03
        m0, v0 = exact_gp_reference(x, y, xq, hyp)
        m1, v1 = fitc_gp(x, y, x, hyp).predict(xq, hyp)
        assert np.abs(m1 - m0).max() < 1e-5 and np.abs(v1 - v0).max() < 1e-5
    proto = OpenLoopProtocol(stride=3)
    a = summarise(evaluate_openloop(ours, test, proto, progress=False))["all"]["rms_3d_mm"]
    b = summarise(evaluate_openloop(iaal, test, proto, progress=False))["all"]["rms_3d_mm"]
    assert np.isfinite(a) and abs(a - b) / b < 0.05
