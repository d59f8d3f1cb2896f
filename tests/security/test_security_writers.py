"""Issue 32, R1, R2 and R13: no writer of ours follows a link or reuses a file it did not create.

For every writer (CSV, text/Markdown, PNG, JSON, HTML, the output lock, checkpoint files) a symbolic
link and a hard link to a file outside the output folder are planted at every name it could use
for its temporary file (the old ``<name>.tmp``, ``<stem>.tmp``, and the first random names it
draws, made predictable here) and at the final name. The outside folder is compared byte for byte
before and after; the file written must be right, and the refusals one error naming the path.
The end-to-end cases run ``evaluate.py rescore`` and ``leaderboard`` as a user would.
"""

from __future__ import annotations

import csv
import json
import os
import re
import subprocess
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

from handover_env import atomic_write as aw
from handover_env.atomic_write import UnsafeTargetError, atomic_write_bytes
from handover_eval.benchmark.files import CLOSEDLOOP_COLUMNS
from handover_eval.benchmark.outcomes import EVENTS
from handover_eval.benchmark.protocol import CLOSEDLOOP_SETS
from handover_eval.cli import evaluate
from handover_eval.output_lock import OutputLock, OutputLockError
from handover_eval.reporting import write_csv, write_png, write_text

ROOT = Path(__file__).resolve().parents[2]
VICTIM = b"precious: not ours to write\n"
#: The first random parts the writer draws (made predictable by :func:`predictable_names`).
DRAWS = ("0" * 16, "1" * 16, "2" * 16)


# ------------------------------------------------------------------------------ helpers
def snapshot(folder: Path) -> dict[str, object]:
    """Every entry under ``folder``: a file's bytes, a link's target, a folder's mark."""
    out: dict[str, object] = {}
    for p in sorted(folder.rglob("*")):
        rel = str(p.relative_to(folder))
        if p.is_symlink():
            out[rel] = ("link", os.readlink(p))
        elif p.is_dir():
            out[rel] = "dir"
        else:
            out[rel] = p.read_bytes()
    return out


@pytest.fixture
def outside(tmp_path: Path) -> Path:
    """A folder of a user's files, outside every output folder."""
    folder = tmp_path / "outside"
    folder.mkdir()
    for i in range(12):
        (folder / f"victim{i}.txt").write_bytes(VICTIM)
    return folder


@pytest.fixture
def predictable_names(monkeypatch) -> Iterator[None]:
    """The writer's random temporary names drawn from :data:`DRAWS` first, so a test can plant
    links at them; it must then draw past every planted one."""
    draws = iter(DRAWS)
    real = aw.secrets.token_hex
    monkeypatch.setattr(aw.secrets, "token_hex", lambda n: next(draws, None) or real(n))
    yield


def temp_names(name: str) -> list[str]:
    """Every temporary name a writer of ``name`` used or could use: the old fixed ones and the
    first random ones it draws under :func:`predictable_names`."""
    stem = name.rsplit(".", 1)[0]
    return [f"{name}.tmp", f"{stem}.tmp", *(f".{name}.{d}.tmp" for d in DRAWS)]


def plant(folder: Path, names: list[str], outside: Path, kind: str) -> None:
    """A ``kind`` link ("symlink" or "hardlink") to a different outside victim at each name."""
    folder.mkdir(parents=True, exist_ok=True)
    for i, name in enumerate(names):
        victim = outside / f"victim{i}.txt"
        if kind == "symlink":
            (folder / name).symlink_to(victim)
        else:
            os.link(victim, folder / name)


def _figure():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(2, 2))
    ax.plot([0, 1], [1, 0])
    return fig


def _json_checkpoint(path: Path) -> None:
    from baselines.checkpoint_io import write_json

    write_json(path, {"type": "bc_mlp", "x": [1, 2]})


#: writer -> (file name, write it at the path, what the file must hold).
WRITERS: dict[str, tuple[str, Callable[[Path], object], Callable[[bytes], bool]]] = {
    "csv": ("table.csv", lambda p: write_csv([{"agent": "a", "rms": 1.5}], p),
            lambda b: b == b"agent,rms\r\na,1.5\r\n"),
    "text": ("benchmark.md", lambda p: write_text("| a | 1 ± 2 |\n", p),
             lambda b: b == "| a | 1 ± 2 |\n".encode()),
    "png": ("leaderboard.png", lambda p: write_png(_figure(), p),
            lambda b: b.startswith(b"\x89PNG\r\n\x1a\n") and len(b) > 1000),
    "json": ("result.json", lambda p: write_text(json.dumps({"k": 1}) + "\n", p),
             lambda b: json.loads(b) == {"k": 1}),
    "html": ("leaderboard.html", lambda p: write_text("<!doctype html><p>ok</p>\n", p),
             lambda b: b == b"<!doctype html><p>ok</p>\n"),
    "checkpoint-json": ("config.json", _json_checkpoint,
                        lambda b: json.loads(b) == {"type": "bc_mlp", "x": [1, 2]}),
    "bytes": ("model.bin", lambda p: atomic_write_bytes(p, b"\x00weights"),
              lambda b: b == b"\x00weights"),
}


