"""A public recording with the receiver's whole skeleton, for replaying a person in the env.

:class:`handover_env.data.dataset.Episode` keeps what the planners learn from (pelvis xy, hand,
object). Replaying a recorded *person* in the env also needs the rest of the body: the ZED
BODY_34 skeleton (T, 34, 3). :func:`load_recording` reads both from one public pickle with the
same safe unpickler and validation as the dataset loader.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from handover_env.data.dataset import DatasetError, Episode
from handover_env.data.public import (
    _NAME_RE,
    _validate_record,
    episode_from_record,
    safe_load_pickle,
)


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
        pose = np.asarray(self.receiver_pose, dtype=np.float64)
        if pose.ndim != 3 or pose.shape[1:] != (34, 3):
            raise DatasetError(
                f"{self.episode.source_id}: receiver_pose must be (T, 34, 3), got {pose.shape}"
            )
        if pose.shape[0] != self.episode.length:
            raise DatasetError(
                f"{self.episode.source_id}: receiver_pose has {pose.shape[0]} frames, "
                f"the episode {self.episode.length}"
            )
        if not np.all(np.isfinite(pose)):
            raise DatasetError(f"{self.episode.source_id}: receiver_pose contains NaN or inf")
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
    match = _NAME_RE.match(path.name)
    if match is None:
        raise DatasetError(
            f"{path}: not a public-dataset file name (motion_normal_<i>.pkl or "
            "motion_variation_<i>.pkl)"
        )
    record = _validate_record(safe_load_pickle(path), str(path))
    episode = episode_from_record(record, path.stem, is_ood=match.group(1) == "motion_variation")
    return Recording(episode=episode, receiver_pose=record["pose_receiver"].copy())
