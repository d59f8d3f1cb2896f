"""Minimum-jerk motion toward a moving target: how the receiver's hand reaches (Hoff & Arbib 1993).

Human point-to-point reaches follow the minimum-jerk profile (Flash & Hogan 1985). Reaching for
a moving object, people re-plan continuously: at every instant the hand follows the minimum-jerk
path from its current position, velocity and acceleration to the target's predicted state at
the end of the remaining movement time (Hoff & Arbib 1993). :func:`min_jerk_step` is one such
re-planned step; calling it every control step with a shrinking remaining time gives the reach.
"""

from __future__ import annotations

import numpy as np


def min_jerk_coefficients(x0: np.ndarray, v0: np.ndarray, a0: np.ndarray, x1: np.ndarray,
                          v1: np.ndarray, duration: float) -> np.ndarray:
    """(6, ...) coefficients c of x(s) = sum c_k s^k, the quintic from (x0, v0, a0) at s = 0 to
    (x1, v1, 0) at s = ``duration``."""
    d = float(duration)
    if not d > 0:
        raise ValueError(f"duration must be > 0, got {duration}")
    x0, v0, a0 = (np.asarray(v, dtype=np.float64) for v in (x0, v0, a0))
    h = np.asarray(x1, dtype=np.float64) - x0 - v0 * d - 0.5 * a0 * d * d
    dv = np.asarray(v1, dtype=np.float64) - v0 - a0 * d
    da = -a0
    c3 = (10.0 * h - 4.0 * dv * d + 0.5 * da * d * d) / d**3
    c4 = (-15.0 * h + 7.0 * dv * d - da * d * d) / d**4
    c5 = (6.0 * h - 3.0 * dv * d + 0.5 * da * d * d) / d**5
    return np.stack([x0, v0, 0.5 * a0, c3, c4, c5])


def min_jerk_step(x0: np.ndarray, v0: np.ndarray, a0: np.ndarray, x1: np.ndarray, v1: np.ndarray,
                  duration: float, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """State (x, v, a) after ``dt`` along the minimum-jerk path to (x1, v1, a = 0) in ``duration``.

    If ``dt >= duration`` the target state is returned.
    """
    if dt >= duration:
        x1 = np.asarray(x1, dtype=np.float64)
        return x1.copy(), np.asarray(v1, dtype=np.float64).copy(), np.zeros_like(x1)
    c = min_jerk_coefficients(x0, v0, a0, x1, v1, duration)
    s = float(dt)
    x = c[0] + s * (c[1] + s * (c[2] + s * (c[3] + s * (c[4] + s * c[5]))))
    v = c[1] + s * (2 * c[2] + s * (3 * c[3] + s * (4 * c[4] + s * 5 * c[5])))
    a = 2 * c[2] + s * (6 * c[3] + s * (12 * c[4] + s * 20 * c[5]))
    return x, v, a