# ------------------------------------------------------------------------------ R1: each writer
@pytest.mark.parametrize("kind", ["symlink", "hardlink"])
@pytest.mark.parametrize("writer", sorted(WRITERS))
def test_links_at_every_temporary_name_are_never_followed_or_reused(
        writer, kind, tmp_path, outside, predictable_names) -> None:
    name, write, holds = WRITERS[writer]
    out = tmp_path / "out"
    names = temp_names(name)
    plant(out, names, outside, kind)
    before, planted = snapshot(outside), snapshot(out)
    write(out / name)
    assert snapshot(outside) == before  # no outside file truncated or written
    after = snapshot(out)
    assert holds(after.pop(name)) and after == planted  # every planted link left as it was
    assert (out / name).lstat().st_nlink == 1 and not (out / name).is_symlink()


@pytest.mark.parametrize("writer", sorted(WRITERS))
def test_a_hard_link_at_the_final_name_is_replaced_not_written_through(
        writer, tmp_path, outside) -> None:
    name, write, holds = WRITERS[writer]
    out = tmp_path / "out"
    plant(out, [name], outside, "hardlink")
    before = snapshot(outside)
    write(out / name)
    assert snapshot(outside) == before
    assert holds((out / name).read_bytes()) and (out / name).stat().st_nlink == 1


@pytest.mark.parametrize("writer", sorted(WRITERS))
def test_a_symlink_at_the_final_name_out_of_the_folder_is_refused(
        writer, tmp_path, outside) -> None:
    name, write, _ = WRITERS[writer]
    out = tmp_path / "out"
    plant(out, [name], outside, "symlink")
    before, planted = snapshot(outside), snapshot(out)
    with pytest.raises(UnsafeTargetError, match=re.escape(
            f"{out / name}: a symbolic link to {outside / 'victim0.txt'}, outside the folder "
            f"{out}; refusing to write there (remove the link)")):
        write(out / name)
    assert snapshot(outside) == before and snapshot(out) == planted  # nothing written, no temp


def test_a_symlink_inside_the_folder_is_replaced_and_odd_targets_are_refused(tmp_path) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "kept.md").write_text("kept\n")
    (out / "report.md").symlink_to("kept.md")  # inside the folder: the link itself is replaced
    write_text("new\n", out / "report.md")
    assert not (out / "report.md").is_symlink() and (out / "report.md").read_text() == "new\n"
    assert (out / "kept.md").read_text() == "kept\n"
    (out / "table.csv").mkdir()
    with pytest.raises(UnsafeTargetError, match="table.csv: exists and is not a regular file"):
        write_csv([{"a": 1}], out / "table.csv")
    os.mkfifo(out / "fifo.md")
    with pytest.raises(UnsafeTargetError, match="fifo.md: exists and is not a regular file"):
        write_text("x", out / "fifo.md")
    (out / "dir-link.md").symlink_to("table.csv")
    with pytest.raises(UnsafeTargetError, match="dir-link.md: a symbolic link to .*table.csv, "
                       "which is not a regular file"):
        write_text("x", out / "dir-link.md")
    (out / "loop.md").symlink_to("loop.md")
    with pytest.raises(UnsafeTargetError, match="loop.md: a symbolic link loop"):
        write_text("x", out / "loop.md")
    assert sorted(p.name for p in out.iterdir()) == [
        "dir-link.md", "fifo.md", "kept.md", "loop.md", "report.md", "table.csv"]


def test_a_failing_writer_leaves_the_old_file_and_no_temporary(tmp_path) -> None:
    out = tmp_path / "out"
    write_text("old\n", out / "benchmark.md")

    def boom(f) -> None:
        f.write(b"half")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError, match="disk full"):
        aw.atomic_write(out / "benchmark.md", boom)
    assert os.listdir(out) == ["benchmark.md"] and (out / "benchmark.md").read_text() == "old\n"


# ------------------------------------------------------------------------------ R2: the lock
@pytest.mark.parametrize("kind, message", [
    ("symlink", "is a symbolic link; refusing to follow it"),
    ("hardlink", "has 2 names \\(a hard link to another file\\?\\); refusing to write it"),
])
def test_a_linked_lock_file_is_refused_and_its_target_kept(kind, message, tmp_path,
                                                          outside) -> None:
    out = tmp_path / "out"
    plant(out, [".lock"], outside, kind)
    before = snapshot(outside)
    with pytest.raises(OutputLockError,
                       match=re.escape(f"--out {out}: the lock file {out / '.lock'} ") + message):
        OutputLock(out).acquire()
    assert snapshot(outside) == before
    assert (out / ".lock").is_symlink() == (kind == "symlink")


