"""The recorded receivers' arm at the transfer (``handover-data grasp-height``): where the hand
takes the object, above or below its centre, and the elbow's swivel direction. The heights and
the swivel direction of hand-built arms in closed form (the latter for a walker heading along -x,
so that the walking frame's rotation is exercised), the skips counted, bad input, the command on
recordings built from the synthetic generator, the committed page, and the development copy
(skipped when it is absent)."""

from __future__ import annotations

import json
import math
import pickle
from pathlib import Path

import numpy as np
import pytest
from synthetic_skeletons import skeleton

from handover_env.data import detect
from handover_env.data.public import RIGHT_HAND_JOINT
from handover_env.person.synthetic import generate_synthetic
from handover_eval.calibration.grasp_height import (
    AXES,
    CLEAR_SHARE,
    HAND_NAMES,
    JOINT_NAMES,
    SWIVEL_JOINTS,
    SWIVEL_SKIPS,
    ElbowSwivel,
    TransferHeights,
    elbow_swivel,
    recording_heights,
    swivel_stats,
    transfer_heights,
    walking_frame,
)
from handover_eval.calibration.grasp_height_report import describe, markdown
from handover_eval.cli.data import main

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs" / "calibration"
REAL = ROOT.parent / "shared" / "data" / "dynamic_handover_dataset" / "whole_motions"
#: The constant arm of :func:`_constant_arm`: joint z minus object z, m, and the forearm's rise
#: over its horizontal run (elbow 0.2 m to the side of the wrist, 0.1 m below it).
KNOWN = {"RIGHT_WRIST": -0.10, "RIGHT_HAND": -0.12, "RIGHT_HANDTIP": -0.14, "RIGHT_ELBOW": -0.20}
ELEVATION = math.degrees(math.atan2(0.10, 0.20))
OBJECT_Z = 1.10


