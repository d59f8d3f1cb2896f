"""ACT baseline through LeRobot's ACTPolicy: LeRobot data path, training, checkpoints, errors."""

from __future__ import annotations

import json
import os
import shutil
from dataclasses import asdict

import numpy as np
import pytest
import torch

os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("HF_DATASETS_OFFLINE", "1")

import torch as _torch  # noqa: E402

_torch.set_num_threads(1)  # 2 threads on a shared 2-core box run ~10x slower

from baselines_toy import toy_dataset  # noqa: E402

from baselines.act import (  # noqa: E402
    ACTAgent,
    ACTAgentConfig,
    DropoutMasks,
    FastDropout,
    fast_dropout,
    feature_stats,
    lerobot_samples,
    normalise_samples,
    open_export,
)
from baselines.checkpoint_io import CheckpointError  # noqa: E402
from handover_env.data.features import FeatureSpec  # noqa: E402
from handover_env.data.lerobot_export import export_lerobot  # noqa: E402

TINY = dict(
    policy=dict(
        dim_model=32,
        n_heads=2,
        dim_feedforward=64,
        n_encoder_layers=1,
        latent_dim=4,
        optimizer_lr=1e-3,
    ),
    batch_size=16,
    steps=40,
    eval_every=20,
    use_giver_state=True,
)  # on this 8-episode toy set, receiver-only needs ~80 steps to improve


@pytest.fixture(scope="module")
def data():
    return toy_dataset(n=8, length=45, seed=2)


@pytest.fixture(scope="module")
def export(data, tmp_path_factory):
    return export_lerobot(data, tmp_path_factory.mktemp("act") / "lerobot", history=10)


@pytest.fixture(scope="module")
def trained(export, tmp_path_factory):
    out = tmp_path_factory.mktemp("act") / "ckpt"
    return ACTAgent(ACTAgentConfig(**TINY)).fit_lerobot(export, out_dir=out), out


def test_policy_is_lerobots_state_only_act():
    from lerobot.configs.types import FeatureType, NormalizationMode
    from lerobot.policies.act.modeling_act import ACTPolicy

    assert ACTAgentConfig().use_giver_state is False  # receiver-only by default, as in evaluate.py
    agent = ACTAgent(ACTAgentConfig(**TINY))
    pc = agent.policy.config
    assert isinstance(agent.policy, ACTPolicy)
    assert pc.image_features == {} and pc.env_state_feature.type is FeatureType.ENV
    assert pc.robot_state_feature.shape == (3,) and pc.action_feature.shape == (3,)
    assert pc.chunk_size == 30 and pc.n_action_steps == 1 and pc.temporal_ensemble_coeff == 0.01
    assert pc.normalization_mapping["ENV"] is NormalizationMode.MEAN_STD
    assert pc.pretrained_backbone_weights is None and not hasattr(agent.policy.model, "backbone")
    paper = ACTAgentConfig(paper_scale=True)
    model = paper.model()
    assert (model["dim_model"], model["dim_feedforward"], model["n_encoder_layers"]) == (
        512,
        3200,
        4,
    )
    assert (
        paper.policy_config().dim_model == 512 and ACTAgentConfig().policy_config().dim_model == 128
    )


def test_training_shows_a_tqdm_bar_of_its_steps(export, capsys):
    ACTAgent(ACTAgentConfig(**dict(TINY, steps=2, eval_every=2))).fit_lerobot(export, progress=True)
    err = capsys.readouterr().err
    assert "act" in err and "2/2" in err


