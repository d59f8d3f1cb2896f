"""The reach's giver-dependent line and per-person offsets: one recording's offset
(:mod:`handover_env.person.reach_offset`), the offsets' distribution, and ``handover-data
reach-spread`` on recordings built from the synthetic generator and on the development copy
(skipped when it is absent)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from synthetic_skeletons import write_folder

from handover_env.data.filtering import smooth_track
from handover_env.person.reach_offset import (
    REACH_OFFSET,
    ReachOffsetDistribution,
    reach_offset,
    recorded_reach,
    recording_reach_offset,
)
from handover_env.person.receiver_rules import TAKE_CLOSEST, TAKE_INTERCEPT
from handover_eval.calibration.reach_spread import (
    choose_distribution,
    fit_line,
    predict_summary,
    residual_summary,
)
from handover_eval.cli.data import main

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs" / "calibration"
REAL = ROOT.parent / "shared" / "data" / "dynamic_handover_dataset" / "whole_motions"


def _skeleton(t: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """A shoulder walking along -x at y = -0.9, z = 1.4; the object still at (0, -0.5, 1.4)."""
    pose = np.zeros((t, 34, 3))
    pose[:, 12] = np.column_stack([np.linspace(1.0, -0.6, t), np.full(t, -0.9), np.full(t, 1.4)])
    obj = np.tile([0.0, -0.5, 1.4], (t, 1))
    return pose, obj


# ----------------------------------------------------------------------- one recording
def test_recorded_reach_and_offset_of_a_known_walk() -> None:
    pose, obj = _skeleton()
    k, onset = 25, 10  # shoulder x at frame 25 = 1.0 - 1.6 * 25 / 39
    rec = recorded_reach(pose, obj, transfer=k, onset=onset)
    x_k = 1.0 - 1.6 * k / 39
    assert rec.reach == pytest.approx(math.hypot(x_k, 0.4))
    assert rec.closest == pytest.approx(0.4, abs=1e-3)  # the path passes 0.4 m from it at x = 0
    assert reach_offset(0.6, 0.4, 0.411, 0.25) == pytest.approx(0.6 - 0.511)
    assert recording_reach_offset(pose, obj, k, onset, 0.411, 0.25) == pytest.approx(
        rec.reach - (0.411 + 0.25 * rec.closest))


def test_recorded_reach_refuses_bad_input() -> None:
    pose, obj = _skeleton()
    with pytest.raises(ValueError, match="skeleton"):
        recorded_reach(pose[:, :10], obj, 5, 1)
    with pytest.raises(ValueError, match="obj must be"):
        recorded_reach(pose, obj[:-1], 5, 1)
    with pytest.raises(ValueError, match="outside the recording"):
        recorded_reach(pose, obj, 40, 1)
    with pytest.raises(ValueError, match="comes after the transfer"):
        recorded_reach(pose, obj, 5, 6)
    with pytest.raises(ValueError, match="frame index"):
        recorded_reach(pose, obj, True, 1)
    pose[20, 12, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        recorded_reach(pose, obj, 25, 10)
    with pytest.raises(ValueError, match="finite numbers"):
        reach_offset(0.5, math.nan, 0.4, 0.2)


# ----------------------------------------------------------------------- the distribution
def test_offset_draws_follow_their_distribution_and_the_seed() -> None:
    normal = ReachOffsetDistribution("normal", 0.01, 0.08, (), "test")
    rng = np.random.default_rng(1)
    draws = np.array([normal.draw(rng) for _ in range(20_000)])
    assert draws.mean() == pytest.approx(0.01, abs=0.003)
    assert draws.std() == pytest.approx(0.08, rel=0.03)
    a, b = (REACH_OFFSET.draw(np.random.default_rng(7)) for _ in range(2))
    assert a == b  # the same seed, the same person
    rng = np.random.default_rng(2)
    draws = np.array([REACH_OFFSET.draw(rng) for _ in range(20_000)])
    for p, v in REACH_OFFSET.quantiles[1:-1]:
        assert np.quantile(draws, p) == pytest.approx(v, abs=0.006)
    assert draws.std() == pytest.approx(REACH_OFFSET.sd, rel=0.05)


def test_distribution_refuses_bad_numbers() -> None:
    with pytest.raises(ValueError, match="kind must be"):
        ReachOffsetDistribution("uniform", 0.0, 0.1, (), "x")
    with pytest.raises(ValueError, match="increasing"):
        ReachOffsetDistribution("quantiles", 0.0, 0.1, ((0.5, 0.0), (0.2, 0.1)), "x")
    with pytest.raises(ValueError, match="at least two"):
        ReachOffsetDistribution("quantiles", 0.0, 0.1, ((0.5, 0.0),), "x")
    with pytest.raises(ValueError, match="sd >= 0"):
        ReachOffsetDistribution("normal", 0.0, -0.1, (), "x")


def test_constants_equal_the_committed_report() -> None:
    report = json.loads((DOCS / "reach_spread.json").read_text())
    off = report["offset"]
    assert REACH_OFFSET.kind == off["distribution"]
    assert REACH_OFFSET.mean == off["mean"] and REACH_OFFSET.sd == off["sd"]
    assert [list(q) for q in REACH_OFFSET.quantiles] == off["quantiles"]
    # the giver's part the offsets are taken from is the person's take-distance line
    line = report["line"]
    assert line["matches_person"]
    assert (round(line["intercept"], 3), round(line["slope"], 3)) == (TAKE_INTERCEPT, TAKE_CLOSEST)
    assert report["held_out"]["all"]["r"] == pytest.approx(0.48, abs=0.01)


# ----------------------------------------------------------------------- the analysis
def test_fit_and_distribution_choice() -> None:
    rng = np.random.default_rng(3)  # a normal sample within 2 SE of a normal's shape
    x = rng.uniform(0.0, 0.8, 2000)
    y = 0.4 + 0.25 * x + rng.normal(0.0, 0.08, x.size)
    line = fit_line(x, y)
    assert line["intercept"] == pytest.approx(0.4, abs=0.01)
    assert line["slope"] == pytest.approx(0.25, abs=0.02)
    res = residual_summary(y - (line["intercept"] + line["slope"] * x))
    assert res["sd"] == pytest.approx(0.08, rel=0.05)
    assert choose_distribution(res)[0] == "normal"
    heavy = residual_summary(rng.standard_t(3, 2000) * 0.05)
    assert choose_distribution(heavy)[0] == "quantiles"
    pred = predict_summary(x, y, line, res["sd"])
    assert pred["rmse"] == pytest.approx(0.08, rel=0.06)
    assert pred["line_plus_offset_sd"] == pytest.approx(np.std(y), rel=0.05)
    with pytest.raises(ValueError, match="cannot fit the reach line"):
        fit_line(np.ones(5), np.arange(5.0))


def test_reach_spread_cli_on_the_synthetic_generator(tmp_path: Path) -> None:
    folder = write_folder(tmp_path / "whole_motions", n=40)
    out = tmp_path / "calib"
    argv = ["reach-spread", str(folder), "--out", str(out), "--folds", "2",
            "--calibration-folds", "1"]
    assert main(argv) == 0
    report = json.loads((out / "reach_spread.json").read_text())
    n_cal, n_held = report["calibration"]["all"]["n"], report["held_out"]["all"]["n"]
    assert report["line"]["n"] == report["offset"]["n"] == n_cal >= 5 and n_held >= 5
    assert abs(report["offset"]["mean"]) < 1e-3  # least-squares residuals
    assert report["offset"]["distribution"] in ("normal", "quantiles")
    assert 0.0 < report["offset"]["sd"] < 0.3
    page = (out / "reach_spread.md").read_text()
    assert "## How well the giver's part predicts (held-out half)" in page
    assert (out / "reach_spread.png").stat().st_size > 10_000
    assert main(["reach-spread", str(tmp_path / "missing"), "--out", str(out)]) == 2


# ----------------------------------------------------------------------- the real dataset
ABSENT = "the development copy of the public dataset is absent"


@pytest.mark.skipif(not REAL.is_dir(), reason=ABSENT)
def test_one_recordings_offset_is_its_residual_on_the_development_copy() -> None:
    """The replay-time function gives each recording the residual the distribution is made of."""
    from handover_env.data.public import list_public_files, safe_load_pickle
    from handover_eval.calibration.report import analyse_file

    files = list_public_files(REAL)
    chosen = files[:30] + [p for p in files if p.name.startswith("motion_variation_")][:10]
    compared = 0
    for path in chosen:
        result = analyse_file(path)
        events, m = result.analysis.events, result.analysis.measures
        if events["transfer"] is None or events["onset"] is None:
            continue
        record = safe_load_pickle(path)
        pose = smooth_track(record["pose_receiver"], 30.0)
        obj = smooth_track(record["pose_object"], 30.0)
        own = recording_reach_offset(pose, obj, events["transfer"], events["onset"],
                                     TAKE_INTERCEPT, TAKE_CLOSEST)
        expected = m["object_shoulder_transfer"] - (
            TAKE_INTERCEPT + TAKE_CLOSEST * m["path_closest_onset"])
        assert own == pytest.approx(expected, abs=1e-9)
        assert abs(own) < 0.4
        compared += 1
    assert compared >= 35
