"""The handover variants as Task objects (dm_control style), one module per variant.

A task owns what makes a variant: how the receiver is set up at ``reset``, when the robot may
move, when an episode ends and with which outcome, and the reward (:class:`HandoverReward`,
whose weights are constructor arguments). A task reads the env through :class:`HandoverState`
and returns these values; the env stores them (a task writes no env attribute). The env
(:class:`handover_env.envs.base_handover.HandoverEnvBase`)
owns the physics, the controller, the wrist sensor, the release and the observation.

A new variant is one file here: a :class:`HandoverTask` subclass. Use it with any handover env,
``gym.make("handover_env/DynamicHandover-v0", task=MyTask())``, or register an id for it.
"""

from handover_env.envs.tasks.base import HandoverReward, HandoverState, HandoverTask
from handover_env.envs.tasks.dynamic import DynamicHandover
from handover_env.envs.tasks.static import STOP_XY, StaticHandover

__all__ = [
    "STOP_XY",
    "DynamicHandover",
    "HandoverReward",
    "HandoverState",
    "HandoverTask",
    "StaticHandover",
]
