"""Documented reward shaping beside :class:`~handover_env.envs.tasks.base.HandoverReward`: a
penalty on the change of the action and one on body contact force beyond the receiving hand.

Both are costs per 30 Hz step (dt = 1/30 s), added to the env's reward by the training wrapper
(:class:`baselines.rl.envs.HandoverTrainingEnv`) and reported in ``info`` as
``reward_action_change`` and ``reward_contact`` beside the env's ``reward_time``,
``reward_force``, ``reward_outcome`` and the wrapper's ``reward_shaping``; their weights are in
the checkpoint's ``reward`` record. Neither names an agent's target or uses an agent's numbers.

**Action change** (``action_change`` = w_a): ``-w_a * |u_t - u_{t-1}|^2 / 4``, ``u`` the action
as it reaches the robot ([-1, 1]^4, after the filter of :mod:`baselines.rl.action_filter`; its first
step is compared with the start action). Its largest value is ``-w_a * 4`` (every component from
-1 to 1). A jerky residual shakes the held bottle, whose inertia the wrist F/T reads as a pull
(docs/sensing.md): this cost is on the cause, the policy's own change of command.

**Body contact beyond the hand** (``contact_penalty`` = w_c):
``-w_c * dt * Σ_s F_s / L_s`` over every body segment s but the receiving (right) hand, ``F_s``
the segment's filtered contact force from the robot and the held bottle at the end of the step
(the env's contact monitor, :mod:`handover_env.envs.contacts`) and ``L_s`` its body region's
maximum permissible quasi-static force of ISO/TS 15066:2016, Annex A, Table A.2
(:data:`handover_env.person.body_model.ISO_REGIONS`: e.g. chest 140 N, upper arm 150 N, lower arm
160 N). Those limits are the standard's pain-onset thresholds: Annex A derives them from a study
of pain onset under quasi-static contact (University of Mainz; later measured again by Behrens
et al., Front. Robot. AI 2022, 667818, and Han et al., Sensors 2022, 22(8) 2996). Dividing by
``L_s`` weighs each region by its own pain onset: a second of contact at a region's limit costs
``w_c``, whatever the region. The receiving hand is left out: a handover is the bottle meeting
that hand. The env ends an episode as unsafe only above twice a limit, or above it for 0.5 s;
this cost is on every newton below that too, since a handover needs no contact with the body at
all.
"""

from __future__ import annotations

import numpy as np

from baselines.rl.action_filter import DT
from handover_env.person.body_model import ISO_REGIONS
from handover_env.person.skeleton import SEGMENTS

#: The receiving hand, whose contact with the bottle is the handover.
RECEIVING_HAND = "hand_r"
#: N, each segment's ISO/TS 15066 quasi-static limit (Table A.2), in SEGMENTS order.
PAIN_ONSET_N = np.array([ISO_REGIONS[s.region][1] for s in SEGMENTS])
#: 1 for every segment but the receiving hand.
BEYOND_HAND = np.array([0.0 if s.name == RECEIVING_HAND else 1.0 for s in SEGMENTS])


def action_change_cost(weight: float, u: np.ndarray, u_previous: np.ndarray) -> float:
    """``-weight * |u - u_previous|^2 / 4`` (module docstring)."""
    d = np.asarray(u, dtype=np.float64) - np.asarray(u_previous, dtype=np.float64)
    return -weight * float(d @ d) / 4.0


def segment_forces(env) -> np.ndarray:
    """(S,) N: each body segment's filtered contact force now, from the env's contact monitor
    (read from the unwrapped env: it is no part of the observation)."""
    forces = getattr(env.unwrapped.contacts, "force", None)
    if forces is None or np.shape(forces) != PAIN_ONSET_N.shape:
        raise RuntimeError("the env's contact monitor has no per-segment force to penalise")
    return np.asarray(forces, dtype=np.float64)


def contact_cost(weight: float, forces: np.ndarray) -> float:
    """``-weight * dt * Σ_s F_s / L_s`` over the segments beyond the receiving hand."""
    if weight == 0:
        return 0.0
    f = np.nan_to_num(np.asarray(forces, dtype=np.float64), nan=0.0, posinf=1e6)
    return -weight * DT * float(np.sum(BEYOND_HAND * np.maximum(f, 0.0) / PAIN_ONSET_N))
