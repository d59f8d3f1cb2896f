"""Public-dataset-shaped recordings built from the embedded synthetic generator, for tests of the
calibration commands without the dataset.

A synthetic :class:`~handover_env.data.dataset.Episode` has the receiver's pelvis xy, right hand
and the object. :func:`write_folder` dresses each in a BODY_34 skeleton (every joint at a fixed
offset from the pelvis in the walking frame, the right arm from a shoulder at the recorded
proportions to the episode's hand) and a standing giver whose right hand holds the object while
it is within the giver's reach, and writes them as ``motion_normal_<i>.pkl`` /
``motion_variation_<i>.pkl`` pickles of numpy arrays, as the public dataset's.
"""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np

from handover_env.data.dataset import Episode
from handover_env.data.filtering import lowpass
from handover_env.person.synthetic import generate_synthetic

RATE = 30.0
PELVIS_Z = 0.92
#: Right shoulder from the pelvis: (forward, left, up), m (data: 0.17 m to the side, z 1.41).
SHOULDER = (0.0, -0.17, 0.49)
GIVER_PELVIS = np.array([-0.1, 0.0, 0.8])
GIVER_REACH = 0.9


def _frame(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Forward and left unit vectors (T, 3) of a pelvis xy track."""
    v = np.gradient(lowpass(xy, RATE, 0.5), axis=0)
    n = np.linalg.norm(v, axis=1, keepdims=True)
    fwd = np.where(n > 1e-9, v / np.maximum(n, 1e-9), np.array([-1.0, 0.0]))
    f3 = np.column_stack([fwd, np.zeros(len(fwd))])
    left = np.column_stack([-fwd[:, 1], fwd[:, 0], np.zeros(len(fwd))])
    return f3, left


def skeleton(ep: Episode, shoulder_z: float = 1.41) -> dict[str, np.ndarray]:
    """The public-dataset record (``pose_receiver``, ``pose_giver``, ``pose_object``,
    ``quat_object``) of a synthetic episode (module docstring)."""
    t = ep.length
    pelvis = np.column_stack([ep.receiver_xy, np.full(t, PELVIS_Z)])
    fwd, left = _frame(ep.receiver_xy)
    up = np.array([0.0, 0.0, 1.0])
    rng = np.random.default_rng(0)
    rest = rng.uniform(-0.15, 0.15, size=(34, 3)) * np.array([1.0, 1.0, 3.0])
    pose = pelvis[:, None, :] + (rest[None, :, 0, None] * fwd[:, None, :]
                                 + rest[None, :, 1, None] * left[:, None, :]
                                 + rest[None, :, 2, None] * up)
    pose[:, 0] = pelvis
    shoulder = pelvis + SHOULDER[1] * left + (shoulder_z - PELVIS_Z) * up
    hand = ep.receiver_hand_xyz
    pose[:, 12] = shoulder
    pose[:, 11] = shoulder + 0.13 * left
    pose[:, 13] = 0.5 * (shoulder + hand) - 0.08 * up
    away = hand - shoulder
    away /= np.maximum(np.linalg.norm(away, axis=1, keepdims=True), 1e-9)
    pose[:, 14] = hand - 0.05 * away
    pose[:, 15] = hand
    pose[:, 16] = hand + 0.05 * away
    pose[:, 17] = hand + 0.03 * away + 0.02 * up
    obj = ep.giver_xyz
    giver = np.tile(GIVER_PELVIS + rng.uniform(-0.2, 0.2, size=(34, 3)), (t, 1, 1))
    giver[:, 0] = GIVER_PELVIS
    holding = np.linalg.norm(obj[:, :2] - GIVER_PELVIS[:2], axis=1) < GIVER_REACH
    giver[holding, 14:18] = obj[holding, None, :]
    return {"pose_receiver": pose, "pose_giver": giver, "pose_object": obj.copy(),
            "quat_object": ep.object_quat.copy()}


def write_folder(folder: Path, n: int = 40, ood_fraction: float = 0.25, seed: int = 0) -> Path:
    """``n`` synthetic episodes as public-dataset pickles in ``folder`` (created)."""
    folder.mkdir(parents=True)
    counts = {"normal": 0, "variation": 0}
    for ep in generate_synthetic(n, ood_fraction, seed=seed, progress=False):
        kind = "variation" if ep.is_ood else "normal"
        path = folder / f"motion_{kind}_{counts[kind]}.pkl"
        path.write_bytes(pickle.dumps(skeleton(ep), protocol=4))
        counts[kind] += 1
    return folder
