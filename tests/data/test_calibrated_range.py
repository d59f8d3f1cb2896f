"""The range of walks the person was calibrated on: the fields of a walk
(:mod:`handover_env.person.calibrated_range`), the check, the committed constants, and
``handover-data calibrated-range`` on recordings built from the synthetic generator and on the
development copy (skipped when it is absent)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from synthetic_skeletons import write_folder

from handover_env.person import calibrated_range as cr
from handover_env.person import motion
from handover_env.person.calibrated_range import (
    CALIBRATED_RANGE,
    CalibratedRange,
    check,
    recording_fields,
    walk_fields,
    warning_text,
)
from handover_env.person.trajectory import base_trajectory
from handover_eval.calibration import walks
from handover_eval.cli.data import main

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs" / "calibration"
REAL = ROOT.parent / "shared" / "data" / "dynamic_handover_dataset" / "whole_motions"
RATE = 30.0


def _walk(speed: float = 0.8, y: float = -0.9, stop: float = 0.0) -> np.ndarray:
    """A pelvis track from x = 2.5 toward -x along y at ``speed``, standing ``stop`` s at x = 1."""
    xs, x = [], 2.5
    while x > -0.8:
        xs.append(x)
        x -= speed / RATE
        if stop and abs(x - 1.0) < speed / RATE / 2:
            xs += [x] * int(round(stop * RATE))
    return np.column_stack([xs, np.full(len(xs), y)])


def test_fields_of_a_known_walk() -> None:
    f = walk_fields(_walk(0.8, -0.9))
    assert f["speed"] == pytest.approx(0.8, rel=0.01)
    assert f["pass_distance"] == pytest.approx(0.9, abs=1e-3)
    assert f["pause"] == 0.0
    stopped = walk_fields(_walk(0.8, -0.9, stop=1.0))
    # an abrupt 1 s stand, seen through the 1 Hz low-pass: its edges rounded off
    assert 0.6 < stopped["pause"] < 1.1
    pose = np.zeros((len(_walk()), 34, 3))
    pose[:, 0, :2] = _walk()
    pose[:, 12, 2] = 1.40
    assert recording_fields(pose)["height"] == pytest.approx(1.40 / cr.SHOULDER_HEIGHT_RATIO)
    with pytest.raises(ValueError, match="pelvis xy track"):
        walk_fields(np.zeros((5, 2)))
    with pytest.raises(ValueError, match="NaN"):
        walk_fields(np.full((20, 2), np.nan))
    with pytest.raises(ValueError, match="skeleton"):
        recording_fields(np.zeros((20, 3)))


def test_definitions_are_the_walk_statistics_and_the_walkers() -> None:
    assert (cr.SPEED_CUTOFF_HZ, cr.PAUSE_SPEED, cr.PAUSE_MIN_TIME) == (
        walks.SPEED_CUTOFF_HZ, walks.PAUSE_SPEED, walks.PAUSE_MIN_TIME)
    assert cr.SHOULDER_HEIGHT_RATIO == motion.SHOULDER_HEIGHT_RATIO
    for kind, seed in (("id", 3), ("ood", 10_004), ("ood", 10_007)):
        walker = motion.sample_walker(np.random.default_rng(seed), kind)
        xy = base_trajectory(walker, RATE).xy
        ours, theirs = walk_fields(xy), walks.walk_statistics(xy)
        assert ours["speed"] == pytest.approx(theirs["speed_median"])
        assert ours["pause"] == pytest.approx(max(theirs.pause_durations, default=0.0))


def test_check_names_the_field_value_and_range() -> None:
    rng = CalibratedRange(speed=(0.6, 1.1), height=(1.68, 1.76), pass_distance=(0.7, 1.26),
                          pause=(0.0, 1.9))
    assert check({"speed": 0.8, "height": 1.72, "pass_distance": 0.9, "pause": 0.0}, rng) == []
    assert check({"speed": math.nan}, rng) == []  # unknown values are not judged
    outside = check({"speed": 1.6, "height": 1.72, "pause": 2.5}, rng)
    assert outside == [("speed", 1.6, (0.6, 1.1)), ("pause", 2.5, (0.0, 1.9))]
    text = warning_text(outside, "walker (seed 3)")
    assert "walker (seed 3)" in text and "speed" in text and "1.60 m/s outside [0.60, 1.10]" in text
    assert "pause" in text and "calibrated_range.md" in text
    # a value just past a bound reads apart from it
    text = warning_text([("height", 1.7604, (1.68, 1.76))], "walker (seed 4)")
    assert "1.7604 m outside [1.6800, 1.7600]" in text, text
    with pytest.raises(ValueError, match="unknown calibrated-range field"):
        check({"sped": 1.0}, rng)
    with pytest.raises(ValueError, match="low <= high"):
        CalibratedRange(speed=(1.0, 0.5), height=(1.7, 1.8), pass_distance=(0.7, 1.2),
                        pause=(0.0, 1.0))


def test_constants_equal_the_committed_report() -> None:
    report = json.loads((DOCS / "calibrated_range.json").read_text())
    assert {k: list(v) for k, v in CALIBRATED_RANGE.as_dict().items()} == report["range"]
    assert report["quantile_range"] == [cr.LOW_Q, cr.HIGH_Q]


def test_default_walkers_mostly_within_and_a_fast_walker_outside() -> None:
    inside = 0
    for seed in range(40):
        walker = motion.sample_walker(np.random.default_rng(seed), "id")
        fields = {**walk_fields(base_trajectory(walker, RATE).xy), "height": walker.height}
        inside += not check(fields)
    assert inside >= 34  # drawn from the recorded distribution: a few tails fall outside
    walker = motion.sample_walker(np.random.default_rng(5000), "id")
    fast = motion.WalkerParams(**{**walker.__dict__, "speed": 1.6})
    fields = walk_fields(base_trajectory(fast, RATE).xy)
    outside = check(fields)
    assert [name for name, _, _ in outside] == ["speed"]
    assert outside[0][1] == pytest.approx(1.6, rel=0.05)
    assert outside[0][2] == CALIBRATED_RANGE.speed


def test_calibrated_range_cli_on_the_synthetic_generator(tmp_path: Path) -> None:
    folder = write_folder(tmp_path / "whole_motions", n=30)
    out = tmp_path / "calib"
    assert main(["calibrated-range", str(folder), "--out", str(out), "--folds", "2",
                 "--calibration-folds", "1"]) == 0
    report = json.loads((out / "calibrated_range.json").read_text())
    assert report["recordings"] == 30
    within = report["within"]["calibration/all"]
    n_calibration = report["quantiles"]["speed"]["calibration/all"]["n"]
    assert within["all_fields"] == within["n"] == n_calibration
    for name, (lo, hi) in report["range"].items():
        assert lo <= hi, name
    assert 0.5 < report["range"]["speed"][0] < report["range"]["speed"][1] < 1.5
    page = (out / "calibrated_range.md").read_text()
    assert "## The range" in page and "## What the person does outside it" in page
    assert main(["calibrated-range", str(tmp_path / "missing"), "--out", str(out)]) == 2


ABSENT = "the development copy of the public dataset is absent"


@pytest.mark.skipif(not REAL.is_dir(), reason=ABSENT)
def test_the_constants_come_from_the_development_copy() -> None:
    from handover_eval.calibration.calibrated_range import (
        assign_halves,
        derive_range,
        measure_folder,
    )

    rows, skipped = measure_folder(REAL, progress=False)
    assert not skipped and len(rows) == 875
    assign_halves(rows, 10, 0, 5)
    assert derive_range(rows) == CALIBRATED_RANGE
    held = [r for r in rows if not r["calibration"]]
    assert sum(not check({k: r[k] for k in cr.FIELDS}) for r in held) >= 0.97 * len(held)
