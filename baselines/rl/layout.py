"""The tensors of an RL checkpoint's ``model.safetensors``, known from its config alone.

A checkpoint's weights are checked against this layout (every key, shape and dtype, and so the
file's exact size) *before* a policy is built or the file is read whole
(:func:`baselines.rl.files.read_checkpoint`): a crafted ``config.json`` or weights file cannot make
the loader allocate more than :data:`baselines.rl.config.MAX_POLICY_PARAMS` parameters.

The layout is Stable-Baselines3's ``MlpPolicy`` state dict for the networks of
:func:`baselines.rl.policy.policy_kwargs` (a flatten feature extractor, which holds no weights):

* PPO (``ActorCriticPolicy``): ``log_std`` (A,); ``mlp_extractor.policy_net`` and
  ``mlp_extractor.value_net``, each ``Linear`` layers of ``net_arch`` at indices 0, 2, 4, ...
  (an activation between them); ``action_net`` (A x last) and ``value_net`` (1 x last).
* SAC (``SACPolicy``): ``actor.latent_pi`` (``net_arch``), ``actor.mu`` and ``actor.log_std``
  (A x last); ``critic`` and ``critic_target``, each two Q-networks ``qf0``, ``qf1`` of
  ``net_arch`` on the observation and action, then a ``Linear`` to one value.

O is the policy's observation size (:class:`~handover_env.envs.observation.ObsLayout` of
``history`` frames, plus the base agent's 4-d target for a residual and 4 values per remembered
action, ``last_actions``), A = 4 (x, y, z, yaw). With gSDE (``use_sde``) PPO's ``log_std`` is
(last width x A) and SAC's actor has ``actor.log_std`` (last width x A) and ``actor.mu.0`` (SB3
clips the mean with a Hardtanh after it) instead of its two Linear heads. With
``privileged_critic`` the value network (PPO) or both Q-networks and their targets (SAC) take
the observation plus the :data:`PRIVILEGED_SIZE` values of the privileged state
(:mod:`baselines.rl.privileged`); the actor's input is unchanged.
``tests/security/test_security_rl.py`` checks this layout against SB3's built policies, key for key.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # RLConfig checks its size with this module: no import at run time
    from baselines.rl.config import RLConfig

#: Values of the privileged state an asymmetric critic sees (baselines.rl.privileged).
PRIVILEGED_SIZE = 18
#: The action's size: the Cartesian target (x, y, z) and the yaw.
ACTION_SIZE = 4
#: The residual's extra observation: the base agent's target (x, y, z, yaw).
BASE_TARGET_SIZE = 4
DTYPE = "F32"
Layout = dict[str, tuple[int, ...]]


def observation_size(history: int, form: str, last_actions: int = 0) -> int:
    """O: the flat observation of ``history`` camera frames (+ the base target for a residual,
    + 4 values per remembered action)."""
    from handover_env.envs.observation import ObsLayout

    return (ObsLayout(history).size + (BASE_TARGET_SIZE if form == "residual" else 0)
            + ACTION_SIZE * last_actions)


def _mlp(prefix: str, n_in: int, widths: tuple[int, ...], n_out: int | None = None) -> Layout:
    """``Linear`` layers at even indices of an ``nn.Sequential`` (activations between them)."""
    out: Layout = {}
    dims = [n_in, *widths] + ([n_out] if n_out is not None else [])
    for i in range(len(dims) - 1):
        out[f"{prefix}.{2 * i}.weight"] = (dims[i + 1], dims[i])
        out[f"{prefix}.{2 * i}.bias"] = (dims[i + 1],)
    return out


def policy_layout(config: RLConfig) -> Layout:
    """{state-dict key: shape} of the SB3 policy of ``config`` (every tensor float32)."""
    obs = observation_size(config.history, config.form, config.last_actions)
    critic_obs = obs + (PRIVILEGED_SIZE if config.privileged_critic else 0)
    act, arch = ACTION_SIZE, config.net_arch
    last = arch[-1]
    # gSDE: a log std per (latent feature, action); else one per action (PPO) or a Linear (SAC)
    sde_std = (last, act)
    if config.algo == "ppo":
        return {"log_std": sde_std if config.use_sde else (act,),
                **_mlp("mlp_extractor.policy_net", obs, arch),
                **_mlp("mlp_extractor.value_net", critic_obs, arch),
                "action_net.weight": (act, last), "action_net.bias": (act,),
                "value_net.weight": (1, last), "value_net.bias": (1,)}
    out = _mlp("actor.latent_pi", obs, arch)
    if config.use_sde:  # SB3 clips the mean (Hardtanh after the Linear: mu.0)
        out.update({"actor.log_std": sde_std, "actor.mu.0.weight": (act, last),
                    "actor.mu.0.bias": (act,)})
    else:
        out.update({"actor.mu.weight": (act, last), "actor.mu.bias": (act,),
                    "actor.log_std.weight": (act, last), "actor.log_std.bias": (act,)})
    for critic in ("critic", "critic_target"):
        for q in ("qf0", "qf1"):
            out.update(_mlp(f"{critic}.{q}", critic_obs + act, arch, 1))
    return out


def checkpoint_layout(config: RLConfig) -> Layout:
    """{key: shape} of ``model.safetensors``: ``policy.<key>`` and ``io.offset``, ``io.scale``."""
    n = observation_size(config.history, config.form, config.last_actions)
    out = {f"policy.{k}": v for k, v in policy_layout(config).items()}
    out["io.offset"] = out["io.scale"] = (n,)
    return out


def parameter_count(config: RLConfig) -> int:
    """The number of float32 values of the checkpoint's tensors (the policy's and the I/O's)."""
    return sum(math.prod(shape) for shape in checkpoint_layout(config).values())
