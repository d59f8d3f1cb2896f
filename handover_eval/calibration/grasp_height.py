"""The recorded receivers' right arm at the transfer: where their hand took the object (above or
below its centre) and where they held the elbow (its swivel direction off the shoulder-wrist
line) (``handover-data grasp-height PATH/whole_motions --out docs/calibration``).

Why this exists:

* the hand's side: the simulated person's modelled hand is to take the bottle by its **lower
  part** (below the robot gripper's pads, approached from below) instead of its top part; that
  change is the env's switch ``grasp_below`` (``handover_env/person/settings.py``,
  :class:`~handover_env.person.settings.ReceiverConfig`), and this command is the recorded
  evidence it cites (``docs/calibration/grasp_height.md``);
* the elbow's direction: the simulated person's two-link arm IK
  (``handover_env/person/posing.py``, ``arm_kernel``) places the elbow in the plane of the
  shoulder-wrist line and a "pole" direction given in the torso frame (x forward, y left, z up).
  That pole was (0, -0.35, -1) normalised, down and out to the right, an uncited choice; for a
  folded arm (an object taken close to the body) it swung the elbow out toward the robot, past
  the gripper, where the recordings hold it down and back. The pole is to become the calibration
  half's normalised mean swivel direction measured here (JSON
  ``elbow_pole.calibration.pooled.direction``, ``[forward, left, up]``).

:func:`run_grasp_height`

1. loads every recording of the folder with the safe loader, as ``reach-spread`` does
   (:func:`~handover_env.data.public.safe_load_pickle`, numpy arrays only;
   :func:`~handover_env.data.public.validate_record`), filters the receiver's skeleton and the
   object's track as a replay does (:func:`~handover_env.data.filtering.smooth_track` at 30 Hz)
   and detects the transfer on them (:func:`~handover_env.data.detect.detect_transfer`, the
   frame ``transfer-stats`` and ``reach-spread`` use);
2. at that frame measures (:func:`transfer_heights`) the height (z) of the receiver's right-arm
   BODY_34 joints (:data:`JOINT_NAMES`: wrist, hand, hand tip, elbow; indices from
   :data:`handover_env.person.skeleton.J`) relative to the object's recorded position
   (``pose_object``, an episode's ``giver_xyz``: the object's mocap position, which the env
   treats as the bottle's centre), each joint's distance from it, and the forearm's elevation
   (elbow to wrist, degrees above horizontal);
3. at the same frame measures the elbow's swivel direction (:func:`elbow_swivel`): with S, E, W
   the right shoulder, elbow and wrist (:data:`SWIVEL_JOINTS`), ``u = (W - S) / |W - S|`` and
   ``perp = (E - S) - ((E - S) . u) u``, the direction is ``d = perp / |perp|``, expressed in
   the receiver's walking frame at the transfer: forward = the unit horizontal direction of the
   pelvis's (joint 0) xy displacement from frame ``f - 5`` to ``f + 5`` (clipped to the
   recording), up = world z, left = up x forward. A recording is skipped, and counted, when
   ``|W - S|`` or ``|perp|`` is under 1 mm (:data:`MIN_REACH`, :data:`MIN_PERP`: no plane to
   speak of) or the pelvis moved less than 5 cm over those frames (:data:`MIN_HEADING`: no
   heading);
4. splits the recordings into Table I's halves (:func:`~handover_eval.calibration.report.
   table1_folds` over every file in :func:`~handover_env.data.public.list_public_files` order,
   10 folds, seed 0: folds 0-4 calibrate, 5-9 are held out), as ``reach-spread`` does;
5. writes ``grasp_height.json`` and ``grasp_height.md``: per joint and group (calibration /
   held-out half, ID / OOD / pooled) n, the 5/25/50/75/95 % quantiles
   (:func:`~handover_eval.calibration.report.quantiles`) and the share of recordings with the
   joint below the object's centre; the forearm elevation's quantiles; per group the elbow's
   swivel direction (``elbow_pole``: n and the skips, the normalised mean direction with the
   mean resultant length R, the mean unit vector, the per-component median, the angle of each
   direction from the normalised mean, and the median shoulder-to-wrist direction and distance);
   the detection counts.

The ZED hand joints are noisy (about 0.1 m; :mod:`handover_env.data.detect`) and sit well off
the object at the transfer, so the page uses only the side of the centre the hand was on, not
the exact height. The same noise is in the shoulder, elbow and wrist, so one recording's swivel
direction says little; the pole is an average over several hundred recordings (R tells how
concentrated they are). Only statistics over recordings leave this module; no per-recording
value is written.
"""

