"""evaluate.py: Table I, sample efficiency and trade-off in --quick mode, checkpoint reuse, bad
input."""

from __future__ import annotations

import csv
import math
import os
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("HF_HUB_OFFLINE", "1")

from handover_env.person.synthetic import generate_synthetic  # noqa: E402
from handover_eval.cli import evaluate  # noqa: E402
from handover_eval.methods import MethodOptions, build_agent, fit_agent  # noqa: E402


def _rows(path: Path) -> list[dict]:
    with path.open() as fh:
        return list(csv.DictReader(fh))


def test_table1_quick_all_methods(table1_quick: Path) -> None:
    """The shared ``table1 --quick`` run (tests/eval/conftest.py): every method's tables."""
    out = table1_quick / "out"
    rows = _rows(out / "table1.csv")
    assert [r["method"] for r in rows] == ["ours", "iaal", "act", "bc_mlp", "cv"]
    for r in rows:
        for key in ("id_rms_3d_mm", "ood_rms_3d_mm"):
            assert math.isfinite(float(r[key])) and float(r[key]) > 0
        assert float(r["id_rms_axis_mm"]) == pytest.approx(
            float(r["id_rms_3d_mm"]) / math.sqrt(3), rel=1e-4
        )
    folds = _rows(out / "table1_folds.csv")
    assert len(folds) == 5 * 3  # methods x folds
    for (
        r
    ) in rows:  # the current-frame column is the mean over folds of each fold's row-0 per-axis RMS
        mine = [float(f["id_now_axis_mm"]) for f in folds if f["method"] == r["method"]]
        assert float(r["id_now_axis_mm"]) == pytest.approx(
            sum(mine) / len(mine), rel=1e-4
        )  # CSV keeps 6 digits
        assert 0 < float(r["id_now_axis_mm"]) < float(r["id_rms_3d_mm"])
    episodes = _rows(out / "table1_episodes.csv")
    assert len(episodes) == 5 * 30  # every episode is tested exactly once per method
    md = (out / "table1.md").read_text()
    assert "55.13 ± 2.48" in md and "BC-MLP" in md and "IAAL" in md
    printed = (table1_quick / "stdout.txt").read_text()
    assert "Ours (SPGP)" in printed and "wrote" in printed


def test_table1_folds_in_two_processes_equal_the_serial_loop(
    table1_quick: Path, tmp_path: Path
) -> None:
    """map_folds: the same per-episode errors whether the folds run in-process or in 2 workers
    (the shared run's, whose other methods are fitted and scored apart from these two)."""
    argv = ["table1", "--quick", "--no-progress", "--methods", "ours", "bc_mlp", "--workers", "1",
            "--out", str(tmp_path)]
    assert evaluate.main(argv) == 0
    serial = _rows(tmp_path / "table1_episodes.csv")
    two = [r for r in _rows(table1_quick / "out" / "table1_episodes.csv")
           if r["method"] in ("ours", "bc_mlp")]
    assert len(serial) == 2 * 30
    assert serial == two


def test_sample_efficiency_quick(sample_efficiency_quick: Path) -> None:
    """The shared ``sample-efficiency --quick`` run (tests/eval/conftest.py)."""
    out = sample_efficiency_quick / "out"
    rows = _rows(out / "sample_efficiency.csv")
    assert {(r["method"], float(r["ratio"])) for r in rows} == {
        ("ours", 0.5), ("ours", 1.0), ("bc_mlp", 0.5), ("bc_mlp", 1.0)}
    half = [r for r in rows if r["method"] == "ours" and float(r["ratio"]) == 0.5][0]
    full = [r for r in rows if r["method"] == "ours" and float(r["ratio"]) == 1.0][0]
    assert float(half["n_train_mean"]) < float(full["n_train_mean"])
    from handover_eval.openloop.report import degradation_pct

    typed = [{k: (v if k == "method" else float(v)) for k, v in r.items()} for r in rows]
    pct = degradation_pct(typed)
    assert pct["ours"] == pytest.approx(
        100 * (float(half["all_rms_3d_mm"]) / float(full["all_rms_3d_mm"]) - 1)
    )
    assert "RMS at ratio 0.5 vs 1" in (sample_efficiency_quick / "stdout.txt").read_text()
    assert (out / "sample_efficiency.png").stat().st_size > 10_000


def test_tradeoff_quick(tmp_path: Path) -> None:
    argv = ["tradeoff", "--quick", "--no-progress", "--out", str(tmp_path), "--rates", "0.2", "1.0",
            "--timing-episodes", "3"]
    assert evaluate.main(argv) == 0
    rows = _rows(tmp_path / "tradeoff.csv")
    assert [r["method"] for r in rows] == ["ours", "ours", "iaal"]
    for r in rows:
        assert float(r["frame_ms_median"]) > 0 and int(r["n_timed_frames"]) > 0
    iaal = rows[-1]
    assert float(iaal["speedup_vs_iaal"]) == pytest.approx(1.0)
    # FITC at rate 1.0 is the exact GP (agents/gp.py), so its RMS equals IAAL's.
    assert float(rows[1]["all_rms_3d_mm"]) == pytest.approx(float(iaal["all_rms_3d_mm"]), rel=1e-6)
    assert (tmp_path / "tradeoff.png").stat().st_size > 10_000


def test_learned_checkpoint_is_reused(tmp_path: Path) -> None:
    data = generate_synthetic(n=12, ood_fraction=0.25, seed=3)
    options = MethodOptions(quick=True, bc_epochs=2)
    first, reused = fit_agent("bc_mlp", build_agent("bc_mlp", options), data, tmp_path)
    assert not reused
    second, reused = fit_agent("bc_mlp", build_agent("bc_mlp", options), data, tmp_path)
    assert reused
    ep = data[0]
    times = np.arange(5, 20)
    np.testing.assert_array_equal(
        first.predict_episode(ep, times), second.predict_episode(ep, times)
    )
    # Another training set is another checkpoint.
    _, reused = fit_agent(
        "bc_mlp", build_agent("bc_mlp", options), data.subset(range(10)), tmp_path
    )
    assert not reused


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["table1", "--methods", "ours", "gpt"], "unknown method"),
        (["table1", "--data", "/nonexistent/whole_motions"], "no such file"),
        (["tradeoff", "--methods", "act"], "nonparametric"),
        (["table1", "--workers", "0"], "workers"),
        (["table1", "--act-steps", "0"], "act_steps"),
    ],
)
def test_bad_input_gives_clear_error(
    argv: list[str], message: str, capsys: pytest.CaptureFixture
) -> None:
    assert evaluate.main(argv + ["--no-progress"]) == 2
    assert message in capsys.readouterr().err


def test_dataset_too_small_for_folds(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    path = generate_synthetic(n=6, ood_fraction=0.34, seed=1).save(tmp_path / "tiny.npz")
    assert (
        evaluate.main(
            ["table1", "--data", str(path), "--folds", "10", "--methods", "ours", "--no-progress"]
        )
        == 2
    )
    assert "folds" in capsys.readouterr().err