def _constant_arm(record: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """A synthetic recording whose object is carried at a constant height and whose right arm's
    joints keep constant heights below it (their horizontal paths are the generator's)."""
    r, o = record["pose_receiver"].copy(), record["pose_object"].copy()
    o[:, 2] = OBJECT_Z
    for name, index in (("RIGHT_WRIST", 14), ("RIGHT_HAND", 15), ("RIGHT_HANDTIP", 16)):
        r[:, index, 2] = OBJECT_Z + KNOWN[name]
    r[:, 17, 2] = OBJECT_Z - 0.13  # thumb: a hand joint the detector also reads
    r[:, 13, :2] = r[:, 14, :2] + np.array([0.0, 0.20])
    r[:, 13, 2] = OBJECT_Z + KNOWN["RIGHT_ELBOW"]
    return {**record, "pose_receiver": r, "pose_object": o}


def _arm_at(frame: int = 3, t: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """A still skeleton and object; at ``frame`` the right arm in a known pose."""
    pose = np.zeros((t, 34, 3))
    obj = np.tile([0.4, -0.5, 1.2], (t, 1))
    pose[frame, 13] = [0.1, -0.5, 1.0]  # elbow: 0.3 m behind the object, 0.2 m below it
    pose[frame, 14] = [0.3, -0.5, 1.1]  # wrist: 0.2 m on, 0.1 m up -> 26.57 deg
    pose[frame, 15] = [0.35, -0.5, 1.12]
    pose[frame, 16] = [0.4, -0.5, 1.25]  # hand tip: above the centre
    return pose, obj


def test_joint_indices_are_body34s() -> None:
    from handover_env.person.skeleton import J

    assert [J[n] for n in JOINT_NAMES] == [14, 15, 16, 13]
    assert (J["RIGHT_ELBOW"], J["RIGHT_WRIST"], J["RIGHT_HAND"]) == (
        detect.R_ELBOW, detect.R_WRIST, detect.R_HAND)
    assert J["RIGHT_HAND"] == RIGHT_HAND_JOINT
    assert [J[n] for n in SWIVEL_JOINTS] == [12, 13, 14] and J["PELVIS"] == 0


def test_heights_of_a_known_arm_in_closed_form() -> None:
    pose, obj = _arm_at()
    h = transfer_heights(pose, obj, 3)
    assert h.height == pytest.approx({"RIGHT_WRIST": -0.1, "RIGHT_HAND": -0.08,
                                      "RIGHT_HANDTIP": 0.05, "RIGHT_ELBOW": -0.2})
    assert h.distance["RIGHT_ELBOW"] == pytest.approx(math.hypot(0.3, 0.2))
    assert h.distance["RIGHT_HANDTIP"] == pytest.approx(0.05)
    assert h.forearm_elevation == pytest.approx(ELEVATION)
    pose[3, 14, 2] = 0.9  # the wrist 0.1 m below the elbow: the forearm falls
    assert transfer_heights(pose, obj, 3).forearm_elevation == pytest.approx(-ELEVATION)
    # the skeleton stands still: no heading, so no swivel direction, and the reason kept
    assert h.swivel is None and h.swivel_skip == "no_heading"


# ---------------------------------------------------------------- the elbow's swivel direction
#: A walker heading along world -x: its forward is (-1, 0, 0), its left (0, -1, 0).
FORWARD, LEFT, UP = np.array([-1.0, 0.0, 0.0]), np.array([0.0, -1.0, 0.0]), np.eye(3)[2]


def _world(local: tuple[float, float, float]) -> np.ndarray:
    """A walking-frame vector (forward, left, up) of the -x walker in world coordinates."""
    return local[0] * FORWARD + local[1] * LEFT + local[2] * UP


def _walker_arm(elbow: tuple[float, float, float], wrist: tuple[float, float, float],
                step: float = 0.1, t: int = 11) -> np.ndarray:
    """A skeleton whose pelvis walks ``step`` m per frame along -x and whose right shoulder is
    at the origin in every frame, the elbow and the wrist given in the walking frame."""
    pose = np.zeros((t, 34, 3))
    pose[:, 0, 0] = -step * np.arange(t)
    pose[:, 0, 2] = 0.93
    pose[:, 13] = _world(elbow)
    pose[:, 14] = _world(wrist)
    return pose


def test_walking_frame_of_a_walker_heading_along_minus_x() -> None:
    axes = walking_frame(_walker_arm((0, 0, -0.3), (0.4, 0, 0)), 5)
    assert axes == pytest.approx(np.array([FORWARD, LEFT, UP]))
    assert np.cross(axes[2], axes[0]) == pytest.approx(axes[1])  # left = up x forward


def test_swivel_direction_of_a_hand_built_arm_in_closed_form() -> None:
    # the wrist straight forward, the elbow below, behind the shoulder and out to the right:
    # the part along the arm (behind) drops out, d = (0, -0.6, -0.8)
    swivel, why = elbow_swivel(_walker_arm((-0.1, -0.15, -0.2), (0.5, 0.0, 0.0)), 5)
    assert why == "" and isinstance(swivel, ElbowSwivel)
    assert swivel.direction == pytest.approx((0.0, -0.6, -0.8))
    assert swivel.reach == pytest.approx((1.0, 0.0, 0.0)) and swivel.reach_length == 0.5
    # the wrist forward and down, u = (0.8, 0, -0.6), the elbow below, behind and right of the
    # shoulder: E - S = (-0.05, -0.05, -0.3), its part along u is 0.14 u = (0.112, 0, -0.084),
    # so perp = (-0.162, -0.05, -0.216): down and back, slightly out to the right
    swivel, why = elbow_swivel(_walker_arm((-0.05, -0.05, -0.3), (0.4, 0.0, -0.3)), 5)
    perp = np.array([-0.162, -0.05, -0.216])
    assert why == ""
    assert swivel.direction == pytest.approx(tuple(perp / np.linalg.norm(perp)))
    assert swivel.reach == pytest.approx((0.8, 0.0, -0.6))
    assert swivel.reach_length == pytest.approx(0.5)
    assert describe(swivel.direction) == "down and back, slightly out to the right"
    assert describe((-0.6, -0.3, -0.742)) == "down, back and out to the right"
    assert describe((0.0, 0.03, 1.0)) == "up"
    # the same arm turned and moved about the world gives the same walking-frame direction
    pose = _walker_arm((-0.05, -0.05, -0.3), (0.4, 0.0, -0.3))
    c, s_ = math.cos(2.0), math.sin(2.0)
    turned = pose @ np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]]).T + [3.0, -1.0, 0.2]
    assert elbow_swivel(turned, 5)[0].direction == pytest.approx(swivel.direction)
    # the heading's window is clipped to the recording: frame 0 sees frames 0 .. 5
    assert elbow_swivel(pose, 0)[0].direction == pytest.approx(swivel.direction)


