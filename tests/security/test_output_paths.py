"""Issue 16 item 15: output paths that are folders give one clear error and leave nothing behind.
Issue 20 item 2: one check (``handover_env.paths.output_folder``) of every output-folder option."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

from handover_eval.cli.data import main

REPO = Path(__file__).resolve().parents[2]


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

    from handover_env.person.synthetic import generate_synthetic

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


# ---------------------------------------------------------------------- issue 20 item 2
#: Every command that writes into an output folder, with the option naming it; a valid rest of
#: the command line that would run if the folder were fine.
OUTPUT_OPTIONS = [
    ("train", ["bc-mlp", "--smoke", "--no-progress"], "--out"),
    ("train", ["act", "--smoke", "--no-progress"], "--out"),
    ("train", ["act", "--smoke", "--no-progress", "--out", "ok"], "--export-root"),
    ("train", ["preference", "--iterations", "1", "--no-progress"], "--out"),
    ("train", ["preference-check", "--no-progress"], "--out"),
    ("evaluate", ["table1", "--quick", "--methods", "ours", "--no-progress"], "--out"),
    ("evaluate", ["sample-efficiency", "--quick", "--methods", "ours", "--no-progress"], "--out"),
    ("evaluate", ["tradeoff", "--quick", "--no-progress"], "--out"),
    ("evaluate", ["closed-loop", "--quick", "--no-progress"], "--out"),
    ("evaluate", ["closed-loop", "--quick", "--no-progress", "--out", "ok"], "--checkpoints"),
    ("evaluate", ["theta-sweep", "--quick", "--no-progress"], "--out"),
    ("evaluate", ["user-study", "--quick", "--no-progress"], "--out"),
]


def _cli(which: str):
    from handover_eval.cli import evaluate as evaluate_cli
    from handover_eval.cli import train as train_cli

    return {"train": train_cli.main, "evaluate": evaluate_cli.main}[which]


@pytest.mark.parametrize(("which", "argv", "flag"), OUTPUT_OPTIONS)
@pytest.mark.parametrize("value", ["", "   "])
def test_an_empty_output_folder_is_refused_by_every_command(
    which, argv, flag, value, tmp_path, monkeypatch, capsys
):
    """`--out ""` (an unset shell variable) never falls back to results/ in the current folder."""
    monkeypatch.chdir(tmp_path)
    assert _cli(which)([*argv, flag, value]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"{which}.py: error: {flag} is empty (an unset shell variable?)"
    assert list(tmp_path.iterdir()) == []  # no results/, no ok/


@pytest.mark.parametrize(("which", "argv", "flag"), OUTPUT_OPTIONS)
def test_an_output_folder_that_is_a_file_is_refused_by_every_command_after_expanding_home(
    which, argv, flag, tmp_path, monkeypatch, capsys
):
    home = tmp_path / "home"
    home.mkdir()
    (home / "notes.txt").write_text("keep me")
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.chdir(tmp_path)
    assert _cli(which)([*argv, flag, "~/notes.txt"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"{which}.py: error: {flag} {home / 'notes.txt'}: exists and is not a folder"
    assert (home / "notes.txt").read_text() == "keep me"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["home"]


def test_output_folder_expands_home_and_names_its_option(tmp_path, monkeypatch) -> None:
    from handover_env.paths import UnsafePathError, output_folder

    monkeypatch.setenv("HOME", str(tmp_path))
    assert output_folder("~/runs/a", "--out") == tmp_path / "runs" / "a"  # need not exist
    (tmp_path / "dangling").symlink_to(tmp_path / "nowhere")
    for bad, message in [
        ("\t\n", "--cache is empty"),
        ("a\0b", "--cache 'a\\x00b': a path cannot hold a NUL byte"),
        ("~/dangling", f"--cache {tmp_path / 'dangling'}: a symbolic link to nothing"),
    ]:
        with pytest.raises(UnsafePathError, match="^" + re.escape(message)) as exc:
            output_folder(bad, "--cache")
        assert str(exc.value).startswith(message)
    assert not (tmp_path / "nowhere").exists()
