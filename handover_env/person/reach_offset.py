"""A recorded receiver's own reach: how far from the shoulder they took the object, beyond what
the giver's presentation predicts.

The take distance (the right shoulder's distance from the object at the transfer, the
statistic the env reports as ``reach_distance``) is modelled as two parts:

    take = a + b * closest  +  offset

* the **giver-dependent part** ``a + b * closest``: ``closest`` is the nearest the receiver's
  right shoulder comes, from the reach onset on, to the object held where it was at the onset
  (how far from the person's path the giver holds the object). ``a`` and ``b`` are a
  least-squares line fitted on the calibration half of the recordings
  (``handover-data reach-spread``, ``docs/calibration/reach_spread.md``); the person's
  :data:`handover_env.person.receiver_rules.TAKE_INTERCEPT` / ``TAKE_CLOSEST`` are that line;
* the **per-person offset**: what the giver does not explain, i.e. how far this person likes to
  reach. Its distribution over people is that of the line's residuals on the calibration half
  (:data:`REACH_OFFSET`); a recorded person's own offset is :func:`recording_reach_offset`.

This module imports nothing else of the person (the calibration reads it too), so the line's
coefficients are arguments. The recorded events (the transfer and the reach onset frames) come from
the recordings' detectors (``handover_env.data.detect``); the tracks must be smoothed as they are
there (:func:`handover_env.data.filtering.smooth_track`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: BODY_34 right shoulder (the reach is measured from it).
R_SHOULDER = 12


@dataclass(frozen=True)
class RecordedReach:
    """One recording's reach at its transfer.

    Attributes:
        reach: right shoulder to object at the transfer frame, m.
        closest: the nearest the shoulder's path from the onset on comes to the object where it
            was at the onset, m (the giver-dependent part's input).
    """

    reach: float
    closest: float


def recorded_reach(
    receiver: np.ndarray, obj: np.ndarray, transfer: int, onset: int
) -> RecordedReach:
    """The reach and the closest approach of one recording (smoothed tracks, module docstring).

    Args:
        receiver: (T, 34, 3) BODY_34 skeleton, m.
        obj: (T, 3) object position, m.
        transfer: frame of the transfer.
        onset: frame of the reach onset (at or before ``transfer``).

    Raises:
        ValueError: wrong shapes, non-finite samples, or frames outside the recording or out of
            order; the message names what is wrong.
    """
    r = np.asarray(receiver, dtype=np.float64)
    o = np.asarray(obj, dtype=np.float64)
    if r.ndim != 3 or r.shape[1] <= R_SHOULDER or r.shape[2] != 3:
        raise ValueError(f"receiver must be a (T, 34, 3) skeleton, got {r.shape}")
    if o.shape != (r.shape[0], 3):
        raise ValueError(f"obj must be ({r.shape[0]}, 3) like the receiver, got {o.shape}")
    for name, frame in (("transfer", transfer), ("onset", onset)):
        if isinstance(frame, bool) or not isinstance(frame, (int, np.integer)):
            raise ValueError(f"{name} must be a frame index (int), got {frame!r}")
        if not 0 <= frame < r.shape[0]:
            raise ValueError(f"{name} frame {frame} is outside the recording (0 .. "
                             f"{r.shape[0] - 1})")
    if onset > transfer:
        raise ValueError(f"the reach onset (frame {onset}) comes after the transfer ({transfer})")
    shoulder = r[:, R_SHOULDER]
    if not (np.isfinite(shoulder[onset:]).all() and np.isfinite(o[[onset, transfer]]).all()):
        raise ValueError("the shoulder or the object track has NaN/inf samples")
    reach = float(np.linalg.norm(o[transfer] - shoulder[transfer]))
    closest = float(np.min(np.linalg.norm(shoulder[onset:] - o[onset], axis=1)))
    return RecordedReach(reach, closest)


def reach_offset(reach: float, closest: float, intercept: float, slope: float) -> float:
    """The per-person offset: the reach minus the giver-dependent part ``intercept + slope *
    closest``, m."""
    values = (reach, closest, intercept, slope)
    if not all(isinstance(v, (int, float, np.floating)) and math.isfinite(v) for v in values):
        raise ValueError(f"reach_offset needs finite numbers, got {values!r}")
    return float(reach - (intercept + slope * closest))


def recording_reach_offset(
    receiver: np.ndarray,
    obj: np.ndarray,
    transfer: int,
    onset: int,
    intercept: float,
    slope: float,
) -> float:
    """One recorded person's own offset (m): :func:`recorded_reach`'s reach minus the line's
    prediction from its closest approach (:func:`reach_offset`). A replayed person with this
    offset reaches as the recorded one did, beyond what the giver explains."""
    rec = recorded_reach(receiver, obj, transfer, onset)
    return reach_offset(rec.reach, rec.closest, intercept, slope)


@dataclass(frozen=True)
class ReachOffsetDistribution:
    """The per-person offsets over people: the residuals of the giver-dependent line on the
    calibration half of the recordings.

    Attributes:
        kind: ``"normal"`` (mean ``mean``, SD ``sd``) or ``"quantiles"`` (the piecewise-linear
            quantile function through ``quantiles``; a draw beyond their first or last
            probability takes the end value).
        mean, sd: of the residuals, m.
        quantiles: ``(probability, offset m)`` pairs of the residuals, probabilities increasing
            within [0, 1].
        source: the command that measured them.
    """

    kind: str
    mean: float
    sd: float
    quantiles: tuple[tuple[float, float], ...]
    source: str

    def __post_init__(self) -> None:
        if self.kind not in ("normal", "quantiles"):
            raise ValueError(f"kind must be 'normal' or 'quantiles', got {self.kind!r}")
        probs = np.array([p for p, _ in self.quantiles], dtype=np.float64)
        values = np.array([v for _, v in self.quantiles], dtype=np.float64)
        if self.kind == "quantiles" and probs.size < 2:
            raise ValueError("a 'quantiles' distribution needs at least two quantiles")
        if probs.size and (probs[0] < 0.0 or probs[-1] > 1.0 or np.any(np.diff(probs) <= 0)
                           or np.any(np.diff(values) < 0)):
            raise ValueError("quantiles must be (probability, value) pairs with probabilities "
                             "increasing within [0, 1] and values not decreasing")
        if not (math.isfinite(self.mean) and math.isfinite(self.sd) and self.sd >= 0.0):
            raise ValueError(f"mean and sd must be finite with sd >= 0, got {self.mean!r}, "
                             f"{self.sd!r}")

    def draw(self, rng: np.random.Generator) -> float:
        """One person's offset, m, drawn with ``rng`` (one standard-normal or uniform draw)."""
        if self.kind == "normal":
            return float(self.mean + self.sd * rng.standard_normal())
        probs, values = zip(*self.quantiles, strict=True)
        return float(np.interp(rng.random(), probs, values))


#: The offsets' distribution measured by ``handover-data reach-spread
#: PATH/whole_motions --out docs/calibration`` on the calibration half (Table I folds 0-4, 427
#: recordings with a transfer and a reach onset) of the 875-recording development copy
#: (``docs/calibration/reach_spread.json``; a test checks that these numbers equal it): SD
#: 0.078 m around the line 0.411 + 0.250 x closest; excess kurtosis +0.60, beyond two standard
#: errors of a normal's, so the residuals' own quantile function.
REACH_OFFSET = ReachOffsetDistribution(
    kind="quantiles",
    mean=0.0,
    sd=0.0778,
    quantiles=(
        (0.005, -0.2206), (0.01, -0.1852), (0.025, -0.1557), (0.05, -0.1272), (0.10, -0.0994),
        (0.25, -0.0554), (0.50, 0.0051), (0.75, 0.0504), (0.90, 0.0923), (0.95, 0.1212),
        (0.975, 0.1420), (0.99, 0.1825), (0.995, 0.2151),
    ),
    source="handover-data reach-spread PATH/whole_motions --out docs/calibration",
)

__all__ = [
    "REACH_OFFSET",
    "R_SHOULDER",
    "ReachOffsetDistribution",
    "RecordedReach",
    "reach_offset",
    "recorded_reach",
    "recording_reach_offset",
]