# ------------------------------------------------------------------------------ checkpoints
def _stage(out: Path) -> None:
    """A two-file checkpoint written as one unit."""
    from baselines.checkpoint_io import staged_write, write_json

    with staged_write(out) as stage:
        write_json(stage / "config.json", {"type": "bc_mlp"})
        (stage / "training_state").mkdir()
        atomic_write_bytes(stage / "training_state" / "last.safetensors", b"weights")


@pytest.mark.parametrize("kind", ["symlink", "hardlink"])
def test_checkpoint_writes_follow_no_link(kind, tmp_path, outside, predictable_names) -> None:
    """Links at the old commit-record name and the temporary names inside a leftover staging
    folder (discarded, never followed), and hard links at the final names (replaced)."""
    out = tmp_path / "ck"
    stage = out / ".staging"
    plant(stage, ["COMMIT.json.tmp", *temp_names("COMMIT.json")[2:],
                  *temp_names("config.json")[2:]], outside, kind)
    (out / "training_state").mkdir()
    for i, name in enumerate(["config.json", "training_state/last.safetensors"]):
        os.link(outside / f"victim{i}.txt", out / name)
    before = snapshot(outside)
    _stage(out)
    assert snapshot(outside) == before
    assert json.loads((out / "config.json").read_bytes()) == {"type": "bc_mlp"}
    assert (out / "training_state" / "last.safetensors").read_bytes() == b"weights"
    assert (out / "config.json").stat().st_nlink == 1 and not stage.exists()
    assert (out / "training_state" / "last.safetensors").stat().st_nlink == 1


def test_checkpoint_refuses_a_symlinked_destination_or_staging_folder(tmp_path, outside) -> None:
    from baselines.checkpoint_io import CheckpointError

    out = tmp_path / "ck"
    plant(out, ["config.json"], outside, "symlink")
    before = snapshot(outside)
    with pytest.raises(CheckpointError, match=re.escape(
            f"commit entry 'config.json': {out}/config.json is a symbolic link; refused, "
            "nothing changed")):
        _stage(out)
    (out / "config.json").unlink()
    (out / ".staging").symlink_to(outside, target_is_directory=True)
    with pytest.raises(CheckpointError, match=re.escape(f"{out}/.staging: not a folder")):
        _stage(out)
    assert snapshot(outside) == before


def test_a_bc_mlp_checkpoint_is_written_past_planted_links(tmp_path, outside,
                                                          predictable_names) -> None:
    from baselines_toy import toy_dataset

    from baselines.bc_mlp import BCMLPAgent, BCMLPConfig

    agent = BCMLPAgent(BCMLPConfig(hidden=(8,), batch_size=64, max_epochs=1)).fit(
        toy_dataset(n=8, length=45, seed=1))
    out = tmp_path / "bc"
    plant(out, ["config.json", "model.safetensors"], outside, "hardlink")
    plant(out / ".staging", [*temp_names("config.json")[2:]], outside, "symlink")
    before = snapshot(outside)
    agent.save(out)
    assert snapshot(outside) == before
    again = BCMLPAgent.load(out)
    for key, value in agent.net.state_dict().items():
        assert np.array_equal(again.net.state_dict()[key].numpy(), value.numpy()), key
    assert sorted(p.name for p in out.iterdir()) == ["config.json", "model.safetensors"]


# ------------------------------------------------------------------------------ end to end
def _episodes_csv(path: Path) -> Path:
    """A small valid closedloop_episodes.csv: two agents, every set, two receivers each."""
    rows = []
    for agent in ("mine", "reactive"):
        for s, name in enumerate(CLOSEDLOOP_SETS):
            for r in range(2):
                ok = (s + r) % 3 != 0
                row = {c: "0" for c in CLOSEDLOOP_COLUMNS}
                row.update(
                    agent=agent, set=name, receiver=f"{name}-{r:04d}", seed=str(100 * s + r),
                    fold="", model_fold="", is_ood=str(name.endswith("ood")),
                    pass_y="-1.2" if name == "far-pass" else "nan",
                    outcome="success" if ok else "missed", success=str(ok),
                    first_failure="" if ok else "no_grasp",
                    handover_time=f"{1.5 + r / 4}" if ok else "nan",
                    transfer_time="1.3", reach_onset_time="0.5",
                    release_time=f"{1.5 + r / 4}" if ok else "nan",
                    release_force="7.9", peak_contact_force="12.6", time_lost="0.1",
                    reach_distance="0.51", arm_extended_time="1.1", pull_force="13.2",
                    robot_jerk_rms="78.1", delta_t="nan", delta_x="nan", steps="50",
                )
                row.update({f"ev_{e}": "False" for e in EVENTS})
                row.update(ev_reached="True", ev_grasped=str(ok), ev_released=str(ok),
                           ev_missed=str(not ok))
                rows.append(row)
    with path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(CLOSEDLOOP_COLUMNS))
        w.writeheader()
        w.writerows(rows)
    return path


