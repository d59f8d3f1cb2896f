"""Transfer, reach-onset and release detectors, the track filter, the calibration split and report.

The detectors run on synthetic recordings built here with a known reach onset, transfer, giver
release and slow-down; one test checks the development copy of the public dataset (skipped when
it is absent).
"""

from __future__ import annotations

import json
import math
import pickle
from pathlib import Path

import numpy as np
import pytest

from handover_env.data.dataset import HandoverDataset, stratified_fold_ids
from handover_env.data.detect import (
    check_recording,
    detect_reach_onset,
    detect_transfer,
    to_body_frame,
    walking_frame,
)
from handover_env.data.filtering import hampel, lowpass, smooth_track
from handover_env.person.synthetic import generate_synthetic
from handover_eval.calibration.measures import analyse_recording
from handover_eval.calibration.release import detect_release
from handover_eval.calibration.report import analyse_file, assign_halves
from handover_eval.cli.data import build_parser, main

RATE = 30.0
REAL = (
    Path(__file__).resolve().parents[2].parent
    / "shared" / "data" / "dynamic_handover_dataset" / "whole_motions"
)
OBJECT = np.array([0.55, -0.55, 1.35])
GRASP_OFFSET = np.array([0.0, -0.10, 0.0])  # hand 10 cm on the receiver's side of the object


def _min_jerk(u: np.ndarray) -> np.ndarray:
    u = np.clip(u, 0.0, 1.0)
    return u**3 * (10 - 15 * u + 6 * u**2)


def _world(pelvis: np.ndarray, body: np.ndarray) -> np.ndarray:
    """Body (forward, left, up) -> world for a receiver walking toward -x (left = -y)."""
    return pelvis + np.stack([-body[..., 0], -body[..., 1], body[..., 2]], axis=-1)


