"""The reactive baseline agent: hand over at an offset from the receiver, extrapolated by t_f.

From the observed receiver base track alone (``ObsLayout.receiver_track``), the handover point is

    p(t + t_f) = [x_r + v_x t_f - forward, y_r + v_y t_f + lateral, height]

i.e. the receiver's current (smoothed) pelvis position, moved toward the robot (+y, the side the
receiver's right hand faces) and slightly ahead along the walk, extrapolated by the forecast time
t_f of Θ at the receiver's current velocity (paper Sec. IV-B: the robot tracks x_d(t + t_f)). It
is clipped to the robot's workspace. Before the receiver is near (its handover point farther
than ``engage_distance`` from the robot base in x) it holds the ready pose; after the release it
holds its last target until the fingers have let go of the object (``object_held`` = 0), then
returns to the ready pose. The gripper yaw points at the receiver's path (-y), turned toward where
the receiver comes
from by at most ``max_yaw_turn``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agents.base import Agent, validate_history
from handover_env.config import HandoverParams
from handover_env.envs.observation import ObsLayout

RATE = 30.0


@dataclass(frozen=True)
class ReactiveConfig:
    """Settings of :class:`ReactiveAgent`.

    Args:
        lateral_offset: m from the receiver's pelvis toward the robot (+y).
        forward_offset: m ahead of the pelvis along -x (where the right hand reaches).
        handover_height: m, fixed handover height (dataset median about 1.27 m at transfer).
        velocity_window: frames used to estimate the receiver velocity (least-squares slope).
        engage_distance: m; the agent leaves the ready pose when the handover point is within
            this x-distance of the robot base.
        ready_pos: the ready pose (x, y, z), m.
        ready_yaw: the ready gripper yaw, rad.
        x_range, y_range: the workspace clip of the handover point, m.
        horizon: H, frames returned by :meth:`ReactiveAgent.predict`.
    """

    lateral_offset: float = 0.42
    forward_offset: float = 0.1
    handover_height: float = 1.2
    velocity_window: int = 8
    engage_distance: float = 1.2
    ready_pos: tuple[float, float, float] = (0.3, -0.4, 1.15)
    ready_yaw: float = -math.pi / 2
    x_range: tuple[float, float] = (-0.15, 0.7)
    y_range: tuple[float, float] = (-0.8, -0.35)
    horizon: int = 30

    def __post_init__(self) -> None:
        nums = (
            self.lateral_offset,
            self.forward_offset,
            self.handover_height,
            self.engage_distance,
            self.ready_yaw,
            *self.ready_pos,
            *self.x_range,
            *self.y_range,
        )
        if not all(math.isfinite(v) for v in nums):
            raise ValueError("ReactiveConfig values must be finite")
        if self.velocity_window < 2 or self.horizon < 1:
            raise ValueError("velocity_window must be >= 2 and horizon >= 1")
        if self.x_range[0] >= self.x_range[1] or self.y_range[0] >= self.y_range[1]:
            raise ValueError("x_range and y_range must be (low, high) with low < high")
        if not 0.5 <= self.handover_height <= 2.0:
            raise ValueError(f"handover_height must be in [0.5, 2] m, got {self.handover_height}")


class ReactiveAgent(Agent):
    """Constant-velocity reactive handover agent (the baseline every other agent is measured
    against).

    Args:
        params: Θ; the agent reads its t_f (:data:`handover_env.config.AGENT_FIELDS`).
        config: offsets, height, ready pose and workspace.
        layout: the env's observation layout.
    """

    def __init__(self, params: HandoverParams | None = None, config: ReactiveConfig | None = None,
                 layout: ObsLayout | None = None) -> None:
        self.params = params or HandoverParams()
        self.config = config or ReactiveConfig()
        self.layout = layout or ObsLayout()
        self.horizon = self.config.horizon
        self._last: np.ndarray | None = None

    def reset(self) -> None:
        """Forget the last target (kept only to hold still while the fingers open)."""
        self._last = None

    def _velocity(self, hist: np.ndarray) -> np.ndarray:
        n = min(self.config.velocity_window, hist.shape[0])
        if n < 2:
            return np.zeros(2)
        seg = hist[-n:]
        t = (np.arange(n) - (n - 1) / 2.0) / RATE
        return (t @ (seg - seg.mean(axis=0))) / (t @ t)

    def _point(self, xy: np.ndarray, vel: np.ndarray, dt: float) -> np.ndarray:
        c = self.config
        p = np.array(
            [
                xy[0] + vel[0] * dt - c.forward_offset,
                xy[1] + vel[1] * dt + c.lateral_offset,
                c.handover_height,
            ]
        )
        p[0] = min(max(p[0], c.x_range[0]), c.x_range[1])
        p[1] = min(max(p[1], c.y_range[0]), c.y_range[1])
        return p

    def predict(self, receiver_history: np.ndarray) -> np.ndarray:
        """(H, 3) handover points for the next H frames by constant-velocity extrapolation.

        Row k is the point at time (k / 30 s + t_f) ahead of the last observed frame.
        """
        hist = validate_history(receiver_history)
        vel = self._velocity(hist)
        xy = hist[-1]
        out = np.empty((self.horizon, 3))
        for k in range(self.horizon):
            out[k] = self._point(xy, vel, k / RATE + self.params.forecast_time)
        return out

    def act(self, obs: np.ndarray) -> np.ndarray:
        """(x, y, z, yaw) float32 target for this 30 Hz step."""
        c = self.config
        layout = self.layout
        track = layout.receiver_track(obs)
        released, held = layout.gripper_open(obs), layout.object_held(obs)
        frames = layout.frames_seen(obs)
        ready = np.array([*c.ready_pos, c.ready_yaw], dtype=np.float32)
        if released and held and self._last is not None:
            # The fingers are still opening: stay put instead of yanking the object back.
            return self._last.copy()
        if released or frames < 1:
            return ready
        vel = self._velocity(track)
        p = self._point(track[-1], vel, self.params.forecast_time)
        unclipped_x = track[-1][0] + vel[0] * self.params.forecast_time - c.forward_offset
        if unclipped_x > c.x_range[1] + c.engage_distance:
            return ready
        # Yaw: point at the receiver's path, turned up to 20 deg toward where it comes from (+x).
        lateral = max(0.1, p[1] - (track[-1][1]))
        turn = math.atan2(max(0.0, track[-1][0] - p[0]), lateral)
        yaw = c.ready_yaw + min(turn, math.radians(20.0))
        self._last = np.array([p[0], p[1], p[2], yaw], dtype=np.float32)
        return self._last.copy()
