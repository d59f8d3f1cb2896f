"""Issue 20: loading a checkpoint writes nothing; only the writer finishes an interrupted commit,
and only after every destination is checked to stay inside the folder (items: the symlinked
staging hole, 8 (a kill during the first commit) and 9 (bounded normalisation statistics))."""

from __future__ import annotations

import json
import os
import re
import shutil
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("HF_DATASETS_OFFLINE", "1")

import torch  # noqa: E402

torch.set_num_threads(1)

from baselines_toy import toy_dataset  # noqa: E402
from planted import PAYLOAD, Untouched, plant  # noqa: E402
from safetensors.torch import load_file, save_file  # noqa: E402

from baselines.act import ACTAgent, ACTAgentConfig  # noqa: E402
from baselines.bc_mlp import BCMLPAgent, BCMLPConfig  # noqa: E402
from baselines.checkpoint_io import (  # noqa: E402
    CheckpointError,
    check_out_dir,
    checkpoint_kind,
    recover,
    staged_write,
)

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from handover_eval.cli import train  # noqa: E402

ACT_TINY = {"policy": {"dim_model": 16, "n_heads": 2, "dim_feedforward": 32, "n_encoder_layers": 1,
                       "latent_dim": 4}, "batch_size": 8, "steps": 2, "eval_every": 1,
            "use_giver_state": True}
PRE_STATS = "policy_preprocessor_step_3_normalizer_processor.safetensors"
POST_STATS = "policy_postprocessor_step_0_unnormalizer_processor.safetensors"


@pytest.fixture(scope="module")
def data():
    return toy_dataset(n=6, length=40, seed=5)


@pytest.fixture(scope="module")
def data_path(tmp_path_factory) -> Path:
    return toy_dataset(n=8, length=40, seed=6).save(tmp_path_factory.mktemp("data") / "toy.npz")