from __future__ import annotations

import math
import os
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from handover_env.data.detect import RATE_HZ, detect_transfer
from handover_env.data.errors import DatasetError
from handover_env.data.filtering import smooth_track
from handover_env.data.public import (
    OOD_PREFIX,
    safe_load_pickle,
    validate_record,
)
from handover_env.person.skeleton import J
from handover_eval.calibration.report import (
    DEFAULT_CALIBRATION_FOLDS,
    DEFAULT_FOLDS,
    DEFAULT_SEED,
    QUANTILES,
    measure_files,
    quantiles,
    table1_folds,
)

JSON_NAME, MD_NAME = "grasp_height.json", "grasp_height.md"
COMMAND = "handover-data grasp-height PATH/whole_motions --out docs/calibration"
#: The receiver's right-arm joints measured (BODY_34 names of :data:`~.skeleton.J`): the three
#: hand joints first, then the elbow.
JOINT_NAMES = ("RIGHT_WRIST", "RIGHT_HAND", "RIGHT_HANDTIP", "RIGHT_ELBOW")
HAND_NAMES = JOINT_NAMES[:3]
SHORT = {"RIGHT_WRIST": "wrist", "RIGHT_HAND": "hand", "RIGHT_HANDTIP": "hand tip",
         "RIGHT_ELBOW": "elbow"}
GROUPS = ("calibration/id", "calibration/ood", "calibration/all",
          "held_out/id", "held_out/ood", "held_out/all")
#: The page calls the hand "below the centre" when each hand joint is below it in at least this
#: share of the recordings of both halves.
CLEAR_SHARE = 0.95
SKELETON_SHAPE = (len(J), 3)
#: The joints of the elbow's swivel direction (BODY_34 names of :data:`~.skeleton.J`): S, E, W.
SWIVEL_JOINTS = ("RIGHT_SHOULDER", "RIGHT_ELBOW", "RIGHT_WRIST")
#: The pelvis joint whose horizontal displacement gives the walking frame's forward axis.
PELVIS = "PELVIS"
#: The walking frame's axes, in the order of every direction's components.
AXES = ("forward", "left", "up")
#: Frames either side of the transfer over which the pelvis's displacement gives the heading.
HEADING_HALF_WINDOW = 5
#: Least horizontal pelvis displacement over that window for a heading, m.
MIN_HEADING = 0.05
#: Least shoulder-to-wrist distance and least elbow offset from that line, m.
MIN_REACH = 1e-3
MIN_PERP = 1e-3
#: Why a recording with a transfer has no swivel direction (the keys of the skip counts).
SWIVEL_SKIPS = ("wrist_at_shoulder", "straight_arm", "no_heading")
#: The simulated arm's pole before this page (torso frame: x forward, y left, z up), not
#: normalised; quoted on the page for comparison.
OLD_POLE = (0.0, -0.35, -1.0)
HALVES = ("calibration", "held_out")
KINDS = {"id": "id", "ood": "ood", "pooled": "all"}  # elbow_pole's key -> the group's kind


@dataclass(frozen=True)
class ElbowSwivel:
    """One recording's right arm at the transfer, in the walking frame (:data:`AXES`), in
    memory only (never written).

    Attributes:
        direction: the unit direction of the elbow off the shoulder-wrist line, ``d``.
        reach: the unit shoulder-to-wrist direction, ``u``.
        reach_length: ``|W - S|``, m.
    """

    direction: tuple[float, float, float]
    reach: tuple[float, float, float]
    reach_length: float


