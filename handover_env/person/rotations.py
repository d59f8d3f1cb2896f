"""Rotations of the person's body: swings, frames, yaws and quaternions, and a vector's length.

The rotation library of :mod:`handover_env.person.skeleton` (retargeting), :mod:`.gait` (the
walking pose and the arm's inverse kinematics), :mod:`.pose` and :mod:`.person`:

* :func:`swing`: the smallest rotation taking one direction onto another (Rodrigues), batched,
  with one pair of 3-vectors computed in floats bit for bit as the batched form;
* :func:`triad`: an orthonormal frame from a primary and a secondary direction;
* :func:`yaw_matrix`: a rotation about world z;
* :func:`mat_to_quat`: rotation matrices to unit quaternions (w, x, y, z), w >= 0;
* :func:`length`: ``np.linalg.norm``'s value of one vector without its Python-level checks.

Rotation matrices are (..., 3, 3) with a frame's x, y, z axes as columns.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from handover_env.person.posing import swing_mat

#: Up to this many matrices, :func:`mat_to_quat` calls MuJoCo per matrix.
_FEW_MATRICES = 32


def _normalize(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, 1e-12)


def swing(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(..., 3, 3) smallest rotation taking direction ``a`` onto direction ``b`` (Rodrigues).

    Antiparallel inputs (a rotation of pi, whose axis is undefined) turn about any axis normal to
    ``a``; the body never needs it (a limb would have to point straight back up along its parent).
    """
    if a.shape == b.shape == (3,) and a.dtype == b.dtype == np.float64:
        # one pair (a pose's arm): the same arithmetic in floats
        return _swing_one(a, b)
    a, b = _normalize(a), _normalize(b)
    v = np.cross(a, b)
    c = np.sum(a * b, axis=-1)
    vx = np.zeros(v.shape[:-1] + (3, 3))
    vx[..., 0, 1], vx[..., 0, 2], vx[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    vx[..., 1, 0], vx[..., 2, 0], vx[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    k = 1.0 / np.maximum(1.0 + c, 1e-9)
    eye = np.broadcast_to(np.eye(3), vx.shape)
    return eye + vx + (vx @ vx) * k[..., None, None]


def length(v: np.ndarray) -> float:
    """|v| of a vector, ``np.linalg.norm``'s value: for a contiguous float64 1-D array the same
    BLAS dot product it takes, without its Python-level checks (a pose's few norms per step)."""
    v = np.asarray(v)
    if v.dtype == np.float64 and v.ndim == 1 and v.flags.c_contiguous:
        return math.sqrt(v.dot(v))
    return float(np.linalg.norm(v))


def _swing_one(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`swing` of one pair of 3-vectors (:func:`handover_env.person.posing.swing_mat`, the
    same arithmetic in the same order as the batched form: bit for bit its value)."""
    return np.array(swing_mat(*a.tolist(), *b.tolist())).reshape(3, 3)


def triad(primary: np.ndarray, secondary: np.ndarray) -> np.ndarray:
    """(..., 3, 3) orthonormal frame with z along ``primary`` and y toward ``secondary``."""
    z = _normalize(primary)
    y = _normalize(secondary - np.sum(secondary * z, axis=-1, keepdims=True) * z)
    x = np.cross(y, z)
    return np.stack([x, y, z], axis=-1)


def yaw_matrix(yaw: np.ndarray | float) -> np.ndarray:
    """(..., 3, 3) rotation by ``yaw`` about world z."""
    yaw = np.asarray(yaw, dtype=np.float64)
    c, s = np.cos(yaw), np.sin(yaw)
    out = np.zeros(yaw.shape + (3, 3))
    out[..., 0, 0], out[..., 0, 1], out[..., 1, 0], out[..., 1, 1] = c, -s, s, c
    out[..., 2, 2] = 1.0
    return out


def mat_to_quat(rot: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions (w, x, y, z) of rotation matrices (..., 3, 3), w >= 0.

    A few matrices (one pose per env step) go through MuJoCo's ``mju_mat2Quat``, many (a whole
    recording) through the vectorised branch-free form below: the same quaternions either way.
    """
    if rot.size <= 9 * _FEW_MATRICES:
        flat = np.ascontiguousarray(rot, dtype=np.float64).reshape(-1, 9)
        out = np.empty((flat.shape[0], 4))
        for i in range(flat.shape[0]):
            mujoco.mju_mat2Quat(out[i], flat[i])
        out *= np.where(out[:, :1] < 0, -1.0, 1.0)
        return out.reshape(rot.shape[:-2] + (4,))
    m = rot
    tr = m[..., 0, 0] + m[..., 1, 1] + m[..., 2, 2]
    cands = np.stack(
        [
            np.stack(
                [
                    1 + tr,
                    m[..., 2, 1] - m[..., 1, 2],
                    m[..., 0, 2] - m[..., 2, 0],
                    m[..., 1, 0] - m[..., 0, 1],
                ],
                -1,
            ),
            np.stack(
                [
                    m[..., 2, 1] - m[..., 1, 2],
                    1 + m[..., 0, 0] - m[..., 1, 1] - m[..., 2, 2],
                    m[..., 0, 1] + m[..., 1, 0],
                    m[..., 0, 2] + m[..., 2, 0],
                ],
                -1,
            ),
            np.stack(
                [
                    m[..., 0, 2] - m[..., 2, 0],
                    m[..., 0, 1] + m[..., 1, 0],
                    1 - m[..., 0, 0] + m[..., 1, 1] - m[..., 2, 2],
                    m[..., 1, 2] + m[..., 2, 1],
                ],
                -1,
            ),
            np.stack(
                [
                    m[..., 1, 0] - m[..., 0, 1],
                    m[..., 0, 2] + m[..., 2, 0],
                    m[..., 1, 2] + m[..., 2, 1],
                    1 - m[..., 0, 0] - m[..., 1, 1] + m[..., 2, 2],
                ],
                -1,
            ),
        ],
        axis=-2,
    )
    diag = np.stack([tr, m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]], axis=-1)
    best = np.argmax(diag, axis=-1)
    q = np.take_along_axis(cands, best[..., None, None], axis=-2)[..., 0, :]
    q = _normalize(q)
    return q * np.where(q[..., :1] < 0, -1.0, 1.0)
