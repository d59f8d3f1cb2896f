"""How far from the shoulder this person takes the object: the part that answers the giver and
the person's own offset.

The take distance (:func:`handover_env.person.receiver_rules.take_distance`) is

    take = TAKE_INTERCEPT + TAKE_CLOSEST * closest + offset

* the **giver-dependent part** ``TAKE_INTERCEPT + TAKE_CLOSEST * closest`` is modelled for every
  person: the least-squares line of the recorded reach on how far from the person's path the
  giver holds the object (:mod:`handover_env.person.reach_offset`,
  ``docs/calibration/reach_spread.md``);
* the **offset** is the person's own, what the giver does not explain (how far they like to
  reach). :func:`person_offset` gives it:

  - a scripted walker draws it from the calibration half's residuals
    (:data:`handover_env.person.reach_offset.REACH_OFFSET`) with the env's seeded generator, after
    the walk itself is drawn (so the walk of a seed is the same with and without it);
  - a replayed recording with its skeleton and object carries its own: the recorded reach minus
    the line's prediction from the recorded approach
    (:func:`handover_env.person.reach_offset.recording_reach_offset`), at the recorded transfer and
    reach onset that the recordings' detectors find (:mod:`handover_env.data.detect`, on the
    tracks smoothed as a replay smooths them). The replayed person is that person;
  - a replay without a skeleton (a pelvis track), or a recording in which no transfer or no
    reach onset is detected, has no recorded reach: it draws an offset like a scripted walker.

The offset is opt-in (the person setting ``reach_offset``, off by default: every person then reaches
by the line alone and nothing is drawn). With it on, under giver replay the simulated reach contains
the recorded reach's residual by construction, and its correlation with the recorded reach per
recording no longer tests the model; the line's prediction on the held-out half does
(``docs/calibration/reach_spread.md``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from handover_env.data.detect import detect_reach_onset, detect_transfer
from handover_env.data.filtering import smooth_track
from handover_env.person.person import RATE
from handover_env.person.reach_offset import REACH_OFFSET, recording_reach_offset
from handover_env.person.receiver_rules import TAKE_CLOSEST, TAKE_INTERCEPT
from handover_env.person.recording import Recording

#: Where an offset came from (:attr:`PersonOffset.origin`; ``"off"``: the person setting
#: ``reach_offset`` is off and the offset is 0).
ORIGINS = ("off", "drawn", "recorded")


@dataclass(frozen=True)
class PersonOffset:
    """A person's own reach offset.

    Attributes:
        value: m, added to the giver-dependent part of the take distance.
        origin: ``"drawn"`` from :data:`~handover_env.person.reach_offset.REACH_OFFSET`,
            ``"recorded"`` (the replayed recording's own) or ``"off"`` (the opt-in person
            setting ``reach_offset`` is off: 0).
    """

    value: float
    origin: str


def recorded_offset(recording: Recording) -> float | None:
    """The recorded person's own offset, m, or None when the recording has no detected transfer
    or reach onset (module docstring)."""
    pose = smooth_track(np.asarray(recording.receiver_pose, dtype=np.float64), RATE)
    obj = smooth_track(np.asarray(recording.episode.giver_xyz, dtype=np.float64), RATE)
    transfer = detect_transfer(pose, obj, RATE).frame
    if transfer is None:
        return None
    onset = detect_reach_onset(pose, transfer, RATE).frame
    if onset is None:
        return None
    return recording_reach_offset(pose, obj, transfer, onset, TAKE_INTERCEPT, TAKE_CLOSEST)


def person_offset(rng: np.random.Generator, kind: str, episode: Any = None) -> PersonOffset:
    """The offset of the person of a new episode (module docstring).

    Args:
        rng: the env's generator (a draw uses one uniform number of it).
        kind: ``"id"``, ``"ood"`` (scripted walkers) or ``"replay"``.
        episode: the replayed source (a :class:`Recording` carries its own offset).
    """
    if kind == "replay" and isinstance(episode, Recording):
        own = recorded_offset(episode)
        if own is not None:
            return PersonOffset(own, "recorded")
    return PersonOffset(REACH_OFFSET.draw(rng), "drawn")


__all__ = ["ORIGINS", "PersonOffset", "person_offset", "recorded_offset"]