@dataclass(frozen=True)
class TransferHeights:
    """One recording's arm at the transfer, in memory only (never written).

    Attributes:
        height: joint name -> its z minus the object's z, m (negative: below the centre).
        distance: joint name -> its distance from the object's position, m.
        forearm_elevation: the elbow-to-wrist direction's angle above horizontal, degrees.
        swivel: the elbow's swivel direction (:func:`elbow_swivel`), or None when skipped...
        swivel_skip: ...for this reason (one of :data:`SWIVEL_SKIPS`; "" with a direction).
    """

    height: dict[str, float]
    distance: dict[str, float]
    forearm_elevation: float
    swivel: ElbowSwivel | None = None
    swivel_skip: str = ""


@dataclass
class HeightRow:
    """One recording: its kind, its heights (None without a transfer), its half."""

    is_ood: bool
    heights: TransferHeights | None
    failure: str = ""
    calibration: bool = False


def _array(name: str, value: object, tail: tuple[int, ...]) -> np.ndarray:
    """``value`` as a finite float64 array of shape ``(T, *tail)``, T >= 1 (else ValueError)."""
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be an array of numbers: {exc}") from exc
    if arr.ndim != 1 + len(tail) or arr.shape[1:] != tail or arr.shape[0] == 0:
        want = "(T, " + ", ".join(map(str, tail)) + ")"
        raise ValueError(f"{name} must have shape {want} with T >= 1, got {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} has NaN/inf values")
    return arr


def _frame_index(frame: object, length: int) -> int:
    """``frame`` as an index into ``length`` frames (else ValueError)."""
    if isinstance(frame, bool) or not isinstance(frame, (int, np.integer)):
        raise ValueError(f"frame must be a frame index (int), got {frame!r}")
    if not 0 <= int(frame) < length:
        raise ValueError(f"frame {frame} is outside the recording (0 .. {length - 1})")
    return int(frame)


