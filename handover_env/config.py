"""Handover parameters Theta = {K, B, t_f, f_r} (paper Sec. IV-B) with the paper's learned
defaults."""

from __future__ import annotations

import math
import numbers
from dataclasses import asdict, dataclass

# CoSpar search ranges from the paper (Sec. V-B-1): K in [80, 140], B in [10, 20],
# t_f in [0, 1] s, f_r in [5, 20] N.
THETA_RANGES: dict[str, tuple[float, float]] = {
    "stiffness": (80.0, 140.0),
    "damping": (10.0, 20.0),
    "forecast_time": (0.0, 1.0),
    "release_force": (5.0, 20.0),
}


#: Θ's fields the robot reads, in the env: K and B in the impedance controller (Eq. 1), f_r in
#: the release (tests/eval/test_theta_split.py: the env reads these and no other).
ROBOT_FIELDS: tuple[str, ...] = ("stiffness", "damping", "release_force")
#: Θ's field the agent reads: t_f, how far ahead its target x_d(t + t_f) is (no agent reads a
#: robot field).
AGENT_FIELDS: tuple[str, ...] = ("forecast_time",)


@dataclass(frozen=True)
class HandoverParams:
    """The jointly tuned handover parameters Theta (paper Sec. IV-B).

    Defaults are the paper's learned Theta-hat = [114.3, 17.1, 0.14, 7.1]. One value travels to
    both sides of the closed loop: the env reads :data:`ROBOT_FIELDS`, the agent
    :data:`AGENT_FIELDS`.

    Args:
        stiffness: translational Cartesian stiffness K in N/m (Eq. 1).
        damping: translational Cartesian damping B in N*s/m (Eq. 1).
        forecast_time: t_f in seconds; the robot tracks x_d(t + t_f) instead of x_d(t).
        release_force: f_r in newtons; the gripper opens when the external force exceeds it.
    """

    stiffness: float = 114.3
    damping: float = 17.1
    forecast_time: float = 0.14
    release_force: float = 7.1

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            if (
                isinstance(value, bool)
                or not isinstance(value, numbers.Real)
                or not math.isfinite(value)
            ):
                raise ValueError(f"{name} must be a finite number, got {value!r}")
            object.__setattr__(self, name, float(value))
        if self.stiffness <= 0 or self.damping < 0:
            raise ValueError(
                f"need stiffness > 0 and damping >= 0, got K={self.stiffness}, B={self.damping}"
            )
        if self.forecast_time < 0:
            raise ValueError(f"forecast_time must be >= 0, got {self.forecast_time}")
        if self.release_force <= 0:
            raise ValueError(f"release_force must be > 0, got {self.release_force}")

    def as_array(self) -> tuple[float, float, float, float]:
        """(K, B, t_f, f_r) in the paper's order."""
        return (self.stiffness, self.damping, self.forecast_time, self.release_force)