def test_swivel_skips_are_named() -> None:
    arm = ((-0.05, -0.1, -0.3), (0.3, 0.0, -0.3))
    assert elbow_swivel(_walker_arm(arm[0], (0.0, 0.0, 0.0)), 5) == (None, "wrist_at_shoulder")
    assert elbow_swivel(_walker_arm((0.1, 0.0, -0.1), arm[1]), 5) == (None, "straight_arm")
    assert elbow_swivel(_walker_arm((0.1, 0.0, -0.0995), arm[1]), 5)[1] == "straight_arm"
    assert elbow_swivel(_walker_arm(*arm, step=0.0), 5) == (None, "no_heading")
    # 9 mm a frame: 9 cm over frames 0 .. 10, but only 4.5 cm over the clipped 5 .. 10
    slow = _walker_arm(*arm, step=0.009)
    assert elbow_swivel(slow, 5)[1] == "" and elbow_swivel(slow, 10) == (None, "no_heading")
    assert elbow_swivel(_walker_arm(*arm, step=0.0045), 5) == (None, "no_heading")
    assert set(SWIVEL_SKIPS) == {"wrist_at_shoulder", "straight_arm", "no_heading"}


def test_swivel_stats_in_closed_form_and_the_skips_counted() -> None:
    def heights(swivel: ElbowSwivel | None, skip: str = "") -> TransferHeights:
        return TransferHeights({}, {}, 0.0, swivel, skip)

    group = [heights(ElbowSwivel((1.0, 0.0, 0.0), (0.6, 0.0, -0.8), 0.4)),
             heights(ElbowSwivel((0.0, 1.0, 0.0), (0.8, 0.0, -0.6), 0.5)),
             heights(None, "no_heading"), heights(None, "no_heading"),
             heights(None, "straight_arm")]
    v = swivel_stats(group)
    assert v["n"] == 2
    assert v["skipped"] == {"wrist_at_shoulder": 0, "straight_arm": 1, "no_heading": 2}
    assert v["mean"] == pytest.approx([0.5, 0.5, 0.0])
    assert v["direction"] == pytest.approx([0.7071, 0.7071, 0.0])
    assert v["resultant_length"] == pytest.approx(0.7071)
    assert v["median"] == pytest.approx([0.5, 0.5, 0.0])
    assert v["angle_from_direction_deg"]["p50"] == pytest.approx(45.0, abs=1e-4)
    assert v["shoulder_to_wrist_median"] == pytest.approx([0.7, 0.0, -0.7])
    assert v["shoulder_to_wrist_distance_median"] == pytest.approx(0.45)
    empty = swivel_stats([heights(None, "wrist_at_shoulder")])
    assert empty["n"] == 0 and empty["skipped"]["wrist_at_shoulder"] == 1
    assert empty["direction"] is None and empty["resultant_length"] is None
    assert empty["median"] is None and empty["angle_from_direction_deg"]["n"] == 0


def test_recording_heights_through_the_filter_and_the_detector() -> None:
    """Constant heights pass the filter unchanged, so at whichever frame the transfer is
    detected the heights are the known ones."""
    detected = 0
    for ep in generate_synthetic(6, 0.0, seed=0, progress=False):
        rec = _constant_arm(skeleton(ep))
        h, failure = recording_heights(rec["pose_receiver"], rec["pose_object"])
        if h is None:
            assert failure in detect.FAILURES
            continue
        assert h.height == pytest.approx(KNOWN, abs=1e-9)
        assert h.forearm_elevation == pytest.approx(ELEVATION, abs=1e-6)
        detected += 1
    assert detected >= 4