def _env() -> dict:
    return {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1", "HF_HUB_OFFLINE": "1"}


def test_rescore_into_a_folder_with_planted_links_writes_nothing_outside(tmp_path,
                                                                         outside) -> None:
    """The issue's case: ``rescore`` run on a downloaded folder holding a link at
    ``benchmark.md.tmp`` (and at every other old temporary name, and a hard link)."""
    episodes = _episodes_csv(tmp_path / "closedloop_episodes.csv")
    assert evaluate.main(["rescore", str(episodes), "--out", str(tmp_path / "clean")]) == 0
    clean = snapshot(tmp_path / "clean")
    assert set(clean) == {"benchmark.md", "closedloop_table.csv"}
    o = tmp_path / "o"
    plant(o, ["benchmark.md.tmp", "closedloop_table.csv.tmp"], outside, "symlink")
    os.link(outside / "victim2.txt", o / "benchmark.tmp")
    os.link(outside / "victim3.txt", o / "benchmark.md")  # a hard link at the final name
    before = snapshot(outside)
    proc = subprocess.run([sys.executable, str(ROOT / "evaluate.py"), "rescore", str(episodes),
                           "--out", "o"], cwd=tmp_path, env=_env(), capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert snapshot(outside) == before
    after = snapshot(o)
    assert {k: after[k] for k in clean} == clean  # the same report as in a clean folder
    assert after["benchmark.md.tmp"] == ("link", str(outside / "victim0.txt"))
    assert sorted(after) == ["benchmark.md", "benchmark.md.tmp", "benchmark.tmp",
                             "closedloop_table.csv", "closedloop_table.csv.tmp"]


def test_rescore_refuses_a_report_linked_out_of_its_folder(tmp_path, outside, capsys) -> None:
    episodes = _episodes_csv(tmp_path / "closedloop_episodes.csv")
    o = tmp_path / "o"
    plant(o, ["benchmark.md"], outside, "symlink")
    before = snapshot(outside)
    assert evaluate.main(["rescore", str(episodes), "--out", str(o)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (f"evaluate.py: error: {o / 'benchmark.md'}: a symbolic link to "
                   f"{outside / 'victim0.txt'}, outside the folder {o}; refusing to write there "
                   "(remove the link)")
    assert snapshot(outside) == before


# ------------------------------------------------------------------------------ R13
@pytest.mark.parametrize("command", ["rescore", "leaderboard"])
def test_leaderboard_and_rescore_hold_the_output_lock(command, tmp_path, capsys) -> None:
    episodes = _episodes_csv(tmp_path / "closedloop_episodes.csv")
    out = tmp_path / "o"
    args = [str(episodes)] if command == "rescore" else [str(tmp_path / "result.json")]
    with OutputLock(out):  # another run on the same --out (flock: per open file)
        assert evaluate.main([command, *args, "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith(f"evaluate.py: error: --out {out} is in use by another run: its "
                              f"lock {out / '.lock'} is held by pid {os.getpid()}"), err
        assert sorted(os.listdir(out)) == [".lock"]  # nothing read, nothing written
    if command == "rescore":
        assert evaluate.main([command, *args, "--out", str(out)]) == 0
        assert sorted(os.listdir(out)) == ["benchmark.md", "closedloop_table.csv"]  # no lock


@pytest.mark.parametrize("argv, flag", [
    (["rescore", "EPISODES", "--out", ""], "--out"),
    (["leaderboard", "RESULT", "--out", ""], "--out"),
    (["leaderboard", "RESULT", "--out", "  "], "--out"),
    (["benchmark", "--agent", "reactive", "--tracks", "closedloop", "--quick", "--out", ""],
     "--out"),
    (["benchmark", "--agent", "reactive", "--tracks", "closedloop", "--quick", "--checkpoints",
      ""], "--checkpoints"),
])
def test_an_empty_output_option_is_refused_not_taken_for_the_default(
        argv, flag, tmp_path, monkeypatch, capsys) -> None:
    episodes = _episodes_csv(tmp_path / "closedloop_episodes.csv")
    argv = [str(episodes) if a == "EPISODES" else str(tmp_path / "r.json") if a == "RESULT" else a
            for a in argv]
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    assert evaluate.main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"evaluate.py: error: {flag} is empty (an unset shell variable?)"
    assert os.listdir(work) == []  # no results/ made