@pytest.fixture(scope="module")
def bc_dir(data, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("bc") / "ckpt"
    BCMLPAgent(BCMLPConfig(hidden=(16,), max_epochs=2, use_giver_state=True)).fit(
        data, out_dir=out).save(out)
    return out


@pytest.fixture(scope="module")
def act_dir(data, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("act") / "ckpt"
    ACTAgent(ACTAgentConfig(**ACT_TINY)).fit(data, out_dir=out).save(out)
    return out


def cli(method: str, data_path: Path, out: Path, *extra: str) -> list[str]:
    steps = ["--steps", "4", "--eval-every", "2"] if method == "act" else []
    return [method, "--smoke", "--data", str(data_path), "--out", str(out), "--no-progress",
            *steps, *extra]


@pytest.fixture
def outside(tmp_path) -> Path:
    """A folder outside the checkpoint (a Python environment's site-packages, say) with a file
    the attack tries to overwrite."""
    site = tmp_path / "site-packages"
    site.mkdir()
    (site / "victim.pth").write_text("ORIGINAL")
    return site


# ---------------------------------------------------------------------- loading writes nothing
@pytest.mark.parametrize("kind", ["bc", "act"])
def test_loading_a_planted_checkpoint_writes_nothing(request, tmp_path, outside, kind):
    folder = shutil.copytree(request.getfixturevalue(f"{kind}_dir"), tmp_path / "ckpt")
    plant(folder, outside)
    untouched = Untouched(outside, folder)
    cls = BCMLPAgent if kind == "bc" else ACTAgent
    with pytest.raises(CheckpointError, match=re.escape(str(folder / ".staging"))) as info:
        cls.load(folder)
    message = str(info.value)
    assert f"{folder / '.staging'}: an interrupted checkpoint write" in message
    assert "--resume" in message and "\n" not in message
    untouched.check()


@pytest.mark.parametrize("kind", ["bc", "act"])
def test_an_uncommitted_staging_folder_is_ignored_by_loading(request, tmp_path, outside, kind):
    """A write killed before its commit record leaves the previous checkpoint whole: it loads, and
    the staging folder is left for the writer to discard."""
    folder = shutil.copytree(request.getfixturevalue(f"{kind}_dir"), tmp_path / "ckpt")
    plant(folder, outside)
    (folder / ".staging" / "COMMIT.json").unlink()
    untouched = Untouched(outside, folder)
    agent = (BCMLPAgent if kind == "bc" else ACTAgent).load(folder)
    assert agent.fitted
    untouched.check()


@pytest.mark.parametrize("kind", ["bc", "act"])
def test_a_file_linked_out_of_the_folder_is_refused_by_loading(request, tmp_path, outside, kind):
    folder = shutil.copytree(request.getfixturevalue(f"{kind}_dir"), tmp_path / "ckpt")
    shutil.move(folder / "model.safetensors", outside / "model.safetensors")
    (folder / "model.safetensors").symlink_to(outside / "model.safetensors")
    untouched = Untouched(outside, folder)
    with pytest.raises(CheckpointError, match="model.safetensors: a symbolic link out of"):
        (BCMLPAgent if kind == "bc" else ACTAgent).load(folder)
    untouched.check()


@pytest.mark.parametrize("name", ["bc_mlp", "act"])
def test_the_evaluation_reuse_never_recovers_a_planted_cache(data, tmp_path, outside, name):
    """evaluate.py's checkpoint cache (handover_eval.methods.fit_agent, which also loads the fold
    models handover_eval.act_folds pre-trains): a planted commit is refused, the checkpoint is
    retrained, and nothing outside the cache changes."""
    from handover_eval.methods import MethodOptions, build_agent, checkpoint_slot, fit_agent

    options = MethodOptions(seed=0, quick=True, act_steps=2, bc_epochs=2, workers=1)
    cache = tmp_path / "cache"
    assert not fit_agent(name, build_agent(name, options), data, cache)[1]
    folder, _ = checkpoint_slot(name, build_agent(name, options), data, cache)
    plant(folder, outside)
    untouched = Untouched(outside)
    agent, reused = fit_agent(name, build_agent(name, options), data, cache)
    assert not reused and agent.fitted
    untouched.check()
    assert not (folder / "lnk").exists() and not (folder / ".staging").exists()
    assert fit_agent(name, build_agent(name, options), data, cache)[1]  # clean again: reused


# ---------------------------------------------------------------------- the writers check first
@pytest.mark.parametrize("method", ["bc-mlp", "act"])
def test_resume_refuses_a_planted_commit_and_changes_nothing(
    data_path, tmp_path, outside, capsys, method
):
    folder = tmp_path / "run"
    assert train.main(cli(method, data_path, folder)) == 0
    plant(folder, outside)
    untouched = Untouched(outside, folder)
    capsys.readouterr()
    assert train.main(cli(method, data_path, folder, "--resume")) == 2
    err = capsys.readouterr().err
    assert f"commit entry 'lnk/x.pth': {folder / 'lnk'} is a symbolic link" in err, err
    untouched.check()


def test_resume_refuses_a_symlinked_checkpoint_file(data_path, tmp_path, outside, capsys):
    """--resume rewrites train_summary.json (and every checkpoint file): never through a link."""
    folder = tmp_path / "run"
    assert train.main(cli("bc-mlp", data_path, folder)) == 0
    (folder / "train_summary.json").unlink()
    (folder / "train_summary.json").symlink_to(outside / "victim.pth")
    untouched = Untouched(outside, folder)
    capsys.readouterr()
    assert train.main(cli("bc-mlp", data_path, folder, "--resume")) == 2
    assert "train_summary.json is a symbolic link" in capsys.readouterr().err
    untouched.check()


def test_a_staged_write_refuses_a_planted_commit(bc_dir, tmp_path, outside):
    folder = shutil.copytree(bc_dir, tmp_path / "ckpt")
    plant(folder, outside)
    untouched = Untouched(outside, folder)
    with pytest.raises(CheckpointError, match=r"commit entry 'lnk/x\.pth'"):
        with staged_write(folder) as stage:
            (stage / "a.json").write_text("{}")
    with pytest.raises(CheckpointError, match=r"commit entry 'lnk/x\.pth'"):
        BCMLPAgent.load(bc_dir).save(folder)
    untouched.check()


def test_a_staged_write_never_writes_through_a_link_in_the_folder(data, tmp_path, outside):
    """The writer's own commit is checked too: a symlinked training_state (or any symlinked
    folder) of the checkpoint refuses the checkpoint before its commit record exists."""
    folder = tmp_path / "ckpt"
    folder.mkdir()
    (folder / "lnk").symlink_to(outside, target_is_directory=True)
    untouched = Untouched(outside)
    with pytest.raises(CheckpointError, match=r"commit entry 'lnk/x\.pth'"):
        with staged_write(folder) as stage:
            (stage / "lnk").mkdir()
            (stage / "lnk" / "x.pth").write_text(PAYLOAD)
    assert not (folder / ".staging").exists()
    (folder / "training_state").symlink_to(outside, target_is_directory=True)
    with pytest.raises(CheckpointError, match=r"'training_state/[a-z_]+\.[a-z]+'.* symbolic link"):
        BCMLPAgent(BCMLPConfig(hidden=(8,), max_epochs=1)).fit(data, out_dir=folder)
    untouched.check()
    assert sorted(p.name for p in folder.iterdir()) == ["lnk", "training_state"]


def _commit(folder: Path, entries: list, files: dict[str, str] | None = None) -> None:
    stage = folder / ".staging"
    stage.mkdir(exist_ok=True)
    for rel, text in (files or {}).items():
        (stage / rel).parent.mkdir(parents=True, exist_ok=True)
        (stage / rel).write_text(text)
    (stage / "COMMIT.json").write_text(json.dumps({"files": entries}))


def _staged_source_link(folder: Path, outside: Path) -> str:
    _commit(folder, ["a.json"])
    (folder / ".staging" / "a.json").symlink_to(outside / "victim.pth")
    return r"'a\.json': the staged .*a\.json is a symbolic link"


def _staged_folder_link(folder: Path, outside: Path) -> str:
    _commit(folder, ["sub/victim.pth"])
    (folder / ".staging" / "sub").symlink_to(outside, target_is_directory=True)
    return r"'sub/victim\.pth': the staged .*sub is a symbolic link"


def _staging_is_a_link(folder: Path, outside: Path) -> str:
    (outside / "y.json").write_text("{}")  # the staged file and its record, through the link
    (outside / "COMMIT.json").write_text(json.dumps({"files": ["y.json"]}))
    (folder / ".staging").symlink_to(outside, target_is_directory=True)
    return r"\.staging: not a folder \(a symbolic link\?\)"


def _record_is_a_link(folder: Path, outside: Path) -> str:
    (folder / ".staging").mkdir()
    (outside / "rec.json").write_text(json.dumps({"files": []}))
    (folder / ".staging" / "COMMIT.json").symlink_to(outside / "rec.json")
    return r"COMMIT\.json: not a regular file"


def _deep_link(folder: Path, outside: Path) -> str:
    (folder / "a").mkdir()
    (folder / "a" / "b").symlink_to(outside, target_is_directory=True)
    _commit(folder, ["a/b/victim.pth"], {"a/b/victim.pth": PAYLOAD})
    return r"'a/b/victim\.pth': .*a/b is a symbolic link"


def _final_link(folder: Path, outside: Path) -> str:
    (folder / "victim.pth").symlink_to(outside / "victim.pth")
    _commit(folder, ["ok.json", "victim.pth"], {"ok.json": "{}", "victim.pth": PAYLOAD})
    return r"'victim\.pth': .*victim\.pth is a symbolic link"


def _entry(rel: object) -> Callable[[Path, Path], str]:
    def make(folder: Path, outside: Path) -> str:
        _commit(folder, [rel], {"x.json": "{}"})
        return r"not a plain relative path"
    return make


UNSAFE = {
    "staged-source-link": _staged_source_link,
    "staged-folder-link": _staged_folder_link,
    "staging-is-a-link": _staging_is_a_link,
    "record-is-a-link": _record_is_a_link,
    "deep-link": _deep_link,
    "final-link": _final_link,
    "dotdot": _entry("../site-packages/x.pth"),
    "absolute": _entry("/tmp/x.pth"),
    "dot": _entry("./x.json"),
    "staging-entry": _entry(".staging/COMMIT.json"),
    "not-a-string": _entry(["x.json"]),
}


@pytest.mark.parametrize("name", sorted(UNSAFE))
def test_an_unsafe_commit_is_refused_by_name_and_nothing_changes(tmp_path, outside, name):
    folder = tmp_path / "ckpt"
    folder.mkdir()
    (folder / "ok.json").write_text("old")
    message = UNSAFE[name](folder, outside)
    untouched = Untouched(outside, folder)
    for attempt in (recover, lambda f: check_out_dir(f, "bc_mlp", True, False), checkpoint_kind,
                    lambda f: check_out_dir(f, "bc_mlp", False, True)):
        with pytest.raises(CheckpointError, match=message) as info:
            attempt(folder)
        assert "\n" not in str(info.value)
        # even --overwrite stops here; the message says how to go on
        assert f"delete {folder / '.staging'}" in str(info.value)
    untouched.check()


def test_a_safe_interrupted_commit_is_still_finished_by_the_writer(tmp_path):
    folder = tmp_path / "ckpt"
    folder.mkdir()
    (folder / "sub").mkdir()
    (folder / "sub" / "b.json").write_text("old")
    _commit(folder, ["a.json", "sub/b.json", "new/c.json"],
            {"sub/b.json": "new", "new/c.json": "new"})
    (folder / "a.json").write_text("new")  # moved by the interrupted pass
    with staged_write(folder) as stage:
        (stage / "d.json").write_text("next")
    assert [(folder / r).read_text() for r in ("a.json", "sub/b.json", "new/c.json", "d.json")] \
        == ["new", "new", "new", "next"]
    assert not (folder / ".staging").exists()


# ---------------------------------------------------------------------- item 8
@pytest.mark.parametrize("method", ["bc-mlp", "act"])
def test_a_kill_during_the_first_commit_is_resumed(data_path, tmp_path, monkeypatch, method):
    """Killed after the first checkpoint's COMMIT.json was complete but before any file was moved
    into place, the folder holds only .staging: --resume finishes that commit and continues, and
    ends with the weights of an uninterrupted run."""
    kind = method.replace("-", "_")
    assert train.main(cli(method, data_path, tmp_path / "straight")) == 0
    killed = tmp_path / "killed"
    real = os.replace

    def kill_first_move(src, dst):
        if ".staging" in str(src) and ".staging" not in str(dst):
            raise KeyboardInterrupt
        return real(src, dst)

    with monkeypatch.context() as m:
        m.setattr(os, "replace", kill_first_move)
        assert train.main(cli(method, data_path, killed)) == 130
    assert (killed / ".staging" / "COMMIT.json").is_file()
    assert sorted(p.name for p in killed.iterdir() if p.name != "lerobot_dataset") == [".staging"]
    assert checkpoint_kind(killed) == kind
    check_out_dir(killed, kind, resume=True, overwrite=False)  # a checkpoint to resume
    with pytest.raises(CheckpointError, match="already holds a .* run; pass --resume"):
        check_out_dir(killed, kind, resume=False, overwrite=False)
    with pytest.raises(CheckpointError, match="interrupted checkpoint write"):
        (BCMLPAgent if kind == "bc_mlp" else ACTAgent).load(killed)
    assert (killed / ".staging" / "COMMIT.json").is_file()  # loading did not finish it
    assert train.main(cli(method, data_path, killed, "--resume")) == 0
    assert not (killed / ".staging").exists()
    for name in ("model.safetensors", "training_state/last.safetensors"):
        a, b = load_file(tmp_path / "straight" / name), load_file(killed / name)
        assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a), name


# ---------------------------------------------------------------------- item 9
def _edit(path: Path, key: str, index: int, value: float) -> None:
    tensors = load_file(path)
    tensors[key] = tensors[key].clone()
    tensors[key].view(-1)[index] = value
    save_file(tensors, path)


@pytest.mark.parametrize("key, index, value, message", [
    ("out_std", 0, 1e30, r"out_std\[0\] = 1e\+30 is not in \[1e-06, 100\] m"),
    ("out_mean", 2, -1e3, r"out_mean\[2\] = -1000 is not within ±100 m"),
    ("in_std", 1, 1e-30, r"in_std\[1\] = 1e-30 is not in \[1e-06, 100\] m"),
    ("in_mean", 5, 250.0, r"in_mean\[5\] = 250 is not within ±200 m"),  # a history offset
    ("in_mean", 1, 150.0, r"in_mean\[1\] = 150 is not within ±100 m"),  # the current position
])
def test_bc_mlp_statistics_beyond_the_data_are_one_error_naming_file_and_key(
    bc_dir, tmp_path, key, index, value, message
):
    folder = shutil.copytree(bc_dir, tmp_path / "ckpt")
    assert float(load_file(bc_dir / "model.safetensors")["out_std"].max()) < 100
    _edit(folder / "model.safetensors", key, index, value)
    with pytest.raises(CheckpointError, match=message) as info:
        BCMLPAgent.load(folder)
    assert str(info.value).startswith(f"{folder / 'model.safetensors'}: ")
    assert "\n" not in str(info.value)


def test_resume_checks_the_statistics_too(data_path, tmp_path, capsys):
    folder = tmp_path / "run"
    assert train.main(cli("bc-mlp", data_path, folder)) == 0
    _edit(folder / "model.safetensors", "out_std", 0, 1e30)
    capsys.readouterr()
    assert train.main(cli("bc-mlp", data_path, folder, "--resume")) == 2
    assert f"{folder / 'model.safetensors'}: out_std[0] = 1e+30" in capsys.readouterr().err


@pytest.mark.parametrize("file, key, index, value, message", [
    (POST_STATS, "action.std", 0, 1e30, r"action\.std\[0\] = 1e\+30 is not in \(0, 100\] m"),
    (POST_STATS, "action.mean", 1, 1e9, r"action\.mean\[1\] = 1e\+09 is not within ±100 m"),
    (PRE_STATS, "observation.environment_state.std", 4, 500.0,
     r"observation\.environment_state\.std\[4\] = 500 is not in \(0, 200\] m"),
    (PRE_STATS, "observation.state.max", 0, -1e6,
     r"observation\.state\.max\[0\] = -1e\+06 is not within ±100 m"),
])
def test_act_statistics_beyond_the_data_are_one_error_naming_file_and_key(
    act_dir, tmp_path, file, key, index, value, message
):
    folder = shutil.copytree(act_dir, tmp_path / "ckpt")
    _edit(folder / file, key, index, value)
    with pytest.raises(CheckpointError, match=message) as info:
        ACTAgent.load(folder)
    assert str(info.value).startswith(f"{folder / file}: ") and "\n" not in str(info.value)