def test_bad_input_is_one_clear_value_error() -> None:
    pose, obj = _arm_at()
    cases = [
        ((pose[:, :33], obj, 3), r"receiver must have shape \(T, 34, 3\)"),
        ((pose[0], obj, 3), r"receiver must have shape \(T, 34, 3\)"),
        ((pose, obj[:, :2], 3), r"obj must have shape \(T, 3\)"),
        ((pose, obj[:-1], 3), "disagree in length"),
        ((pose[:0], obj[:0], 0), "T >= 1"),
        ((pose, obj, 6), "outside the recording"),
        ((pose, obj, -1), "outside the recording"),
        ((pose, obj, True), "frame index"),
        ((pose, obj, 2.0), "frame index"),
        (([["a"]], obj, 3), "array of numbers"),
    ]
    for args, message in cases:
        with pytest.raises(ValueError, match=message):
            transfer_heights(*args)
    bad = pose.copy()
    bad[1, 20, 0] = np.nan
    with pytest.raises(ValueError, match="receiver has NaN/inf"):
        transfer_heights(bad, obj, 3)
    with pytest.raises(ValueError, match="receiver has NaN/inf"):
        recording_heights(bad, obj)
    bad_obj = obj.copy()
    bad_obj[0, 2] = np.inf
    with pytest.raises(ValueError, match="obj has NaN/inf"):
        recording_heights(pose, bad_obj)
    with pytest.raises(ValueError, match="need at least"):
        recording_heights(pose, obj)  # 6 frames: too short to detect a transfer in
    for args, message in [
        ((pose[:, :33], 3), r"receiver must have shape \(T, 34, 3\)"),
        ((pose[:0], 0), "T >= 1"),
        ((bad, 3), "receiver has NaN/inf"),
        ((pose, 6), "outside the recording"),
        ((pose, -1), "outside the recording"),
        ((pose, True), "frame index"),
        ((pose, 1.0), "frame index"),
        (([["a"]], 3), "array of numbers"),
    ]:
        with pytest.raises(ValueError, match=message):
            elbow_swivel(*args)


def test_grasp_height_cli_on_recordings_of_known_heights(tmp_path: Path,
                                                         capsys: pytest.CaptureFixture) -> None:
    folder = tmp_path / "whole_motions"
    folder.mkdir()
    counts = {"normal": 0, "variation": 0}
    for ep in generate_synthetic(24, 0.25, seed=0, progress=False):
        kind = "variation" if ep.is_ood else "normal"
        (folder / f"motion_{kind}_{counts[kind]}.pkl").write_bytes(
            pickle.dumps(_constant_arm(skeleton(ep)), protocol=4))
        counts[kind] += 1
    out = tmp_path / "calib"
    assert main(["grasp-height", str(folder), "--out", str(out), "--folds", "2",
                 "--calibration-folds", "1"]) == 0
    printed = capsys.readouterr().out
    assert "calibration (n = " in printed and "held-out (n = " in printed
    report = json.loads((out / "grasp_height.json").read_text())
    assert report["recordings"] == 24 and report["skipped_files"] == 0
    det = report["detection"]
    assert det["calibration/all"]["recordings"] + det["held_out/all"]["recordings"] == 24
    for half in ("calibration", "held_out"):
        assert det[f"{half}/all"]["transfer"] >= 5
        for name in JOINT_NAMES:
            v = report["height"][name][f"{half}/all"]
            assert v["share_below"] == 1.0 and v["below"] == v["n"]
            assert v["p5"] == v["p50"] == v["p95"] == pytest.approx(KNOWN[name], abs=1e-4)
        fore = report["forearm_elevation"][f"{half}/all"]
        assert fore["p50"] == pytest.approx(ELEVATION, abs=1e-4)
        assert fore["share_wrist_above_elbow"] == 1.0
    det_all = {h: det[f"{h}/all"]["transfer"] for h in ("calibration", "held_out")}
    pole = report["elbow_pole"]
    assert pole["axes"] == list(AXES)
    for half in ("calibration", "held_out"):
        assert set(pole[half]) == {"id", "ood", "pooled"}
        v = pole[half]["pooled"]
        assert v["n"] + sum(v["skipped"].values()) == det_all[half]
        assert v["n"] == pole[half]["id"]["n"] + pole[half]["ood"]["n"] >= 5
        assert np.linalg.norm(v["direction"]) == pytest.approx(1.0, abs=1e-3)
        assert 0.0 < v["resultant_length"] <= 1.0
    assert "elbow swivel direction (forward, left, up" in printed
    page = (out / "grasp_height.md").read_text()
    assert "**The recorded receivers took the object from below its centre.**" in page
    assert "## The elbow's swivel direction at the transfer" in page
    assert "Caveat: only the side is used" in page
    assert page == markdown(report)  # the page is the JSON's
    assert main(["grasp-height", str(tmp_path / "missing"), "--out", str(out)]) == 2


