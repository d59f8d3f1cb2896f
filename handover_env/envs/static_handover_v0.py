"""``handover_env/StaticHandover-v0``: the paper's static baseline (after Meng et al. 2022)."""

from __future__ import annotations

import math
from typing import Any

from handover_env.envs.base_handover import HandoverEnvBase

STOP_XY = (0.45, -0.95)  # the predefined area where the receiver stops, m


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
    :func:`handover_env.person.stopped`); so the static baseline meets the same recorded people as
    the dynamic agents. They do not reach while walking. There they raise the right hand; the
    hand counts as detected when fully raised. Until ``detect + stabilisation_delay`` the robot holds its
    ready pose whatever the action (``robot_enabled`` = 0 in the observation). The raised hand
    waits until the robot brings the object within ``ReceiverConfig.present_reach`` (0.15 m),
    then grasps and pulls it toward the hip. Only the TimeLimit (600 steps, 20 s) ends an episode
    without a handover. The matching agent is :class:`agents.static.StaticAgent` (deliver to the
    hand seen at ``robot_enabled``).

    ## Timing
    Handover time is measured as in the paper's user study (Sec. V-C): from when the receiver
    leaves the start point to the gripper release. ``info["handover_time"]`` excludes the
    stabilisation delay, as the paper does; ``info["handover_time_with_delay"]`` includes it.

    ## Arguments
    As the dynamic env, plus ``stabilisation_delay`` (s, default 2.0).
    """

    static = True

    def _configure_receiver(self, kind: str, options: dict[str, Any]) -> None:
        # Scripted walkers walk to the stop area; recorded people follow their recording until
        # their pelvis reaches the stop line (x = STOP_XY[0]), where both stop and stand.
        overrides = ({**dict(options.get("walker") or {}), "end_x": STOP_XY[0] - 0.3, "pass_y": STOP_XY[1]}
                     if kind in ("id", "ood") else None)
        self.receiver.reset(
            self.np_random, kind=kind, height=options.get("height"), speed=options.get("speed"),
            episode=options.get("episode"), hand_mode=options.get("hand_mode", "reach"),
            walker_overrides=overrides, stop_x=STOP_XY[0],
        )

    def _after_step(self) -> None:
        if math.isinf(self.t_enabled) and not math.isnan(self.receiver.t_hand_raised):
            self.t_detect = self.receiver.t_hand_raised
            self.t_enabled = self.t_detect + self.stabilisation_delay
        super()._after_step()
