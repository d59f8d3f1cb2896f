"""Toy users with a quadratic utility over Theta, for unit tests of the CoSpar algorithm only.

They answer "which of the two was better?" with the probit noise CoSpar assumes (paper Eq. 2),
from a utility that is a function of Theta itself: a test of the learner, never of the handover.
The study's participants, who judge real episodes, are :mod:`agents.participants`. The ideals
are drawn uniformly in the paper's ranges (not around any learned Theta-hat).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handover_env.config import THETA_RANGES

_NAMES = ("stiffness", "damping", "forecast_time", "release_force")
_LOW = np.array([THETA_RANGES[n][0] for n in _NAMES])
_SPAN = np.array([THETA_RANGES[n][1] - THETA_RANGES[n][0] for n in _NAMES])


@dataclass
class QuadraticUser:
    """A participant whose satisfaction falls off quadratically around an ideal Theta.

    Args:
        ideal: (4,) preferred (K, B, t_f, f_r).
        sensitivity: (4,) weight of each parameter's squared error, in range-normalised units.
        noise: probit noise of the answers (utility units); 0 answers deterministically.
        seed: seeds the answer noise.
    """

    ideal: np.ndarray
    sensitivity: np.ndarray
    noise: float = 0.05
    seed: int = 0

    def __post_init__(self) -> None:
        self.ideal = np.asarray(self.ideal, dtype=np.float64).reshape(4)
        self.sensitivity = np.asarray(self.sensitivity, dtype=np.float64).reshape(4)
        if not (np.all(np.isfinite(self.ideal)) and np.all(self.sensitivity >= 0)):
            raise ValueError("ideal must be finite and sensitivity non-negative")
        if self.noise < 0:
            raise ValueError(f"noise must be >= 0, got {self.noise}")
        self._rng = np.random.default_rng(self.seed)

    def utility(self, theta: np.ndarray) -> float:
        """Latent satisfaction of Theta (higher is better, 0 at the ideal)."""
        z = (np.asarray(theta, dtype=np.float64).reshape(4) - self.ideal) / _SPAN
        return float(-np.sum(self.sensitivity * z**2))

    def prefers(self, a: np.ndarray, b: np.ndarray) -> bool:
        """True when the user says handover ``a`` was better than ``b`` (paper Eq. 2 noise
        model)."""
        margin = self.utility(a) - self.utility(b)
        if self.noise > 0:
            margin += np.sqrt(2.0) * self.noise * self._rng.standard_normal()
        return bool(margin > 0)


def sample_users(n: int, seed: int = 0, noise: float = 0.05) -> list[QuadraticUser]:
    """``n`` toy users with ideals uniform in the paper's ranges."""
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    rng = np.random.default_rng(seed)
    users = []
    for i in range(n):
        ideal = _LOW + _SPAN * rng.uniform(0.1, 0.9, size=4)
        sensitivity = rng.uniform(0.5, 2.0, size=4)
        users.append(QuadraticUser(ideal, sensitivity, noise=noise, seed=seed * 1000 + i))
    return users
