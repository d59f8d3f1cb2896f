"""The far-pass stress set's lateral range, derived from the recordings (protocol v1).

The scripted walkers of the closed-loop track pass the robot at the recordings' typical lateral
distance, where every agent, even one that holds still, succeeds. The far-pass set puts scripted
ID walkers on passing lines ``y = pass_y`` in the recordings' lateral tail: from the pelvis y at
the moment of transfer, over all recordings with a detected transfer, the range is

    [q05, q25]  (the 5 % and 25 % quantiles: a quarter of the recorded receivers took the object
                 with the pelvis beyond q25, and 1 in 20 beyond q05)

so the set stays within what people did and does not extrapolate past the 5 % tail.
:func:`pelvis_y_at_transfer` measures one recording (the smoothed skeleton and object, the
transfer detector of :mod:`handover_env.data.detect`, as the closed loop's recorded
transfer); :func:`derive_range` the quantiles over a folder. ``evaluate.py far-pass --data
PATH/whole_motions`` prints them; the protocol's :data:`.protocol.FAR_PASS_Y` holds the values
measured on the 875-recording development copy.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

RATE_HZ = 30.0
#: The quantiles printed; the range is (LOW_Q, HIGH_Q).
QUANTILES = (0.0, 0.05, 0.10, 0.25, 0.50, 0.75, 1.0)
LOW_Q, HIGH_Q = 0.05, 0.25


def pelvis_y_at_transfer(path: str | Path) -> float:
    """The recorded receiver's smoothed pelvis y (m) at the detected transfer, NaN if none."""
    from handover_env.data.detect import detect_transfer
    from handover_env.data.filtering import smooth_track
    from handover_env.person.recording import load_recording

    rec = load_recording(path)
    pose = smooth_track(rec.receiver_pose, RATE_HZ)
    det = detect_transfer(pose, smooth_track(rec.episode.giver_xyz, RATE_HZ), RATE_HZ)
    return math.nan if det.frame is None else float(pose[det.frame, 0, 1])


@dataclass(frozen=True)
class FarPassDerivation:
    """What :func:`derive_range` measured.

    Attributes:
        n_recordings: recordings read.
        n_transfers: of them with a detected transfer (the quantiles are over these).
        quantiles: (q, pelvis y m) for every q of :data:`QUANTILES`.
        low, high: the far-pass range [q05, q25], m (low < high: farther from the robot first).
    """

    n_recordings: int
    n_transfers: int
    quantiles: tuple[tuple[float, float], ...]
    low: float
    high: float


def derive_range(paths: Sequence[str | Path], progress: bool = True) -> FarPassDerivation:
    """The far-pass range from the recordings at ``paths`` (module docstring)."""
    if not paths:
        raise ValueError("no recordings to derive the far-pass range from")
    ys = np.array(
        [pelvis_y_at_transfer(p) for p in tqdm(paths, desc="recordings", disable=not progress)]
    )
    ys = ys[np.isfinite(ys)]
    if ys.size < 2:
        raise ValueError(f"only {ys.size} recording(s) with a detected transfer")
    qs = tuple((q, float(np.quantile(ys, q))) for q in QUANTILES)
    return FarPassDerivation(
        len(paths), int(ys.size), qs, float(np.quantile(ys, LOW_Q)), float(np.quantile(ys, HIGH_Q))
    )


def derivation_text(d: FarPassDerivation) -> str:
    """The quantiles and the range, as ``evaluate.py far-pass`` prints them."""
    lines = [
        f"pelvis y at the recorded transfer: {d.n_transfers} of {d.n_recordings} recordings",
        *(f"  q{100 * q:03.0f}: {y:+.3f} m" for q, y in d.quantiles),
        f"far-pass range [q{100 * LOW_Q:02.0f}, q{100 * HIGH_Q:02.0f}] = "
        f"[{d.low:+.3f}, {d.high:+.3f}] m",
    ]
    return "\n".join(lines)
