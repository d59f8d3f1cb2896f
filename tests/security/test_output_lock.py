"""Issue 20 item 6: every command that writes into an --out holds an exclusive lock on it.

The concurrency tests are real: the first run (or a process holding its lock) is another process,
the second run is ``python train.py ...`` / ``python evaluate.py ...`` in a subprocess.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from baselines_toy import toy_dataset

from handover_eval.output_lock import OutputLock, OutputLockError

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "HF_HUB_OFFLINE": "1", "HF_DATASETS_OFFLINE": "1", "PYTHONPATH": str(ROOT)}
HOLD = (
    "import sys\n"
    "from handover_eval.output_lock import OutputLock\n"
    "with OutputLock(sys.argv[1]):\n"
    "    print('held', flush=True)\n"
    "    sys.stdin.read()\n"  # until the test closes our stdin
)


class Holder:
    """Another process that holds the lock of ``folder`` until :meth:`stop` (or is killed)."""

    def __init__(self, folder: Path) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-c", HOLD, str(folder)], stdin=subprocess.PIPE,
            stdout=subprocess.PIPE, text=True, env=ENV, cwd=ROOT,
        )
        assert self.proc.stdout.readline().strip() == "held"

    def stop(self) -> None:
        self.proc.stdin.close()
        assert self.proc.wait(timeout=60) == 0

    def kill(self) -> None:
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(timeout=60)
        self.proc.stdin.close()


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file()}


def _refusal(res: subprocess.CompletedProcess, script: str, folder: Path, pid: int) -> str:
    err = res.stderr.strip()
    assert res.returncode == 2, res.stderr
    assert "\n" not in err and "Traceback" not in err, err
    assert err == (
        f"{script}: error: --out {folder} is in use by another run: its lock {folder / '.lock'} "
        f"is held by pid {pid}; wait for that run to end or choose another --out"
    )
    return err


def test_a_second_holder_is_refused_at_once_and_a_killed_holder_leaves_no_stale_lock(tmp_path):
    out = tmp_path / "out"
    holder = Holder(out)
    assert (out / ".lock").read_text() == f"{holder.proc.pid}\n"
    with pytest.raises(OutputLockError, match=f"held by pid {holder.proc.pid}"):
        OutputLock(out).acquire()
    holder.kill()  # SIGKILL: no clean-up ran, the lock file is still there, unlocked
    assert (out / ".lock").exists()
    with OutputLock(out) as lock:  # the OS dropped the lock with its process
        assert lock.held and (out / ".lock").read_text() == f"{os.getpid()}\n"
    assert not (out / ".lock").exists()


def test_release_deletes_the_lock_and_the_folders_it_made_if_left_empty(tmp_path):
    new = tmp_path / "a" / "b"
    with OutputLock(new):
        assert sorted(p.name for p in new.iterdir()) == [".lock"]
    assert list(tmp_path.iterdir()) == []  # nothing written: a and a/b are gone again
    kept = tmp_path / "kept"
    with OutputLock(kept):
        (kept / "table.csv").write_text("x\n")
    assert sorted(p.name for p in kept.iterdir()) == ["table.csv"]  # results stay, no lock


def test_a_symlinked_lock_file_is_refused_and_not_followed(tmp_path, capsys):
    from handover_eval.cli import train

    out = tmp_path / "out"
    out.mkdir()
    target = tmp_path / "precious.txt"
    target.write_text("keep me")
    (out / ".lock").symlink_to(target)
    with pytest.raises(OutputLockError, match="is a symbolic link"):
        OutputLock(out).acquire()
    assert train.main(["bc-mlp", "--smoke", "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (
        f"train.py: error: --out {out}: the lock file {out / '.lock'} is a symbolic link; "
        "refusing to follow it (remove it)"
    )
    assert target.read_text() == "keep me" and (out / ".lock").is_symlink()
    assert sorted(p.name for p in out.iterdir()) == [".lock"]


def test_a_hard_linked_lock_file_is_refused_and_its_other_file_kept(tmp_path, capsys):
    """Issue 32 R2: writing the pid would truncate the file the lock shares its inode with."""
    from handover_eval.cli import evaluate

    out = tmp_path / "out"
    out.mkdir()
    target = tmp_path / "precious.txt"
    target.write_text("keep me")
    os.link(target, out / ".lock")
    with pytest.raises(OutputLockError, match="has 2 names"):
        OutputLock(out).acquire()
    assert evaluate.main(["rescore", str(tmp_path / "none.csv"), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (
        f"evaluate.py: error: --out {out}: the lock file {out / '.lock'} has 2 names (a hard "
        "link to another file?); refusing to write it (remove it)"
    )
    assert target.read_text() == "keep me" and (out / ".lock").stat().st_nlink == 2
    assert sorted(p.name for p in out.iterdir()) == [".lock"]


def test_train_refuses_an_out_in_use_and_loses_nothing(tmp_path, capsys):
    """Without the lock, the second run's --overwrite would delete the first run's checkpoint."""
    from handover_eval.cli import train

    data = toy_dataset(n=8, length=45, seed=1).save(tmp_path / "toy.npz")
    out = tmp_path / "run"
    argv = ["bc-mlp", "--smoke", "--data", str(data), "--out", str(out), "--no-progress"]
    assert train.main(argv) == 0
    capsys.readouterr()
    before = _files(out)
    assert ".lock" not in before and "train_summary.json" in before  # the lock is no result
    holder = Holder(out)  # the first run, still running (e.g. a --resume extending it)
    try:
        res = subprocess.run(
            [sys.executable, str(ROOT / "train.py"), *argv, "--overwrite"],
            capture_output=True, text=True, env=ENV, cwd=tmp_path, timeout=300,
        )
        _refusal(res, "train.py", out, holder.proc.pid)
        assert {k: v for k, v in _files(out).items() if k != ".lock"} == before
    finally:
        holder.stop()
    assert _files(out) == before
    assert train.main([*argv, "--overwrite"]) == 0  # free again: the refusal was the lock
    assert not (out / ".lock").exists()


def test_evaluate_refuses_an_out_in_use_and_loses_nothing(tmp_path):
    out = tmp_path / "closed"
    out.mkdir()
    (out / "closed_loop.csv").write_text("agent,success\nours,0.9\n")
    before = _files(out)
    holder = Holder(out)
    try:
        res = subprocess.run(
            [sys.executable, str(ROOT / "evaluate.py"), "closed-loop", "--quick", "--no-progress",
             "--out", str(out), "--checkpoints", str(tmp_path / "ck")],
            capture_output=True, text=True, env=ENV, cwd=tmp_path, timeout=300,
        )
        _refusal(res, "evaluate.py", out, holder.proc.pid)
    finally:
        holder.stop()
    assert _files(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["closed"]  # no cache, no results/


def test_the_workers_of_a_run_do_not_take_its_lock(tmp_path):
    """table1 with 2 worker processes: they run under the CLI's lock and never contend for it."""
    out = tmp_path / "t1"
    res = subprocess.run(
        [sys.executable, str(ROOT / "evaluate.py"), "table1", "--quick", "--no-progress",
         "--methods", "ours", "--workers", "2", "--out", str(out)],
        capture_output=True, text=True, env=ENV, cwd=tmp_path, timeout=600,
    )
    assert res.returncode == 0, res.stderr
    assert sorted(p.name for p in out.iterdir()) == [
        "table1.csv", "table1.md", "table1_episodes.csv", "table1_folds.csv"
    ]
