"""The constant-velocity predictor: the reactive agent's extrapolation as a trajectory predictor.

In trajectory prediction, constant velocity is the baseline learned models are held against
(Schöller et al., "What the Constant Velocity Model Can Teach Us About Pedestrian Motion
Prediction", RA-L 2020). Here it predicts the giver (= robot target) trajectory from the receiver's
pelvis track alone, with no learned parameter:

    x_g(t_c + k / 30) = [x_r + v_x k / 30 - forward, y_r + v_y k / 30 + lateral, height]

for k = 0 .. H-1: the receiver's current pelvis position ``(x_r, y_r)`` moved by its velocity
``v`` (least-squares slope over the last ``velocity_window`` frames), offset toward the robot and
ahead along the walk by the reactive agent's offsets, at its fixed handover height, clipped to
its workspace (:class:`agents.reactive.ReactiveConfig`; the offsets and the height are the
dataset's medians at transfer). It is exactly :meth:`agents.reactive.ReactiveAgent.predict` with
no forecast time: here row 0 is the current frame, as the open-loop protocol asks, and in closed
loop the forecast time t_f of Θ is applied by the predictive wrapper
(:class:`agents.predictive.PredictiveAgent`, the same wrapper as the SPGP planner and the learned
baselines), so it is compared with them on equal terms. ``fit`` learns nothing.
"""

from __future__ import annotations

import numpy as np

from agents.predictive import ClosedLoopConfig, PredictiveAgent
from agents.reactive import ReactiveAgent, ReactiveConfig
from handover_env.config import HandoverParams
from handover_env.envs.observation import ObsLayout


class ConstantVelocityAgent(PredictiveAgent):
    """Constant-velocity giver-trajectory predictor in the predictive wrapper (method ``cv``).

    Args:
        config: offsets, height, velocity window, workspace clip and horizon H (the reactive
            agent's settings; ``horizon`` is the predicted chunk length).
        params: Θ; ``forecast_time`` is used by the closed-loop wrapper only.
        closed_loop: the wrapper's ensembling, ready pose and yaw settings.
        layout: the env's observation layout.
    """

    def __init__(
        self,
        config: ReactiveConfig | None = None,
        params: HandoverParams | None = None,
        closed_loop: ClosedLoopConfig | None = None,
        layout: ObsLayout | None = None,
    ) -> None:
        super().__init__(params, closed_loop, layout)
        self.config = config or ReactiveConfig()
        self.horizon = self.config.horizon
        # The reactive agent's extrapolation at zero forecast time: row k is k / 30 s ahead.
        self._extrapolate = ReactiveAgent(HandoverParams(forecast_time=0.0), self.config)

    def predict(self, receiver_history: np.ndarray) -> np.ndarray:
        """(H, 3) giver positions for the next H frames; row 0 is the current frame."""
        return self._extrapolate.predict(receiver_history)
