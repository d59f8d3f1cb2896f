"""A public recording with the receiver's whole skeleton: the person's replay source in the env.

:class:`handover_env.data.dataset.Episode` keeps what the planners learn from (pelvis xy, hand,
object). Replaying a recorded *person* in the env also needs the rest of the body: the ZED
BODY_34 skeleton (T, 34, 3). :func:`load_recording` reads both from one public pickle with the
same safe unpickler and validation as the dataset loader.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from handover_env.data.dataset import Episode
from handover_env.data.errors import DatasetError
from handover_env.data.limits import MAX_ABS_COORD_M, MAX_FRAMES, MIN_BONE_M
from handover_env.data.public import (
    FILE_NAME_RE,
    episode_from_record,
    safe_load_pickle,
    validate_record,
)
from handover_env.person.skeleton import N_JOINTS, shortest_bone


def position_array(value: Any, what: str, tail: tuple[int, ...]) -> np.ndarray:
    """A recorded position array, checked as :class:`Episode` checks its own, as float64.

    The one check of every replayed track and skeleton (:class:`Recording`, and
    :func:`handover_env.person.person.recorded_motion` for every replay input form).

    Args:
        value: the array (or nested lists).
        what: what it is, for the error (e.g. ``"replay receiver_xy"``).
        tail: the shape after the frame axis, e.g. ``(2,)`` or ``(34, 3)``.

    Raises:
        DatasetError: not real numbers (bools, strings, objects and complex numbers are not),
            not of shape (T, *tail) with 2 <= T <= MAX_FRAMES, NaN or inf, or a coordinate
            beyond +-MAX_ABS_COORD_M; the message begins with ``what``.
    """
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:  # ragged nested lists
        raise DatasetError(f"{what} is not an array of numbers: {exc}") from None
    if arr.dtype.kind not in "iuf":
        raise DatasetError(
            f"{what} must be an array of real numbers (ints or floats), got dtype {arr.dtype}"
        )
    shape = ", ".join(str(n) for n in tail)
    if arr.ndim != 1 + len(tail) or arr.shape[1:] != tail or arr.shape[0] < 2:
        raise DatasetError(f"{what} must have shape (T>=2, {shape}), got {arr.shape}")
    if arr.shape[0] > MAX_FRAMES:
        raise DatasetError(f"{what} has {arr.shape[0]:,} frames, more than {MAX_FRAMES:,}")
    arr = np.asarray(arr, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        raise DatasetError(f"{what} contains NaN or inf")
    peak = float(np.abs(arr).max())
    if peak > MAX_ABS_COORD_M:
        raise DatasetError(
            f"{what} reaches {peak:.3g} m, outside the +-{MAX_ABS_COORD_M:g} m a recorded "
            "position may have"
        )
    return arr


def skeleton_array(value: Any, frames: int, what: str) -> np.ndarray:
    """A recorded BODY_34 skeleton (frames, 34, 3) as float64: :func:`position_array`'s checks,
    and no bone shorter than ``MIN_BONE_M`` in any frame (an all-zero or collapsed skeleton has
    no directions to retarget the body onto).

    Raises:
        DatasetError: the message begins with ``what`` and names the bone and the frame.
    """
    pose = position_array(value, what, (N_JOINTS, 3))
    if pose.shape[0] != frames:
        raise DatasetError(
            f"{what} must have shape ({frames}, {N_JOINTS}, 3) (one skeleton per frame of the "
            f"track), got {pose.shape}"
        )
    length, frame, bone = shortest_bone(pose)
    if length < MIN_BONE_M:
        raise DatasetError(
            f"{what} is degenerate: bone {bone} is {length * 1000:.1f} mm long at frame {frame} "
            f"(every bone must be at least {MIN_BONE_M * 1000:g} mm; an all-zero skeleton has none)"
        )
    return pose


@dataclass(frozen=True)
class Recording:
    """One recorded handover with the receiver's full skeleton.

    Attributes:
        episode: the canonical episode (pelvis xy, hand, giver/object, ID/OOD, source id).
        receiver_pose: (T, 34, 3) receiver BODY_34 joints, m, raw as recorded (30 Hz).
    """

    episode: Episode
    receiver_pose: np.ndarray

    def __post_init__(self) -> None:
        if not isinstance(self.episode, Episode):
            raise DatasetError(
                f"a Recording's episode must be an Episode, got {type(self.episode).__name__}"
            )
        pose = skeleton_array(
            self.receiver_pose, self.episode.length, f"{self.episode.source_id}: receiver_pose"
        )
        pose.setflags(write=False)
        object.__setattr__(self, "receiver_pose", pose)

    @property
    def source_id(self) -> str:
        return self.episode.source_id


def load_recording(path: str | os.PathLike) -> Recording:
    """Load ``motion_normal_<i>.pkl`` / ``motion_variation_<i>.pkl`` with the receiver's skeleton.

    Raises:
        UnsafePickleError, DatasetError: as :func:`handover_env.data.public.load_public_file`.
    """
    path = Path(path)
    match = FILE_NAME_RE.fullmatch(path.name)
    if match is None:
        raise DatasetError(
            f"{path}: not a public-dataset file name (motion_normal_<i>.pkl or "
            "motion_variation_<i>.pkl)"
        )
    record = validate_record(safe_load_pickle(path), str(path))
    episode = episode_from_record(record, path.stem, is_ood=match.group(1) == "motion_variation")
    return Recording(episode=episode, receiver_pose=record["pose_receiver"].copy())
