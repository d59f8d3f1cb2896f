"""BC-MLP baseline and the shared baseline features: learning, determinism, checkpoints, errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

torch.set_num_threads(1)  # 2 threads on a shared 2-core box run ~10x slower

from baselines_toy import toy_dataset  # noqa: E402

from baselines.bc_mlp import BCMLPAgent, BCMLPConfig  # noqa: E402
from baselines.checkpoint_io import CheckpointError  # noqa: E402
from handover_env.data.features import (  # noqa: E402
    FeatureSpec,
    encode_history,
    encode_receiver,
    episode_frames,
)

SMALL = dict(hidden=(32, 32), batch_size=64, max_epochs=4, patience=50, use_giver_state=True)


@pytest.fixture(scope="module")
def data():
    return toy_dataset(n=12, length=50, seed=0)


@pytest.fixture(scope="module")
def trained(data, tmp_path_factory):
    out = tmp_path_factory.mktemp("bc") / "ckpt"
    agent = BCMLPAgent(BCMLPConfig(**SMALL)).fit(data, out_dir=out)
    return agent, out


# ----------------------------------------------------------------- features
def test_receiver_encoding_is_current_position_plus_offsets():
    window = np.array([[3.0, 1.0], [2.5, 1.0], [2.0, 0.5]])
    np.testing.assert_allclose(encode_receiver(window), [2.0, 0.5, 1.0, 0.5, 0.5, 0.5])
    # fewer frames than W: the first frame is repeated, as in the env's observation buffer
    np.testing.assert_allclose(encode_history(window[:1], history=3), [3.0, 1.0, 0, 0, 0, 0])


def test_episode_frames_chunks_are_the_future_giver_with_padding(data):
    ep = data[0]
    f = episode_frames(ep, FeatureSpec(history=4, horizon=30), np.array([0, ep.length - 5]))
    np.testing.assert_allclose(f.action[0], ep.giver_xyz[:30], atol=1e-6)
    np.testing.assert_allclose(f.action[1, :5], ep.giver_xyz[-5:], atol=1e-6)
    assert f.action_is_pad[1].sum() == 25 and not f.action_is_pad[0].any()
    np.testing.assert_allclose(f.state[1], ep.giver_xyz[ep.length - 5], atol=1e-6)


# ----------------------------------------------------------------- training
def test_loss_decreases_and_early_stopping_state_is_saved(trained):
    agent, out = trained
    log = agent.train_log
    assert log["val_loss"][-1] < log["val_loss"][0]
    assert log["train_loss"][-1] < log["train_loss"][0]
    cfg = json.loads((out / "config.json").read_text())
    assert cfg["type"] == "bc_mlp" and cfg["features"]["horizon"] == 30


def test_early_stopping_stops_on_patience(data):
    agent = BCMLPAgent(
        BCMLPConfig(hidden=(8,), batch_size=64, max_epochs=200, patience=1, lr=0.5)
    ).fit(data)
    assert agent.train_log["stopped_early"] and agent.train_log["epoch"] < 200


def test_deterministic_under_seed(data, trained):
    agent, _ = trained
    again = BCMLPAgent(BCMLPConfig(**SMALL)).fit(data)
    for k, v in agent.net.state_dict().items():
        assert torch.equal(v, again.net.state_dict()[k]), k


def test_resume_continues_exactly(data, tmp_path):
    cfg = dict(SMALL, max_epochs=4)
    straight = BCMLPAgent(BCMLPConfig(**cfg)).fit(data)
    BCMLPAgent(BCMLPConfig(**cfg)).fit(data, out_dir=tmp_path, max_epochs=2)
    resumed = BCMLPAgent(BCMLPConfig(**cfg)).fit(data, out_dir=tmp_path, resume=True)
    assert resumed.train_log["epoch"] == 4
    np.testing.assert_allclose(
        resumed.train_log["val_loss"], straight.train_log["val_loss"], rtol=1e-6
    )


# ----------------------------------------------------------------- inference and checkpoints
def test_checkpoint_round_trip_gives_identical_predictions(data, trained, tmp_path):
    agent, out = trained
    ep = data[3]
    times = np.arange(5, ep.length)
    pred = agent.predict_episode(ep, times)
    assert pred.shape == (times.size, 30, 3)
    # the predictions follow the walk, so equal predictions below mean equal weights
    assert np.ptp(pred[:, 0, :], axis=0).max() > 1e-3
    np.testing.assert_array_equal(BCMLPAgent.load(out).predict_episode(ep, times), pred)
    agent.save(tmp_path / "saved")
    np.testing.assert_array_equal(
        BCMLPAgent.load(tmp_path / "saved").predict_episode(ep, times), pred
    )
    # predict / predict_sequence agree with the batched episode path
    t = 20
    np.testing.assert_allclose(
        agent.predict(ep.receiver_xy[: t + 1], ep.giver_xyz[t]), pred[t - 5], atol=1e-6
    )
    seq = agent.predict_sequence(ep.receiver_xy, times, giver_xyz=ep.giver_xyz)
    np.testing.assert_array_equal(seq, pred)


def test_act_in_env_observation(trained):
    agent, _ = trained
    layout = agent.layout
    parts = {name: np.zeros(shape) for name, shape, _ in layout.fields}
    agent.reset()
    for k in range(5):
        parts["receiver_xy_history"] = np.tile([2.0 - 0.03 * k, -0.8], (layout.history, 1))
        parts["receiver_frames_seen"] = np.array([k + 1.0])
        parts["ee_pos"] = np.array([0.3, -0.4, 1.1])
        action = agent.act(layout.flatten(parts))
        assert action.shape == (4,) and action.dtype == np.float32 and np.all(np.isfinite(action))


def test_clear_errors(data, trained, tmp_path):
    agent, out = trained
    with pytest.raises(CheckpointError, match="no BC-MLP checkpoint folder"):
        BCMLPAgent.load(tmp_path / "missing")
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "config.json").write_text(json.dumps({"type": "act", "format": 1}))
    with pytest.raises(CheckpointError, match="not 'bc_mlp'"):
        BCMLPAgent.load(tmp_path / "other")
    with pytest.raises(ValueError, match="horizon H=400 frames is longer than"):
        BCMLPAgent(BCMLPConfig(**SMALL, horizon=400)).fit(data)
    with pytest.raises(ValueError, match="giver"):
        agent.predict(data[0].receiver_xy[:10])
    with pytest.raises(ValueError, match=r"shape \(T, 2\)"):
        agent.predict(np.zeros((10, 3)), np.zeros(3))
    with pytest.raises(ValueError, match="env_state"):
        agent.predict_batch(np.zeros((2, 7)), np.zeros((2, 3)))
    with pytest.raises(RuntimeError, match="not trained"):
        BCMLPAgent(BCMLPConfig(**SMALL)).predict(data[0].receiver_xy, np.zeros(3))
    with pytest.raises(ValueError, match="history"):
        BCMLPConfig(history=1)
    assert BCMLPConfig().use_giver_state is False  # receiver-only by default, as in evaluate.py


def test_receiver_only_variant_needs_no_giver(data):
    agent = BCMLPAgent(BCMLPConfig(**dict(SMALL, max_epochs=2, use_giver_state=False))).fit(data)
    ep = data[1]
    pred = agent.predict(ep.receiver_xy[:15])
    assert pred.shape == (30, 3)
    np.testing.assert_allclose(agent.predict_episode(ep, np.array([14]))[0], pred, atol=1e-6)
    np.testing.assert_allclose(
        agent.predict_sequence(ep.receiver_xy, np.array([14]))[0], pred, atol=1e-6
    )


REAL = (
    Path(__file__).resolve().parents[2]
    / ".."
    / "shared"
    / "data"
    / "dynamic_handover_dataset"
    / "whole_motions"
)


@pytest.mark.skipif(
    not REAL.is_dir(), reason="the development copy of the public dataset is absent"
)
def test_learns_real_recordings_by_the_shared_protocol():
    from handover_env.data.public import load_public_dataset
    from handover_eval.openloop.protocol import evaluate_openloop, summarise

    real = load_public_dataset(REAL, progress=False)
    train_idx, test_idx = real.stratified_kfold(10, seed=0)[0]
    train = real.subset(train_idx[::8])  # ~100 episodes keep the test fast
    agent = BCMLPAgent(BCMLPConfig(hidden=(128, 128), max_epochs=8, patience=3)).fit(train)
    summary = summarise(evaluate_openloop(agent, real.subset(test_idx[::4]), progress=False))
    # a useful predictor: far below the ~0.5 m spread of the giver positions; paper BC-MLP 152 mm
    assert summary["id"]["rms_3d_mm"] < 200, summary
