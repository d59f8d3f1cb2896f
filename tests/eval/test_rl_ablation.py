"""``evaluate.py rl-ablation``: issue 36's ablation rows from a real (``--quick``) RL checkpoint and
hand-made closed-loop files whose numbers are known, and its refusals."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

import evaluate
from handover_eval.cli import train
from handover_eval.closedloop.presentation import QUANTITIES
from handover_eval.rl.ablation import (
    AblationError,
    agent_scores,
    parse_curves,
    parse_run,
    read_curves,
    read_table,
    run_ablation,
    seed_summary,
)
from handover_eval.rl.output import write_ablation
from handover_eval.rl.statistics import iqm


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("rl") / "run"
    assert train.main(["rl", "--quick", "--no-progress", "--out", str(out), "--base", "cv"]) == 0
    return out


def _episode(agent: str, set_: str, k: int, outcome: str, time: float, contact: float,
             jerk: float) -> dict:
    row = {"agent": agent, "set": set_, "receiver": f"{set_}-{k}", "seed": str(k),
           "is_ood": str(set_ == "ood"), "outcome": outcome,
           "is_success": str(outcome == "success"),
           "handover_time": "nan" if outcome != "success" else repr(time),
           "body_contact_force": repr(contact), "robot_jerk_rms": repr(jerk),
           "reach_onset_time": "nan" if k == 0 else "0.2", "release_time": "0.3"}
    return {**row, **dict.fromkeys(QUANTITIES, "0.3")}


def _evaluation(folder: Path, rl_time: float, rl_fail: int, paired_time: float) -> Path:
    """cv and rl-residual, 4 episodes per set; rl-residual fails its first ``rl_fail`` ones
    prematurely and presses one episode per set at 80 N."""
    folder.mkdir(parents=True)
    rows = []
    for set_ in ("id", "ood", "replay"):
        for k in range(4):
            rows.append(_episode("cv", set_, k, "success", 2.0 + k, 0.0, 60.0))
            outcome = "premature_release" if k < rl_fail else "success"
            rows.append(_episode("rl-residual", set_, k, outcome, rl_time + k,
                                 80.0 if k == 3 else 10.0, 100.0 + k))
    with (folder / "closed_loop_episodes.csv").open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    with (folder / "closed_loop_paired.csv").open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["agent", "set", "metric", "diff", "diff_low", "diff_high",
                    "ci_excludes_zero"])
        for set_ in ("walker-id", "walker-ood", "replay-all"):
            w.writerow(["rl-residual", set_, "success", -rl_fail / 4, -0.5, 0.0, False])
            w.writerow(["rl-residual", set_, "handover_time", paired_time, paired_time - 0.1,
                        paired_time + 0.05, paired_time + 0.05 < 0])
    return folder


def test_the_rows_hold_the_curve_the_scores_and_the_paired_differences(checkpoint, tmp_path):
    a = _evaluation(tmp_path / "a", 1.5, 1, -0.2)
    b = _evaluation(tmp_path / "b", 2.5, 2, 0.1)
    with pytest.raises(AblationError, match="seed 0 is given twice"):  # one checkpoint, twice
        run_ablation([parse_run(f"levers={checkpoint}:{a}"),
                      parse_run(f"levers={checkpoint}:{b}")])
    rows, refs = run_ablation([parse_run(f"levers={checkpoint}:{a}")], ["cv", "reactive"])
    second, _ = run_ablation([parse_run(f"levers={checkpoint}:{b}")])
    second[0].seed = 7  # stands for another seed of the configuration
    rows += second
    assert [r.agent for r in refs] == ["cv"]  # reactive ran in neither
    assert refs[0].sets["replay-all"] == {"n": 4.0, "success": 1.0, "handover_time": 3.5,
                                          "contact_over": 0.0, "robot_jerk": 60.0,
                                          "premature": 0.0, "premature_before_reach": 0.0}
    first = rows[0]
    assert first.reference == "cv" and first.flags == "--base cv"
    assert first.steps == 256 and math.isclose(first.steps_per_s, 256 / first.wall_s)
    s = first.scores.sets["walker-ood"]
    # successes k = 1, 2, 3 at 1.5 + k s; one of four over 50 N; jerk 100..103; the premature
    # release (k = 0) came with no reach onset
    assert s == {"n": 4.0, "success": 0.75, "handover_time": 3.5, "contact_over": 0.25,
                 "robot_jerk": 101.5, "premature": 1.0, "premature_before_reach": 1.0}
    assert rows[1].scores.sets["replay-all"]["premature_before_reach"] == 1.0  # k = 1 reached
    assert first.paired["replay-all"]["handover_time"] == (
        -0.2, pytest.approx(-0.3), pytest.approx(-0.15), True)
    (summary,) = seed_summary(rows)
    assert summary["seeds"] == [first.seed, 7]
    assert summary["handover_time_mean"] == pytest.approx(-0.05)
    assert summary["handover_time_iqm"][0] == pytest.approx(iqm(np.array([-0.2, 0.1])))
    assert summary["success_mean"] == pytest.approx(-0.375)


def test_the_command_writes_md_csv_png_and_prints_the_table(checkpoint, tmp_path, capsys):
    a = _evaluation(tmp_path / "a", 1.5, 1, -0.2)
    out = tmp_path / "out"
    assert evaluate.main(["rl-ablation", "--run", f"levers={checkpoint}:{a}", "--out",
                          str(out)]) == 0
    text = capsys.readouterr().out
    assert "| levers |" in text and "-0.20 [-0.30, -0.15]*" in text
    assert (out / "rl_ablation.png").read_bytes()[:4] == b"\x89PNG"
    with (out / "rl_ablation.csv").open() as fh:
        table = list(csv.DictReader(fh))
    assert [t["configuration"] for t in table] == ["cv", "levers"]
    assert float(table[1]["replay-all_success"]) == 0.75


def test_bad_input_is_one_line_naming_what_is_wrong(checkpoint, tmp_path, capsys):
    a = _evaluation(tmp_path / "a", 1.5, 1, -0.2)
    cases = {
        "levers": "expected LABEL=RUN_FOLDER:EVALUATION_FOLDER",
        f"x={tmp_path / 'none'}:{a}": "not a folder",
        f"x={a}:{a}": "config.json",  # an evaluation folder is not a checkpoint
    }
    for run, message in cases.items():
        assert evaluate.main(["rl-ablation", "--run", run, "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1, err
    assert not (tmp_path / "o").exists()


def test_two_rl_agents_or_a_missing_paired_column_are_refused(checkpoint, tmp_path):
    a = _evaluation(tmp_path / "a", 1.5, 1, -0.2)
    text = (a / "closed_loop_episodes.csv").read_text()
    (a / "closed_loop_episodes.csv").write_text(
        text + text.splitlines()[2].replace("rl-residual", "rl-scratch", 1) + "\n")
    with pytest.raises(AblationError, match="expected one RL agent"):
        run_ablation([parse_run(f"x={checkpoint}:{a}")])
    b = _evaluation(tmp_path / "b", 1.5, 1, -0.2)
    (b / "closed_loop_paired.csv").write_text("agent,set\nrl-residual,replay-all\n")
    with pytest.raises(AblationError, match=r"no column\(s\)"):
        run_ablation([parse_run(f"x={checkpoint}:{b}")])


def test_a_paired_file_linked_out_of_the_folder_is_refused(checkpoint, tmp_path):
    a = _evaluation(tmp_path / "a", 1.5, 1, -0.2)
    outside = tmp_path / "outside.csv"
    (a / "closed_loop_paired.csv").rename(outside)
    (a / "closed_loop_paired.csv").symlink_to(outside)
    with pytest.raises(AblationError, match="closed_loop_paired.csv"):
        run_ablation([parse_run(f"x={checkpoint}:{a}")])


def test_scores_need_every_set():
    rows = [_episode("cv", "id", 0, "success", 1.0, 0.0, 1.0)]
    with pytest.raises(AblationError, match="no ood episodes of cv"):
        agent_scores(rows, "cv", Path("e.csv"))


# ------------------------------------------------------- an earlier table and the seeds' curves
def _table(checkpoint: Path, tmp_path: Path) -> tuple[Path, list]:
    """rl_ablation.csv of two seeds of one run (one evaluation each), and those rows."""
    a = _evaluation(tmp_path / "a", 1.5, 1, -0.2)
    b = _evaluation(tmp_path / "b", 2.5, 2, 0.1)
    rows, refs = run_ablation([parse_run(f"levers={checkpoint}:{a}")])
    other, _ = run_ablation([parse_run(f"levers={checkpoint}:{b}")])
    other[0].seed = 7  # another seed of the configuration
    rows += other
    write_ablation(rows, refs, seed_summary(rows), tmp_path / "t")
    return tmp_path / "t" / "rl_ablation.csv", rows


def test_an_earlier_table_reads_back_every_row_as_written(checkpoint, tmp_path):
    path, rows = _table(checkpoint, tmp_path)
    back, refs = read_table(path)
    assert [r.agent for r in refs] == ["cv"]
    for r, b in zip(rows, back, strict=True):
        assert (b.label, b.seed, b.flags, b.steps, b.reference) == (
            r.label, r.seed, "--base cv", r.steps, "cv")
        assert b.wall_s == r.wall_s and b.curve_end == r.curve_end
        assert b.scores.sets == r.scores.sets  # full precision, NaN-free here
        assert b.paired == r.paired  # the star rebuilt from the CI: the closed-loop rule
    out = tmp_path / "again"
    write_ablation(back, refs, seed_summary(back), out)
    assert (out / "rl_ablation.csv").read_bytes() == path.read_bytes()
    assert (out / "rl_ablation.md").read_bytes() == (path.parent / "rl_ablation.md").read_bytes()


def test_a_table_joins_new_runs_and_its_reference_must_agree(checkpoint, tmp_path):
    path, _ = _table(checkpoint, tmp_path)
    c = _evaluation(tmp_path / "c", 1.5, 1, -0.3)
    rows, refs = run_ablation([parse_run(f"new={checkpoint}:{c}")], tables=[path])
    assert [(r.label, r.seed) for r in rows] == [("levers", rows[0].seed), ("levers", 7),
                                                 ("new", rows[0].seed)]
    assert [r.agent for r in refs] == ["cv"]
    with pytest.raises(AblationError, match="seed 0 is given twice"):
        run_ablation([], tables=[path, path])
    d = _evaluation(tmp_path / "d", 1.5, 1, -0.3)
    text = (d / "closed_loop_episodes.csv").read_text().replace(",60.0,", ",61.0,")
    (d / "closed_loop_episodes.csv").write_text(text)  # cv's robot jerk differs
    with pytest.raises(AblationError, match="reference cv's scores differ"):
        run_ablation([parse_run(f"new={checkpoint}:{d}")], tables=[path])


@pytest.mark.parametrize("column, value, message", [
    ("replay-all_success", "abc", "is not a number"),
    ("seed", "-1", "whole number"),
    ("steps", "2.5", "whole number"),
    ("wall_s", "inf", "not a finite number"),
    ("agent", "cv", "is not one of"),
])
def test_a_bad_table_is_one_error_naming_the_field(checkpoint, tmp_path, column, value,
                                                   message):
    path, _ = _table(checkpoint, tmp_path)
    with path.open() as fh:
        lines = list(csv.DictReader(fh))
    lines[1][column] = value  # the first seed row
    with path.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(lines[0]))
        w.writeheader()
        w.writerows(lines)
    with pytest.raises(AblationError, match=message) as err:
        read_table(path)
    assert str(path) in str(err.value) and column in str(err.value)


def test_a_table_that_is_not_one_or_links_out_is_refused(checkpoint, tmp_path, capsys):
    other = tmp_path / "other.csv"
    other.write_text("configuration,seed\nx,0\n")
    with pytest.raises(AblationError, match="not an rl_ablation.csv"):
        read_table(other)
    path, _ = _table(checkpoint, tmp_path)
    (tmp_path / "in").mkdir()
    (tmp_path / "in" / "rl_ablation.csv").symlink_to(path)
    assert evaluate.main(["rl-ablation", "--table", str(tmp_path / "in" / "rl_ablation.csv"),
                          "--out", str(tmp_path / "o")]) == 2
    assert "rl_ablation.csv" in capsys.readouterr().err
    assert evaluate.main(["rl-ablation", "--out", str(tmp_path / "o")]) == 2
    assert "no runs and no earlier table" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def _log(folder: Path, success: list[float]) -> None:
    folder.mkdir(parents=True)
    with (folder / "train_log.csv").open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["steps", "success_rate", "handover_time", "return", "episodes",
                    "wall_time_s"])
        for k, s in enumerate(success):
            w.writerow([1000 * k, s, "nan" if s == 0 else 2.0, 10 * s, k, k])


def test_curves_draw_every_seed_and_summarise_the_iqm(checkpoint, tmp_path, capsys):
    path, _ = _table(checkpoint, tmp_path)
    logs = tmp_path / "logs"
    for seed, curve in ((0, [0.9, 0.5]), (1, [1.0, 0.0]), (12, [0.8, 0.7])):
        _log(logs / f"seed-{seed}", curve)
    out = tmp_path / "out"
    assert evaluate.main(["rl-ablation", "--table", str(path), "--curves", f"old={logs}",
                          "--out", str(out)]) == 0
    assert "wrote" in capsys.readouterr().out
    assert (out / "old" / "learning_curves.png").read_bytes()[:4] == b"\x89PNG"
    summary = json.loads((out / "old" / "seeds_summary.json").read_text())
    assert summary["seeds"] == 3
    assert summary["end_success_rate"]["iqm"] == pytest.approx(iqm(np.array([0.5, 0.0, 0.7])))
    assert summary["start_return"]["iqm"] == pytest.approx(iqm(np.array([9.0, 10.0, 8.0])))
    assert [s for s, _ in read_curves(logs)] == [0, 1, 12]


def test_bad_curves_are_refused(tmp_path):
    for text in ("noequals", "../x=somewhere", "a b=somewhere", ".=x"):
        with pytest.raises(AblationError, match="expected LABEL=FOLDER"):
            parse_curves(text)
    with pytest.raises(AblationError, match="no seed-S folders"):
        read_curves(tmp_path)
    _log(tmp_path / "seed-0", [0.5, 0.5])
    log = tmp_path / "seed-0" / "train_log.csv"
    log.write_text(log.read_text().replace("0.5,", "nan,", 1))
    with pytest.raises(AblationError, match="must be finite"):
        read_curves(tmp_path)