def recording(
    n: int = 130,
    onset: int = 55,
    transfer: int = 70,
    release: int = 100,
    back: int = 110,
    speed: float = 0.8,
    slow: float = 0.0,
    carried_from: int | None = None,
    never_near: bool = False,
    object_stays: bool = False,
) -> dict[str, np.ndarray]:
    """A receiver walking toward -x who reaches for a still object and takes it at ``transfer``.

    ``slow`` dips the walking speed by that fraction around the transfer (Gaussian, sigma 0.5 s).
    ``carried_from`` makes the object travel with the receiver from that frame while the hand
    stays 0.35 m from it until the transfer. ``object_stays`` leaves the object where it is.
    """
    i = np.arange(n)
    v = speed * (1.0 - slow * np.exp(-0.5 * ((i - transfer) / (0.5 * RATE)) ** 2))
    x_at = np.concatenate([[0.0], np.cumsum((v[1:] + v[:-1]) / 2) / RATE])
    x = 0.85 + (x_at[transfer] - x_at)  # pelvis x is 0.85 at the transfer
    pelvis = np.stack([x, np.full(n, -0.9), np.full(n, 0.92)], axis=1)
    t = i / RATE
    # arm swing: forward at the stride frequency, up and down at the step frequency with a trough
    # at the onset (the bottom from which a reach starts is otherwise ambiguous within a swing)
    bob = -0.06 - 0.01 * np.cos(2 * np.pi * 1.6 * (t - onset / RATE))
    walk_hand = np.stack([0.08 * np.sin(2 * np.pi * 0.8 * t), np.full(n, -0.27), bob], axis=1)
    hand = _world(pelvis, walk_hand)
    target = OBJECT + GRASP_OFFSET
    s = _min_jerk((i - onset) / (transfer - onset))[:, None]
    reach = slice(onset, transfer + 1)
    hand[reach] = (1 - s[reach]) * hand[reach] + s[reach] * target
    hold_body = to_body_frame(target, pelvis[transfer], np.array([-1.0, 0.0]))
    drawn = _min_jerk((i - back) / 10.0)[:, None]
    near_body = np.array([0.10, -0.25, 0.10])
    body_after = (1 - drawn) * hold_body + drawn * near_body
    hand[transfer:] = _world(pelvis[transfer:], body_after[transfer:])
    obj = np.repeat(OBJECT[None], n, axis=0)
    if not (object_stays or never_near):
        obj[transfer:] = hand[transfer:] - GRASP_OFFSET
    if carried_from is not None:
        # the object travels with the receiver from carried_from on; the tracked hand stays 0.35 m
        # from it and closes in to the grasp only over the 8 frames before the transfer
        obj[carried_from:] = OBJECT + (pelvis[carried_from:] - pelvis[carried_from])
        far = obj + np.array([0.0, -0.35, 0.0])
        w = _min_jerk((i - carried_from) / 8.0)[:, None]
        close = _min_jerk((i - transfer + 8) / 8.0)[:, None]
        grip = (1 - close) * far + close * (obj + GRASP_OFFSET)
        hand = (1 - w) * _world(pelvis, walk_hand) + w * grip
    if never_near:
        hand = _world(pelvis, walk_hand)
    receiver = _world(pelvis[:, None], np.tile([0.0, 0.0, 0.3], (n, 34, 1)))
    receiver[:, 0] = pelvis
    receiver[:, 12] = _world(pelvis, np.array([0.0, -0.17, 0.48]))
    receiver[:, 13] = _world(pelvis, np.array([0.0, -0.20, 0.20]))
    offsets = {
        14: (0.04, 0.0, 0.02),
        15: (0.0, 0.0, 0.0),
        16: (0.0, 0.0, -0.06),
        17: (0.0, 0.04, 0.0),
    }
    for j, off in offsets.items():
        receiver[:, j] = hand + np.array(off)
    giver_pelvis = np.array([-0.1, 0.0, 0.8])
    giver = np.tile(giver_pelvis, (n, 34, 1))
    giver[:, 7:11] = giver_pelvis + np.array([0.0, 0.3, 0.2])
    holding = obj + np.array([0.15, 0.10, 0.0])
    away = _min_jerk((i - release) / 15.0)[:, None] * np.array([0.2, 0.5, -0.2])  # lets go in 0.5 s
    giver[:, 14:18] = np.where((i < release)[:, None], holding, holding[release] + away)[:, None, :]
    return {"pose_receiver": receiver, "pose_object": obj, "pose_giver": giver}


# ----------------------------------------------------------------------------- the filter
def test_filter_removes_a_spike_keeps_a_slow_signal() -> None:
    t = np.arange(150) / RATE
    slow = np.stack([0.2 * np.sin(2 * np.pi * 0.5 * t), 0.8 * t], axis=1)
    spiky = slow.copy()
    spiky[60, 0] += 0.5
    cleaned, outliers = hampel(spiky)
    assert outliers[60, 0] and outliers.sum() == 1
    out = smooth_track(spiky, RATE)
    assert out.shape == spiky.shape
    assert np.abs(out - slow).max() < 0.01
    assert abs(out[60, 0] - slow[60, 0]) < 0.01
    ramp = np.stack([0.8 * t, -0.3 * t + 1.0], axis=1)  # a steady walk stays exactly linear
    np.testing.assert_allclose(smooth_track(ramp, RATE), ramp, atol=1e-9)


def test_filter_is_zero_phase_and_cuts_high_frequencies() -> None:
    t = np.arange(300) / RATE
    gait = np.sin(2 * np.pi * 1.0 * t)
    out = lowpass(gait, RATE)
    inner = slice(60, 240)
    lags = np.arange(-5, 6)
    corr = [np.dot(out[inner], np.roll(gait, lag)[inner]) for lag in lags]
    assert lags[int(np.argmax(corr))] == 0
    jitter = np.sin(2 * np.pi * 6.0 * t)
    assert np.abs(lowpass(jitter, RATE)[inner]).max() < 0.01
    skeleton = np.random.default_rng(0).standard_normal((90, 34, 3))
    assert smooth_track(skeleton, RATE).shape == (90, 34, 3)


