"""The giver-replay reference agent: the robot moves the object along the recorded human giver's
path.

In a replayed recording the human giver's object path (``Episode.giver_xyz``, OptiTrack) is the
ground truth of where the object was, frame by frame. This agent feeds that path through the same
closed-loop wrapper as every planner (:class:`agents.predictive.PredictiveAgent`: ACT-style
temporal ensembling of 1 s chunks, forecast time t_f, the yaw rule, the ready pose), so its
chunk at frame f is simply the recording's next 30 frames. It is the reference that says
whether a simulated handover happens where the recorded one did: give it the episode the
receiver replays (:meth:`GiverReplayAgent.set_episode`) before each env episode.

It needs the recording and is not a method one could deploy: it predicts perfectly.
"""

from __future__ import annotations

import numpy as np

from agents.base import validate_history
from agents.predictive import ClosedLoopConfig, PredictiveAgent
from handover_env.config import HandoverParams
from handover_env.data.dataset import Episode
from handover_env.envs.observation import ObsLayout


class GiverReplayAgent(PredictiveAgent):
    """Replays the recorded giver's object path with the common closed-loop wrapper.

    Args:
        episode: the recording to follow (or set later with :meth:`set_episode`).
        params: Theta (t_f is used).
        closed_loop: ensembling, ready pose and yaw settings.
        layout: the env's observation layout.
    """

    def __init__(
        self,
        episode: Episode | None = None,
        params: HandoverParams | None = None,
        closed_loop: ClosedLoopConfig | None = None,
        layout: ObsLayout | None = None,
    ) -> None:
        super().__init__(params, closed_loop, layout)
        self._giver: np.ndarray | None = None
        if episode is not None:
            self.set_episode(episode)

    def set_episode(self, episode: Episode | np.ndarray) -> None:
        """Follow ``episode.giver_xyz`` (or a (T, 3) array of object positions at 30 Hz)."""
        giver = np.asarray(getattr(episode, "giver_xyz", episode), dtype=np.float64)
        if giver.ndim != 2 or giver.shape[1] != 3 or giver.shape[0] < 1:
            raise ValueError(f"giver path must have shape (T, 3), got {giver.shape}")
        if not np.all(np.isfinite(giver)):
            raise ValueError("giver path contains NaN or inf")
        self._giver = giver

    def predict(self, receiver_history: np.ndarray) -> np.ndarray:
        """(30, 3): the recorded object positions from the current frame on (the last frame is
        held beyond the recording's end)."""
        if self._giver is None:
            raise RuntimeError("GiverReplayAgent needs set_episode() before predict()/act()")
        frame = validate_history(receiver_history).shape[0] - 1
        idx = np.minimum(np.arange(frame, frame + self.horizon), self._giver.shape[0] - 1)
        return self._giver[idx].copy()
