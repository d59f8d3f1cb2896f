"""What BC-MLP and ACT share: turning feature rows into open-loop and closed-loop predictions.

Both baselines map (receiver history features, current giver xyz) rows to (H, 3) giver chunks
through ``predict_batch`` (see :mod:`handover_env.data.features`). This base class builds those rows
for
one history (``predict``), for a recorded episode at many query frames (``predict_episode``, what
the open-loop protocol calls) and from raw arrays (``predict_sequence``), and reads the robot's
TCP (``ee_pos``) as the giver state in the env (``act``).
"""

from __future__ import annotations

from abc import abstractmethod

import numpy as np

from agents.base import validate_history
from agents.predictive import PredictiveAgent
from handover_env.data.dataset import Episode
from handover_env.data.features import encode_history, episode_frames, validate_giver


class GiverConditionedAgent(PredictiveAgent):
    """A :class:`PredictiveAgent` whose network reads receiver history plus the current giver xyz.

    Subclasses set ``config`` (with ``history``, ``spec`` and ``use_giver_state``) and implement
    :meth:`predict_batch`. ``predict_rows_per_batch`` bounds the rows per network call in
    :meth:`predict_episode` (None: all rows at once).
    """

    predict_rows_per_batch: int | None = None
    _giver_now: np.ndarray | None = None

    @abstractmethod
    def predict_batch(self, env_state: np.ndarray, state: np.ndarray) -> np.ndarray:
        """(B, H, 3) giver chunks for B feature rows (env_state (B, 2W), state (B, 3))."""

    def predict(
        self, receiver_history: np.ndarray, giver_xyz: np.ndarray | None = None
    ) -> np.ndarray:
        """(H, 3) future giver xyz from the receiver history and the current giver xyz."""
        hist = validate_history(receiver_history)
        giver = validate_giver(giver_xyz) if self.config.use_giver_state else np.zeros(3)
        return self.predict_batch(encode_history(hist, self.config.history)[None], giver[None])[0]

    def predict_sequence(
        self, receiver_xy: np.ndarray, query_times: np.ndarray, giver_xyz: np.ndarray | None = None
    ) -> np.ndarray:
        """Batched open-loop predictions at ``query_times``: (Q, H, 3).

        ``giver_xyz`` is the episode's (T, 3) giver trajectory; only its rows at the query times
        (the current frames) are read.
        """
        receiver_xy = validate_history(receiver_xy)
        if giver_xyz is None:
            if self.config.use_giver_state:
                validate_giver(None)
            giver_xyz = np.zeros((receiver_xy.shape[0], 3))
        giver = np.asarray(giver_xyz, dtype=np.float64)
        if giver.shape != (receiver_xy.shape[0], 3):
            raise ValueError(
                f"giver_xyz must have shape ({receiver_xy.shape[0]}, 3), got {giver.shape}"
            )
        n = len(giver)
        episode = Episode(
            receiver_xy, np.zeros((n, 3)), giver, np.tile([1.0, 0, 0, 0], (n, 1)), False, "query"
        )
        return self.predict_episode(episode, query_times)

    def predict_episode(self, episode: Episode, query_times: np.ndarray) -> np.ndarray:
        """Open-loop predictions at frames ``query_times`` of ``episode`` (its giver gives the
        state)."""
        f = episode_frames(episode, self.config.spec, query_times)
        if len(f) == 0:
            return np.zeros((0, self.horizon, 3))
        step = self.predict_rows_per_batch or len(f)
        return np.concatenate(
            [
                self.predict_batch(f.env_state[i : i + step], f.state[i : i + step])
                for i in range(0, len(f), step)
            ]
        )

    def act(self, obs: np.ndarray) -> np.ndarray:
        """(x, y, z, yaw) target (``PredictiveAgent.act``), with ``ee_pos`` as the giver state."""
        obs = np.asarray(obs)
        if obs.shape == (self.layout.size,):
            self._giver_now = self.layout.part(obs, "ee_pos").astype(np.float64)
        return super().act(obs)
