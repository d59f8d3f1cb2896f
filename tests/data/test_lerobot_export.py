"""LeRobot export of the canonical dataset: features, reload offline, delta_timestamps chunks,
errors."""

from __future__ import annotations

import os

import numpy as np
import pytest

os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("HF_DATASETS_OFFLINE", "1")

import torch as _torch  # noqa: E402

_torch.set_num_threads(1)  # 2 threads on a shared 2-core box run ~10x slower

from baselines_toy import toy_dataset  # noqa: E402

from handover_env.data.features import FeatureSpec, episode_frames  # noqa: E402
from handover_env.data.lerobot_export import (  # noqa: E402
    TASK,
    action_delta_timestamps,
    export_lerobot,
    read_sidecar,
)


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    data = toy_dataset(n=6, length=40, seed=1)
    root = export_lerobot(
        data, tmp_path_factory.mktemp("export") / "ds", repo_id="local/toy", history=5
    )
    return data, root


def test_reloads_offline_with_same_length_and_features(exported):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    data, root = exported
    ds = LeRobotDataset("local/toy", root=root)
    assert len(ds) == data.n_frames
    assert ds.num_episodes == len(data)
    assert ds.fps == 30
    assert tuple(ds.features["observation.environment_state"]["shape"]) == (10,)
    assert tuple(ds.features["observation.state"]["shape"]) == (3,)
    assert tuple(ds.features["action"]["shape"]) == (3,)
    item = ds[data[0].length + 3]  # episode 1, frame 3
    ep = data[1]
    np.testing.assert_allclose(
        item["observation.state"].numpy(), ep.giver_xyz[3], rtol=0, atol=1e-6
    )
    np.testing.assert_allclose(item["action"].numpy(), ep.giver_xyz[3], rtol=0, atol=1e-6)
    want = episode_frames(ep, FeatureSpec(history=5), np.array([3])).env_state[0]
    np.testing.assert_allclose(item["observation.environment_state"].numpy(), want, atol=1e-6)
    assert item["task"] == TASK
    assert set(ds.meta.stats) >= {"observation.environment_state", "observation.state", "action"}


def test_delta_timestamps_give_the_future_giver_chunk(exported):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    data, root = exported
    ds = LeRobotDataset("local/toy", root=root, delta_timestamps=action_delta_timestamps(30, 30))
    ep = data[0]
    t = ep.length - 10  # the chunk runs 20 frames past the episode end
    item = ds[t]
    chunk, pad = item["action"].numpy(), item["action_is_pad"].numpy()
    assert chunk.shape == (30, 3) and pad.shape == (30,)
    np.testing.assert_allclose(chunk[:10], ep.giver_xyz[t:], atol=1e-6)
    np.testing.assert_allclose(chunk[10:], np.repeat(ep.giver_xyz[-1:], 20, axis=0), atol=1e-6)
    assert not pad[:10].any() and pad[10:].all()


def test_sidecar_records_windows_and_episode_flags(exported):
    data, root = exported
    meta = read_sidecar(root)
    assert meta["history"] == 5 and meta["horizon"] == 30
    assert meta["source_id"] == [ep.source_id for ep in data]
    assert meta["is_ood"] == [ep.is_ood for ep in data]


def test_refuses_existing_root_and_too_long_horizon(exported, tmp_path):
    data, root = exported
    with pytest.raises(FileExistsError, match="already exists"):
        export_lerobot(data, root)
    with pytest.raises(ValueError, match="horizon H=500 frames is longer than"):
        export_lerobot(data, tmp_path / "x", horizon=500)
    with pytest.raises(FileNotFoundError, match="not a handover LeRobot export"):
        read_sidecar(tmp_path)
