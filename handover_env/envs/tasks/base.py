"""The task interface of the handover envs and their shared reward and episode end.

A task reads the env's physics through :class:`HandoverState` and returns values: the receiver
it sets up, when the robot may move, the outcome and the reward terms. It never writes an env
attribute; the env asks the task and stores the answers itself (as dm_control's ``Task``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Protocol

import mujoco
import numpy as np

from handover_env.config import HandoverParams

#: How far below where it was last held (m) an object that nobody holds counts as dropped.
DROP_DISTANCE = 0.15
#: Height (m) below which an object is on the floor.
FLOOR_HEIGHT = 0.1


@dataclass(frozen=True)
class HandoverReward:
    """The reward of a handover step, as weighted terms (reported in ``info`` as ``reward_<term>``).

    Per step: ``time = -time_cost * dt``; ``force = -dt * max(0, |F_ext| - force_threshold * f_r) /
    force_scale`` (the wrist force beyond ``force_threshold`` times the release threshold f_r);
    at the end ``outcome = +success`` on success and ``-failure`` on any other outcome. The
    defaults are the project's constants: 1 per s, 2 f_r, 10 N, +10, -10.

    Args:
        time_cost: reward lost per second of the episode.
        force_threshold: multiple of f_r above which the wrist force is penalised.
        force_scale: N of excess force that cost as much as the time (per second).
        success: reward of a successful handover.
        failure: penalty of any other end (premature release, dropped, unsafe force, missed,
            unstable).
    """

    time_cost: float = 1.0
    force_threshold: float = 2.0
    force_scale: float = 10.0
    success: float = 10.0
    failure: float = 10.0

    def __post_init__(self) -> None:
        for name in ("time_cost", "force_threshold", "force_scale", "success", "failure"):
            value = getattr(self, name)
            if (
                isinstance(value, bool)
                or not isinstance(value, (int, float))
                or not math.isfinite(value)
            ):
                raise ValueError(f"HandoverReward.{name} must be a finite number, got {value!r}")
        if self.force_scale <= 0:
            raise ValueError(f"HandoverReward.force_scale must be > 0, got {self.force_scale!r}")

    def terms(
        self, dt: float, wrist_force: float, release_force: float, outcome: str
    ) -> dict[str, float]:
        """The terms of one step: ``{"time", "force", "outcome"}``; the reward is their sum in that
        order."""
        force = 0.0
        excess = wrist_force - self.force_threshold * release_force
        if excess > 0:
            force = -(dt * excess / self.force_scale)
        end = 0.0
        if outcome == "success":
            end = self.success
        elif outcome != "running":
            end = -self.failure
        return {"time": -self.time_cost * dt, "force": force, "outcome": end}


TERMS = ("time", "force", "outcome")


class HandoverState(Protocol):
    """What a task reads of a handover env (:class:`handover_env.envs.base_handover.HandoverEnvBase`
    is one)."""

    np_random: np.random.Generator
    data: mujoco.MjData
    receiver: Any  # handover_env.person.receiver.Receiver: the simulated person
    contacts: Any  # handover_env.envs.contacts.ContactMonitor: robot/object contacts on the body
    params: HandoverParams  # Θ; a task reads f_r (``params.release_force``), a robot field
    dt: float
    safety_force: float
    outcome: str
    released: bool
    released_while_held: bool
    pull_force: float

    @property
    def receiver_holds(self) -> bool: ...

    @property
    def gripper_holds(self) -> bool: ...

    @property
    def last_held_z(self) -> float: ...

    def object_position(self) -> np.ndarray: ...

    def wrist_force_magnitude(self) -> float: ...

    def clear_of_gripper(self, ox: float, oy: float, oz: float) -> bool: ...


@dataclass
class HandoverTask:
    """A handover variant: receiver set-up, when the robot may move, episode end, reward.

    Args:
        reward: the reward's weights.
    """

    reward: HandoverReward = field(default_factory=HandoverReward)

    #: seconds subtracted from the measured handover time in ``info["handover_time"]``.
    handover_delay: float = field(default=0.0, init=False)

    def configure_receiver(self, env: HandoverState, kind: str, options: dict[str, Any]) -> None:
        """Set up the receiver for a new episode (``reset``); ``options`` are reset()'s options."""
        walker = options.get("walker")
        if walker is not None and not isinstance(walker, dict):
            raise ValueError(
                "options['walker'] must be a dict of WalkerParams fields, got "
                f"{type(walker).__name__}"
            )
        env.receiver.reset(
            env.np_random, kind=kind, height=options.get("height"), speed=options.get("speed"),
            episode=options.get("episode"), hand_mode=options.get("hand_mode", "reach"),
            walker_overrides=walker,
        )

    def enabled_time(self, env: HandoverState) -> float:
        """When the robot may first follow the agent's action (s after reset); math.inf: not yet
        known. The env asks at reset and, while the answer is math.inf, after every step
        (before the outcome is judged)."""
        return 0.0

    def detection_time(self, env: HandoverState) -> float:
        """When the robot detected the receiver's cue to start (s after reset; math.nan: no cue
        yet, or none in this variant). Asked with :meth:`enabled_time` while that is math.inf."""
        return math.nan

    def walked_past(self, env: HandoverState, t: float) -> bool:
        """The person went on without the object (a ``missed`` handover)."""
        return False

    def outcome(self, env: HandoverState) -> str:
        """The episode's outcome after this step (``"running"`` while it goes on).

        ``unsafe_force`` (the pull above ``safety_force`` or a body contact above its ISO limit),
        ``premature_release``, ``success`` (released, held by the person, clear of the gripper),
        ``dropped``, ``missed`` (:meth:`walked_past`), in that order of precedence.
        """
        ox, oy, oz = env.object_position().tolist()
        holds = env.receiver_holds
        if env.pull_force > env.safety_force or env.contacts.unsafe_segment >= 0:
            return "unsafe_force"
        if env.released and not env.released_while_held:
            return "premature_release"
        if env.released and holds and not env.gripper_holds and env.clear_of_gripper(ox, oy, oz):
            return "success"
        if (
            not env.gripper_holds
            and not holds
            and (oz < env.last_held_z - DROP_DISTANCE or oz < FLOOR_HEIGHT)
        ):
            return "dropped"
        if not holds and not env.released and self.walked_past(env, float(env.data.time)):
            return "missed"
        return "running"

    def reward_terms(self, env: HandoverState) -> dict[str, float]:
        """This step's reward terms (see :class:`HandoverReward`)."""
        return self.reward.terms(
            env.dt, env.wrist_force_magnitude(), env.params.release_force, env.outcome
        )
