"""Camera-model figures recomputed from the recordings (skips without the development copy).

Nothing from the dataset is stored: every figure is recomputed here and compared with the
"paper" camera profile and with the camera model's output on scripted walkers.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from handover_env.person.motion import sample_walker
from handover_env.person.trajectory import base_trajectory
from handover_env.sensors import Camera, make_profile
from handover_eval.calibration.sensing import sensing_figures, track_jitter
from handover_eval.cli.data import main

REAL = Path(os.environ.get("HANDOVER_PUBLIC_DIR", "") or (
    Path(__file__).resolve().parents[2].parent
    / "shared" / "data" / "dynamic_handover_dataset" / "whole_motions"
))
needs_data = pytest.mark.skipif(
    not REAL.is_dir(), reason="public dataset copy not found at ../shared/data"
)


def test_sensing_command_refuses_a_folder_without_recordings(tmp_path, capsys):
    assert main(["sensing", str(tmp_path)]) == 2
    assert "no motion_normal_<i>.pkl" in capsys.readouterr().err


@needs_data
def test_sensing_command_prints_the_figures(capsys):
    assert main(["sensing", str(REAL), "--limit", "5"]) == 0
    out = capsys.readouterr().out
    assert "ID recordings: 5" in out and "pelvis jitter" in out and "mm" in out


@pytest.fixture(scope="module")
def figures() -> dict[str, float]:
    return sensing_figures(REAL)


@needs_data
def test_simulated_pelvis_jitter_matches_the_recordings(figures):
    """Acceptance: the same statistic (track_jitter) within 20 % on a walker's smooth track."""
    params = make_profile("paper").camera
    rng = np.random.default_rng(0)
    seen = []
    for i in range(40):
        tr = base_trajectory(sample_walker(rng, "id"))
        cam = Camera(params).reset(np.random.default_rng(1000 + i))
        seen.append(np.array([cam.frame(float(t), {"pelvis": xy}).points["pelvis"]
                              for t, xy in zip(tr.t, tr.xy)]))
    model, recorded = track_jitter(seen), figures["pelvis_jitter"]
    print(f"pelvis jitter: recordings {1000 * recorded:.2f} mm, camera model {1000 * model:.2f} mm")
    assert model == pytest.approx(recorded, rel=0.2)


@needs_data
def test_paper_camera_profile_quotes_the_recordings(figures):
    cam = make_profile("paper").camera
    assert figures["recordings"] >= 700 and figures["repeated_frames"] == 0
    assert cam.pelvis_sigma == pytest.approx(figures["pelvis_sigma"], rel=0.05)
    assert cam.hand_sigma == pytest.approx(figures["hand_sigma"], rel=0.05)
    assert cam.hand_rho == pytest.approx(figures["hand_rho"], abs=0.02)
    assert cam.lost_fraction == pytest.approx(figures["refit_fraction"], rel=0.1)
    assert cam.lost_run == pytest.approx(figures["refit_mean_run"], rel=0.1)
    assert 0.5 < figures["pelvis_lag1"] < 0.95  # why the pelvis noise is not an AR(1) fit
