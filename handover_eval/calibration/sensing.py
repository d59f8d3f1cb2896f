"""Camera-noise figures derived from the recordings (issue 24): the numbers behind the camera model.

The development copy of the public dataset holds what the paper's ZED 2i + ZED SDK 4.0 body
tracker reported at 30 Hz (receiver skeletons, BODY_34) next to OptiTrack object tracks. This
module measures, at run time and from statistics only (nothing per recording is kept):

* **Jitter** (:func:`track_jitter`), the one statistic by which recorded and simulated tracks are
  compared: the RMS, over frames and the x and y axes, of a track's residual from the project's
  zero-phase 2 Hz low-pass (:func:`handover_env.data.filtering.lowpass`), the first and last
  :data:`EDGE_FRAMES` frames left out. The low-pass keeps the gait (steps at ~1.6 Hz), so the
  residual is what the tracker adds above walking (plus the step harmonics of the real body).
* **Pelvis noise** (:func:`white_sigma_for_jitter`): the standard deviation of frame-independent
  noise whose high-pass residual, through the filter's exact frequency response, has the recorded
  jitter. The recorded residual is correlated from frame to frame (lag-1 autocorrelation ~0.77,
  :func:`residual_lag1`) because it also holds the walking body's own step harmonics, mostly
  along the walking direction; a first-order Gauss-Markov (AR(1)) process cannot reproduce that
  (fitting one drives rho to 1 and sigma to ~0.13 m), so the pelvis noise is taken as white and
  only its total above 2 Hz is matched. The ZED SDK says its tracking filters the detections but
  not how, so no SDK smoothing is modelled on top: the recordings already are its output.
* **Hand error** (:func:`carry_residual`): while the receiver carries the object away (from the
  transfer, :func:`handover_env.data.detect_transfer`, to the end), the ZED right hand
  (joint 15) and the OptiTrack object move together; the hand-minus-object vector less its mean
  over that stretch (the grip offset) is the hand keypoint's error: its RMS and lag-1
  autocorrelation give the hand's AR(1) sigma and rho directly.
* **Lost frames** (:func:`refit_bursts`): the ZED SDK keeps predicting a body it lost (tracking
  state SEARCHING) and re-fits it when found, so the recordings have no missing frames (no frame
  repeats the previous one) but show re-fit bursts: pelvis speeds over
  :data:`handover_eval.calibration.measures.PELVIS_SPIKE_SPEED` (2 m/s). Their fraction of frames
  and their mean run length stand in for the lost-frame rate.

``handover-data sensing PUBLIC_DIR`` prints every figure; the "paper" camera profile
(:mod:`handover_env.sensors.profiles`) quotes them.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np
from scipy.signal import butter, sosfreqz

from handover_env.data.filtering import CUTOFF_HZ, ORDER, lowpass, smooth_track
from handover_eval.calibration.measures import PELVIS_SPIKE_SPEED

RATE_HZ = 30.0
#: Frames left out at each end of a track (the filter's odd padding pins the end samples).
EDGE_FRAMES = 5
PELVIS, R_HAND = 0, 15
#: Shortest carry stretch used (frames after the transfer), 1/3 s.
MIN_CARRY_FRAMES = 10


def highpass_residual(track: np.ndarray, rate_hz: float = RATE_HZ) -> np.ndarray:
    """``track - lowpass(track)`` without the :data:`EDGE_FRAMES` end frames, (T - 10, D)."""
    arr = np.asarray(track, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[0] < 2 * EDGE_FRAMES + 3:
        raise ValueError(f"a track must be (T, D) with T >= {2 * EDGE_FRAMES + 3}, got {arr.shape}")
    return (arr - lowpass(arr, rate_hz))[EDGE_FRAMES:-EDGE_FRAMES]


def track_jitter(tracks: Iterable[np.ndarray], rate_hz: float = RATE_HZ) -> float:
    """The jitter statistic, m: RMS of the high-pass residual pooled over tracks, frames and axes.

    Args:
        tracks: (T, 2) tracks (e.g. pelvis xy), recorded or simulated, at ``rate_hz``.
    """
    sq, n = 0.0, 0
    for track in tracks:
        r = highpass_residual(track, rate_hz)
        sq += float(np.sum(r * r))
        n += r.size
    if n == 0:
        raise ValueError("track_jitter needs at least one track")
    return math.sqrt(sq / n)


def residual_lag1(tracks: Iterable[np.ndarray], rate_hz: float = RATE_HZ) -> float:
    """Pooled lag-1 autocorrelation of the high-pass residual (sum e_k e_k-1 / sum e_k^2)."""
    num, den = 0.0, 0.0
    for track in tracks:
        r = highpass_residual(track, rate_hz)
        num += float(np.sum(r[1:] * r[:-1]))
        den += float(np.sum(r * r))
    return num / den


def _residual_response(rate_hz: float, n: int = 8192) -> tuple[np.ndarray, np.ndarray]:
    """(omega, G^2): the residual filter 1 - |H|^2 of :func:`lowpass`, squared, on [0, pi)."""
    sos = butter(ORDER, CUTOFF_HZ, btype="low", fs=rate_hz, output="sos")
    w, h = sosfreqz(sos, worN=n)
    g = 1.0 - np.abs(h) ** 2
    return w, g * g


def ar1_highpass(rho: float, rate_hz: float = RATE_HZ) -> tuple[float, float]:
    """Variance gain and lag-1 autocorrelation of a unit AR(1) process after the residual filter."""
    w, g2 = _residual_response(rate_hz)
    s = (1.0 - rho * rho) / (1.0 - 2.0 * rho * np.cos(w) + rho * rho)
    gain = float(np.mean(g2 * s))
    return gain, float(np.mean(g2 * s * np.cos(w)) / gain)


def white_sigma_for_jitter(jitter: float, rate_hz: float = RATE_HZ) -> float:
    """Standard deviation of frame-independent noise whose high-pass residual has ``jitter``."""
    return jitter / math.sqrt(ar1_highpass(0.0, rate_hz)[0])


def carry_residual(receiver: np.ndarray, obj: np.ndarray, rate_hz: float = RATE_HZ
                   ) -> np.ndarray | None:
    """Right hand minus object from the transfer on, less its mean (the grip offset), (K, 3).

    None when no transfer is detected or fewer than :data:`MIN_CARRY_FRAMES` frames follow it.
    """
    from handover_env.data.detect import detect_transfer

    det = detect_transfer(smooth_track(receiver, rate_hz), smooth_track(obj, rate_hz), rate_hz)
    if det.frame is None or receiver.shape[0] - det.frame < MIN_CARRY_FRAMES:
        return None
    e = receiver[det.frame:, R_HAND] - obj[det.frame:]
    return e - e.mean(axis=0)


def refit_bursts(pelvis_xy: np.ndarray, rate_hz: float = RATE_HZ) -> tuple[int, int, int]:
    """(burst frames, bursts, frame steps) of pelvis speeds over ``PELVIS_SPIKE_SPEED``."""
    speed = np.linalg.norm(np.diff(pelvis_xy, axis=0), axis=1) * rate_hz
    fast = speed > PELVIS_SPIKE_SPEED
    starts = int(np.sum(fast[1:] & ~fast[:-1]) + (1 if fast.size and fast[0] else 0))
    return int(fast.sum()), starts, int(fast.size)


def sensing_figures(
    public_dir: str | Path,
    limit: int | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> dict[str, float]:
    """Every camera figure of the module docstring over the ID recordings of ``public_dir``.

    Returns a dict: ``recordings``, ``pelvis_jitter`` (m), ``pelvis_lag1``, ``pelvis_sigma`` (m),
    ``hand_sigma`` (m, RMS over the three axes), ``hand_rho``, ``carry_recordings``,
    ``refit_fraction`` (of frames), ``refit_mean_run`` (frames), ``repeated_frames``.
    """
    from handover_env.data.public import ID_PREFIX, list_public_files
    from handover_env.person.recording import load_recording

    files = [p for p in list_public_files(public_dir) if p.name.startswith(ID_PREFIX)]
    files = files[:limit] if limit else files
    pelvis, carries = [], []
    burst_frames = bursts = steps = repeats = 0
    for i, path in enumerate(files):
        rec = load_recording(path)
        pose = np.asarray(rec.receiver_pose, dtype=np.float64)
        pelvis.append(pose[:, PELVIS, :2])
        flat = pose.reshape(pose.shape[0], -1)
        repeats += int(np.sum(np.all(flat[1:] == flat[:-1], axis=1)))
        bf, nb, ns = refit_bursts(pose[:, PELVIS, :2])
        burst_frames, bursts, steps = burst_frames + bf, bursts + nb, steps + ns
        e = carry_residual(pose, np.asarray(rec.episode.giver_xyz, dtype=np.float64))
        if e is not None:
            carries.append(e)
        if progress is not None:
            progress(i + 1, len(files))
    if not pelvis:
        raise ValueError(f"{public_dir}: no ID recordings")
    jitter, lag1 = track_jitter(pelvis), residual_lag1(pelvis)
    sigma = white_sigma_for_jitter(jitter)
    hand = np.concatenate(carries) if carries else np.zeros((0, 3))
    lag_num = sum(float(np.sum(c[1:] * c[:-1])) for c in carries)
    return {
        "recordings": float(len(files)),
        "pelvis_jitter": jitter,
        "pelvis_lag1": lag1,
        "pelvis_sigma": sigma,
        "hand_sigma": float(np.sqrt(np.mean(hand * hand))) if hand.size else math.nan,
        "hand_rho": lag_num / float(np.sum(hand * hand)) if hand.size else math.nan,
        "carry_recordings": float(len(carries)),
        "refit_fraction": burst_frames / steps if steps else math.nan,
        "refit_mean_run": burst_frames / bursts if bursts else math.nan,
        "repeated_frames": float(repeats),
    }


def format_figures(figures: dict[str, float]) -> str:
    """The figures as lines of text, units stated."""
    f = figures
    return "\n".join([
        f"ID recordings: {f['recordings']:.0f}",
        f"pelvis jitter (RMS xy residual of the 2 Hz zero-phase low-pass): "
        f"{1000 * f['pelvis_jitter']:.2f} mm, lag-1 autocorrelation {f['pelvis_lag1']:.3f}",
        f"pelvis frame noise for that jitter: sigma {1000 * f['pelvis_sigma']:.2f} mm",
        f"hand (joint 15) - object residual while carrying ({f['carry_recordings']:.0f} "
        f"recordings): sigma {1000 * f['hand_sigma']:.1f} mm, rho {f['hand_rho']:.3f}",
        f"re-fit bursts (pelvis > 2 m/s): {100 * f['refit_fraction']:.3f} % of frames, mean run "
        f"{f['refit_mean_run']:.2f} frames; repeated frames: {f['repeated_frames']:.0f}",
    ])
