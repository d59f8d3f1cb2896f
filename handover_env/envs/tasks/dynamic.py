"""The dynamic handover: the receiver keeps walking and takes the object on the way."""

from __future__ import annotations

from dataclasses import dataclass

from handover_env.envs.tasks.base import HandoverState, HandoverTask

#: s after the end of their walk at which a person without the object has missed it.
WALK_END_GRACE = 1.0


@dataclass
class DynamicHandover(HandoverTask):
    """The receiver walks past (scripted or replayed); the robot may move from the start.

    The episode ends as ``missed`` when the person left the object behind (a modelled hand gives up
    on an unheld object behind them) or their walk ended over :data:`WALK_END_GRACE` s ago without
    it.

    Args:
        reward: the reward's weights (:class:`~handover_env.envs.tasks.base.HandoverReward`).
    """

    def walked_past(self, env: HandoverState, t: float) -> bool:
        rec = env.receiver
        return rec.state == "passed" or (
            rec.finished and t > rec.duration + rec.time_lost + WALK_END_GRACE
        )
