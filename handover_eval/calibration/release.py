"""The end of a recorded handover: the giver lets go, and the receiver draws the arm back.

The detectors of :mod:`handover_env.data.detect` (see its docstring for what the recordings
show) that only the receiver's calibration reads: **release** (:func:`detect_release`) and
**arm back** (:func:`detect_arm_back`). Same inputs: smoothed tracks at 30 Hz.
"""

from __future__ import annotations

import numpy as np

from handover_env.data.detect import (
    GIVER_HAND_JOINTS,
    PELVIS,
    R_HAND,
    RATE_HZ,
    baseline_slice,
    nearest_distance,
)

# Release. The giver's hand holds the object at 0.22 m (median; ZED-OptiTrack offset). During the
# shared hold that distance drifts at ~0.05 m/s (the giver's arm turns with the receiver); letting
# go, the hand pulls away at 0.3 .. 1.2 m/s and ends 0.9 m (median) from the object.
RELEASE_BASELINE_TIME = 0.5  # s before the transfer: the giver still holds
RELEASE_MARGIN = 0.10  # m: gone for good once this far beyond the holding distance ...
RELEASE_HOLD_TIME = 0.3  # s: ... for this long (or to the end of the recording)
RELEASE_SPEED = 0.15  # m/s: the release is the last frame before that moving away slower than this
# Arm back: the hand's horizontal distance from the pelvis within this of its walking median
# (0.29 m while walking, 0.46 m at the transfer: medians).
ARM_BACK_MARGIN = 0.08  # m


def detect_release(
    giver: np.ndarray, obj: np.ndarray, transfer: int, rate_hz: float = RATE_HZ
) -> tuple[int | None, str]:
    """The frame at which the giver lets go of the object (the end of the shared hold).

    The holding distance is the median distance from the object to the giver's nearest hand
    joint over the :data:`RELEASE_BASELINE_TIME` before the transfer. The hand is gone once it is
    :data:`RELEASE_MARGIN` beyond that and stays so for :data:`RELEASE_HOLD_TIME` (or to the end);
    the release is the last frame before that at which the hand moved away from the object slower
    than :data:`RELEASE_SPEED` (the start of the fast separation; the slow drift of the shared
    hold does not count).
    """
    distance = nearest_distance(giver[:, list(GIVER_HAND_JOINTS)], obj)
    start = max(0, transfer - int(round(RELEASE_BASELINE_TIME * rate_hz)))
    holding = float(np.median(distance[start : transfer + 1]))
    away = distance > holding + RELEASE_MARGIN
    stay = max(1, int(round(RELEASE_HOLD_TIME * rate_hz)))
    for j in np.flatnonzero(away[transfer:]) + transfer:
        if away[j : j + stay].all():
            opening = np.gradient(distance)[transfer:j] * rate_hz
            slow = np.flatnonzero(opening <= RELEASE_SPEED)
            return (int(transfer + slow[-1]) if slow.size else int(transfer)), ""
    return None, "the giver's hand stays at the object to the end of the recording"


def detect_arm_back(
    receiver: np.ndarray, transfer: int, start: int, rate_hz: float = RATE_HZ
) -> int | None:
    """First frame from ``start`` at which the hand is drawn back to the body (the arm-extended
    end).

    Back means: the horizontal distance of joint 15 from the pelvis is within
    :data:`ARM_BACK_MARGIN` of its walking median (over the onset baseline). The receiver may still
    hold the object up in front; the arm is no longer stretched out. In the recordings this happens
    0.2 s (median) before the giver lets go: the receiver draws the object in while the giver still
    holds it, which is the pull that makes the giver release. None if not before the end.
    """
    horizontal = np.linalg.norm(receiver[:, R_HAND, :2] - receiver[:, PELVIS, :2], axis=1)
    base = float(np.median(horizontal[baseline_slice(transfer, rate_hz)]))
    back = np.flatnonzero(horizontal[start:] <= base + ARM_BACK_MARGIN)
    return int(start + back[0]) if back.size else None


__all__ = ["detect_arm_back", "detect_release"]
