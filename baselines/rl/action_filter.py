"""The smooth action map and the policy's memory of its own actions.

**Filter.** With ``action_tau`` = τ > 0 the action reaches the robot through a first-order
low-pass filter, once per 30 Hz env step (dt = 1/30 s):

    u_t = u_{t-1} + α (a_t - u_{t-1}),    α = dt / (τ + dt),

``a_t`` the policy's action in [-1, 1]^4 and ``u_t`` what the action map
(:meth:`baselines.rl.envs.PolicyIO.target`) turns into the Cartesian target. The map is affine in
the action, so filtering the action is filtering the residual (the correction added to the base
agent's target) or, from scratch, the target itself; the base agent's own target is not
filtered. A step of the action reaches 63 % of its size after τ, and the filter's cut-off is
1 / (2π τ) (τ = 0.1 s: 1.6 Hz); whatever the policy samples, exploring or not, the commanded
residual moves by at most α times the action range per step. τ = 0 is no filter (u_t = a_t).

**Start.** ``u`` starts at the action of no residual (0) or, from scratch, at the action whose
target is the ready pose (clipped to [-1, 1]), so the first step of an episode moves no more than
a later one.

**Memory.** With ``last_actions`` = k > 0 the policy observes its k last filtered actions
``u_{t-1} .. u_{t-k}`` (most recent first; the start action before the episode's first step),
flattened to 4 k values already in [-1, 1]. With a filter, ``u_{t-1}`` is the filter's state, so
the policy's observation holds what its next target depends on.
"""

from __future__ import annotations

import numpy as np

from baselines.rl.layout import ACTION_SIZE

#: s, the env's step (the camera's 30 Hz).
DT = 1.0 / 30.0


def filter_gain(tau: float) -> float:
    """α = dt / (τ + dt) of the first-order filter of time constant ``tau`` (1 with no filter)."""
    if not tau >= 0:
        raise ValueError(f"action_tau must be >= 0 s, got {tau!r}")
    return DT / (tau + DT)


class ActionMemory:
    """The filter state and the last actions of one episode (module docstring).

    Args:
        tau: s, the filter's time constant (0: none).
        last_actions: k, past actions the policy observes.
        start: the action of the episode's start (no residual, or the ready pose from scratch).
    """

    def __init__(self, tau: float, last_actions: int, start: np.ndarray) -> None:
        self.alpha = filter_gain(tau)
        self.k = int(last_actions)
        self.start = np.asarray(start, dtype=np.float64).reshape(ACTION_SIZE)
        self.reset()

    def reset(self) -> None:
        """A new episode: the filter and the memory at the start action."""
        self.u = self.start.copy()
        self.past = np.tile(self.start, (self.k, 1))

    def apply(self, action: np.ndarray) -> np.ndarray:
        """The filtered action ``u_t`` of the policy's ``action`` (clipped to [-1, 1]); it is
        remembered as the last action."""
        a = np.clip(np.asarray(action, dtype=np.float64).reshape(ACTION_SIZE), -1.0, 1.0)
        self.u = self.u + self.alpha * (a - self.u)
        if self.k:
            self.past = np.roll(self.past, 1, axis=0)
            self.past[0] = self.u
        return self.u.copy()

    def observation(self) -> np.ndarray:
        """The k last filtered actions, most recent first (4 k values; empty with k = 0)."""
        return self.past.reshape(-1).copy()
