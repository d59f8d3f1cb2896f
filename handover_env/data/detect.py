"""When and where the object changes hands in a recorded handover, and how the hand gets there.

Pure numpy detectors over one recording of the public Dynamic Handover Dataset (paper Sec. IV-A,
"Data Collection"): the receiver's ZED BODY_34 skeleton ``(T, 34, 3)``, the object (OptiTrack)
``(T, 3)`` and, optionally, the giver's skeleton, at 30 Hz. They feed the calibration of the
simulated receiver (issue 12, section 2; DESIGN.md "The simulated person") and give a replayed
person their own reach (:mod:`handover_env.person.take`). Every threshold is a module constant,
chosen from the 875-recording development copy as noted beside it. The inputs should already be
smoothed (:func:`handover_env.data.filtering.smooth_track`; the calibration's
``analyse_recording`` does that). The giver's release and the arm drawn back, which only the
calibration reads, are :mod:`handover_eval.calibration.release`'s.

What the recordings show, and so what is detected (aligned medians over the development copy):
the giver offers the object, the receiver's right hand rises about 0.37 m within about 0.4 s and
arrives at the object; from then on the object travels with the receiver while the giver's hand
stays on it for a further ~1.2 s (a *shared hold*: the giver turns with the receiver), then the
giver lets go and the receiver carries the object on. Hence three events:

* **transfer** (:func:`detect_transfer`): the receiver's hand arrives at the object and takes it.
  Rule: take the first frame at which the nearest right-hand joint (14 wrist, 15 hand, 16 tip,
  17 thumb; ZED hand joints are noisy by ~0.1 m, so the nearest of the four) is within
  :data:`NEAR_RADIUS` of the object and stays within :data:`HOLD_RADIUS` for :data:`HOLD_TIME`;
  from there, the transfer is the first frame at which the hand stops closing in (the distance
  falls slower than :data:`ARRIVAL_SPEED`), i.e. the end of the reach; and the object must then
  move with the receiver: over :data:`COMOVE_TIME` its mean velocity along the receiver's walking
  direction is at least :data:`COMOVE_FRACTION` of the receiver's walking speed, and it must not
  have travelled with the receiver for more than :data:`MAX_LEAD_TIME` already. A fixed
  distance alone would fire at different points of the approach, because the ZED-OptiTrack hand
  offset at contact varies between recordings (0.05 .. 0.3 m); the end of the approach does not.
  The object's own motion corroborates it: it starts to follow the receiver 1 frame before the
  detected arrival (median; 25-75 %: 5 frames before .. 3 after).
* **release** (``handover_eval.calibration.release.detect_release``): the giver lets go: the
  giver's nearest hand joint leaves its holding distance to the object for good.
* **reach onset** (:func:`detect_reach_onset`): the start of the final rise of the right hand
  (joint 15) above its walking height; **arm back** (``release.detect_arm_back``): after the
  release, the hand is drawn back to its walking distance from the body.

Body frame (:func:`walking_frame`, :func:`to_body_frame`): origin at the pelvis, x forward along
the walking direction (from the pelvis velocity low-passed below the stride frequency), y to the
receiver's left, z up. The receiver's right side faces the giver, so the object has a negative y.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handover_env.data.filtering import lowpass

RATE_HZ = 30.0
PELVIS, R_SHOULDER, R_ELBOW, R_WRIST, R_HAND = 0, 12, 13, 14, 15
#: Right wrist, hand, hand tip, thumb: the receiver's hand is the nearest of these to the object.
HAND_JOINTS = (14, 15, 16, 17)
#: Both hands of the giver (left 7-10, right 14-17): whichever holds the object.
GIVER_HAND_JOINTS = (7, 8, 9, 10, 14, 15, 16, 17)
#: Shoulder -> elbow -> wrist -> hand: the arm whose length normalises the reach.
ARM_CHAIN = (12, 13, 14, 15)

# Transfer. Data: 99 % of the recordings come within 0.30 m; the distance at the end of the
# approach is 0.14 m (median), 0.07 .. 0.26 (5-95 %); the approach runs at ~1.5 m/s at 0.30 m.
NEAR_RADIUS = 0.30  # m
HOLD_RADIUS = 0.40  # m
HOLD_TIME = 0.4  # s
ARRIVAL_SPEED = 0.3  # m/s
# In the 0.5 s after arrival the object moves along the walk at 0.81 x the walking speed
# (median; 1 %: 0.36), so 0.3 only rejects a hand that hovers by an object that stays behind.
COMOVE_TIME = 0.5  # s
COMOVE_FRACTION = 0.3
# An object that has already travelled with the receiver (>= half the walking speed along the walk)
# for over 1 s when the tracked hand arrives was taken earlier by a hand the ZED tracks too far from
# it (12 of 875 recordings; the lead is 0.03 s median, 0.53 s at 95 %): no reliable transfer frame.
LEAD_FRACTION = 0.5
MAX_LEAD_TIME = 1.0  # s

# Walking frame: the pelvis velocity is low-passed below the stride frequency (~0.8 Hz) for the
# heading, so the gait's lateral sway does not swing it, and below the step frequency (~1.6 Hz)
# for the walking speed, so the tracker's step-rate speed oscillation does not count as slowing.
HEADING_CUTOFF_HZ = 0.5
SPEED_CUTOFF_HZ = 1.0
MIN_HEADING_SPEED = 0.1  # m/s: slower than this, the last heading is held

# Reach onset. The walking baseline of the hand height ends 1 s before the transfer (95 % of reaches
# are shorter); the hand rises 0.37 m (median; 5 %: 0.24) above it by the transfer.
BASELINE_GAP = 1.0  # s
MIN_BASELINE_FRAMES = 8
ONSET_RISE = 0.05  # m above the walking median
# From the last frame below ONSET_RISE, step back to where the rise began (the local minimum of
# the hand height), at most this far: a bell-shaped reach has risen 5 cm ~2-3 frames in.
ONSET_BACKTRACK = 0.3  # s



@dataclass(frozen=True)
class TransferDetection:
    """Result of :func:`detect_transfer`.

    Attributes:
        frame: the transfer frame, or None.
        near_frame: the frame at which the hand came within :data:`NEAR_RADIUS` (None if never).
        reason: why there is no transfer, in words ("" when there is one).
        category: the same as one of :data:`FAILURES` ("" when there is a transfer).
        distance: (T,) nearest right-hand joint to object distance, m.
    """

    frame: int | None
    near_frame: int | None
    reason: str
    category: str
    distance: np.ndarray


#: Why a recording gets no transfer: category -> description (the last check a candidate failed).
FAILURES: dict[str, str] = {
    "never_near": f"the tracked hand never comes within {NEAR_RADIUS:.2f} m of the object",
    "near_at_end": f"the hand comes within {NEAR_RADIUS:.2f} m only in the last {HOLD_TIME:g} s",
    "not_held": f"the hand comes near but does not stay within {HOLD_RADIUS:.2f} m for "
                f"{HOLD_TIME:g} s",
    "not_comoving": "the object does not move with the receiver after the hand arrives",
    "carried_before": f"the object travels with the receiver over {MAX_LEAD_TIME:g} s before the "
    "tracked hand arrives (hand tracked too far from it)",
}


@dataclass(frozen=True)
class WalkingFrame:
    """The receiver's walking frame per frame: unit ``forward`` and ``left`` (T, 2), ``speed``
    (T,)."""

    forward: np.ndarray
    left: np.ndarray
    speed: np.ndarray


def check_recording(
    receiver: np.ndarray, obj: np.ndarray, giver: np.ndarray | None = None, rate_hz: float = RATE_HZ
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Validate one recording's arrays; returns them as float64.

    Raises:
        ValueError: a shape other than (T, 34, 3) / (T, 3), unequal lengths, fewer than
            ``2 * HOLD_TIME`` seconds of frames, NaN/inf, or a non-positive rate.
    """
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f"rate_hz must be a positive number, got {rate_hz!r}")
    arrays = {"receiver": receiver, "object": obj, "giver": giver}
    shapes = {"receiver": (34, 3), "object": (3,), "giver": (34, 3)}
    out: dict[str, np.ndarray] = {}
    for name, value in arrays.items():
        if value is None:
            continue
        arr = np.asarray(value, dtype=np.float64)
        if arr.ndim != 1 + len(shapes[name]) or arr.shape[1:] != shapes[name]:
            want = "(T, " + ", ".join(map(str, shapes[name])) + ")"
            raise ValueError(f"{name} must have shape {want}, got {np.shape(value)}")
        if not np.isfinite(arr).all():
            raise ValueError(f"{name} has NaN/inf values; smooth or fill the track first")
        out[name] = arr
    lengths = {name: arr.shape[0] for name, arr in out.items()}
    if len(set(lengths.values())) != 1:
        raise ValueError(f"arrays disagree in length (frames): {lengths}")
    need = int(np.ceil(2 * HOLD_TIME * rate_hz)) + 2
    if lengths["receiver"] < need:
        raise ValueError(
            f"need at least {need} frames at {rate_hz:g} Hz, got {lengths['receiver']}"
        )
    return out["receiver"], out["object"], out.get("giver")


