"""An external agent for the benchmark, in one file outside the project's packages.

    python evaluate.py benchmark --agent examples/my_agent.py:make_agent --quick
    python evaluate.py leaderboard results/benchmark-quick/*/result.json

It is a new trajectory predictor plugged into the project's predictive wrapper
(``agents.predictive.PredictiveAgent``), which turns predicted giver chunks into closed-loop
robot targets exactly as it does for the SPGP planner, BC-MLP and ACT (temporal ensembling,
the forecast time t_f of Θ, the yaw rule, the ready pose). A predictor only implements
``predict`` (and ``fit`` if it learns):

* ``fit(dataset)``: here a ridge regression, closed form, from the receiver's current state
  (pelvis x, y and its velocity over the last 8 frames) to the giver's next H positions, on
  every frame of every training episode the benchmark gives it (Table I's training folds for
  the open-loop track, the closed loop's fold models; all of --data with --replay-data).
* ``predict(receiver_history) -> (H, 3)``: row 0 is the current frame, row k is k / 30 s ahead.

Nothing here is special to the project: copy this file anywhere and point ``--agent`` at it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agents.base import validate_history
from agents.predictive import PredictiveAgent

RATE = 30.0


@dataclass(frozen=True)
class RidgeConfig:
    """horizon: predicted frames (the protocol compares 30); window: frames of the velocity
    estimate; ridge: the L2 penalty."""

    horizon: int = 30
    window: int = 8
    ridge: float = 1e-3


def features(history: np.ndarray, window: int) -> np.ndarray:
    """[1, x, y, vx, vy] of the newest frame: position and least-squares velocity (m/s)."""
    n = min(window, history.shape[0])
    seg = history[-n:]
    if n < 2:
        vel = np.zeros(2)
    else:
        t = (np.arange(n) - (n - 1) / 2.0) / RATE
        vel = (t @ (seg - seg.mean(axis=0))) / (t @ t)
    return np.concatenate([[1.0], history[-1], vel])


class RidgeAgent(PredictiveAgent):
    """A linear map from the receiver's state to the next H giver positions."""

    def __init__(self, config: RidgeConfig | None = None) -> None:
        super().__init__()
        self.config = config or RidgeConfig()
        self.horizon = self.config.horizon
        self.weights: np.ndarray | None = None  # (5, H * 3)

    def fit(self, dataset) -> RidgeAgent:
        c = self.config
        xs, ys = [], []
        for ep in dataset:
            for t in range(1, ep.length - c.horizon):
                xs.append(features(ep.receiver_xy[: t + 1], c.window))
                ys.append(ep.giver_xyz[t : t + c.horizon].reshape(-1))
        if not xs:
            raise ValueError("no training episode is longer than the horizon")
        x, y = np.asarray(xs), np.asarray(ys)
        gram = x.T @ x + c.ridge * len(x) * np.eye(x.shape[1])
        self.weights = np.linalg.solve(gram, x.T @ y)
        return self

    def predict(self, receiver_history: np.ndarray) -> np.ndarray:
        if self.weights is None:
            raise RuntimeError("fit the agent before predicting")
        hist = validate_history(receiver_history)
        return (features(hist, self.config.window) @ self.weights).reshape(self.horizon, 3)


def make_agent(ridge: float = 1e-3) -> RidgeAgent:
    """The factory ``--agent examples/my_agent.py:make_agent`` calls (``--agent-config
    '{"ridge": 0.01}'`` sets its keyword arguments)."""
    return RidgeAgent(RidgeConfig(ridge=float(ridge)))
