"""The shared open-loop RMS protocol (handover_eval/openloop.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agents.base import Agent
from handover_env.data.dataset import Episode, HandoverDataset
from handover_eval import (
    OpenLoopProtocol,
    episode_errors,
    episode_rms,
    evaluate_openloop,
    kfold_rms,
    query_times,
    summarise,
)


class _Oracle(Agent):
    """Knows the test episode's giver trajectory; adds a fixed offset (and records what it saw)."""

    horizon = 30

    def __init__(self, giver: np.ndarray | None = None, offset=(0.0, 0.0, 0.0)) -> None:
        self.giver, self.offset, self.seen = giver, np.asarray(offset), []

    def fit(self, dataset):
        return self

    def predict(self, receiver_history):
        t = len(receiver_history) - 1
        self.seen.append(len(receiver_history))
        rows = np.minimum(t + np.arange(self.horizon), len(self.giver) - 1)
        return self.giver[rows] + self.offset

    def reset(self):
        pass

    def act(self, obs):
        return np.zeros(4, dtype=np.float32)


class _Constant(_Oracle):
    def predict(self, receiver_history):
        return np.tile(self.offset, (self.horizon, 1))


def _episode(n: int, ood: bool = False, sid: str = "e") -> Episode:
    t = np.arange(n, dtype=float)
    return Episode(receiver_xy=np.column_stack([t, t]), receiver_hand_xyz=np.zeros((n, 3)),
                   giver_xyz=np.column_stack([0.01 * t, np.zeros(n), np.ones(n)]),
                   object_quat=np.tile([1.0, 0, 0, 0], (n, 1)), is_ood=ood, source_id=sid)


def test_query_times_and_history_seen():
    p = OpenLoopProtocol()
    assert (p.horizon, p.first_query, p.stride) == (30, 5, 1)
    np.testing.assert_array_equal(query_times(10, p), [5, 6, 7, 8])
    np.testing.assert_array_equal(
        query_times(12, OpenLoopProtocol(first_query=0, stride=4)), [0, 4, 8]
    )
    assert query_times(6, p).size == 0
    ep = _episode(12)
    agent = _Oracle(ep.giver_xyz)
    episode_rms(agent, ep, p)
    assert agent.seen == [6, 7, 8, 9, 10, 11]  # receiver_xy[: t_c + 1] for t_c = 5..10


def test_perfect_prediction_scores_zero_and_offset_scores_its_norm():
    ep = _episode(50)
    assert episode_rms(_Oracle(ep.giver_xyz), ep)[0] == 0.0
    rms, n = episode_rms(_Oracle(ep.giver_xyz, offset=(0.03, 0.04, 0.0)), ep)
    assert math.isclose(rms, 50.0, rel_tol=1e-12)  # 3D error 0.05 m everywhere
    # Rows past the episode end are not compared: sum over queries of min(H, L - t_c).
    assert n == sum(min(30, 50 - t) for t in range(5, 49))


def test_rms_is_pooled_over_rows_not_averaged_per_query():
    ep = _episode(8)  # queries at 5 and 6, with 3 and 2 comparable rows
    agent = _Constant(offset=(0.0, 0.0, 0.0))
    rms, n = episode_rms(agent, ep)
    rows = np.concatenate([np.arange(5, 8), np.arange(6, 8)])
    err2 = np.sum(ep.giver_xyz[rows] ** 2, axis=1)
    assert n == 5 and math.isclose(rms, 1000 * math.sqrt(err2.mean()), rel_tol=1e-12)


def test_evaluate_summarise_and_kfold():
    eps = [_episode(40 + i, ood=(i % 4 == 0), sid=f"e{i}") for i in range(12)] + [
        _episode(5, sid="too_short")
    ]
    ds = HandoverDataset(eps)
    recs = evaluate_openloop(_Constant(offset=(0.0, 0.0, 1.0)), ds, progress=False)
    assert [r.source_id for r in recs] == [
        f"e{i}" for i in range(12)
    ]  # the episode without a query is skipped
    for r in recs:
        assert math.isclose(r.rms_axis_mm, r.rms_3d_mm / math.sqrt(3))
    s = summarise(recs)
    assert s["id"]["n_episodes"] == 9 and s["ood"]["n_episodes"] == 3
    ids = [r.rms_3d_mm for r in recs if not r.is_ood]
    assert math.isclose(s["id"]["rms_3d_mm"], np.mean(ids)) and math.isclose(
        s["id"]["rms_3d_std"], np.std(ids, ddof=1)
    )
    out = kfold_rms(
        lambda: _Constant(offset=(0.0, 0.0, 1.0)),
        HandoverDataset(eps[:12]),
        k=3,
        seed=0,
        progress=False,
    )
    assert len(out["per_fold"]) == 3 and len(out["records"]) == 12
    fold_means = [f["id"]["rms_3d_mm"] for f in out["per_fold"]]
    assert math.isclose(out["id"][0], np.mean(fold_means)) and math.isclose(
        out["id"][1], np.std(fold_means, ddof=1)
    )
    assert math.isclose(out["id_axis"][0], out["id"][0] / math.sqrt(3))


def test_current_frame_error_reads_row_zero_only_per_coordinate():
    ep = _episode(50)
    rms, now_axis, n = episode_errors(_Oracle(ep.giver_xyz, offset=(0.03, 0.04, 0.0)), ep)
    assert math.isclose(rms, 50.0, rel_tol=1e-12)
    assert math.isclose(
        now_axis, 50.0 / math.sqrt(3), rel_tol=1e-12
    )  # 0.05 m in 3D = 28.87 mm per coordinate

    class _LateDrift(_Oracle):
        """Exact at row 0, 0.1 m off in z on every later row."""

        def predict(self, receiver_history):
            out = super().predict(receiver_history).copy()
            out[1:, 2] += 0.1
            return out

    rms, now_axis, n = episode_errors(_LateDrift(ep.giver_xyz), ep)
    assert now_axis == 0.0 and rms > 50.0
    recs = evaluate_openloop(_LateDrift(ep.giver_xyz), HandoverDataset([ep]), progress=False)
    assert recs[0].rms_now_axis_mm == 0.0 and summarise(recs)["all"]["rms_now_axis_mm"] == 0.0
    out = kfold_rms(
        lambda: _Constant(offset=(0.0, 0.0, 1.0)),
        HandoverDataset([_episode(40 + i, ood=(i % 4 == 0), sid=f"e{i}") for i in range(12)]),
        k=3,
        seed=0,
        progress=False,
    )
    assert math.isfinite(out["id_now_axis"][0]) and math.isfinite(out["ood_now_axis"][0])


def test_bad_predictions_and_settings_raise():
    ep = _episode(20)

    class _Bad(_Constant):
        def predict(self, receiver_history):
            return np.full((self.horizon, 3), np.nan)

    with pytest.raises(ValueError, match="agent returned NaN/inf predictions"):
        episode_rms(_Bad(), ep)
    short = _Constant()
    short.horizon = 5
    with pytest.raises(
        ValueError, match=r"predictions of shape \(14, 5, 3\), need \(14, >= 30, 3\)"
    ):
        episode_rms(short, ep)
    for kwargs in ({"horizon": 0}, {"first_query": -1}, {"stride": 0}, {"stride": 1.5}):
        with pytest.raises(ValueError, match=f"^{next(iter(kwargs))} must be an integer"):
            OpenLoopProtocol(**kwargs)