def nearest_distance(points: np.ndarray, obj: np.ndarray) -> np.ndarray:
    """(T,) distance from the object (T, 3) to the nearest of ``points`` (T, J, 3)."""
    return np.linalg.norm(points - obj[:, None, :], axis=2).min(axis=1)


def walking_frame(pelvis_xy: np.ndarray, rate_hz: float = RATE_HZ) -> WalkingFrame:
    """Walking direction and speed from the pelvis track (T, 2).

    The heading is the direction of the pelvis velocity low-passed at :data:`HEADING_CUTOFF_HZ`;
    where that speed is below :data:`MIN_HEADING_SPEED` the last heading is held (the first
    valid heading is used before it). The speed is the norm of the velocity low-passed at
    :data:`SPEED_CUTOFF_HZ`. A receiver that never walks gets a NaN heading.
    """
    xy = np.asarray(pelvis_xy, dtype=np.float64)
    slow = np.gradient(lowpass(xy, rate_hz, HEADING_CUTOFF_HZ), axis=0) * rate_hz
    fast = np.gradient(lowpass(xy, rate_hz, SPEED_CUTOFF_HZ), axis=0) * rate_hz
    norm = np.linalg.norm(slow, axis=1)
    valid = norm > MIN_HEADING_SPEED
    if not valid.any():
        nan = np.full_like(xy, np.nan)
        return WalkingFrame(nan, nan, np.linalg.norm(fast, axis=1))
    index = np.where(valid, np.arange(norm.size), -1)
    index = np.maximum.accumulate(index)
    index[index < 0] = int(np.argmax(valid))
    forward = slow[index] / norm[index, None]
    left = np.stack([-forward[:, 1], forward[:, 0]], axis=1)
    return WalkingFrame(forward, left, np.linalg.norm(fast, axis=1))


