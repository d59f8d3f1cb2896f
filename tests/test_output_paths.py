"""Issue 16 item 15: output paths that are folders give one clear error and leave nothing behind."""

from __future__ import annotations

import sys
from pathlib import Path

from handover_env.data.__main__ import main

REPO = Path(__file__).resolve().parents[1]


def test_convert_to_a_folder_named_npz_leaves_no_temporary_file(tmp_path: Path, capsys) -> None:
    from crafted import write_good_pickle

    pub = tmp_path / "pub"
    pub.mkdir()
    write_good_pickle(pub / "motion_normal_0.pkl")
    target = tmp_path / "out.npz"
    target.mkdir()
    assert main(["convert", str(pub), str(target)]) == 2
    assert f"error: {target}: exists and is not a file" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.npz", "pub"]
    assert main(["synth", "--n", "3", str(target)]) == 2  # the same check for synth


def test_save_removes_its_temporary_file_on_failure(tmp_path: Path, monkeypatch) -> None:
    import numpy as np

    from handover_env.data import generate_synthetic

    def fail(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(np, "savez_compressed", fail)
    try:
        generate_synthetic(n=2, seed=0).save(tmp_path / "d.npz")
    except OSError:
        pass
    assert list(tmp_path.iterdir()) == []


def test_plot_to_a_folder_is_refused_and_writes_nothing(tmp_path: Path, capsys) -> None:
    folder = tmp_path / "figs"
    folder.mkdir()
    assert main(["plot", "synthetic", str(folder)]) == 2
    assert f"error: '{folder}': is a folder" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["figs"] and not list(folder.iterdir())
    assert (
        main(["plot", "synthetic", str(tmp_path / "paths")]) == 2
    )  # no suffix: matplotlib adds .png
    assert "must end in one of .png, .pdf, .svg" in capsys.readouterr().err
    assert not (tmp_path / "paths.png").exists()


def test_plot_reports_the_file_it_wrote(tmp_path: Path, capsys) -> None:
    out = tmp_path / "p.svg"
    assert main(["plot", "synthetic", str(out), "--max-episodes", "3"]) == 0
    assert capsys.readouterr().out.strip() == f"wrote {out}"
    assert out.read_text().lstrip().startswith("<?xml")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.svg"]


def test_evaluate_out_that_is_a_file_is_a_one_line_error(tmp_path: Path, capsys) -> None:
    sys.path.insert(0, str(REPO))
    from handover_eval.cli import evaluate

    target = tmp_path / "results.txt"
    target.write_text("keep me")
    assert evaluate.main(["table1", "--quick", "--methods", "ours", "--out", str(target)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"evaluate.py: error: --out {target}: exists and is not a folder"
    assert target.read_text() == "keep me"
