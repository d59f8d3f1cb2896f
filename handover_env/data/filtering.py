"""One documented smoothing filter for recorded (ZED BODY_34) tracks: :func:`smooth_track`.

Issue 12 asks that recorded receivers be "filtered once" before they drive a simulated body. The
filter has two stages, both along the time axis and independently per channel:

1. **Outlier pass (Hampel type).** The residual of the track from its running median over
   ``2 * half_window + 1`` frames (3 by default) is compared with a robust scale of that residual
   over the whole track (1.4826 x its median absolute value, the MAD estimate of a standard
   deviation). Samples whose residual exceeds ``max(n_sigmas * scale, min_deviation)`` are
   replaced by the running median. A running median follows a steady walk or a reach exactly (the
   median of a monotone window is its middle sample), so only a sample that jumps away from both
   its neighbours is touched. The floor ``min_deviation`` = 0.10 m (the "hand jump" of issue 12)
   keeps genuine fast turnarounds: a 5-frame median with a 0.03 m floor would have clipped ~20,000
   joint coordinates of swinging feet and hands in the development copy; this setting changes 63
   samples in 14 of the 875 recordings, almost all feet, and none of the pelvis.
2. **Zero-phase low-pass.** A Butterworth filter of ``order`` run forward and backward
   (:func:`scipy.signal.sosfiltfilt`), so nothing is delayed: the effective response is the
   squared Butterworth magnitude, ``1 / (1 + (f / cutoff)^(2 * order))``. The straight line
   between the first and last sample is taken out before filtering and put back after, and the
   rest is padded by odd reflection over two cutoff periods: a steady walk passes unchanged, with
   no start-up transient at the ends (as with any odd padding, the two end samples stay put).

Choice of the cutoff (2 Hz) from the gait spectrum of the 875-recording development copy: the
receivers' stride frequency (left-right ankle separation) is 0.73 / 0.79 / 0.82 Hz (25/50/75 %),
so the step frequency is about 1.6 Hz; the pelvis speed spectrum has its power at 0.5 .. 1.9 Hz
and falls by 10x by 3 Hz. A 2 Hz cutoff keeps the step fundamental (gain 0.86 at 1.6 Hz) and a
reach (about 0.4 s) and removes the step harmonics and the tracker's bursts: pelvis speeds of
2 .. 5.8 m/s over 3 .. 6 frames where the ZED tracker re-fits the skeleton. The recordings have
practically no isolated one-frame spikes (the ZED SDK already smooths; of the 2,851 hand steps
over 0.1 m, one goes out and straight back), so the outlier pass is a guard for other downloads
and rarely changes a sample here; the report
(``handover-data transfer-stats``) prints what each stage does.
"""

from __future__ import annotations

import numpy as np

# scipy.ndimage and scipy.signal are imported where they are used: together they are about two
# thirds of `import handover_env`'s time, and an env that replays no recording never filters.

#: Low-pass cutoff, Hz: just above the median step frequency (about 1.6 Hz).
CUTOFF_HZ = 2.0
#: Butterworth order (applied twice by the forward-backward pass).
ORDER = 4
#: Outlier pass: running-median half window (frames), threshold in robust sigmas, and the
#: smallest deviation ever called an outlier (m; the tracks are smooth, so this floor decides).
HAMPEL_HALF_WINDOW = 1
HAMPEL_SIGMAS = 4.0
HAMPEL_MIN_DEVIATION = 0.10
_MAD_TO_SIGMA = 1.4826


def _as_track(x: np.ndarray, name: str = "x") -> np.ndarray:
    arr = np.asarray(x)
    if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
        raise ValueError(f"{name} must hold real numbers, got dtype {arr.dtype}")
    arr = arr.astype(np.float64, copy=False)
    if arr.ndim < 1 or arr.shape[0] < 3:
        raise ValueError(f"{name} must have shape (T, ...) with T >= 3 frames, got {arr.shape}")
    if not np.isfinite(arr).all():
        bad = np.flatnonzero(~np.isfinite(arr.reshape(arr.shape[0], -1)).all(axis=1))
        raise ValueError(
            f"{name} has NaN/inf in {bad.size} frame(s), first at frame {int(bad[0])}; "
            "fill or drop them before smoothing"
        )
    return arr


