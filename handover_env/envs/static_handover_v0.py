"""``handover_env/StaticHandover-v0``: the paper's static baseline (after Meng et al. 2022)."""

from __future__ import annotations

from handover_env.envs.base_handover import HandoverEnvBase
from handover_env.envs.tasks.base import HandoverReward, HandoverTask
from handover_env.envs.tasks.static import STOP_XY, StaticHandover

__all__ = ["STOP_XY", "StaticHandoverEnv"]


class StaticHandoverEnv(HandoverEnvBase):
    """The static handover baseline: the receiver walks into a predefined area, stops and raises
    the right hand; the robot may move only after it has detected the hand and waited
    ``stabilisation_delay`` (2 s) for the detection to stabilise (paper Sec. V-C, after Meng et
    al. 2022).

    Same robot, action and observation spaces, rewards and outcomes as
    :class:`handover_env.envs.dynamic_handover_v0.DynamicHandoverEnv` (see there), except:

    ## Receiver
    A scripted walker heading for ``STOP_XY`` = (0.45, -0.95), or a recorded person following their
    recording, decelerates and stops when the pelvis reaches the stop line x = 0.45 (see
    :func:`handover_env.person.person.stopped`); so the static baseline meets the same recorded
    people as the dynamic agents. They do not reach while walking. There they raise the right
    hand; the hand counts as detected when fully raised. Until ``detect + stabilisation_delay`` the
    robot holds its
    ready pose whatever the action (``robot_enabled`` = 0 in the observation). The raised hand
    waits until the robot brings the object within ``ReceiverConfig.present_reach`` (0.15 m),
    then grasps and pulls it toward the hip. Only the TimeLimit (600 steps, 20 s) ends an episode
    without a handover. The matching agent is :class:`agents.static.StaticAgent` (deliver to the
    hand seen at ``robot_enabled``).

    ## Timing
    Handover time is measured as in the paper's user study (Sec. V-C): from when the receiver
    leaves the start point to the gripper release. ``info["handover_time"]`` excludes the
    stabilisation delay, as the paper does; ``info["handover_time_with_delay"]`` includes it.

    ## Task
    :class:`handover_env.envs.tasks.static.StaticHandover` (receiver set-up, the robot's start,
    no ``missed``, the reward).

    ## Sensing
    As the dynamic env (``sensing="paper"`` by default: the camera model's latency and hand
    noise reach the agent's view of the raised hand, the release uses the measured wrist force;
    ``sensing="ideal"``: the exact world). The hand counts as detected when fully raised (the
    task's rule, on the true hand).

    ## Arguments
    As the dynamic env, plus ``stabilisation_delay`` (s, default 2.0).

    ## Version History
    * v0: the dynamic env's robot, person, spaces and outcomes; the receiver stops at
      ``STOP_XY`` and raises the right hand, the robot may move ``stabilisation_delay`` after the
      hand is detected, no ``missed``; TimeLimit 600 steps (20 s).
    """

    def default_task(self, reward: HandoverReward) -> HandoverTask:
        """:class:`~handover_env.envs.tasks.static.StaticHandover` with this env's
        ``stabilisation_delay``."""
        return StaticHandover(reward=reward, stabilisation_delay=self.stabilisation_delay)