def test_filter_rejects_bad_input() -> None:
    x = np.zeros((50, 3))
    x[10, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        smooth_track(x, RATE)
    with pytest.raises(ValueError, match="T >= 3"):
        smooth_track(np.zeros(2), RATE)
    with pytest.raises(ValueError, match="cutoff_hz"):
        smooth_track(np.zeros((50, 3)), RATE, cutoff_hz=20.0)
    with pytest.raises(ValueError, match="real numbers"):
        smooth_track(np.array(["a", "b", "c"]), RATE)


# -------------------------------------------------------------------------- the detectors
@pytest.mark.parametrize("smooth", [False, True])
def test_detects_transfer_onset_release(smooth: bool) -> None:
    rec = recording()
    r, o, g = rec["pose_receiver"], rec["pose_object"], rec["pose_giver"]
    a = analyse_recording(r, o, g, RATE, smooth=smooth)
    # the min-jerk reach is within 2 cm of its end 2 frames early, where the hand stops closing in
    assert a.failure == "" and abs(a.events["transfer"] - 70) <= 2
    assert abs(a.events["onset"] - 55) <= 2
    assert abs(a.events["release"] - 100) <= 2
    assert 110 <= a.events["arm_back"] <= 120
    m = a.measures
    assert m["pelvis_x_transfer"] == pytest.approx(0.85, abs=0.06)  # 0.8 m/s x 2 frames
    assert m["object_z_transfer"] == pytest.approx(1.35, abs=0.01)
    assert m["object_fwd_transfer"] == pytest.approx(0.30, abs=0.06)  # 0.85 - 0.55
    assert m["object_lat_transfer"] == pytest.approx(-0.35, abs=0.02)  # to the receiver's right
    assert m["hand_lat_transfer"] == pytest.approx(-0.25, abs=0.02)
    assert m["d15_transfer"] == pytest.approx(0.10, abs=0.02)
    assert m["hold_duration"] == pytest.approx(1.0, abs=0.1)
    assert m["prereach_speed"] == pytest.approx(0.8, abs=0.02)
    assert m["min_rel_speed"] == pytest.approx(1.0, abs=0.03) and abs(m["time_lost"]) < 0.03
    assert abs(m["lateral_deviation"]) < 0.01
    assert m["ttc_onset"] == pytest.approx(
        m["object_shoulder_fwd_onset"] / m["walking_speed_onset"]
    )


def test_object_speed_and_jerk_at_transfer_are_the_tracks_differences() -> None:
    """A constant jerk c along x from 10 frames before the transfer: the third difference of the
    unsmoothed track is c h^3 exactly, and numpy's central gradient of the cubic c t^3 / 6 is
    c t^2 / 2 + c h^2 / 6."""
    rec = recording()
    r, o, g = rec["pose_receiver"], rec["pose_object"].copy(), rec["pose_giver"]
    k0, c, h = 60, 0.5, 1.0 / RATE
    t = np.clip(np.arange(o.shape[0]) - k0, 0, None) * h
    o[:, 0] += c * t**3 / 6.0
    a = analyse_recording(r, o, g, RATE, smooth=False)
    k = a.events["transfer"]
    assert k - 3 >= k0
    m = a.measures
    assert m["object_jerk_transfer"] == pytest.approx(c, rel=1e-6)
    assert m["object_jerk_transfer_raw"] == pytest.approx(c, rel=1e-6)
    tk = (k - k0) * h
    assert m["object_speed_transfer"] == pytest.approx(c * tk**2 / 2 + c * h**2 / 6, rel=1e-9)


def test_slowdown_is_measured() -> None:
    rec = recording(slow=0.5)
    a = analyse_recording(rec["pose_receiver"], rec["pose_object"], rec["pose_giver"], RATE)
    assert abs(a.events["transfer"] - 70) <= 2
    i = np.arange(130)
    rel = 1.0 - 0.5 * np.exp(-0.5 * ((i - 70) / 15.0) ** 2)
    truth_lost = float(np.sum(1.0 - rel[40:85]) / RATE)
    assert a.measures["min_rel_speed"] == pytest.approx(0.5, abs=0.05)
    assert a.measures["time_lost"] == pytest.approx(truth_lost, abs=0.05)


def test_no_transfer_and_why() -> None:
    never = recording(never_near=True)
    d = detect_transfer(never["pose_receiver"], never["pose_object"], RATE)
    assert d.frame is None and d.category == "never_near" and "never within" in d.reason
    left = recording(object_stays=True)
    d = detect_transfer(left["pose_receiver"], left["pose_object"], RATE)
    assert d.frame is None and d.category in ("not_held", "not_comoving")
    carried = recording(carried_from=20)
    d = detect_transfer(carried["pose_receiver"], carried["pose_object"], RATE)
    assert d.frame is None and d.category == "carried_before"


def test_onset_release_edge_cases() -> None:
    rec = recording()
    assert detect_reach_onset(rec["pose_receiver"], 5, RATE).frame is None
    giver = rec["pose_giver"].copy()
    giver[:, 14:18] = rec["pose_object"][:, None] + np.array([0.15, 0.1, 0.0])  # never lets go
    release, why = detect_release(giver, rec["pose_object"], 70, RATE)
    assert release is None and "to the end" in why


def test_walking_frame_and_body_frame() -> None:
    n = 60
    pelvis = np.stack([np.linspace(2.0, 0.0, n), np.full(n, -0.9)], axis=1)
    w = walking_frame(pelvis, RATE)
    np.testing.assert_allclose(w.forward, np.tile([-1.0, 0.0], (n, 1)), atol=1e-6)
    np.testing.assert_allclose(w.left, np.tile([0.0, -1.0], (n, 1)), atol=1e-6)
    assert np.median(w.speed) == pytest.approx(2.0 / (n - 1) * RATE, rel=1e-3)
    body = to_body_frame(
        np.array([0.5, -0.5, 1.3]), np.array([1.0, -0.9, 0.9]), np.array([-1.0, 0.0])
    )
    np.testing.assert_allclose(body, [0.5, -0.4, 0.4])
    still = walking_frame(np.zeros((40, 2)), RATE)
    assert np.isnan(still.forward).all()


def test_detectors_reject_bad_input() -> None:
    rec = recording()
    r, o = rec["pose_receiver"], rec["pose_object"]
    with pytest.raises(ValueError, match=r"\(T, 34, 3\)"):
        detect_transfer(r[:, :33], o, RATE)
    with pytest.raises(ValueError, match=r"\(T, 3\)"):
        detect_transfer(r, o[:, :2], RATE)
    with pytest.raises(ValueError, match="disagree"):
        detect_transfer(r, o[:-1], RATE)
    bad = o.copy()
    bad[3, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        analyse_recording(r, bad)
    with pytest.raises(ValueError, match="at least"):
        check_recording(r[:10], o[:10])
    with pytest.raises(ValueError, match="rate_hz"):
        check_recording(r, o, rate_hz=0.0)


# ----------------------------------------------------------------------- split and report
def test_fold_ids_are_table_one_folds() -> None:
    data = generate_synthetic(40, 0.25, seed=3, progress=False)
    folds = stratified_fold_ids(data.ood_mask, 5, seed=0)
    for f, (_, test) in enumerate(data.stratified_kfold(5, seed=0)):
        np.testing.assert_array_equal(np.flatnonzero(folds == f), test)
    assert isinstance(data, HandoverDataset)


def _write_folder(folder: Path, n_id: int = 3, n_ood: int = 2) -> Path:
    folder.mkdir()
    for kind, count in (("normal", n_id), ("variation", n_ood)):
        for j in range(count):
            rec = recording(transfer=70 + 2 * j, onset=55 + 2 * j)
            quat = np.tile([1.0, 0.0, 0.0, 0.0], (rec["pose_object"].shape[0], 1))
            blob = pickle.dumps({**rec, "quat_object": quat}, protocol=4)
            (folder / f"motion_{kind}_{j}.pkl").write_bytes(blob)
    return folder


def test_transfer_stats_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit, match="^0$") as exc:
        build_parser().parse_args(["transfer-stats", "--help"])
    assert exc.value.code == 0 and "--calibration-folds" in capsys.readouterr().out
    folder = _write_folder(tmp_path / "whole_motions")
    out = tmp_path / "calib"
    argv = [
        "transfer-stats",
        str(folder),
        "--out",
        str(out),
        "--folds",
        "2",
        "--calibration-folds",
        "1",
    ]
    assert main([*argv, "--no-figures"]) == 0
    summary = json.loads((out / "receiver_calibration.json").read_text())
    assert summary["detection"]["all/all"]["transfer"] == 5
    assert summary["groups"]["calibration/all"] + summary["groups"]["held_out/all"] == 5
    q = summary["quantiles"]["pelvis_x_transfer"]["all/all"]
    assert q["n"] == 5 and q["p50"] == pytest.approx(0.85, abs=0.05)
    text = (out / "receiver_calibration.md").read_text()
    assert "## Detection counts" in text and "held-out OOD" in text and "| 5 (100.0 %) |" in text
    assert not (out / "aligned_on_transfer.png").exists()
    assert main(["transfer-stats", str(tmp_path / "missing"), "--out", str(out)]) == 2


def test_figures(tmp_path: Path) -> None:
    from handover_eval.calibration.figures import write_figures

    results = [analyse_file(p) for p in sorted(_write_folder(tmp_path / "whole_motions").iterdir())]
    assign_halves(results, folds=2, calibration_folds=1)
    paths = write_figures(results, tmp_path / "figs")
    assert [p.name for p in paths] == ["aligned_on_transfer.png", "reach_onset.png"]
    assert all(p.stat().st_size > 10_000 for p in paths)


# ----------------------------------------------------------------------- the real dataset
@pytest.mark.skipif(
    not REAL.is_dir(), reason="the development copy of the public dataset is absent"
)
def test_real_recordings_mostly_get_a_transfer() -> None:
    from handover_env.data.public import list_public_files

    files = list_public_files(REAL)
    ood = [p for p in files if p.name.startswith("motion_variation_")]
    chosen = [p for p in files if p not in ood][:48] + ood[:12]
    results = [analyse_file(p) for p in chosen]
    detected = [r for r in results if r.analysis.events["transfer"] is not None]
    assert len(detected) >= 0.9 * len(results)
    med = {
        k: np.nanmedian([r.analysis.measures[k] for r in detected])
        for k in (
            "pelvis_x_transfer",
            "object_z_transfer",
            "hold_duration",
            "reach_duration",
            "d15_transfer",
        )
    }
    assert 0.5 < med["pelvis_x_transfer"] < 1.3 and 1.2 < med["object_z_transfer"] < 1.5
    assert 0.5 < med["hold_duration"] < 1.6 and 0.3 < med["reach_duration"] < 1.0
    assert med["d15_transfer"] < 0.3
    assign_halves(results, folds=2, calibration_folds=1)
    assert {r.calibration for r in results} == {True, False}


@pytest.mark.skipif(
    not REAL.is_dir(), reason="the development copy of the public dataset is absent"
)
def test_the_left_behind_rule_never_fires_before_a_recorded_transfer() -> None:
    """Issue 23: the simulated person's left-behind rule, run on recorded OOD walks (the recorded
    shoulder path as the person's remaining walk), never declares an object left behind before
    the recorded transfer; the pause/turn-back measures see the OOD walks' pauses and turns."""
    from handover_env.data.public import list_public_files

    ood = [p for p in list_public_files(REAL) if p.name.startswith("motion_variation_")][:20]
    results = [analyse_file(p) for p in ood]
    detected = [r.analysis.measures for r in results if r.analysis.events["transfer"] is not None]
    assert len(detected) >= 18
    assert all(math.isnan(m["left_behind"]) for m in detected)
    assert max(m["max_turn"] for m in detected) > 90.0  # some OOD receivers turn round
    assert np.median([m["path_closest_onset"] for m in detected]) < 0.6
