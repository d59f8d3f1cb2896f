"""Closed-loop use of any trajectory predictor: streaming chunks -> ``act(obs)`` targets.

Shared by the SPGP planner, IAAL and the learned baselines (BC-MLP, ACT). A subclass of
:class:`PredictiveAgent` only implements :meth:`Agent.predict` (receiver history -> (H, 3) giver
chunk, row 0 = the current frame). It may also override the streaming hooks
:meth:`PredictiveAgent.stream_reset`, :meth:`PredictiveAgent.stream_update` and
:meth:`PredictiveAgent.stream_predict` to pay only for the newest frame (the SPGP planner keeps
running sums); the default hooks keep the history and call ``predict`` on it.

Per env step (paper Sec. IV-B/C):

1. The new camera frames in ``obs`` (counted with ``receiver_frames_seen``; normally one per
   30 Hz step) are fed to ``stream_update``; after the newest one ``stream_predict`` gives a
   chunk that starts at that frame and goes into a :class:`TemporalEnsembler` (ACT's
   exponential weights, chunk 30 = 1 s as in the paper's real-world setting).
2. The position target is the ensembled trajectory at frame ``f_now + t_f * 30``: the forecast
   time t_f of Theta (default 0.14 s = 4.2 frames), linearly interpolated between 30 Hz rows.
3. **Yaw rule:** the gripper's approach axis points from the target toward the receiver's
   current base position, ``yaw = atan2(y_r - y_t, x_r - x_t)``, clipped to
   ``ready_yaw +- max_yaw_turn`` (the robot faces the receiver's path, -y, and turns at most
   45 deg toward where the receiver is; the rotation is otherwise fixed, gripper horizontal).
4. **Ready pose** until the receiver has been seen for ``min_frames`` frames (the first
   velocities are meaningless) and again once the gripper has released and its fingers have let
   go of the object (until then it holds its last target).

A decrease of ``receiver_frames_seen`` (a new env episode without ``reset()``) resets the
agent. The current observation is available to the hooks as ``self.last_obs`` (agents that
also condition on the robot's own TCP position, like the learned baselines, read ``ee_pos``
from it with ``self.layout.part``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agents.base import Agent, validate_history
from agents.temporal_ensemble import TemporalEnsembler
from handover_env.config import HandoverParams
from handover_env.envs.observation import ObsLayout


@dataclass(frozen=True)
class ClosedLoopConfig:
    """How predicted chunks become env targets.

    Args:
        ensemble_m: ACT's exponential weight rate m (i = 0 is the oldest chunk; see
            :mod:`agents.temporal_ensemble`).
        min_frames: camera frames of the receiver needed before leaving the ready pose.
        ready_pos: the ready (and post-release) position (x, y, z), m, in the dataset/env frame.
        ready_yaw: the ready yaw, rad (-pi/2: facing the receiver's path at -y).
        max_yaw_turn: the largest turn away from ``ready_yaw`` toward the receiver, rad.
        rate_hz: camera / decision rate.
    """

    ensemble_m: float = 0.01
    min_frames: int = 3
    ready_pos: tuple[float, float, float] = (0.3, -0.4, 1.15)
    ready_yaw: float = -math.pi / 2
    max_yaw_turn: float = math.pi / 4
    rate_hz: float = 30.0

    def __post_init__(self) -> None:
        nums = (self.ensemble_m, self.ready_yaw, self.max_yaw_turn, self.rate_hz, *self.ready_pos)
        if not all(math.isfinite(float(v)) for v in nums):
            raise ValueError("ClosedLoopConfig values must be finite")
        if len(self.ready_pos) != 3:
            raise ValueError(f"ready_pos must be (x, y, z), got {self.ready_pos!r}")
        if not isinstance(self.min_frames, (int, np.integer)) or self.min_frames < 1:
            raise ValueError(f"min_frames must be an integer >= 1, got {self.min_frames!r}")
        if self.max_yaw_turn < 0 or self.rate_hz <= 0:
            raise ValueError("max_yaw_turn must be >= 0 and rate_hz > 0")


class PredictiveAgent(Agent):
    """Base class of agents that predict giver chunks; provides ``reset``/``act``.

    Args:
        params: Θ; the agent reads its t_f (:data:`handover_env.config.AGENT_FIELDS`).
        closed_loop: ensembling, ready pose and yaw settings.
        layout: the env's observation layout.
    """

    def __init__(
        self,
        params: HandoverParams | None = None,
        closed_loop: ClosedLoopConfig | None = None,
        layout: ObsLayout | None = None,
    ) -> None:
        self.params = params or HandoverParams()
        self.closed_loop = closed_loop or ClosedLoopConfig()
        self.layout = layout or ObsLayout()
        self._ensembler: TemporalEnsembler | None = None
        self._history: list[np.ndarray] = []
        self._frames_seen = 0
        self._last: np.ndarray | None = None
        self.last_obs: np.ndarray | None = None

    # ------------------------------------------------------------------ streaming hooks
    def stream_reset(self) -> None:
        """Forget the streamed receiver frames (override together with the other hooks)."""
        self._history = []

    def stream_update(self, receiver_xy: np.ndarray) -> None:
        """Take one new 30 Hz receiver frame (2,)."""
        self._history.append(validate_history(np.reshape(receiver_xy, (1, 2)))[0])

    def stream_predict(self) -> np.ndarray:
        """(H, 3) chunk for the newest frame; the default calls ``predict`` on the whole history."""
        return self.predict(np.asarray(self._history))

    # ------------------------------------------------------------------ closed loop
    def reset(self) -> None:
        """Forget the episode: streaming state, ensemble buffer, frame counter."""
        self.stream_reset()
        self._ensembler = TemporalEnsembler(self.horizon, self.closed_loop.ensemble_m)
        self._frames_seen = 0
        self._last: np.ndarray | None = None

    def _ready(self) -> np.ndarray:
        c = self.closed_loop
        return np.array([*c.ready_pos, c.ready_yaw], dtype=np.float32)

    def act(self, obs: np.ndarray) -> np.ndarray:
        """(x, y, z, yaw) float32 target for this 30 Hz step (see the module docstring)."""
        c = self.closed_loop
        obs = np.asarray(obs)
        if obs.shape != (self.layout.size,):
            raise ValueError(f"observation must have shape ({self.layout.size},), got {obs.shape}")
        if self._ensembler is None:
            self.reset()
        layout = self.layout
        seen = layout.frames_seen(obs)
        if seen < self._frames_seen:
            self.reset()
        self.last_obs = obs
        if layout.gripper_open(obs):
            # Released: hold the last target while the fingers open around the object (pulling
            # away now would drag it out of the person's hand), then go back to the ready pose.
            if layout.object_held(obs) and self._last is not None:
                return self._last.copy()
            return self._ready()
        if seen < 1:
            return self._ready()
        new = seen - self._frames_seen
        track = layout.receiver_track(obs).astype(np.float64)
        if new > 0:
            for row in track[-min(new, track.shape[0]):]:
                self.stream_update(row)
            self._frames_seen = seen
            self._ensembler.add(self.stream_predict(), seen - 1)
        if seen < c.min_frames or self._ensembler.empty:
            return self._ready()
        frame = (seen - 1) + self.params.forecast_time * c.rate_hz
        target = self._ensembler.at(frame)
        receiver = track[-1]
        yaw = math.atan2(receiver[1] - target[1], receiver[0] - target[0])
        turn = (yaw - c.ready_yaw + math.pi) % (2 * math.pi) - math.pi
        yaw = c.ready_yaw + min(max(turn, -c.max_yaw_turn), c.max_yaw_turn)
        self._last = np.array([target[0], target[1], target[2], yaw], dtype=np.float32)
        return self._last.copy()
