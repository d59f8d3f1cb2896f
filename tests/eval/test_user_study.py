"""evaluate.py user-study: statistics against closed forms, and the --quick run end to end."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from handover_env.config import THETA_RANGES
from handover_eval.preference.study import binomial_stats, paired_stats, random_theta


def test_paired_stats_closed_forms() -> None:
    a = [4.2, 4.6, 3.8, 4.4, 4.0]
    b = [3.0, 3.9, 2.6, 3.1, 3.3]
    s = paired_stats(a, b)
    d = np.subtract(a, b)
    assert s["mean_diff"] == pytest.approx(d.mean())
    assert s["d_z"] == pytest.approx(d.mean() / d.std(ddof=1))
    assert s["d_av"] == pytest.approx(d.mean() / ((np.std(a, ddof=1) + np.std(b, ddof=1)) / 2))
    t = d.mean() / (d.std(ddof=1) / math.sqrt(len(d)))
    assert s["p"] == pytest.approx(2 * stats.t.sf(abs(t), len(d) - 1))
    # pairs with a missing value (no successful handover) are dropped
    assert paired_stats([1.0, math.nan, 3.0], [0.0, 1.0, 1.0])["n"] == 2


def test_binomial_stats_reproduce_the_papers_h3() -> None:
    s = binomial_stats(29, 40)
    assert s["share"] == 0.725 and s["p"] < 0.01 and s["h"] == pytest.approx(0.47, abs=0.005)
    assert binomial_stats(20, 40)["p"] == pytest.approx(1.0)


def test_random_theta_is_uniform_in_the_papers_ranges() -> None:
    rng = np.random.default_rng(0)
    draws = np.array([random_theta(rng).as_array() for _ in range(4000)])
    for k, name in enumerate(("stiffness", "damping", "forecast_time", "release_force")):
        lo, hi = THETA_RANGES[name]
        assert lo <= draws[:, k].min() and draws[:, k].max() <= hi
        assert draws[:, k].mean() == pytest.approx((lo + hi) / 2, rel=0.03)


def test_user_study_quick_end_to_end(tmp_path: Path) -> None:
    from handover_eval.cli import evaluate

    out = tmp_path / "us"
    assert evaluate.main(["user-study", "--quick", "--out", str(out), "--no-progress"]) == 0
    text = (out / "user_study.md").read_text()
    assert "Simulated participants" in text and "not people" in text
    for needle in ("H1", "H3", "4.3 ± 0.45", "72.5%", "Personalised"):
        assert needle in text
    summary = json.loads((out / "summary.json").read_text())
    assert summary["h3"]["n"] == 2 * 2 and 0.0 <= summary["h3"]["share"] <= 1.0
    trials = list(csv.DictReader((out / "trials.csv").open()))
    assert len(trials) == 2 * 2 * 2 and {r["condition"] for r in trials} == {"dynamic", "static"}
    assert all(1 <= int(r["likert"]) <= 5 for r in trials)
    assert len(list(csv.DictReader((out / "personalised.csv").open()))) == 2
    assert (out / "user_study.png").stat().st_size > 1000
    assert (out / "pooled" / "theta_hat.json").exists()
    assert "What makes the comfort difference" in text
    episodes = json.loads((out / "summary.json").read_text())["timings"]["episodes"]
    assert f"Walker mix: {episodes} ID and 0 OOD walks over all {episodes} episodes" in text
    # each part has its own answer-noise stream: --theta with the pooled Θ̂ reproduces H1-H3
    theta = json.loads((out / "pooled" / "theta_hat.json").read_text())["theta_hat"]
    again = tmp_path / "again"
    assert (
        evaluate.main(
            [
                "user-study",
                "--quick",
                "--out",
                str(again),
                "--no-progress",
                "--no-personalised",
                "--theta",
                *(
                    str(theta[k])
                    for k in ("stiffness", "damping", "forecast_time", "release_force")
                ),
            ]
        )
        == 0
    )
    assert (again / "trials.csv").read_text() == (out / "trials.csv").read_text()
    assert (again / "h3_choices.csv").read_text() == (out / "h3_choices.csv").read_text()


def test_user_study_rejects_bad_input(capsys) -> None:
    from handover_eval.cli import evaluate

    with pytest.raises(SystemExit, match="^2$") as exc:
        evaluate.main(["user-study", "--participants", "1"])
    assert exc.value.code == 2
    assert (
        evaluate.main(["user-study", "--theta", "100", "15", "-1", "8", "--quick", "--no-progress"])
        == 2
    )
    assert "forecast_time" in capsys.readouterr().err
