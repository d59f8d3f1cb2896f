"""The two roles of an agent: a :class:`Predictor` and a :class:`Policy`, and :class:`Agent`,
both.

* :class:`Predictor`, open-loop (Table I, figures): ``fit(dataset)`` then
  ``predict(receiver_history) -> (H, 3)``, the predicted giver (= robot target) positions for
  the next H frames at the dataset rate.
* :class:`Policy`, closed-loop (the envs): ``reset()`` at episode start, then
  ``act(obs) -> (4,)`` once per 30 Hz env step, a Cartesian target (x, y, z, yaw) for the
  impedance controller.
* :class:`Agent`: a predictor that also acts (every planner and learned baseline here, and what a
  benchmark plug-in is: it is scored on both tracks). A policy that only acts (the RL policy)
  subclasses :class:`Policy` alone and has no ``predict``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np

from handover_env.data.dataset import Episode, HandoverDataset


def validate_history(receiver_history: np.ndarray, min_frames: int = 1) -> np.ndarray:
    """Return ``receiver_history`` as a float64 (T, 2) array or raise a clear ``ValueError``."""
    arr = np.asarray(receiver_history, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(f"receiver_history must have shape (T, 2), got {arr.shape}")
    if arr.shape[0] < min_frames:
        raise ValueError(
            f"receiver_history needs at least {min_frames} frame(s), got {arr.shape[0]}"
        )
    if not np.all(np.isfinite(arr)):
        raise ValueError("receiver_history contains NaN or inf")
    return arr


class Policy(ABC):
    """Acts in a handover env: ``reset()`` at each episode's start, ``act(obs)`` every step."""

    @abstractmethod
    def reset(self) -> None:
        """Forget the previous episode (streaming state, ensemble buffers)."""

    @abstractmethod
    def act(self, obs: np.ndarray) -> np.ndarray:
        """One 30 Hz decision in an env: (x, y, z, yaw) float32 Cartesian target."""


class Predictor(ABC):
    """Predicts the giver's next ``horizon`` positions (H frames at 30 Hz) from the receiver's
    track, after ``fit`` on demonstrations."""

    horizon: int = 30

    def fit(self, dataset: HandoverDataset) -> Predictor:  # noqa: B027 - a rule learns nothing
        """Learn from demonstrations; returns ``self``. A predictor without a learned model
        keeps this default, which learns nothing."""
        return self

    @abstractmethod
    def predict(self, receiver_history: np.ndarray) -> np.ndarray:
        """Predict the giver trajectory for the next ``horizon`` frames.

        Args:
            receiver_history: (T, 2) observed receiver base xy up to now at 30 Hz, oldest first.

        Returns:
            (horizon, 3) predicted giver wrist xyz; row 0 is the current frame's target.
        """

    def predict_sequence(self, receiver_xy: np.ndarray, query_times: np.ndarray) -> np.ndarray:
        """Open-loop predictions at several times of one episode: (Q, horizon, 3).

        Row q is ``predict(receiver_xy[: query_times[q] + 1])``. The default loops over
        :meth:`predict`; streaming agents (the SPGP planner) and batched networks override it
        with a faster equivalent that must give the same numbers.
        """
        receiver_xy = validate_history(receiver_xy)
        times = np.asarray(query_times, dtype=np.int64).reshape(-1)
        if times.size and (times.min() < 0 or times.max() >= receiver_xy.shape[0]):
            raise ValueError(f"query times must lie in [0, {receiver_xy.shape[0] - 1}]")
        return np.stack([self.predict(receiver_xy[: t + 1]) for t in times]) if times.size else (
            np.zeros((0, self.horizon, 3))
        )

    def predict_episode(self, episode: Episode, query_times: np.ndarray) -> np.ndarray:
        """Open-loop predictions at ``query_times`` of a recorded ``episode``: (Q, horizon, 3).

        This is what the open-loop protocol calls. The default uses the receiver track alone
        (:meth:`predict_sequence`), as the paper's planner does. Agents that also read the
        giver's current position (the learned baselines' ``observation.state``) override it and
        take the giver row at each query time from the episode, never a later one.
        """
        return self.predict_sequence(episode.receiver_xy, query_times)


class Agent(Predictor, Policy):
    """A :class:`Predictor` that also acts as a :class:`Policy`: scored open-loop and
    closed-loop. Subclasses set ``horizon`` (H, frames at 30 Hz) and implement ``predict``,
    ``reset`` and ``act``."""
