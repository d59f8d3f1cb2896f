"""What an asymmetric critic sees besides the policy's observation: the true state of the person
and of the wrist, read from the simulator (never from the sensors).

With ``privileged_critic`` the training env's observation is a Dict: ``"actor"``, the policy's
observation (:class:`baselines.rl.envs.PolicyIO`), and ``"privileged"``, these
:data:`PRIVILEGED_SIZE` values, normalised like the observation (fixed constants, clipped to ±10):

* the receiver's true pelvis position (3, m, about (0.3, -0.5, 1.0), in 2 m) and its linear
  velocity (3, m/s, in 1 m/s): the free joint of the simulated body;
* the true position of their right hand's grip point (3, m, about (0.3, -0.5, 1.0), in 1 m);
* the true wrist force (3, N, in 20 N): the wrist model's exact filtered estimate
  (``env.unwrapped.wrist.f_true``), where the observation has the sensor's measurement;
* the receiver's state, one-hot over :data:`handover_env.person.receiver.STATES` (walking,
  reaching, holding, presenting, presented, passed).

The actor (the deployed policy) reads ``"actor"`` only; the critic reads both
(:mod:`baselines.rl.policy`). Deployed, the policy is given zeros for ``"privileged"``, which its
action never depends on (tested).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from baselines.rl.layout import PRIVILEGED_SIZE
from handover_env.person.receiver import STATES

OBS_CLIP = 10.0
#: (offset, scale) of each part, as :data:`baselines.rl.envs.PART_SCALES`.
PRIVILEGED_PARTS: dict[str, tuple[tuple[float, ...], float, int]] = {
    "pelvis_pos": ((0.3, -0.5, 1.0), 2.0, 3),
    "pelvis_vel": ((0.0,), 1.0, 3),
    "hand_pos": ((0.3, -0.5, 1.0), 1.0, 3),
    "wrist_force_true": ((0.0,), 20.0, 3),
    "receiver_state": ((0.0,), 1.0, len(STATES)),
}
if sum(n for _, _, n in PRIVILEGED_PARTS.values()) != PRIVILEGED_SIZE:  # the layout's, by hand
    raise ImportError("baselines.rl.layout.PRIVILEGED_SIZE differs from the privileged parts")


def privileged_normalisation() -> tuple[np.ndarray, np.ndarray]:
    """The fixed float64 ``(offset, scale)`` of the privileged vector."""
    offset, scale = [], []
    for off, s, n in PRIVILEGED_PARTS.values():
        offset.append(np.tile(np.asarray(off, dtype=np.float64), n // len(off)))
        scale.append(np.full(n, s))
    return np.concatenate(offset), np.concatenate(scale)


def privileged_state(env: Any) -> np.ndarray:
    """The raw privileged vector of the handover env ``env`` now (module docstring)."""
    u = env.unwrapped
    body = u.ids.receiver.body
    data = u.data
    pelvis = data.xpos[int(body.bodies[0])]
    vel = data.qvel[body.root_dof:body.root_dof + 3]
    hand = data.site_xpos[int(body.grip_site)]
    state = np.zeros(len(STATES))
    if u.receiver.state in STATES:
        state[STATES.index(u.receiver.state)] = 1.0
    return np.concatenate([pelvis, vel, hand, np.asarray(u.wrist.f_true, dtype=np.float64),
                           state])


def privileged_observation(env: Any) -> np.ndarray:
    """The normalised privileged vector (float32, clipped to ±10)."""
    offset, scale = privileged_normalisation()
    z = (privileged_state(env) - offset) / scale
    return np.clip(np.nan_to_num(z, nan=0.0), -OBS_CLIP, OBS_CLIP).astype(np.float32)