def test_vectorised_samples_equal_lerobot_getitem(export):
    ds, _ = open_export(export, "local/handover", FeatureSpec(history=10))
    samples = lerobot_samples(ds, np.arange(ds.num_episodes))
    assert samples["observation.state"].shape[0] == len(ds)
    for i in (0, 1, 44, len(ds) // 2, len(ds) - 1):
        item = ds[i]
        for key in (
            "observation.environment_state",
            "observation.state",
            "action",
            "action_is_pad",
        ):
            assert torch.equal(item[key], samples[key][i]), (i, key)


def test_training_lowers_validation_loss_and_normalises_env(trained):
    agent, out = trained
    val = agent.train_log["val_loss"]
    assert len(val) == 2 and val[-1] < val[0]
    log = [json.loads(line) for line in (out / "train_log.jsonl").read_text().splitlines()]
    assert [r["step"] for r in log] == [20, 40] and [r["val_loss"] for r in log] == val
    stats = agent.preprocessor.steps[-1].stats
    assert "observation.environment_state" in stats  # the ENV feature is normalised too
    saved = json.loads((out / "handover_act.json").read_text())
    assert saved["type"] == "act" and saved["training"]["step"] == 40


def test_deterministic_under_seed(export, trained):
    agent, _ = trained
    again = ACTAgent(ACTAgentConfig(**TINY)).fit_lerobot(export)
    for k, v in agent.policy.state_dict().items():
        assert torch.equal(v, again.policy.state_dict()[k]), k


def test_resume_continues_exactly(export, trained, tmp_path):
    agent, _ = trained
    ACTAgent(ACTAgentConfig(**TINY)).fit_lerobot(export, out_dir=tmp_path, steps=20)
    resumed = ACTAgent(ACTAgentConfig(**TINY)).fit_lerobot(export, out_dir=tmp_path, resume=True)
    assert resumed.train_log["step"] == 40
    np.testing.assert_allclose(
        resumed.train_log["val_loss"], agent.train_log["val_loss"], rtol=1e-5
    )


def test_checkpoint_round_trip_and_predictions(data, trained, tmp_path):
    agent, out = trained
    ep = data[0]
    times = np.arange(5, ep.length)
    pred = agent.predict_episode(ep, times)
    assert pred.shape == (times.size, 30, 3) and np.all(np.isfinite(pred))
    # the predictions follow the walk, so equal predictions below mean equal weights
    assert np.ptp(pred[:, 0, :], axis=0).max() > 1e-3
    np.testing.assert_array_equal(ACTAgent.load(out).predict_episode(ep, times), pred)
    agent.save(tmp_path / "saved")
    np.testing.assert_array_equal(
        ACTAgent.load(tmp_path / "saved").predict_episode(ep, times), pred
    )
    np.testing.assert_allclose(
        agent.predict(ep.receiver_xy[:21], ep.giver_xyz[20]), pred[15], atol=1e-5
    )


def test_act_uses_lerobot_temporal_ensembler(trained):
    agent, _ = trained
    layout = agent.layout
    parts = {name: np.zeros(shape) for name, shape, _ in layout.fields}
    agent.reset()
    for k in range(4):
        parts["receiver_xy_history"] = np.tile([2.0 - 0.03 * k, -0.8], (layout.history, 1))
        parts["receiver_frames_seen"] = np.array([k + 1.0])
        parts["ee_pos"] = np.array([0.3, -0.4, 1.1])
        action = agent.act(layout.flatten(parts))
        assert action.shape == (4,) and np.all(np.isfinite(action))
    assert agent.policy.temporal_ensembler.ensembled_actions.shape == (1, 29, 3)


def test_clear_errors(data, export, trained, tmp_path):
    _, out = trained
    with pytest.raises(ValueError, match=r"shape \(20,\), this ACT config needs \(12,\)"):
        ACTAgent(ACTAgentConfig(**dict(TINY, history=6))).fit_lerobot(export)
    with pytest.raises(CheckpointError, match="no ACT checkpoint folder"):
        ACTAgent.load(tmp_path / "missing")
    (tmp_path / "half").mkdir()
    (tmp_path / "half" / "handover_act.json").write_text((out / "handover_act.json").read_text())
    with pytest.raises(CheckpointError, match="missing config.json"):
        ACTAgent.load(tmp_path / "half")
    with pytest.raises(CheckpointError, match="not 'act'"):
        (tmp_path / "bc").mkdir()
        (tmp_path / "bc" / "handover_act.json").write_text(
            json.dumps({"type": "bc_mlp", "format": 1})
        )
        ACTAgent.load(tmp_path / "bc")
    with pytest.raises(ValueError, match="horizon H=90 frames is longer than"):
        ACTAgent(ACTAgentConfig(**dict(TINY, horizon=90))).fit(data)
    with pytest.raises(ValueError, match="divisible"):
        ACTAgentConfig(policy=dict(dim_model=30, n_heads=4))
    with pytest.raises(ValueError, match="set by the agent"):
        ACTAgentConfig(policy=dict(chunk_size=5))
    with pytest.raises(ValueError, match="not an ACTConfig field"):
        ACTAgentConfig(policy=dict(lr=1e-3))
    with pytest.raises(ValueError, match="is not a"):
        ACTAgentConfig(policy=dict(use_vae="no"))


def test_receiver_only_variant_drops_the_state_feature(export, data):
    agent = ACTAgent(
        ACTAgentConfig(**dict(TINY, steps=4, eval_every=4, use_giver_state=False))
    ).fit_lerobot(export)
    assert agent.policy.config.robot_state_feature is None
    ep = data[1]
    pred = agent.predict(ep.receiver_xy[:15])
    np.testing.assert_allclose(
        agent.predict_sequence(ep.receiver_xy, np.array([14]))[0], pred, atol=1e-5
    )


def test_normalising_once_equals_the_per_batch_preprocessor(export):
    """fit_lerobot normalises all samples up front; a batch of them is bitwise the pipeline's
    batch."""
    from lerobot.policies.act.processor_act import make_act_pre_post_processors

    ds, _ = open_export(export, "local/handover", FeatureSpec(history=10))
    samples = lerobot_samples(ds, np.arange(ds.num_episodes))
    for giver in (True, False):
        agent = ACTAgent(ACTAgentConfig(**dict(TINY, use_giver_state=giver)))
        pre, _ = make_act_pre_post_processors(agent.policy.config, feature_stats(samples))
        whole = normalise_samples(pre, samples, chunk=50)  # several chunks
        assert set(whole) == set(samples)
        idx = torch.randperm(len(ds), generator=torch.Generator().manual_seed(1))[:37]
        batch = pre({k: v[idx] for k, v in samples.items()})
        for key in samples:
            assert torch.equal(whole[key][idx], batch[key]), key
        env = whole["observation.environment_state"]
        np.testing.assert_allclose(env.mean(0).numpy(), 0.0, atol=1e-4)  # really normalised
        state_changed = not torch.equal(whole["observation.state"], samples["observation.state"])
        assert state_changed == giver  # only an input feature is normalised


def test_training_on_export_episodes_equals_exporting_them(data, export, tmp_path):
    """episodes=: split and statistics from those episodes only, the same model as their own
    export."""
    chosen = np.array([0, 2, 3, 5, 6, 7])
    cfg = dict(TINY, steps=12, eval_every=6)
    sub = ACTAgent(ACTAgentConfig(**cfg)).fit_lerobot(
        export_lerobot(data.subset(chosen), tmp_path / "sub", history=10))
    part = ACTAgent(ACTAgentConfig(**cfg)).fit_lerobot(export, episodes=chosen)
    ids = {data[i].source_id for i in chosen}
    split = part.train_log["split"]
    assert set(split["train"]) | set(split["val"]) == ids and not set(split["train"]) & set(
        split["val"]
    )
    assert split == sub.train_log["split"]
    for k, v in sub.policy.state_dict().items():
        assert torch.equal(v, part.policy.state_dict()[k]), k
    assert part.train_log["val_loss"] == sub.train_log["val_loss"]
    # The normaliser's statistics are those of the chosen training episodes, not of the whole
    # export.
    ds, _ = open_export(export, "local/handover", FeatureSpec(history=10))
    train_ep = [i for i in chosen if data[i].source_id in set(split["train"])]
    mean = feature_stats(lerobot_samples(ds, np.array(train_ep)))["observation.environment_state"][
        "mean"
    ]
    every = feature_stats(lerobot_samples(ds, np.arange(len(data))))[
        "observation.environment_state"
    ]["mean"]
    got = part.preprocessor.steps[-1].stats["observation.environment_state"]["mean"]
    np.testing.assert_allclose(np.asarray(got), mean, rtol=1e-6)
    assert not np.allclose(np.asarray(got), every, rtol=1e-3)
    with pytest.raises(ValueError, match="unique"):
        ACTAgent(ACTAgentConfig(**cfg)).fit_lerobot(export, episodes=np.array([0, 1, 1]))
    with pytest.raises(ValueError, match=r"must lie in \[0, 7\]"):
        ACTAgent(ACTAgentConfig(**cfg)).fit_lerobot(export, episodes=np.array([0, 8]))


def test_fast_dropout_is_bernoulli_dropout():
    masks = DropoutMasks(seed=3)
    drop = FastDropout(0.1, masks).train()
    x = torch.ones(1000, 1000, requires_grad=True)
    y = drop(x)
    values = torch.unique(y.detach())
    assert values.tolist() == pytest.approx([0.0, 1 / 0.9])
    kept = float((y != 0).float().mean())
    assert abs(kept - 0.9) < 4 * (0.9 * 0.1 / 1e6) ** 0.5  # 4 sigma
    y.sum().backward()
    assert torch.equal(x.grad, y.detach())  # d(x * noise)/dx = noise
    assert torch.equal(drop.eval()(x), x)
    masks.reseed(5)
    a = masks.noise(torch.Size([4, 1000]), 0.1, torch.float32)
    masks.reseed(5)
    assert torch.equal(
        a, masks.noise(torch.Size([4, 1000]), 0.1, torch.float32)
    )  # resumable: (seed, step)
    masks.reseed(6)
    assert not torch.equal(a, masks.noise(torch.Size([4, 1000]), 0.1, torch.float32))
    # Rows are independent: adjacent rows of one draw do not repeat each other.
    assert not torch.equal(a[0], a[1])


def test_fast_dropout_swaps_only_while_training():
    agent = ACTAgent(ACTAgentConfig(**TINY))
    before = [type(m) for m in agent.policy.modules()]
    n_dropout = sum(t is torch.nn.Dropout for t in before)
    with fast_dropout(agent.policy, DropoutMasks(0)) as swapped:
        assert len(swapped) == n_dropout > 0
        assert not any(type(m) is torch.nn.Dropout for m in agent.policy.modules())
    assert [type(m) for m in agent.policy.modules()] == before


@pytest.mark.parametrize("config", [
    ACTAgentConfig(),
    ACTAgentConfig(paper_scale=True, steps=3000, eval_every=375),
    ACTAgentConfig(policy={"dim_model": 64, "optimizer_lr": 3e-4, "use_vae": False}),
])
def test_format_1_layout_round_trips(config):
    legacy = config.legacy_dict()
    assert legacy["grad_clip_norm"] == 10.0 and "policy" not in legacy
    assert ACTAgentConfig.from_legacy(legacy) == asdict(config)
    assert ACTAgentConfig(policy={"pre_norm": True}).legacy_dict() is None  # not in format 1
    with pytest.raises(CheckpointError, match="not a format-1"):
        ACTAgentConfig.from_legacy({**legacy, "extra": 1})
    with pytest.raises(CheckpointError, match="is not a"):
        ACTAgentConfig.from_legacy({**legacy, "lr": "big"})


def test_a_format_1_checkpoint_still_loads(trained, tmp_path, data):
    agent, out = trained
    folder = tmp_path / "old"
    shutil.copytree(out, folder)
    f = folder / "handover_act.json"
    saved = json.loads(f.read_text())
    f.write_text(json.dumps({**saved, "format": 1, "config": agent.config.legacy_dict()}))
    old = ACTAgent.load(folder)
    assert old.config == agent.config
    ep = data[0]
    np.testing.assert_array_equal(old.predict(ep.receiver_xy[:12], ep.giver_xyz[11]),
                                  agent.predict(ep.receiver_xy[:12], ep.giver_xyz[11]))