def test_the_committed_page_is_its_json_and_states_the_evidence() -> None:
    report = json.loads((DOCS / "grasp_height.json").read_text())
    assert (DOCS / "grasp_height.md").read_text() == markdown(report)
    for half in ("calibration", "held_out"):
        for name in HAND_NAMES:
            assert report["height"][name][f"{half}/all"]["share_below"] >= CLEAR_SHARE
            assert report["height"][name][f"{half}/all"]["p95"] < 0.0
    # the elbow: down and back, concentrated, the same in both halves, and the page says where
    # the pole's JSON is
    pole = report["elbow_pole"]
    directions = {}
    for half in ("calibration", "held_out"):
        for kind in ("id", "ood", "pooled"):
            v = pole[half][kind]
            assert v["n"] >= 30
            assert np.linalg.norm(v["direction"]) == pytest.approx(1.0, abs=1e-3)
            forward, _left, up = v["direction"]
            assert forward < -0.3 and up < -0.5 and v["resultant_length"] > 0.8
        directions[half] = np.array(pole[half]["pooled"]["direction"])
        assert (pole[half]["pooled"]["n"] + sum(pole[half]["pooled"]["skipped"].values())
                == report["detection"][f"{half}/all"]["transfer"])
    assert directions["calibration"] @ directions["held_out"] > math.cos(math.radians(5.0))
    assert "`elbow_pole.calibration.pooled.direction`" in (DOCS / "grasp_height.md").read_text()
    # the transfers are transfer-stats' own: the same detector on the same filtered tracks
    stats = json.loads((DOCS / "receiver_calibration.json").read_text())
    for group in ("calibration/all", "held_out/all"):
        assert report["detection"][group]["transfer"] == stats["detection"][group]["transfer"]


# ----------------------------------------------------------------------- the real dataset
ABSENT = "the development copy of the public dataset is absent"


def _close(a: object, b: object, path: str = "") -> None:
    """``a == b``, floats to the 4th decimal the JSON is rounded to (one unit of it apart at a
    rounding boundary)."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), path
        for k in a:
            _close(a[k], b[k], f"{path}/{k}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _close(x, y, f"{path}/{i}")
    elif isinstance(a, float) and not isinstance(b, bool):
        assert b == pytest.approx(a, abs=1.5e-4), path
    else:
        assert a == b, path


@pytest.mark.skipif(not REAL.is_dir(), reason=ABSENT)
def test_the_committed_numbers_come_from_the_development_copy() -> None:
    from handover_eval.calibration.grasp_height import assign_halves, measure_folder, summarise

    rows, skipped = measure_folder(REAL, progress=False)
    assert not skipped and len(rows) == 875
    # the prototype of the elbow's swivel direction, over every other file of both halves
    proto = swivel_stats([r.heights for r in rows[::2] if r.heights is not None])
    assert proto["mean"] == pytest.approx([-0.528, -0.134, -0.769], abs=6e-4)
    assert proto["median"] == pytest.approx([-0.554, -0.138, -0.802], abs=6e-4)
    assert proto["shoulder_to_wrist_median"] == pytest.approx([0.746, -0.462, -0.461], abs=6e-4)
    assert proto["shoulder_to_wrist_distance_median"] == pytest.approx(0.431, abs=6e-4)
    assign_halves(rows, 10, 0, 5)
    derived = json.loads(json.dumps(summarise(rows, source=REAL.name)))
    committed = json.loads((DOCS / "grasp_height.json").read_text())
    _close(committed["elbow_pole"], derived["elbow_pole"], "/elbow_pole")
    _close(committed, derived)