def to_body_frame(
    points: np.ndarray, pelvis: np.ndarray, forward: np.ndarray
) -> np.ndarray:
    """Express world points (..., 3) in the body frame (forward, left, up) at the pelvis (..., 3).

    ``forward`` (..., 2) is the unit walking direction; the up axis is world z, so the third
    coordinate is the height above the pelvis.
    """
    rel = np.asarray(points, dtype=np.float64) - pelvis
    f = np.asarray(forward, dtype=np.float64)
    fwd = rel[..., 0] * f[..., 0] + rel[..., 1] * f[..., 1]
    lat = -rel[..., 0] * f[..., 1] + rel[..., 1] * f[..., 0]
    return np.stack([fwd, lat, rel[..., 2]], axis=-1)


def detect_transfer(
    receiver: np.ndarray,
    obj: np.ndarray,
    rate_hz: float = RATE_HZ,
    walking: WalkingFrame | None = None,
) -> TransferDetection:
    """The frame at which the receiver's hand arrives at the object and takes it (module docstring).

    Candidates are tried in time order; the first that passes every check is the transfer.

    Args:
        receiver: (T, 34, 3) receiver skeleton (smoothed).
        obj: (T, 3) object position (smoothed the same way).
        rate_hz: frame rate.
        walking: the receiver's :func:`walking_frame` (computed when omitted).
    """
    receiver, obj, _ = check_recording(receiver, obj, None, rate_hz)
    walking = walking_frame(receiver[:, PELVIS, :2], rate_hz) if walking is None else walking
    distance = nearest_distance(receiver[:, list(HAND_JOINTS)], obj)
    closing = -np.gradient(distance) * rate_hz
    n = distance.size
    hold = int(round(HOLD_TIME * rate_hz))
    comove = int(round(COMOVE_TIME * rate_hz))
    obj_vel = np.gradient(obj[:, :2], axis=0) * rate_hz
    along = np.einsum("ij,ij->i", obj_vel, walking.forward)
    near = np.flatnonzero(distance <= NEAR_RADIUS)
    if near.size == 0:
        reason = f"hand never within {NEAR_RADIUS:.2f} m (closest {distance.min():.2f} m)"
        return TransferDetection(None, None, reason, "never_near", distance)
    reason, category = "", ""
    for k in near:
        if k + hold >= n:
            if not reason:
                reason, category = FAILURES["near_at_end"], "near_at_end"
            break
        if not (distance[k : k + hold + 1] <= HOLD_RADIUS).all():
            reason, category = FAILURES["not_held"], "not_held"
            continue
        stops = np.flatnonzero(closing[k : k + hold + 1] < ARRIVAL_SPEED)
        frame = int(k + stops[0]) if stops.size else int(k + np.argmin(distance[k : k + hold + 1]))
        speed = np.nanmedian(walking.speed[: frame + 1])
        window = slice(frame, min(n, frame + comove + 1))
        moving = float(np.mean(along[window]))
        if not np.isfinite(moving) or moving < COMOVE_FRACTION * speed:
            reason = (
                f"object does not move with the receiver after the hand arrives "
                f"({moving:.2f} m/s along the walk vs walking {speed:.2f} m/s)"
            )
            category = "not_comoving"
            continue
        carried = along[: frame + 1] >= LEAD_FRACTION * speed
        lead = frame + 1 - (np.flatnonzero(~carried)[-1] + 1 if (~carried).any() else 0)
        if lead > MAX_LEAD_TIME * rate_hz:
            reason = (
                f"object already travels with the receiver {lead / rate_hz:.1f} s before the "
                f"tracked hand arrives (hand tracked too far from the object)"
            )
            category = "carried_before"
            continue
        return TransferDetection(frame, int(k), "", "", distance)
    return TransferDetection(None, int(near[0]), reason, category, distance)


