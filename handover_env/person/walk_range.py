"""Is this person's walk within the walks the simulated person was calibrated on?

:data:`handover_env.person.calibrated_range.CALIBRATED_RANGE` states the range (calibration half
of the recordings) of four fields: median walking speed, body height, the nearest the pelvis
comes to the giver, the longest pause. :func:`walk_check` measures them for the person of a new
episode, by the range's own definitions (:func:`~handover_env.person.calibrated_range.walk_fields`,
:func:`~handover_env.person.calibrated_range.recording_fields`):

* a scripted walker: its nominal pelvis track (the walk drawn, before a static handover's stop)
  and its height;
* a replayed recording with its skeleton: the recorded skeleton, filtered as a replay is; a
  ``height`` option replaces the measured height (the body is simulated at that height);
* a replayed pelvis track: the track, filtered as a replay is, and the simulated body's height.

Nothing outside is refused: the env warns once and reports ``info["within_calibration"]``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from handover_env.data.filtering import smooth_track
from handover_env.person.calibrated_range import (
    CALIBRATED_RANGE,
    check,
    recording_fields,
    walk_fields,
)
from handover_env.person.person import RATE, PersonMotion
from handover_env.person.recording import Recording


@dataclass(frozen=True)
class WalkCheck:
    """A walk's fields and those outside the calibrated range.

    Attributes:
        fields: ``{field: value}`` of every calibrated-range field.
        outside: ``(field, value, (low, high))`` of every field outside
            (:func:`handover_env.person.calibrated_range.check`).
    """

    fields: dict[str, float]
    outside: list[tuple[str, float, tuple[float, float]]]

    @property
    def within(self) -> bool:
        """True when every field is within the calibrated range."""
        return not self.outside


def walk_check(motion: PersonMotion, kind: str, episode: Any = None,
               height: float | None = None) -> WalkCheck:
    """The calibrated-range fields of the person of a new episode (module docstring).

    Args:
        motion: the person's nominal motion as drawn or replayed (before a static stop).
        kind: ``"id"``, ``"ood"`` or ``"replay"``.
        episode: the replayed source.
        height: the ``height`` reset option, if given.
    """
    if kind == "replay" and isinstance(episode, Recording):
        fields = recording_fields(episode.receiver_pose, RATE)
        if height is not None:
            fields["height"] = float(height)
    else:
        xy = np.asarray(motion.camera_xy, dtype=np.float64)
        fields = walk_fields(smooth_track(xy, RATE) if kind == "replay" else xy, RATE)
        fields["height"] = float(motion.dims.height)
    return WalkCheck(fields, check(fields, CALIBRATED_RANGE))


__all__ = ["WalkCheck", "walk_check"]
