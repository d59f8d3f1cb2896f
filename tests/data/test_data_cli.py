"""The data CLI: every subcommand through main(argv), --help, and one real subprocess run."""

from __future__ import annotations

import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from handover_env.data import HandoverDataset
from handover_eval.cli.data import build_parser, main

REPO = Path(__file__).resolve().parents[2]
COMMANDS = ("info", "convert", "synth", "compare", "export-lerobot", "plot")


def _public_folder(folder: Path, n_id: int = 3, n_ood: int = 1) -> Path:
    rng = np.random.default_rng(0)
    folder.mkdir()
    for kind, count in (("normal", n_id), ("variation", n_ood)):
        for i in range(count):
            t = 80 + 5 * i
            quat = rng.standard_normal((t, 4))
            record = {
                "pose_receiver": rng.standard_normal((t, 34, 3)),
                "pose_giver": rng.standard_normal((t, 34, 3)),
                "pose_object": rng.standard_normal((t, 3)),
                "quat_object": quat / np.linalg.norm(quat, axis=1, keepdims=True),
            }
            (folder / f"motion_{kind}_{i}.pkl").write_bytes(pickle.dumps(record, protocol=4))
    return folder


@pytest.mark.parametrize("command", COMMANDS)
def test_every_subcommand_has_help(command: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit, match="^0$") as exc:
        build_parser().parse_args([command, "--help"])
    assert exc.value.code == 0
    assert "usage:" in capsys.readouterr().out


def test_synth_info_compare_plot(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    a, b = tmp_path / "a.npz", tmp_path / "b.npz"
    assert main(["synth", "--n", "20", "--ood-fraction", "0.2", "--seed", "1", str(a)]) == 0
    assert main(["synth", "--n", "20", "--seed", "2", str(b)]) == 0
    ds = HandoverDataset.load(a)
    assert len(ds) == 20 and int(ds.ood_mask.sum()) == 4
    capsys.readouterr()
    assert main(["info", str(a)]) == 0
    out = capsys.readouterr().out
    assert "episodes: 20 (16 ID, 4 OOD)" in out and f"frames: {ds.n_frames:,}" in out
    assert "walking speed" in out and "transfer height" in out and "duration" in out
    assert main(["compare", str(a), str(b), "--subset", "all"]) == 0
    out = capsys.readouterr().out
    assert "rel. diff" in out and "KS" in out and "transfer x" in out
    png = tmp_path / "paths.png"
    assert main(["plot", str(a), str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_convert_with_and_without_skip_bad(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = _public_folder(tmp_path / "pub")
    out = tmp_path / "real.npz"
    assert main(["convert", str(folder), str(out)]) == 0
    ds = HandoverDataset.load(out)
    assert len(ds) == 4 and int(ds.ood_mask.sum()) == 1 and ds[0].source_id == "motion_normal_0"
    (folder / "motion_normal_9.pkl").write_bytes(b"")
    capsys.readouterr()
    assert main(["convert", str(folder), str(out)]) == 2
    assert "motion_normal_9.pkl: empty file" in capsys.readouterr().err
    assert main(["convert", "--skip-bad", str(folder), str(out)]) == 0
    assert "skipped motion_normal_9.pkl" in capsys.readouterr().out
    assert main(["info", "--skip-bad", str(folder)]) == 0
    assert "episodes: 4 (3 ID, 1 OOD)" in capsys.readouterr().out


def test_errors_are_reported_not_raised(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["info", str(tmp_path / "missing.npz")]) == 2
    assert "error: no dataset at" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    assert main(["convert", str(tmp_path / "empty"), str(tmp_path / "x.npz")]) == 2
    assert "no motion_normal_<i>.pkl" in capsys.readouterr().err
    with pytest.raises(SystemExit, match="^2$"):
        main(["synth", "--ood-fraction", "2", str(tmp_path / "x.npz")])


def test_export_lerobot_calls_the_exporter(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys
) -> None:
    import handover_env.data.lerobot_export as export_module

    calls = {}

    def fake_export(dataset, root, repo_id="local/handover", **kwargs):
        calls.update(n=len(dataset), root=Path(root), repo_id=repo_id, **kwargs)
        return Path(root)

    monkeypatch.setattr(export_module, "export_lerobot", fake_export)
    src = tmp_path / "s.npz"
    assert main(["synth", "--n", "5", str(src)]) == 0
    assert (
        main(
            [
                "export-lerobot",
                str(src),
                str(tmp_path / "lr"),
                "--repo-id",
                "me/demo",
                "--history",
                "4",
            ]
        )
        == 0
    )
    assert calls["n"] == 5 and calls["root"] == tmp_path / "lr" and calls["repo_id"] == "me/demo"
    assert calls["history"] == 4 and calls["horizon"] == 30
    assert "exported 5 episodes" in capsys.readouterr().out


def test_module_runs_as_a_subprocess(tmp_path: Path) -> None:
    out = tmp_path / "s.npz"
    result = subprocess.run(
        [sys.executable, "-m", "handover_eval.cli.data", "synth", "--n", "6", str(out)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    assert "episodes: 6 (5 ID, 1 OOD)" in result.stdout and out.is_file()


def test_no_progress_hides_the_loading_bar_of_a_public_folder(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """evaluate.py's loader (closed-loop, table1, benchmark) shows the folder's loading bar only
    when asked: --no-progress passes progress=False down to the public-dataset reader."""
    from handover_eval.cli.evaluate import load_dataset

    folder = _public_folder(tmp_path / "whole_motions")
    quiet = load_dataset(str(folder), False, 0, progress=False)
    assert "loading whole_motions" not in capsys.readouterr().err
    loud = load_dataset(str(folder), False, 0, progress=True)
    assert "loading whole_motions" in capsys.readouterr().err
    assert len(quiet) == len(loud) == 4
    assert [e.source_id for e in quiet] == [e.source_id for e in loud]
