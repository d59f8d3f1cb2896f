"""Minimum-jerk motion toward a moving target: how the receiver's hand reaches (Hoff & Arbib 1993).

Human point-to-point reaches follow the minimum-jerk profile (Flash & Hogan 1985). Reaching for
a moving object, people re-plan continuously: at every instant the hand follows the minimum-jerk
path from its current position, velocity and acceleration to the target's predicted state at
the end of the remaining movement time (Hoff & Arbib 1993). :func:`min_jerk_step` is one such
re-planned step; calling it every control step with a shrinking remaining time gives the reach.
"""

from __future__ import annotations

import math

import numpy as np

from handover_env.compiled import kernel


@kernel
def quintic(x0: float, v0: float, a0: float, x1: float, v1: float,
            d: float) -> tuple[float, float, float, float, float, float]:
    """The coefficients c0..c5 of x(s) = sum c_k s^k on one axis, the quintic from (x0, v0, a0)
    at s = 0 to (x1, v1, 0) at s = d > 0 (the powers of d as the C library's ``pow``)."""
    h = x1 - x0 - v0 * d - 0.5 * a0 * d * d
    dv = v1 - v0 - a0 * d
    da = -a0
    c3 = (10.0 * h - 4.0 * dv * d + 0.5 * da * d * d) / math.pow(d, 3.0)
    c4 = (-15.0 * h + 7.0 * dv * d - da * d * d) / math.pow(d, 4.0)
    c5 = (6.0 * h - 3.0 * dv * d + 0.5 * da * d * d) / math.pow(d, 5.0)
    return x0, v0, 0.5 * a0, c3, c4, c5


@kernel
def quintic_step(x0: float, v0: float, a0: float, x1: float, v1: float, d: float,
                 s: float) -> tuple[float, float, float]:
    """(x, v, a) at s < d along :func:`quintic` on one axis (Horner's rule)."""
    c0, c1, c2, c3, c4, c5 = quintic(x0, v0, a0, x1, v1, d)
    x = c0 + s * (c1 + s * (c2 + s * (c3 + s * (c4 + s * c5))))
    v = c1 + s * (2 * c2 + s * (3 * c3 + s * (4 * c4 + s * 5 * c5)))
    a = 2 * c2 + s * (6 * c3 + s * (12 * c4 + s * 20 * c5))
    return x, v, a


def _duration(duration: float) -> float:
    d = float(duration)
    if not d > 0:
        raise ValueError(f"duration must be > 0, got {duration}")
    return d


def min_jerk_coefficients(x0: np.ndarray, v0: np.ndarray, a0: np.ndarray, x1: np.ndarray,
                          v1: np.ndarray, duration: float) -> np.ndarray:
    """(6, ...) coefficients c of x(s) = sum c_k s^k, the quintic from (x0, v0, a0) at s = 0 to
    (x1, v1, 0) at s = ``duration`` (:func:`quintic` per axis)."""
    d = _duration(duration)
    arrays = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (x0, v0, a0, x1, v1)))
    flat = [a.ravel().tolist() for a in arrays]
    c = np.array([quintic(*axis, d) for axis in zip(*flat, strict=True)]).reshape(-1, 6)
    return c.T.reshape((6,) + arrays[0].shape)


def min_jerk_step(x0: np.ndarray, v0: np.ndarray, a0: np.ndarray, x1: np.ndarray, v1: np.ndarray,
                  duration: float, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """State (x, v, a) after ``dt`` along the minimum-jerk path to (x1, v1, a = 0) in ``duration``
    (:func:`quintic_step` per axis).

    If ``dt >= duration`` the target state is returned.
    """
    if dt >= duration:
        x1 = np.asarray(x1, dtype=np.float64)
        return x1.copy(), np.asarray(v1, dtype=np.float64).copy(), np.zeros_like(x1)
    d = _duration(duration)
    arrays = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (x0, v0, a0, x1, v1)))
    flat = [a.ravel().tolist() for a in arrays]
    out = np.array([quintic_step(*axis, d, float(dt)) for axis in zip(*flat, strict=True)])
    out = out.reshape(-1, 3)
    shape = arrays[0].shape
    return out[:, 0].reshape(shape), out[:, 1].reshape(shape), out[:, 2].reshape(shape)
