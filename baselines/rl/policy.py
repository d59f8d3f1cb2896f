"""The SB3 algorithm and policy of an :class:`~baselines.rl.config.RLConfig`, built the same way
for training (:func:`build_model`) and for loading a checkpoint (:func:`build_policy`), so that a
checkpoint's weights are loaded into a policy rebuilt from its JSON config, never from SB3's own
``.zip`` (whose entries are cloudpickled: loading one runs code).
"""

from __future__ import annotations

from typing import Any

from handover_env.extras import missing_extra

try:
    import torch
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.policies import BasePolicy
except ModuleNotFoundError as _exc:
    raise missing_extra("rl", _exc, __name__) from None

import gymnasium as gym

from baselines.rl.config import RLConfig

ALGORITHMS = {"ppo": PPO, "sac": SAC}


def policy_kwargs(config: RLConfig) -> dict[str, Any]:
    """The policy's constructor arguments: PPO's actor-critic (tanh MLPs, Gaussian with
    ``log_std_init``), SAC's squashed-Gaussian actor and twin critics (ReLU MLPs)."""
    arch = list(config.net_arch)
    if config.algo == "ppo":
        return {"net_arch": {"pi": arch, "vf": arch}, "log_std_init": config.log_std_init,
                "activation_fn": torch.nn.Tanh}
    return {"net_arch": arch, "activation_fn": torch.nn.ReLU}


def build_model(config: RLConfig, env: Any) -> Any:
    """A fresh PPO or SAC (SB3) on the vectorised ``env``, on CPU, seeded by ``config.seed``."""
    common = dict(learning_rate=config.learning_rate, gamma=config.gamma, seed=config.seed,
                  device="cpu", policy_kwargs=policy_kwargs(config), verbose=0)
    if config.algo == "ppo":
        return PPO("MlpPolicy", env, n_steps=config.n_steps, batch_size=config.batch_size,
                   n_epochs=config.n_epochs, ent_coef=config.ent_coef, **common)
    return SAC("MlpPolicy", env, batch_size=config.batch_size, learning_starts=config.n_steps,
               buffer_size=max(1, min(config.steps, 1_000_000)), **common)


def build_policy(
    config: RLConfig, observation_space: gym.spaces.Box, action_space: gym.spaces.Box,
    initialise: bool = True,
) -> BasePolicy:
    """The policy :func:`build_model` makes, without an env or an algorithm (for loading).

    ``initialise=False`` skips PPO's orthogonal initialisation (a QR decomposition per layer, the
    bulk of the build's time for wide layers), for a policy whose every weight is then loaded
    from a checkpoint (its state dict's keys and shapes are the same)."""
    cls = ALGORITHMS[config.algo].policy_aliases["MlpPolicy"]
    kwargs = policy_kwargs(config)
    if not initialise and config.algo == "ppo":
        kwargs["ortho_init"] = False
    policy = cls(observation_space, action_space, lambda _: config.learning_rate, **kwargs)
    policy.set_training_mode(False)
    return policy