def baseline_slice(transfer: int, rate_hz: float) -> slice:
    """Frames of walking before the reach: from the start to 1 s before the transfer (>= 8
    frames)."""
    return slice(0, max(MIN_BASELINE_FRAMES, transfer - int(round(BASELINE_GAP * rate_hz))))


def hand_height(receiver: np.ndarray) -> np.ndarray:
    """(T,) height of the right hand (joint 15) above the pelvis, m."""
    return receiver[:, R_HAND, 2] - receiver[:, PELVIS, 2]


@dataclass(frozen=True)
class ReachOnset:
    """Result of :func:`detect_reach_onset`.

    Attributes:
        frame: the onset (the bottom from which the hand rises to the object), or None.
        rise_frame: the last frame before the transfer with the hand at most
            :data:`ONSET_RISE` above its walking height (the start of the fast part), or None.
        reason: why there is no onset ("" when there is one).
    """

    frame: int | None
    rise_frame: int | None
    reason: str


def detect_reach_onset(receiver: np.ndarray, transfer: int, rate_hz: float = RATE_HZ) -> ReachOnset:
    """The reach onset: where the hand's final rise from its walking height toward the object
    begins.

    The walking height is the median hand height above the pelvis over :func:`baseline_slice`.
    Take the last frame before ``transfer`` at which the hand is at most :data:`ONSET_RISE` above
    it (``rise_frame``), then step back (at most :data:`ONSET_BACKTRACK`) while the frame before
    is lower still: the onset is the bottom from which the hand rises to the object. None when the
    transfer comes too early for a walking baseline or the hand does not rise.
    """
    if transfer <= MIN_BASELINE_FRAMES:
        return ReachOnset(
            None, None, f"transfer at frame {transfer}: no walking baseline before it"
        )
    height = hand_height(receiver)
    base = float(np.median(height[baseline_slice(transfer, rate_hz)]))
    if height[transfer] - base < ONSET_RISE:
        return ReachOnset(None, None, "the hand does not rise above its walking height")
    rise = int(np.flatnonzero(height[:transfer] <= base + ONSET_RISE)[-1])
    onset = rise
    stop = max(0, onset - int(round(ONSET_BACKTRACK * rate_hz)))
    while onset > stop and height[onset - 1] < height[onset]:
        onset -= 1
    return ReachOnset(onset, rise, "")


def arm_length(receiver: np.ndarray) -> float:
    """Median over frames of the shoulder-elbow-wrist-hand bone lengths (12 -> 13 -> 14 -> 15),
    m."""
    bones = np.diff(receiver[:, list(ARM_CHAIN)], axis=1)
    return float(np.median(np.linalg.norm(bones, axis=2).sum(axis=1)))
