"""Issue 16 items 2, 3, 9: the LeRobot export never deletes a user's folder, never trains on stale
data, and an interrupted export blocks nothing."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("HF_DATASETS_OFFLINE", "1")

import torch  # noqa: E402

torch.set_num_threads(1)

from baselines_toy import toy_dataset  # noqa: E402

from baselines.checkpoint_io import CheckpointError  # noqa: E402
from handover_env.data.__main__ import main  # noqa: E402
from handover_env.data.lerobot_export import export_lerobot, read_sidecar  # noqa: E402
from handover_env.paths import UnsafePathError  # noqa: E402

TINY = {"policy": {"dim_model": 16, "n_heads": 2, "dim_feedforward": 32, "n_encoder_layers": 1,
                   "latent_dim": 4},
        "batch_size": 8, "steps": 2, "eval_every": 1}


@pytest.fixture(scope="module")
def data():
    return toy_dataset(n=6, length=35, seed=4)


def _tree(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


# ---------------------------------------------------------------------- item 2
def test_overwrite_refuses_a_folder_that_is_not_an_export(tmp_path: Path, data, capsys) -> None:
    src = data.save(tmp_path / "d.npz")
    user = tmp_path / "thesis"
    (user / ".git").mkdir(parents=True)
    (user / ".git" / "HEAD").write_text("ref: refs/heads/main\n")
    (user / "paper.tex").write_text("\\documentclass{article}")
    before = _tree(user)
    assert main(["export-lerobot", str(src), str(user), "--overwrite"]) == 2
    assert (
        f"refusing to overwrite {user}: it is not a handover LeRobot export"
        in capsys.readouterr().err
    )
    assert _tree(user) == before


@pytest.mark.parametrize(
    "root",
    ["", " ", ".", "./", "/", "~"],
    ids=["empty", "blank", "dot", "dot-slash", "root", "home"],
)
def test_dangerous_roots_are_refused_before_anything_is_read(
    tmp_path: Path, data, root: str, monkeypatch, capsys
) -> None:
    work = tmp_path / "work"
    work.mkdir()
    (work / "d.npz").write_bytes(b"the user's input")
    monkeypatch.chdir(work)
    assert main(["export-lerobot", "d.npz", root, "--overwrite"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: refusing") and err.count("\n") == 1, err
    assert (work / "d.npz").read_bytes() == b"the user's input"
    with pytest.raises(UnsafePathError):
        export_lerobot(data, root, overwrite=True)


def test_parents_of_the_current_folder_and_home_are_refused(
    tmp_path: Path, data, monkeypatch
) -> None:
    inner = tmp_path / "a" / "b"
    inner.mkdir(parents=True)
    monkeypatch.chdir(inner)
    with pytest.raises(UnsafePathError, match="holds the current folder"):
        export_lerobot(data, tmp_path / "a", overwrite=True)
    monkeypatch.setenv("HOME", str(tmp_path / "users" / "me"))
    (tmp_path / "users" / "me").mkdir(parents=True)
    with pytest.raises(UnsafePathError, match="holds the home folder"):
        export_lerobot(data, tmp_path / "users", overwrite=True)
    with pytest.raises(UnsafePathError, match="is or holds the home folder"):
        export_lerobot(data, tmp_path / "users" / "me", overwrite=True)


def test_overwrite_replaces_an_earlier_export(tmp_path: Path, data) -> None:
    root = export_lerobot(data.subset([0, 1]), tmp_path / "ds", history=4)
    assert read_sidecar(root)["source_id"] == [data[0].source_id, data[1].source_id]
    with pytest.raises(FileExistsError, match="already exists"):
        export_lerobot(data, root, history=4)
    export_lerobot(data, root, history=4, overwrite=True)
    assert read_sidecar(root)["fingerprint"] == data.fingerprint()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]  # no temporary sibling left


# ---------------------------------------------------------------------- item 9
def test_an_interrupted_export_leaves_nothing_that_blocks_a_rerun(
    tmp_path: Path, data, monkeypatch
) -> None:
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    real = LeRobotDataset.save_episode
    calls = {"n": 0}

    def interrupted(self, *args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 2:
            raise KeyboardInterrupt  # Ctrl-C in the middle of the export
        return real(self, *args, **kwargs)

    monkeypatch.setattr(LeRobotDataset, "save_episode", interrupted)
    root = tmp_path / "ds"
    with pytest.raises(KeyboardInterrupt):
        export_lerobot(data, root, history=4)
    assert list(tmp_path.iterdir()) == []
    monkeypatch.setattr(LeRobotDataset, "save_episode", real)
    stale = (
        tmp_path / ".ds.partial-999999999-dead"
    )  # what a SIGKILL leaves: removed by the next run
    (stale / "meta").mkdir(parents=True)
    export_lerobot(data, root, history=4)  # no --overwrite needed
    assert read_sidecar(root)["n_frames"] == data.n_frames
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]


def test_train_rebuilds_a_half_written_export_of_older_code(tmp_path: Path, data, capsys) -> None:
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from handover_eval.cli import train

    src = data.save(tmp_path / "d.npz")
    half = tmp_path / "run" / "lerobot_dataset"  # interrupted by the old exporter: no sidecar
    (half / "meta").mkdir(parents=True)
    (half / "meta" / "info.json").write_text(json.dumps({"robot_type": "handover_giver"}))
    argv = ["act", "--smoke", "--data", str(src), "--out", str(tmp_path / "run"), "--steps", "2",
            "--eval-every", "1", "--no-progress", "--dim-model", "16", "--n-heads", "2"]
    assert train.main(argv) == 0, capsys.readouterr().err
    assert read_sidecar(half)["fingerprint"] == data.fingerprint()
    other = tmp_path / "shared_export"
    (other / "meta").mkdir(parents=True)
    (other / "meta" / "info.json").write_text(json.dumps({"robot_type": "handover_giver"}))
    argv2 = [*argv[:5], str(tmp_path / "run2"), *argv[6:], "--export-root", str(other)]
    assert train.main(argv2) == 2
    assert "pass --overwrite to rebuild it" in capsys.readouterr().err
    assert train.main([*argv2, "--overwrite"]) == 0
    assert read_sidecar(other)["fingerprint"] == data.fingerprint()


# ---------------------------------------------------------------------- item 3
def test_a_second_fold_trains_on_its_own_episodes(tmp_path: Path) -> None:
    from baselines.act import ACTAgent, ACTAgentConfig

    data = toy_dataset(n=12, length=35, seed=4)
    folds = data.stratified_kfold(2, seed=0)
    root = tmp_path / "export"
    (train0, _), (train1, test1) = folds[0], folds[1]
    ACTAgent(ACTAgentConfig(**TINY)).fit(data.subset(train0), export_root=root)
    fold1 = data.subset(train1)
    with pytest.raises(CheckpointError, match="was exported from other data"):
        ACTAgent(ACTAgentConfig(**TINY)).fit(fold1, export_root=root, rebuild_export=False)
    agent = ACTAgent(ACTAgentConfig(**TINY)).fit(fold1, export_root=root)
    meta = read_sidecar(root)
    assert meta["fingerprint"] == fold1.fingerprint() and meta["n_frames"] == fold1.n_frames
    seen = set(agent.train_log["split"]["train"]) | set(agent.train_log["split"]["val"])
    assert seen == {ep.source_id for ep in fold1}
    assert not seen & {data[i].source_id for i in test1}  # no test episode leaks into training
