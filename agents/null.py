"""Reference agents that show what the env can tell apart: a robot that does nothing, and a late
one.

* :class:`NullAgent` holds the object still at the ready pose: whatever handover happens, the
  person made it happen.
* :class:`DelayedAgent` wraps any agent and acts on what it saw ``delay`` seconds ago (its actions
  reach the robot ``delay`` late; until then it holds the ready pose): e.g. the reactive agent with
  a 0.5 s delay, a deliberately lagging robot.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from agents.base import Agent, validate_history

READY = (0.3, -0.4, 1.15, -math.pi / 2)
RATE = 30.0


class NullAgent(Agent):
    """Holds the object at the ready pose for the whole episode.

    Args:
        ready: (x, y, z, yaw) held, the env's ready pose by default.
    """

    def __init__(self, ready: tuple[float, float, float, float] = READY) -> None:
        self.ready = np.asarray(ready, dtype=np.float32)
        if self.ready.shape != (4,) or not np.all(np.isfinite(self.ready)):
            raise ValueError(f"ready must be 4 finite numbers (x, y, z, yaw), got {ready!r}")

    def predict(self, receiver_history: np.ndarray) -> np.ndarray:
        validate_history(receiver_history)
        return np.tile(self.ready[:3].astype(np.float64), (self.horizon, 1))

    def reset(self) -> None:
        """Nothing to forget."""

    def act(self, obs: np.ndarray) -> np.ndarray:
        return self.ready.copy()


class DelayedAgent(Agent):
    """Any agent whose actions arrive ``delay`` seconds late (held at the ready pose until then).

    Args:
        agent: the wrapped agent.
        delay: seconds of delay (rounded to whole 30 Hz steps).
        ready: the action used before the first delayed one arrives.
    """

    def __init__(
        self, agent: Agent, delay: float = 0.5, ready: tuple[float, float, float, float] = READY
    ) -> None:
        if not (math.isfinite(delay) and delay >= 0):
            raise ValueError(f"delay must be a finite number of seconds >= 0, got {delay!r}")
        self.agent = agent
        self.delay = float(delay)
        self.steps = round(delay * RATE)
        self.ready = np.asarray(ready, dtype=np.float32)
        self.horizon = agent.horizon
        self._queue: deque[np.ndarray] = deque()

    def predict(self, receiver_history: np.ndarray) -> np.ndarray:
        hist = validate_history(receiver_history)
        late = hist[: max(1, hist.shape[0] - self.steps)]
        return self.agent.predict(late)

    def reset(self) -> None:
        self.agent.reset()
        self._queue.clear()

    def act(self, obs: np.ndarray) -> np.ndarray:
        self._queue.append(np.asarray(self.agent.act(obs), dtype=np.float32))
        if len(self._queue) > self.steps:
            return self._queue.popleft()
        return self.ready.copy()
