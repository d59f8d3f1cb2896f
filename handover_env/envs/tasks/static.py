"""The static handover (the paper's baseline after Meng et al. 2022): stop, raise a hand, wait."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from handover_env.envs.tasks.base import HandoverState, HandoverTask

STOP_XY = (0.45, -0.95)  # the predefined area where the receiver stops, m


@dataclass
class StaticHandover(HandoverTask):
    """The receiver walks to :data:`STOP_XY`, stops and raises the right hand; the robot may move
    ``stabilisation_delay`` s after the raised hand is detected. The person waits: only the
    TimeLimit ends an episode without a handover (no ``missed``). A scripted walker's path ends at
    the stop area: ``options["walker"]`` may set every other WalkerParams field, while its
    ``end_x`` and ``pass_y`` (checked first, like every field) are replaced by the stop area's, so
    one participant's walker options serve both variants.

    Args:
        reward: the reward's weights (:class:`~handover_env.envs.tasks.base.HandoverReward`).
        stabilisation_delay: s between the hand's detection and the robot's start (paper: 2 s);
            subtracted from ``info["handover_time"]``, as the paper does.
    """

    stabilisation_delay: float = 2.0
    handover_delay: float = field(default=0.0, init=False)

    def __post_init__(self) -> None:
        if not math.isfinite(self.stabilisation_delay) or self.stabilisation_delay < 0:
            raise ValueError(
                "stabilisation_delay must be a finite number >= 0, got "
                f"{self.stabilisation_delay!r}"
            )
        self.handover_delay = float(self.stabilisation_delay)

    def configure_receiver(self, env: HandoverState, kind: str, options: dict[str, Any]) -> None:
        # Scripted walkers walk to the stop area; recorded people follow their recording until
        # their pelvis reaches the stop line (x = STOP_XY[0]), where both stop and stand.
        overrides = (
            {**dict(options.get("walker") or {}), "end_x": STOP_XY[0] - 0.3, "pass_y": STOP_XY[1]}
            if kind in ("id", "ood")
            else None
        )
        env.receiver.reset(
            env.np_random, kind=kind, height=options.get("height"), speed=options.get("speed"),
            episode=options.get("episode"), hand_mode=options.get("hand_mode", "reach"),
            walker_overrides=overrides, stop_x=STOP_XY[0],
        )

    def detection_time(self, env: HandoverState) -> float:
        """When the raised hand was detected (fully raised); math.nan before."""
        return env.receiver.t_hand_raised

    def enabled_time(self, env: HandoverState) -> float:
        """``stabilisation_delay`` after the raised hand's detection; math.inf until then."""
        t_detect = self.detection_time(env)
        return math.inf if math.isnan(t_detect) else t_detect + self.stabilisation_delay
