"""Per-recording quantities for the receiver calibration (issue 12, section 2), from the events of
:mod:`handover_env.data.detect`.

:func:`analyse_recording` smooths one recording with
:func:`~handover_env.data.filtering.smooth_track`,
detects transfer, reach onset, giver release and arm-back, and returns every quantity of
:data:`MEASURES` (NaN where its events are missing). :func:`track_noise` measures the recorded
tracks' speed spikes and jumps before and after the filter. Body-frame coordinates are (forward,
left, up-from-pelvis) as in :func:`~handover_env.data.detect.to_body_frame`; heights
labelled "above pelvis" add the pelvis height (``pelvis_z_transfer``) to become heights above the
floor.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from handover_env.data.detect import (
    GIVER_HAND_JOINTS,
    HEADING_CUTOFF_HZ,
    PELVIS,
    R_HAND,
    R_SHOULDER,
    RATE_HZ,
    WalkingFrame,
    arm_length,
    baseline_slice,
    check_recording,
    detect_reach_onset,
    detect_transfer,
    hand_height,
    nearest_distance,
    to_body_frame,
    walking_frame,
)
from handover_env.data.filtering import lowpass, smooth_track
from handover_eval.calibration.decisions import WALK_MEASURES, walk_measures
from handover_eval.calibration.release import detect_arm_back, detect_release

#: Slow-down window around the transfer, s (before, after).
SLOWDOWN_WINDOW = (1.0, 0.5)
#: Window around the transfer in which a replayed recorded hand may close on the object, s.
GRASP_WINDOW = (0.2, 0.5)
#: Window of the figures' aligned traces around the transfer, s (before, after).
TRACE_WINDOW = (2.0, 1.5)
#: Track noise: a pelvis faster than this (m/s) or a hand step longer than this (m/frame) is a
#: spike.
PELVIS_SPIKE_SPEED = 2.0
HAND_JUMP = 0.10

#: name -> (section, label, unit). The report prints them in this order.
MEASURES: dict[str, tuple[str, str, str]] = {
    "transfer_time": ("timing", "transfer: time from the start of the recording", "s"),
    "transfer_fraction": ("timing", "transfer: time / recording length", ""),
    "reach_duration": ("timing", "reach duration (onset to transfer)", "s"),
    "fast_reach_duration": ("timing", "hand 5 cm above walking height to transfer", "s"),
    "hold_duration": ("timing", "shared hold (transfer to the giver's release)", "s"),
    "release_time": ("timing", "giver release: time from the start", "s"),
    "release_fraction": ("timing", "giver release: time / recording length", ""),
    "after_release": ("timing", "recording left after the release", "s"),
    "nearest_after_transfer": (
        "timing",
        "hand nearest the object (the old argmin 'transfer'), after the transfer",
        "s",
    ),
    "pelvis_x_transfer": ("where", "pelvis x at transfer", "m"),
    "pelvis_y_transfer": ("where", "pelvis y at transfer", "m"),
    "pelvis_z_transfer": ("where", "pelvis height at transfer", "m"),
    "object_x_transfer": ("where", "object x at transfer", "m"),
    "object_y_transfer": ("where", "object y at transfer", "m"),
    "object_z_transfer": ("where", "object z (height) at transfer", "m"),
    "pelvis_x_release": ("where", "pelvis x at release", "m"),
    "pelvis_y_release": ("where", "pelvis y at release", "m"),
    "object_x_release": ("where", "object x at release", "m"),
    "object_y_release": ("where", "object y at release", "m"),
    "object_z_release": ("where", "object z at release", "m"),
    "object_fwd_transfer": ("body frame at transfer", "object forward of pelvis", "m"),
    "object_lat_transfer": ("body frame at transfer", "object lateral (+ left)", "m"),
    "object_up_transfer": ("body frame at transfer", "object above pelvis", "m"),
    "hand_fwd_transfer": ("body frame at transfer", "hand (15) forward of pelvis", "m"),
    "hand_lat_transfer": ("body frame at transfer", "hand lateral (+ left)", "m"),
    "hand_up_transfer": ("body frame at transfer", "hand above pelvis", "m"),
    "hand_rise_transfer": ("body frame at transfer", "hand above its walking height", "m"),
    "object_shoulder_transfer": ("body frame at transfer", "object to right shoulder (12)", "m"),
    "walking_speed_transfer": ("body frame at transfer", "walking speed", "m/s"),
    "object_fwd_onset": ("reach onset", "object forward of pelvis", "m"),
    "object_lat_onset": ("reach onset", "object lateral (+ left)", "m"),
    "object_up_onset": ("reach onset", "object above pelvis", "m"),
    "hand_fwd_onset": ("reach onset", "hand forward of pelvis", "m"),
    "hand_lat_onset": ("reach onset", "hand lateral (+ left)", "m"),
    "hand_up_onset": ("reach onset", "hand above pelvis", "m"),
    "object_shoulder_onset": ("reach onset", "object to right shoulder distance", "m"),
    "object_shoulder_fwd_onset": ("reach onset", "object forward of right shoulder", "m"),
    "ttc_onset": (
        "reach onset",
        "time to contact (object forward of shoulder / walking speed)",
        "s",
    ),
    "walking_speed_onset": ("reach onset", "walking speed", "m/s"),
    "hand_shoulder_transfer": ("reach extent", "hand-shoulder distance at transfer", "m"),
    "arm_length": ("reach extent", "arm length (12-13-14-15 bones)", "m"),
    "reach_fraction": ("reach extent", "hand-shoulder distance / arm length at transfer", ""),
    "object_reach_fraction": (
        "reach extent",
        "object-shoulder distance / arm length at transfer",
        "",
    ),
    "prereach_speed": (
        "slow-down",
        "walking speed before the reach (median, start to onset)",
        "m/s",
    ),
    "min_rel_speed": ("slow-down", "min walking speed / pre-reach, transfer -1 s .. +0.5 s", ""),
    "mean_rel_speed": ("slow-down", "mean walking speed / pre-reach, same window", ""),
    "time_lost": ("slow-down", "time lost vs walking at the pre-reach speed, same window", "s"),
    "lateral_deviation": ("slow-down", "pelvis path bulge toward the object, same window", "m"),
    "min_rel_speed_control": (
        "slow-down",
        "control: min speed / pre-reach, 1.5 s before onset",
        "",
    ),
    "lateral_deviation_control": (
        "slow-down",
        "control: bulge toward the object, 1.5 s before onset",
        "m",
    ),
    "arm_extended": ("arm", "arm extended (onset to hand drawn back to the body)", "s"),
    "arm_back_after_release": (
        "arm",
        "hand drawn back, time after the giver's release (- before)",
        "s",
    ),
    "d15_transfer": ("hand-object distance", "joint 15 to object at transfer", "m"),
    "dnear_transfer": ("hand-object distance", "nearest of 14-17 to object at transfer", "m"),
    "d15_min_hold": ("hand-object distance", "joint 15: min over transfer .. release", "m"),
    "d15_min_window": ("hand-object distance", "joint 15: min over transfer -0.2 s .. +0.5 s", "m"),
    "d15_min": ("hand-object distance", "joint 15: min over the recording", "m"),
    "d15_transfer_raw": ("hand-object distance", "joint 15 at transfer, unsmoothed tracks", "m"),
    "d15_min_raw": ("hand-object distance", "joint 15: min over the recording, unsmoothed", "m"),
    "giver_along_hold": (
        "giver and object",
        "giver pelvis moved along the walk, transfer .. release",
        "m",
    ),
    "giver_pelvis_range": ("giver and object", "giver pelvis: max distance from its start", "m"),
    "object_moved_before": ("giver and object", "object moved from its start by the transfer", "m"),
    "object_toward_receiver": (
        "giver and object",
        "... of which toward the receiver (against the walk)",
        "m",
    ),
    "object_along_before": (
        "giver and object",
        "object speed along the walk / walking, 0.5 s before transfer",
        "",
    ),
    "object_speed_transfer": ("giver and object", "object speed at transfer", "m/s"),
    "object_jerk_transfer": (
        "giver and object",
        "object jerk at transfer (third difference of the last four frames)",
        "m/s³",
    ),
    "object_jerk_transfer_raw": ("giver and object", "the same, unsmoothed track", "m/s³"),
}
MEASURES.update(WALK_MEASURES)
EVENTS = ("near", "transfer", "onset", "release", "arm_back", "nearest")


@dataclass
class RecordingAnalysis:
    """Everything measured on one recording.

    Attributes:
        n_frames: T.
        events: frame of each of :data:`EVENTS` (None when not detected).
        reasons: why an event is missing, by event name.
        measures: every name of :data:`MEASURES` -> value (NaN when undefined).
        traces: aligned traces on the grid of :data:`TRACE_WINDOW` (NaN outside the recording).
        failure: the :data:`~handover_env.data.detect.FAILURES` category when there is no
            transfer, else "".
    """

    n_frames: int
    events: dict[str, int | None]
    failure: str = ""
    reasons: dict[str, str] = field(default_factory=dict)
    measures: dict[str, float] = field(default_factory=dict)
    traces: dict[str, np.ndarray] = field(default_factory=dict)


def trace_lags(rate_hz: float = RATE_HZ) -> np.ndarray:
    """Frame offsets of the aligned traces, from -TRACE_WINDOW[0] to +TRACE_WINDOW[1]."""
    return np.arange(
        -int(round(TRACE_WINDOW[0] * rate_hz)), int(round(TRACE_WINDOW[1] * rate_hz)) + 1
    )


def _aligned(signal: np.ndarray, at: int, lags: np.ndarray) -> np.ndarray:
    index = at + lags
    ok = (index >= 0) & (index < signal.size)
    out = np.full(lags.size, np.nan)
    out[ok] = signal[index[ok]]
    return out


def _bulge(path: np.ndarray, side: float) -> float:
    """Signed largest offset of a path (N, 2) from its chord, positive toward ``side`` (+1 left)."""
    chord = path[-1] - path[0]
    length = np.linalg.norm(chord)
    if length < 1e-6:
        return float("nan")
    left = np.array([-chord[1], chord[0]]) / length
    offset = (path - path[0]) @ left
    return float(offset[np.argmax(np.abs(offset))] * side)


def track_noise(receiver: np.ndarray, rate_hz: float = RATE_HZ) -> dict[str, float]:
    """Pelvis speed spikes and hand jumps of one skeleton track (T, 34, 3).

    Returns ``pelvis_max_speed`` (m/s, frame-to-frame xy), ``pelvis_spike_frames`` (frames faster
    than :data:`PELVIS_SPIKE_SPEED`), ``hand_max_step`` (m, joint 15 per frame, 3D) and
    ``hand_jumps`` (frames with a step over :data:`HAND_JUMP`).
    """
    speed = np.linalg.norm(np.diff(receiver[:, PELVIS, :2], axis=0), axis=1) * rate_hz
    step = np.linalg.norm(np.diff(receiver[:, R_HAND], axis=0), axis=1)
    return {
        "pelvis_max_speed": float(speed.max()),
        "pelvis_spike_frames": float((speed > PELVIS_SPIKE_SPEED).sum()),
        "hand_max_step": float(step.max()),
        "hand_jumps": float((step > HAND_JUMP).sum()),
    }


def analyse_recording(
    receiver: np.ndarray,
    obj: np.ndarray,
    giver: np.ndarray | None = None,
    rate_hz: float = RATE_HZ,
    smooth: bool = True,
) -> RecordingAnalysis:
    """Detect the events of one recording and measure every quantity of :data:`MEASURES`.

    Args:
        receiver: (T, 34, 3) receiver skeleton (``pose_receiver``).
        obj: (T, 3) object position (``pose_object``).
        giver: (T, 34, 3) giver skeleton (``pose_giver``); without it there is no release and
            nothing that depends on it.
        rate_hz: frame rate.
        smooth: apply :func:`smooth_track` to every track first (the detectors' thresholds assume
            it).
    """
    raw_r, raw_o, raw_g = check_recording(receiver, obj, giver, rate_hz)
    r = smooth_track(raw_r, rate_hz) if smooth else raw_r
    o = smooth_track(raw_o, rate_hz) if smooth else raw_o
    g = None if raw_g is None else (smooth_track(raw_g, rate_hz) if smooth else raw_g)
    n = raw_r.shape[0]
    m = {name: float("nan") for name in MEASURES}
    walking = walking_frame(r[:, PELVIS, :2], rate_hz)
    detection = detect_transfer(r, o, rate_hz, walking)
    d15 = np.linalg.norm(r[:, R_HAND] - o, axis=1)
    m["d15_min"] = float(d15.min())
    m["d15_min_raw"] = float(np.linalg.norm(raw_r[:, R_HAND] - raw_o, axis=1).min())
    events: dict[str, int | None] = {e: None for e in EVENTS}
    events["near"], events["nearest"] = detection.near_frame, int(np.argmin(detection.distance))
    out = RecordingAnalysis(n, events, measures=m)
    if detection.frame is None:
        out.reasons["transfer"], out.failure = detection.reason, detection.category
        return out
    k = events["transfer"] = detection.frame
    fwd, pelvis = walking.forward, r[:, PELVIS]
    body_obj = to_body_frame(o, pelvis, fwd)
    body_hand = to_body_frame(r[:, R_HAND], pelvis, fwd)
    shoulder = r[:, R_SHOULDER]
    lags = trace_lags(rate_hz)
    m.update(
        transfer_time=k / rate_hz,
        transfer_fraction=k / (n - 1),
        nearest_after_transfer=(events["nearest"] - k) / rate_hz,
        pelvis_x_transfer=pelvis[k, 0],
        pelvis_y_transfer=pelvis[k, 1],
        pelvis_z_transfer=pelvis[k, 2],
        object_x_transfer=o[k, 0],
        object_y_transfer=o[k, 1],
        object_z_transfer=o[k, 2],
        object_fwd_transfer=body_obj[k, 0],
        object_lat_transfer=body_obj[k, 1],
        object_up_transfer=body_obj[k, 2],
        hand_fwd_transfer=body_hand[k, 0],
        hand_lat_transfer=body_hand[k, 1],
        hand_up_transfer=body_hand[k, 2],
        object_shoulder_transfer=np.linalg.norm(o[k] - shoulder[k]),
        walking_speed_transfer=walking.speed[k],
        hand_shoulder_transfer=np.linalg.norm(r[k, R_HAND] - shoulder[k]),
        arm_length=arm_length(r),
        d15_transfer=d15[k],
        dnear_transfer=detection.distance[k],
        d15_transfer_raw=np.linalg.norm(raw_r[k, R_HAND] - raw_o[k]),
    )
    before_k, after_k = (int(round(w * rate_hz)) for w in GRASP_WINDOW)
    grasp = slice(max(0, k - before_k), k + after_k + 1)
    m["d15_min_window"] = float(d15[grasp].min())
    m["reach_fraction"] = m["hand_shoulder_transfer"] / m["arm_length"]
    m["object_reach_fraction"] = m["object_shoulder_transfer"] / m["arm_length"]
    moved = o[k, :2] - o[0, :2]
    m["object_moved_before"] = float(np.linalg.norm(o[k] - o[0]))
    m["object_toward_receiver"] = float(-moved @ fwd[k])
    before = slice(max(0, k - int(round(0.5 * rate_hz))), k + 1)
    obj_along = np.einsum("ij,ij->i", np.gradient(o[:, :2], axis=0) * rate_hz, fwd)
    m["object_along_before"] = float(np.mean(obj_along[before]) / np.median(walking.speed[: k + 1]))
    m["object_speed_transfer"] = float(np.linalg.norm(np.gradient(o, axis=0)[k]) * rate_hz)
    if k >= 3:  # the env's robot_jerk estimator: (x_k - 3 x_k-1 + 3 x_k-2 - x_k-3) * rate^3
        third = o[k] - 3.0 * o[k - 1] + 3.0 * o[k - 2] - o[k - 3]
        m["object_jerk_transfer"] = float(np.linalg.norm(third) * rate_hz**3)
        raw = raw_o[k] - 3.0 * raw_o[k - 1] + 3.0 * raw_o[k - 2] - raw_o[k - 3]
        m["object_jerk_transfer_raw"] = float(np.linalg.norm(raw) * rate_hz**3)
    out.traces["d15"] = _aligned(d15, k, lags)
    out.traces["dnear"] = _aligned(detection.distance, k, lags)

    reach = detect_reach_onset(r, k, rate_hz)
    onset = reach.frame
    if onset is None:
        out.reasons["onset"] = reach.reason
    else:
        m["fast_reach_duration"] = (k - reach.rise_frame) / rate_hz
        _onset_measures(m, out, r, walking, body_obj, body_hand, onset, k, rate_hz)
    m.update(walk_measures(r, o, walking, k, onset, rate_hz))
    if g is not None:
        release, reason = detect_release(g, o, k, rate_hz)
        giver_d = nearest_distance(g[:, list(GIVER_HAND_JOINTS)], o)
        out.traces["giver"] = _aligned(
            giver_d - np.median(giver_d[max(0, k - 15) : k + 1]), k, lags
        )
        giver_moved = np.linalg.norm(g[:, PELVIS, :2] - g[0, PELVIS, :2], axis=1)
        m["giver_pelvis_range"] = float(giver_moved.max())
        if release is None:
            out.reasons["release"] = reason
        else:
            events["release"] = release
            m.update(
                hold_duration=(release - k) / rate_hz, release_time=release / rate_hz,
                release_fraction=release / (n - 1), after_release=(n - 1 - release) / rate_hz,
                pelvis_x_release=pelvis[release, 0], pelvis_y_release=pelvis[release, 1],
                object_x_release=o[release, 0], object_y_release=o[release, 1],
                object_z_release=o[release, 2], d15_min_hold=d15[k : release + 1].min(),
                giver_along_hold=(g[release, PELVIS, :2] - g[k, PELVIS, :2]) @ fwd[k],
            )
    back = events["arm_back"] = detect_arm_back(r, k, k, rate_hz)
    if back is None:
        out.reasons["arm_back"] = "hand not drawn back before the end of the recording"
    else:
        if onset is not None:
            m["arm_extended"] = (back - onset) / rate_hz
        if events["release"] is not None:
            m["arm_back_after_release"] = (back - events["release"]) / rate_hz
    return out


def _onset_measures(
    m: dict[str, float],
    out: RecordingAnalysis,
    r: np.ndarray,
    walking: WalkingFrame,
    body_obj: np.ndarray,
    body_hand: np.ndarray,
    onset: int,
    k: int,
    rate_hz: float,
) -> None:
    """Fill the reach-onset, slow-down and hand-rise measures of :func:`analyse_recording`."""
    out.events["onset"] = onset
    n = r.shape[0]
    fwd, speed = walking.forward, walking.speed
    shoulder_obj = body_obj[onset] - to_body_frame(
        r[onset, R_SHOULDER], r[onset, PELVIS], fwd[onset]
    )
    height = hand_height(r)
    walking_height = float(np.median(height[baseline_slice(k, rate_hz)]))
    m.update(
        reach_duration=(k - onset) / rate_hz,
        object_fwd_onset=body_obj[onset, 0],
        object_lat_onset=body_obj[onset, 1],
        object_up_onset=body_obj[onset, 2],
        hand_fwd_onset=body_hand[onset, 0],
        hand_lat_onset=body_hand[onset, 1],
        hand_up_onset=body_hand[onset, 2],
        object_shoulder_onset=np.linalg.norm(shoulder_obj),
        object_shoulder_fwd_onset=shoulder_obj[0],
        walking_speed_onset=speed[onset],
        hand_rise_transfer=height[k] - walking_height,
    )
    m["ttc_onset"] = shoulder_obj[0] / speed[onset] if speed[onset] > 0.05 else float("nan")
    if onset < 3:
        return
    pre = float(np.median(speed[: onset + 1]))
    m["prereach_speed"] = pre
    rel = speed / pre
    out.traces["speed"] = _aligned(rel, k, trace_lags(rate_hz))
    out.traces["rise"] = _aligned(height - walking_height, k, trace_lags(rate_hz))
    side = float(np.sign(body_obj[k, 1])) or -1.0
    path = lowpass(r[:, PELVIS, :2], rate_hz, HEADING_CUTOFF_HZ)
    a, b = (
        k - int(round(SLOWDOWN_WINDOW[0] * rate_hz)),
        k + int(round(SLOWDOWN_WINDOW[1] * rate_hz)),
    )
    if a >= 0 and b < n:
        window = slice(a, b + 1)
        m["min_rel_speed"] = float(rel[window].min())
        m["mean_rel_speed"] = float(rel[window].mean())
        m["time_lost"] = float(np.sum(1.0 - rel[a:b]) / rate_hz)
        m["lateral_deviation"] = _bulge(path[window], side)
    c = onset - (b - a)
    if c >= 0:
        m["min_rel_speed_control"] = float(rel[c : onset + 1].min())
        m["lateral_deviation_control"] = _bulge(path[c : onset + 1], side)


__all__ = [
    "EVENTS",
    "MEASURES",
    "RecordingAnalysis",
    "analyse_recording",
    "track_noise",
    "trace_lags",
]
