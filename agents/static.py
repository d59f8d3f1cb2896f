"""The static handover baseline (paper Sec. V-C, after Meng et al. 2022): deliver to the detected
hand.

The receiver walks into a predefined area, stops and raises the right hand. The robot holds its
ready pose until it has detected the hand and waited the stabilisation delay (the env reports
this as ``robot_enabled`` = 1 in the observation); then it takes the hand position it sees at
that moment (``receiver_hand_xyz``, the camera estimate) and moves the object there, keeping the
gripper yaw of the ready pose. Once the fingers have let go of the object it returns to the
ready pose.

In the dynamic env ``robot_enabled`` is 1 from the start, so this agent would go to wherever the
hand is at the first step; it is meant for ``handover_env/StaticHandover-v0``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agents.base import Agent, validate_history
from handover_env.envs.observation import ObsLayout


@dataclass(frozen=True)
class StaticConfig:
    """Settings of :class:`StaticAgent`.

    Args:
        ready_pos: the ready pose (x, y, z), m (the env's ready pose).
        ready_yaw: gripper yaw while waiting and delivering, rad.
        hand_offset: added to the detected hand position to get the object's target, m (the object
            is carried at the TCP). The default puts the bottle's centre 6 cm above the hand, so
            the hand closes on its lower part, below the gripper's fingers (the part the
            simulated person takes, its switch ``grasp_below``), instead of the gripper pushing
            into the hand. ``(0, 0, -0.06)`` is the delivery for a hand that takes the top part
            (``grasp_below`` off; the static baseline of benchmark protocols v1 and v2).
        x_range, y_range, z_range: workspace clip of the delivery point, m.
        horizon: H, frames returned by :meth:`StaticAgent.predict`.
    """

    ready_pos: tuple[float, float, float] = (0.3, -0.4, 1.15)
    ready_yaw: float = -math.pi / 2
    hand_offset: tuple[float, float, float] = (0.0, 0.0, 0.06)
    x_range: tuple[float, float] = (-0.15, 0.7)
    y_range: tuple[float, float] = (-0.8, -0.35)
    z_range: tuple[float, float] = (0.9, 1.45)
    horizon: int = 30

    def __post_init__(self) -> None:
        nums = (
            *self.ready_pos,
            self.ready_yaw,
            *self.hand_offset,
            *self.x_range,
            *self.y_range,
            *self.z_range,
        )
        if not all(math.isfinite(v) for v in nums):
            raise ValueError("StaticConfig values must be finite")
        for name in ("x_range", "y_range", "z_range"):
            lo, hi = getattr(self, name)
            if lo >= hi:
                raise ValueError(f"{name} must be (low, high) with low < high, got {(lo, hi)}")
        if self.horizon < 1:
            raise ValueError(f"horizon must be >= 1, got {self.horizon}")


class StaticAgent(Agent):
    """Wait for the detected hand, then deliver the object to it (the paper's static baseline).

    Args:
        config: ready pose, hand offset and workspace.
        layout: the env's observation layout.
    """

    def __init__(self, config: StaticConfig | None = None, layout: ObsLayout | None = None) -> None:
        self.config = config or StaticConfig()
        self.layout = layout or ObsLayout()
        self.horizon = self.config.horizon
        self._goal: np.ndarray | None = None

    def reset(self) -> None:
        """Forget the hand detected in the previous episode."""
        self._goal = None

    def _clip(self, p: np.ndarray) -> np.ndarray:
        c = self.config
        lo = np.array([c.x_range[0], c.y_range[0], c.z_range[0]])
        hi = np.array([c.x_range[1], c.y_range[1], c.z_range[1]])
        return np.clip(p, lo, hi)

    def predict(self, receiver_history: np.ndarray) -> np.ndarray:
        """(H, 3): the static baseline has no forecast; it holds the ready pose until it acts on a
        detected hand, which a base track alone does not show."""
        validate_history(receiver_history)
        return np.tile(np.asarray(self.config.ready_pos, dtype=np.float64), (self.horizon, 1))

    def act(self, obs: np.ndarray) -> np.ndarray:
        """(x, y, z, yaw) float32 target for this 30 Hz step."""
        c = self.config
        layout = self.layout
        ready = np.array([*c.ready_pos, c.ready_yaw], dtype=np.float32)
        if layout.gripper_open(obs) and not layout.object_held(obs):
            return ready  # released and let go: back to the ready pose
        if self._goal is None:
            if not layout.robot_enabled(obs):
                return ready
            hand = layout.part(obs, "receiver_hand_xyz").astype(np.float64)
            self._goal = self._clip(hand + np.asarray(c.hand_offset))
        return np.array([*self._goal, c.ready_yaw], dtype=np.float32)
