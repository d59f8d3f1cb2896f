"""The dynamic handover: the receiver keeps walking and takes the object on the way."""

from __future__ import annotations

from dataclasses import dataclass

from handover_env.envs.tasks.base import HandoverState, HandoverTask

#: s after the end of their walk at which a person without the object has missed it.
WALK_END_GRACE = 1.0


@dataclass
class DynamicHandover(HandoverTask):
    """The receiver walks past (scripted or replayed); the robot may move from the start.

    The episode ends as ``missed`` when the person left the object behind for good or their walk
    ended over :data:`WALK_END_GRACE` s ago without it. Left behind (the modelled hand's
    ``passed``, :func:`handover_env.person.receiver_rules.left_behind`): the unheld object is
    ``give_up_behind`` behind the shoulder within ``PASS_DISTANCE`` *and the rest of the person's
    walk never brings it ahead of them again* -- a person who pauses, loops or turns back toward it
    has not missed it. Run on the 848 recordings with a transfer, with the recorded walk as the
    person's, this never fires before the recorded transfer (the former rule, without the look
    ahead, fired in 14; ``docs/calibration/receiver_calibration.md``).

    Args:
        reward: the reward's weights (:class:`~handover_env.envs.tasks.base.HandoverReward`).
    """

    def walked_past(self, env: HandoverState, t: float) -> bool:
        rec = env.receiver
        return rec.state == "passed" or (
            rec.finished and t > rec.duration + rec.time_lost + WALK_END_GRACE
        )