def check_tracks(receiver: np.ndarray, obj: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The receiver's skeleton ``(T, 34, 3)`` and the object's track ``(T, 3)`` as float64.

    Raises:
        ValueError: another shape, unequal lengths, no frame, or NaN/inf (one message naming
            the array and the problem).
    """
    r, o = _array("receiver", receiver, SKELETON_SHAPE), _array("obj", obj, (3,))
    if r.shape[0] != o.shape[0]:
        raise ValueError(f"receiver and obj disagree in length: {r.shape[0]} and "
                         f"{o.shape[0]} frames")
    return r, o


def walking_frame(receiver: np.ndarray, frame: int) -> np.ndarray | None:
    """The receiver's walking frame at ``frame``: rows forward, left, up (world coordinates),
    or None when the pelvis moved less than :data:`MIN_HEADING` horizontally between frames
    ``frame -/+ HEADING_HALF_WINDOW`` (clipped to the recording).

    Args:
        receiver: (T, 34, 3) skeleton, already checked; ``frame`` a valid index.
    """
    pelvis = receiver[:, J[PELVIS], :2]
    a = max(frame - HEADING_HALF_WINDOW, 0)
    b = min(frame + HEADING_HALF_WINDOW, receiver.shape[0] - 1)
    step = pelvis[b] - pelvis[a]
    length = float(np.hypot(step[0], step[1]))
    if length < MIN_HEADING:
        return None
    fx, fy = step / length
    # left = up x forward = (0, 0, 1) x (fx, fy, 0)
    return np.array([[fx, fy, 0.0], [-fy, fx, 0.0], [0.0, 0.0, 1.0]])


def elbow_swivel(receiver: np.ndarray, frame: int) -> tuple[ElbowSwivel | None, str]:
    """The elbow's swivel direction at ``frame`` in the walking frame (module docstring, step 3).

    Args:
        receiver: (T, 34, 3) receiver skeleton, BODY_34, metres, z up.
        frame: the transfer frame, 0 <= frame < T.

    Returns:
        ``(swivel, "")``, or ``(None, reason)`` with a reason of :data:`SWIVEL_SKIPS`:
        ``wrist_at_shoulder`` (``|W - S| <`` :data:`MIN_REACH`), ``straight_arm`` (the elbow
        within :data:`MIN_PERP` of the shoulder-wrist line), ``no_heading``
        (:func:`walking_frame`).

    Raises:
        ValueError: a bad skeleton or a frame outside the recording.
    """
    receiver = _array("receiver", receiver, SKELETON_SHAPE)
    f = _frame_index(frame, receiver.shape[0])
    s, e, w = (receiver[f, J[name]] for name in SWIVEL_JOINTS)
    reach = w - s
    reach_length = float(np.linalg.norm(reach))
    if reach_length < MIN_REACH:
        return None, "wrist_at_shoulder"
    u = reach / reach_length
    perp = (e - s) - float(np.dot(e - s, u)) * u
    perp_length = float(np.linalg.norm(perp))
    if perp_length < MIN_PERP:
        return None, "straight_arm"
    axes = walking_frame(receiver, f)
    if axes is None:
        return None, "no_heading"
    d, u_local = axes @ (perp / perp_length), axes @ u
    return ElbowSwivel(tuple(map(float, d)), tuple(map(float, u_local)), reach_length), ""


def transfer_heights(receiver: np.ndarray, obj: np.ndarray, frame: int) -> TransferHeights:
    """The right arm's joints against the object at ``frame`` (module docstring, step 2) and
    the elbow's swivel direction there (step 3, :func:`elbow_swivel`).

    Args:
        receiver: (T, 34, 3) receiver skeleton, BODY_34, metres, z up.
        obj: (T, 3) object position (the bottle's centre).
        frame: the transfer frame, 0 <= frame < T.

    Raises:
        ValueError: bad arrays (:func:`check_tracks`) or a frame outside the recording.
    """
    receiver, obj = check_tracks(receiver, obj)
    frame = _frame_index(frame, obj.shape[0])
    at, o = receiver[frame], obj[frame]
    height = {name: float(at[J[name], 2] - o[2]) for name in JOINT_NAMES}
    distance = {name: float(np.linalg.norm(at[J[name]] - o)) for name in JOINT_NAMES}
    forearm = at[J["RIGHT_WRIST"]] - at[J["RIGHT_ELBOW"]]
    elevation = math.degrees(math.atan2(float(forearm[2]), float(np.hypot(*forearm[:2]))))
    swivel, skip = elbow_swivel(receiver, frame)
    return TransferHeights(height, distance, elevation, swivel, skip)


def recording_heights(
    receiver: np.ndarray, obj: np.ndarray, rate_hz: float = RATE_HZ
) -> tuple[TransferHeights | None, str]:
    """Filter one recording's tracks, detect its transfer and measure the arm there.

    Returns:
        ``(heights, "")``, or ``(None, category)`` when no transfer is detected (a category of
        :data:`handover_env.data.detect.FAILURES`).

    Raises:
        ValueError: bad arrays (:func:`check_tracks`) or too short a recording to detect in.
    """
    receiver, obj = check_tracks(receiver, obj)
    r, o = smooth_track(receiver, rate_hz), smooth_track(obj, rate_hz)
    detection = detect_transfer(r, o, rate_hz)
    if detection.frame is None:
        return None, detection.category
    return transfer_heights(r, o, detection.frame), ""


def measure_folder(
    folder: str | os.PathLike, *, skip_bad: bool = False, progress: bool = True
) -> tuple[list[HeightRow], list[tuple[str, str]]]:
    """One :class:`HeightRow` per recording of ``folder`` (in :func:`list_public_files` order),
    and the skipped files as ``(name, reason)``."""
    def measure(path: Path) -> HeightRow:
        record = validate_record(safe_load_pickle(path), str(path))
        try:
            heights, failure = recording_heights(record["pose_receiver"], record["pose_object"])
        except ValueError as exc:
            raise DatasetError(f"{path}: cannot measure: {exc}") from exc
        return HeightRow(path.name.startswith(OOD_PREFIX), heights, failure)

    return measure_files(folder, measure, desc="grasp-height", skip_bad=skip_bad,
                         progress=progress)


def assign_halves(rows: list[HeightRow], folds: int, seed: int, calibration_folds: int) -> None:
    """Set each row's half: Table I folds ``0 .. calibration_folds - 1`` calibrate (over every
    recording, with a transfer or not, so that the split is Table I's)."""
    fold_of = table1_folds([r.is_ood for r in rows], folds, seed, calibration_folds)
    for row, fold in zip(rows, fold_of, strict=True):
        row.calibration = bool(fold < calibration_folds)


def _group(rows: list[HeightRow], name: str) -> list[HeightRow]:
    half, kind = name.split("/")
    return [r for r in rows if r.calibration == (half == "calibration")
            and (kind == "all" or r.is_ood == (kind == "ood"))]


def _height_stats(values: np.ndarray) -> dict:
    below = int((values < 0.0).sum())
    return {**quantiles(values), "below": below,
            "share_below": round(below / values.size, 4) if values.size else None}


def _vector(v: np.ndarray) -> list[float]:
    return [round(float(x), 4) for x in v]


def swivel_stats(heights: Sequence[TransferHeights]) -> dict:
    """The elbow's swivel statistics of one group's recordings with a transfer (the entry of
    ``elbow_pole``; components in :data:`AXES` order): n, the skips by reason, the normalised
    mean direction ``direction`` with the mean resultant length ``resultant_length`` (the norm
    of the mean of the unit directions: 1 when all are the same, near 0 when they scatter),
    the mean unit vector ``mean``, the per-component ``median``, the quantiles of each
    direction's angle from ``direction`` (degrees), and the median shoulder-to-wrist direction
    and distance (None without a direction)."""
    swivels = [h.swivel for h in heights if h.swivel is not None]
    skipped = Counter(h.swivel_skip for h in heights if h.swivel is None)
    out: dict = {"n": len(swivels), "skipped": {k: skipped.get(k, 0) for k in SWIVEL_SKIPS}}
    d = np.array([s.direction for s in swivels], dtype=np.float64).reshape(-1, 3)
    mean = d.mean(axis=0) if swivels else np.full(3, np.nan)
    r = float(np.linalg.norm(mean)) if swivels else float("nan")
    ok = math.isfinite(r) and r > 0.0
    direction = mean / r if ok else None
    angles = (np.degrees(np.arccos(np.clip(d @ direction, -1.0, 1.0))) if ok
              else np.empty(0))
    reach = np.array([s.reach for s in swivels], dtype=np.float64).reshape(-1, 3)
    length = np.array([s.reach_length for s in swivels], dtype=np.float64)
    return {
        **out,
        "direction": _vector(direction) if ok else None,
        "resultant_length": round(r, 4) if math.isfinite(r) else None,
        "mean": _vector(mean) if swivels else None,
        "median": _vector(np.median(d, axis=0)) if swivels else None,
        "angle_from_direction_deg": quantiles(angles),
        "shoulder_to_wrist_median": _vector(np.median(reach, axis=0)) if swivels else None,
        "shoulder_to_wrist_distance_median": (round(float(np.median(length)), 4) if swivels
                                              else None),
    }


def summarise(
    rows: list[HeightRow],
    *,
    source: str = "",
    folds: int = DEFAULT_FOLDS,
    seed: int = DEFAULT_SEED,
    calibration_folds: int = DEFAULT_CALIBRATION_FOLDS,
    skipped: Sequence[tuple[str, str]] = (),
) -> dict:
    """The JSON-able summary (module docstring).

    Raises:
        ValueError: no recording of the calibration half has a detected transfer.
    """
    groups = {g: _group(rows, g) for g in GROUPS}
    measured = {g: [r.heights for r in m if r.heights is not None] for g, m in groups.items()}
    if not measured["calibration/all"]:
        raise ValueError("no recording of the calibration half has a detected transfer: nothing "
                         "to measure")

    def column(g: str, pick) -> np.ndarray:
        return np.array([pick(h) for h in measured[g]], dtype=np.float64)

    elevation = {}
    for g in GROUPS:
        v = column(g, lambda h: h.forearm_elevation)
        rising = int((v > 0.0).sum())
        elevation[g] = {**quantiles(v), "wrist_above_elbow": rising,
                        "share_wrist_above_elbow": round(rising / v.size, 4) if v.size else None}
    return {
        "command": COMMAND,
        "source": source,
        "recordings": len(rows),
        "skipped_files": len(skipped),
        "skipped": [list(item) for item in skipped],
        "rate_hz": RATE_HZ,
        "split": {
            "method": "Table I stratified folds (handover_env.data.dataset.stratified_fold_ids) "
                      "over the files in list_public_files order",
            "folds": folds, "seed": seed,
            "calibration_folds": list(range(calibration_folds)),
            "held_out_folds": list(range(calibration_folds, folds)),
        },
        "method": "receiver skeleton and object track filtered with "
                  "handover_env.data.filtering.smooth_track(x, 30.0); transfer frame from "
                  "handover_env.data.detect.detect_transfer; heights = joint z - object z there; "
                  "elbow swivel direction d = perp / |perp|, perp = (E - S) - ((E - S).u) u, "
                  "u = (W - S) / |W - S| (S, E, W: right shoulder, elbow, wrist there), in the "
                  "walking frame there",
        "joints": {name: J[name] for name in JOINT_NAMES},
        "quantiles": [f"p{q}" for q in QUANTILES],
        "detection": {
            g: {"recordings": len(m), "transfer": len(measured[g]),
                "no_transfer": dict(sorted(Counter(r.failure for r in m
                                                   if r.heights is None).items()))}
            for g, m in groups.items()
        },
        "height": {name: {g: _height_stats(column(g, lambda h, n=name: h.height[n]))
                          for g in GROUPS} for name in JOINT_NAMES},
        "distance": {name: {g: quantiles(column(g, lambda h, n=name: h.distance[n]))
                            for g in GROUPS} for name in JOINT_NAMES},
        "forearm_elevation": elevation,
        "elbow_pole": {
            "axes": list(AXES),
            "frame": f"the receiver's walking frame at the transfer frame f: forward = the unit "
                     f"horizontal direction of the pelvis's (joint {J[PELVIS]}) xy displacement "
                     f"from frame f-{HEADING_HALF_WINDOW} to f+{HEADING_HALF_WINDOW} (clipped "
                     f"to the recording), up = world z, left = up x forward",
            "joints": {name: J[name] for name in (*SWIVEL_JOINTS, PELVIS)},
            "skip_rules": {
                "wrist_at_shoulder": f"|W - S| < {MIN_REACH} m",
                "straight_arm": f"|perp| < {MIN_PERP} m",
                "no_heading": f"pelvis xy displacement over the frames < {MIN_HEADING} m",
            },
            "old_pole": {"value": list(OLD_POLE),
                         "direction": _vector(np.array(OLD_POLE) / np.linalg.norm(OLD_POLE))},
            **{half: {key: swivel_stats(measured[f"{half}/{kind}"])
                      for key, kind in KINDS.items()} for half in HALVES},
        },
    }


__all__ = [
    "ElbowSwivel",
    "HeightRow",
    "TransferHeights",
    "assign_halves",
    "check_tracks",
    "elbow_swivel",
    "measure_folder",
    "recording_heights",
    "summarise",
    "swivel_stats",
    "transfer_heights",
    "walking_frame",
]
