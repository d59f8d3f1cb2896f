"""Issue 16 items 2, 3, 9, issue 20 items 1, 7 and issue 32 R14: the LeRobot export never deletes
a user's folder (nor a file in an export, even one named like an export's own, nor a folder named
like its temporary ones), writes where it
checked (``~`` expanded once), never trains on stale data, and an interrupted export blocks
nothing."""

from __future__ import annotations

import json
import os
import re
import shutil
from pathlib import Path

import pytest

os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("HF_DATASETS_OFFLINE", "1")

import torch  # noqa: E402

torch.set_num_threads(1)

from baselines_toy import toy_dataset  # noqa: E402

from baselines.checkpoint_io import CheckpointError  # noqa: E402
from handover_env.data.lerobot_export import export_lerobot, read_sidecar  # noqa: E402
from handover_env.paths import UnsafePathError  # noqa: E402
from handover_eval.cli.data import main  # noqa: E402

TINY = {"policy": {"dim_model": 16, "n_heads": 2, "dim_feedforward": 32, "n_encoder_layers": 1,
                   "latent_dim": 4},
        "batch_size": 8, "steps": 2, "eval_every": 1}


@pytest.fixture(scope="module")
def data():
    return toy_dataset(n=6, length=35, seed=4)


def _tree(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def _snapshot(folder: Path) -> dict[str, bytes | None]:
    """Every file (its bytes) and every folder (None) under ``folder``, hidden ones included."""
    return {str(p.relative_to(folder)): None if p.is_dir() else p.read_bytes()
            for p in folder.rglob("*")}


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
    with pytest.raises(
        UnsafePathError, match=r"^refusing (to replace '.*': it is|an empty output path)"
    ):
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
    with pytest.raises(KeyboardInterrupt, match="^$"):
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


def test_train_rebuilds_only_a_real_export(tmp_path: Path, data, capsys) -> None:
    """Issue 20 item 1: a folder holding just LeRobot metadata with our robot type is not an export
    (it was trusted as one and replaced); a real export of other data is rebuilt with --overwrite.
    """
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
    from handover_eval.cli import train

    src = data.save(tmp_path / "d.npz")
    forged = tmp_path / "run" / "lerobot_dataset"
    (forged / "meta").mkdir(parents=True)
    (forged / "meta" / "info.json").write_text(json.dumps({"robot_type": "handover_giver"}))
    before = _tree(forged)
    argv = ["act", "--smoke", "--data", str(src), "--out", str(tmp_path / "run"), "--steps", "2",
            "--eval-every", "1", "--no-progress", "--dim-model", "16", "--n-heads", "2"]
    assert train.main(argv) == 2
    err = capsys.readouterr().err
    assert f"refusing to overwrite {forged}: it is not a handover LeRobot export (no " \
        "meta/handover.json); nothing was deleted" in err, err
    assert _tree(forged) == before
    other = export_lerobot(data.subset([0, 1]), tmp_path / "shared_export", history=10)
    argv2 = [*argv[:5], str(tmp_path / "run2"), *argv[6:], "--export-root", str(other)]
    assert train.main(argv2) == 2
    assert "pass --overwrite to rebuild it" in capsys.readouterr().err
    assert read_sidecar(other)["n_frames"] == data.subset([0, 1]).n_frames
    assert train.main([*argv2, "--overwrite"]) == 0, capsys.readouterr().err
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


# ---------------------------------------------------------------------- issue 20 item 1
def _user_folder(folder: Path, marker: str) -> Path:
    """A user's folder with a git repository, a paper and a forged export marker."""
    (folder / ".git" / "objects").mkdir(parents=True)
    (folder / ".git" / "HEAD").write_text("ref: refs/heads/main\n")
    (folder / "paper.tex").write_text("\\documentclass{article}")
    (folder / "meta").mkdir()
    if marker.startswith("empty-sidecar"):
        (folder / "meta" / "handover.json").write_text("")
    elif marker == "info-robot-type":
        (folder / "meta" / "info.json").write_text(json.dumps({"robot_type": "handover_giver"}))
    return folder


@pytest.mark.parametrize(
    "marker, reason",
    [
        ("empty-sidecar", r"it holds '\.git/', which an export does not write"),
        ("empty-sidecar-only", r"meta/handover\.json: not valid JSON"),
        ("info-robot-type", r"no meta/handover\.json"),
    ],
)
def test_a_forged_marker_does_not_make_a_folder_an_export(
    tmp_path: Path, data, capsys, marker: str, reason: str
) -> None:
    """An empty meta/handover.json, or a meta/info.json with our robot type, made any folder an
    "export": --overwrite deleted the user's files and .git."""
    src = data.save(tmp_path / "d.npz")
    user = _user_folder(tmp_path / "thesis", marker)
    if marker == "empty-sidecar-only":  # pass the check of the entries: the sidecar is read
        for extra in (".git", "paper.tex"):
            path = user / extra
            shutil.rmtree(path) if path.is_dir() else path.unlink()
        (user / "data" / "chunk-000").mkdir(parents=True)
        (user / "data" / "chunk-000" / "file-000.parquet").write_bytes(b"the user's table")
    before = _snapshot(user)
    assert main(["export-lerobot", str(src), str(user), "--overwrite"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert re.search(
        rf"^error: refusing to overwrite {re.escape(str(user))}: it is not a handover LeRobot "
        rf"export \(.*{reason}.*\); nothing was deleted",
        err,
    ), err
    assert _snapshot(user) == before
    with pytest.raises(ValueError, match="refusing to overwrite"):
        export_lerobot(data, user, overwrite=True)
    assert _snapshot(user) == before


@pytest.fixture()
def earlier(tmp_path: Path, data) -> Path:
    return export_lerobot(data.subset([0, 1]), tmp_path / "ds", history=4)


@pytest.mark.parametrize(
    "tamper, reason",
    [
        ("extra-file", r"it holds 'notes\.txt', which an export does not write"),
        ("extra-folder", r"it holds 'data/chunk-000/mine/', which an export does not write"),
        ("git", r"it holds '\.git/', which an export does not write"),
        ("symlink", r"'meta/stats\.json' is a symbolic link"),
        ("sidecar-field", r"fields \['mine'\] differ from those an export writes"),
        ("sidecar-missing-field", r"fields \['fingerprint'\] differ"),
        ("sidecar-rate", r"rate_hz is 1e-300 Hz, outside"),
        ("sidecar-frames", r"meta/info\.json: total_frames \d+, but meta/handover\.json says 1"),
        ("info-robot", r"robot_type 'koch', an export has 'handover_giver'"),
    ],
)
def test_overwrite_of_a_real_export_with_anything_else_in_it_deletes_nothing(
    tmp_path: Path, data, earlier: Path, capsys, tamper: str, reason: str
) -> None:
    """Overwriting a real export deleted everything else in it."""
    src = data.save(tmp_path / "d.npz")
    sidecar = earlier / "meta" / "handover.json"
    meta = json.loads(sidecar.read_text())
    if tamper == "extra-file":
        (earlier / "notes.txt").write_text("my notes")
    elif tamper == "extra-folder":
        (earlier / "data" / "chunk-000" / "mine").mkdir()
    elif tamper == "git":
        (earlier / ".git").mkdir()
        (earlier / ".git" / "HEAD").write_text("ref: refs/heads/main\n")
    elif tamper == "symlink":
        (tmp_path / "elsewhere.json").write_text("{}")
        (earlier / "meta" / "stats.json").unlink()
        (earlier / "meta" / "stats.json").symlink_to(tmp_path / "elsewhere.json")
    elif tamper == "info-robot":
        info = json.loads((earlier / "meta" / "info.json").read_text())
        (earlier / "meta" / "info.json").write_text(json.dumps({**info, "robot_type": "koch"}))
    else:
        if tamper == "sidecar-field":
            meta["mine"] = 1
        elif tamper == "sidecar-missing-field":
            del meta["fingerprint"]
        elif tamper == "sidecar-rate":
            meta["rate_hz"] = 1e-300
        else:
            meta["n_frames"] = 1
        sidecar.write_text(json.dumps(meta))
    before = _snapshot(earlier)
    assert main(["export-lerobot", str(src), str(earlier), "--overwrite"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "nothing was deleted" in err, err
    assert re.search(rf"refusing to overwrite {re.escape(str(earlier))}: .*{reason}", err), err
    assert _snapshot(earlier) == before


# ---------------------------------------------------------------------- issue 32 R14
@pytest.mark.parametrize(
    "planted, reason",
    [
        ("data/chunk-000/file-999.parquet",
         r"it holds 'data/chunk-000/file-999\.parquet', which this export did not write \(not "
         r"in meta/handover\.json files\)"),
        ("meta/episodes/chunk-007/file-000.parquet",
         r"it holds 'meta/episodes/chunk-007/file-000\.parquet', which this export did not write"),
        ("data/chunk-000/file-000.parquet",
         r"'data/chunk-000/file-000\.parquet' changed since this export wrote it"),
        ("meta/tasks.parquet", r"'meta/tasks\.parquet' changed since this export wrote it"),
    ],
    ids=["new-data-file", "new-episodes-chunk", "replaced-data-file", "replaced-tasks"],
)
def test_overwrite_keeps_a_users_file_named_like_an_export_file(
    tmp_path: Path, data, earlier: Path, capsys, planted: str, reason: str
) -> None:
    """``--overwrite`` checked names only: a user's file named like one an export writes, inside
    an export, was deleted with it. Only the files the export's own sidecar lists (path, size,
    SHA-256) are deleted; anything else is one error and nothing is lost."""
    src = data.save(tmp_path / "d.npz")
    assert read_sidecar(earlier)["files"]  # the export lists what it wrote
    target = earlier / planted
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_bytes(b"the user's own table, named like an export's")
    before = _snapshot(earlier)
    assert main(["export-lerobot", str(src), str(earlier), "--overwrite"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.endswith("nothing was deleted (delete it yourself or "
                                                   "choose another folder)\n"), err
    assert re.search(rf"^error: refusing to overwrite {re.escape(str(earlier))}: it is not a "
                     rf"handover LeRobot export \({reason}", err), err
    with pytest.raises(ValueError, match=reason):
        export_lerobot(data, earlier, history=4, overwrite=True)
    assert _snapshot(earlier) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.npz", "ds"]  # no temporary left


def test_the_sidecar_files_list_is_checked(tmp_path: Path, data, earlier: Path) -> None:
    sidecar = earlier / "meta" / "handover.json"
    meta = json.loads(sidecar.read_text())
    assert set(meta["files"]) == {
        str(p.relative_to(earlier)) for p in earlier.rglob("*")
        if p.is_file() and p != sidecar
    }
    for bad, message in [
        ({**meta["files"], "notes.txt": [1, "0" * 64]}, r"files lists 'notes\.txt'"),
        ({k: [v[0], "x"] for k, v in meta["files"].items()},
         r"files\['.*'\] must be \[size in bytes >= 0, SHA-256 as 64 hex digits\]"),
        ({k: [True, v[1]] for k, v in meta["files"].items()}, r"must be \[size in bytes"),
    ]:
        sidecar.write_text(json.dumps({**meta, "files": bad}))
        with pytest.raises(ValueError, match=message):
            read_sidecar(earlier)
    sidecar.write_text(json.dumps({**meta, "export_format": 2}))
    with pytest.raises(ValueError, match="export format 2, this code reads 3"):
        export_lerobot(data, earlier, history=4, overwrite=True)
    sidecar.write_text(json.dumps(meta))
    gone = sorted(meta["files"])[-1]  # a listed file that is gone is no loss
    (earlier / gone).unlink()
    export_lerobot(data, earlier, history=4, overwrite=True)
    assert read_sidecar(earlier)["fingerprint"] == data.fingerprint()


def test_overwrite_never_deletes_the_dataset_being_exported(
    tmp_path: Path, data, earlier: Path, capsys
) -> None:
    """The .npz being exported, saved inside the export, was deleted with it."""
    src = data.save(earlier / "d.npz")
    before = _snapshot(earlier)
    assert main(["export-lerobot", str(src), str(earlier), "--overwrite"]) == 2
    err = capsys.readouterr().err
    assert f"refusing to overwrite {earlier}: it holds {src}, the dataset being exported" in err
    assert err.count("\n") == 1
    link = tmp_path / "link.npz"  # a link to it elsewhere is resolved
    link.symlink_to(src)
    assert main(["export-lerobot", str(link), str(earlier), "--overwrite"]) == 2
    assert "the dataset being exported" in capsys.readouterr().err
    with pytest.raises(ValueError, match="the dataset being exported"):
        export_lerobot(data, earlier, overwrite=True, inputs=[src])
    assert _snapshot(earlier) == before
    src.unlink()  # without it, the export is replaceable again
    export_lerobot(data, earlier, history=4, overwrite=True)
    assert read_sidecar(earlier)["fingerprint"] == data.fingerprint()


def test_a_user_folder_named_like_a_stale_sibling_is_left_alone(
    tmp_path: Path, data, earlier: Path
) -> None:
    """``.<root>.old-<pid>-<hex>`` of a dead pid was deleted silently, whatever it held."""
    users = tmp_path / ".ds.old-999999999-ab12"
    (users / ".git").mkdir(parents=True)
    (users / "paper.tex").write_text("\\documentclass{article}")
    partial = tmp_path / ".ds.partial-999999998-cd34"
    (partial / "meta").mkdir(parents=True)
    (partial / "meta" / "info.json").write_text(json.dumps({"robot_type": "handover_giver"}))
    (partial / "meta" / "todo.txt").write_text("mine")
    stale_old = tmp_path / ".ds.old-999999997-ef56"  # a real export a killed run was replacing
    shutil.copytree(earlier, stale_old)
    stale_partial = tmp_path / ".ds.partial-999999996-0a0b"  # a killed export, mid-way
    shutil.copytree(earlier, stale_partial)
    (stale_partial / "meta" / "handover.json").unlink()
    kept = {users: _snapshot(users), partial: _snapshot(partial)}
    with pytest.warns(UserWarning) as caught:
        export_lerobot(data, earlier, history=4, overwrite=True)
    messages = sorted(str(w.message) for w in caught)
    assert len(messages) == 2, messages
    assert messages[1].startswith(f"left {partial} in place: it is named like a temporary folder "
                                  "of ds but it is not a handover LeRobot export (it holds "
                                  "'meta/todo.txt'")
    assert messages[0].startswith(f"left {users} in place") and "(no meta/handover.json)" in \
        messages[0]
    assert {p: _snapshot(p) for p in kept} == kept
    assert not stale_old.exists() and not stale_partial.exists()
    assert read_sidecar(earlier)["fingerprint"] == data.fingerprint()


# ---------------------------------------------------------------------- issue 20 item 7
def test_a_quoted_tilde_root_is_expanded_once(tmp_path: Path, data, monkeypatch, capsys) -> None:
    """``export-lerobot "~/x"`` checked the expanded path, then wrote a literal ``~`` folder."""
    home, work = tmp_path / "home", tmp_path / "work"
    home.mkdir()
    work.mkdir()
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.chdir(work)
    data.save(home / "d.npz")
    assert main(["export-lerobot", "~/d.npz", "~/x", "--history", "4"]) == 0, \
        capsys.readouterr().err
    assert f"to {home / 'x'} as" in capsys.readouterr().out
    assert read_sidecar(home / "x")["fingerprint"] == data.fingerprint()
    assert main(["export-lerobot", "~/d.npz", "~/x", "--history", "4"]) == 2
    assert f"error: {home / 'x'} already exists" in capsys.readouterr().err
    assert main(["export-lerobot", "~/d.npz", "~/x", "--history", "4", "--overwrite"]) == 0
    assert export_lerobot(data, "~/y", history=4) == home / "y"
    assert list(work.iterdir()) == []  # no literal "~" folder in the current folder
    assert sorted(p.name for p in home.iterdir()) == ["d.npz", "x", "y"]