def hampel(
    x: np.ndarray,
    half_window: int = HAMPEL_HALF_WINDOW,
    n_sigmas: float = HAMPEL_SIGMAS,
    min_deviation: float = HAMPEL_MIN_DEVIATION,
) -> tuple[np.ndarray, np.ndarray]:
    """Replace isolated outliers along axis 0 by the running median (stage 1 of
    :func:`smooth_track`).

    Args:
        x: (T, ...) track.
        half_window: running-median half width in frames (>= 1).
        n_sigmas: threshold in robust standard deviations of the residual (> 0).
        min_deviation: residuals at or below this are never outliers (same unit as ``x``).

    Returns:
        ``(cleaned, outliers)``: the cleaned track (a new array) and a bool mask of the replaced
        samples, both of ``x``'s shape.
    """
    arr = _as_track(x)
    if int(half_window) != half_window or half_window < 1:
        raise ValueError(f"half_window must be an integer >= 1, got {half_window!r}")
    if not n_sigmas > 0 or not min_deviation >= 0:
        raise ValueError(
            f"need n_sigmas > 0 and min_deviation >= 0, got {n_sigmas}, {min_deviation}"
        )
    size = (2 * int(half_window) + 1,) + (1,) * (arr.ndim - 1)
    from scipy.ndimage import median_filter

    median = median_filter(arr, size=size, mode="nearest")
    residual = np.abs(arr - median)
    scale = _MAD_TO_SIGMA * np.median(residual, axis=0, keepdims=True)
    outliers = residual > np.maximum(n_sigmas * scale, min_deviation)
    return np.where(outliers, median, arr), outliers


def lowpass(
    x: np.ndarray, rate_hz: float, cutoff_hz: float = CUTOFF_HZ, order: int = ORDER
) -> np.ndarray:
    """Zero-phase Butterworth low-pass along axis 0 (stage 2 of :func:`smooth_track`).

    Args:
        x: (T, ...) track, T >= 3.
        rate_hz: sampling rate, Hz.
        cutoff_hz: -3 dB frequency of the one-way filter, 0 < cutoff < rate / 2.
        order: Butterworth order (>= 1).
    """
    arr = _as_track(x)
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f"rate_hz must be a positive number, got {rate_hz!r}")
    if not 0 < cutoff_hz < rate_hz / 2:
        raise ValueError(
            f"cutoff_hz must be in (0, rate_hz / 2 = {rate_hz / 2:g}), got {cutoff_hz!r}"
        )
    if int(order) != order or order < 1:
        raise ValueError(f"order must be an integer >= 1, got {order!r}")
    from scipy.signal import butter, sosfiltfilt

    sos = butter(int(order), cutoff_hz, btype="low", fs=rate_hz, output="sos")
    n = arr.shape[0]
    shape = (n,) + (1,) * (arr.ndim - 1)
    line = arr[:1] + (arr[-1:] - arr[:1]) * (np.arange(n) / (n - 1)).reshape(shape)
    padlen = min(n - 1, max(3 * (2 * len(sos) + 1), int(round(2 * rate_hz / cutoff_hz))))
    return line + sosfiltfilt(sos, arr - line, axis=0, padtype="odd", padlen=padlen)


def smooth_track(
    x: np.ndarray,
    rate_hz: float,
    *,
    cutoff_hz: float = CUTOFF_HZ,
    order: int = ORDER,
    half_window: int = HAMPEL_HALF_WINDOW,
    n_sigmas: float = HAMPEL_SIGMAS,
    min_deviation: float = HAMPEL_MIN_DEVIATION,
) -> np.ndarray:
    """The recorded-track filter: Hampel-type outlier pass, then a zero-phase Butterworth low-pass.

    Works on any ``(T, ...)`` array (a skeleton ``(T, 34, 3)``, a point ``(T, 3)``), filtering
    every channel along time. The filter is linear after the outlier pass, so the difference of
    two smoothed tracks is the smoothed difference (hand-object distances computed on smoothed
    tracks are those of the smoothed hand-object vector).

    Args:
        x: (T, ...) track, T >= 3, finite.
        rate_hz: sampling rate, Hz (30 for the public dataset).
        cutoff_hz, order: the low-pass (defaults :data:`CUTOFF_HZ`, :data:`ORDER`).
        half_window, n_sigmas, min_deviation: the outlier pass (see :func:`hampel`).

    Returns:
        The smoothed track, a new float64 array of ``x``'s shape.

    Raises:
        ValueError: wrong shape, too few frames, NaN/inf, or invalid filter settings.
    """
    cleaned, _ = hampel(x, half_window, n_sigmas, min_deviation)
    return lowpass(cleaned, rate_hz, cutoff_hz, order)
