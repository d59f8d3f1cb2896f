"""The SB3 algorithm and policy of an :class:`~baselines.rl.config.RLConfig`, built the same way
for training (:func:`build_model`) and for loading a checkpoint (:func:`build_policy`), so that a
checkpoint's weights are loaded into a policy rebuilt from its JSON config, never from SB3's own
``.zip`` (whose entries are cloudpickled: loading one runs code).

**Exploration.** ``use_sde`` turns on SB3's gSDE for PPO or SAC (``sde_sample_freq``);
``action_noise="pink"`` gives SAC pink action noise (:mod:`baselines.rl.noise`).

**Asymmetric actor-critic** (``privileged_critic``). The observation is a Dict (``"actor"``,
``"privileged"``: :mod:`baselines.rl.privileged`); the actor's features are ``"actor"`` alone
and the critic's both, each through its own extractor (:class:`KeySelect`, no weights). SB3's
``share_features_extractor=False`` alone cannot do this: it builds the actor's and the critic's
extractors from one class with the same arguments, and PPO's ``MlpExtractor`` takes one input
width for its policy and value networks. So two small subclasses do it, changing only which
extractor each side gets: :class:`AsymmetricActorCriticPolicy` (PPO: its value network's input
is the wider one) and :class:`AsymmetricSACPolicy` (SAC: the actor's and both critics'
extractors). Every other part is SB3's own.
"""

from __future__ import annotations

from typing import Any

from handover_env.extras import missing_extra

try:
    import torch
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.policies import ActorCriticPolicy, BasePolicy
    from stable_baselines3.common.torch_layers import BaseFeaturesExtractor, MlpExtractor
    from stable_baselines3.sac.policies import SACPolicy
except ModuleNotFoundError as _exc:
    raise missing_extra("rl", _exc, __name__) from None

import gymnasium as gym

from baselines.rl.config import RLConfig

ALGORITHMS = {"ppo": PPO, "sac": SAC}
ACTOR_KEYS = ("actor",)
CRITIC_KEYS = ("actor", "privileged")


class KeySelect(BaseFeaturesExtractor):
    """The features of a Dict observation: its ``keys``' Boxes, flattened and concatenated."""

    def __init__(self, observation_space: gym.spaces.Dict, keys: tuple[str, ...] = ACTOR_KEYS):
        size = sum(int(observation_space[k].shape[0]) for k in keys)
        super().__init__(observation_space, features_dim=size)
        self.keys = tuple(keys)

    def forward(self, observations: dict[str, torch.Tensor]) -> torch.Tensor:
        return torch.cat([observations[k].flatten(1) for k in self.keys], dim=1)


class AsymmetricActorCriticPolicy(ActorCriticPolicy):
    """PPO's actor-critic with the actor on ``"actor"`` and the value on ``"actor"`` and
    ``"privileged"`` (module docstring)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.update(features_extractor_class=KeySelect,
                      features_extractor_kwargs={"keys": ACTOR_KEYS},
                      share_features_extractor=False)
        super().__init__(*args, **kwargs)

    def _build_mlp_extractor(self) -> None:
        self.vf_features_extractor = KeySelect(self.observation_space, CRITIC_KEYS)
        pi_dim = self.pi_features_extractor.features_dim
        vf_dim = self.vf_features_extractor.features_dim
        self.mlp_extractor = MlpExtractor(pi_dim, net_arch=self.net_arch,
                                          activation_fn=self.activation_fn, device=self.device)
        self.mlp_extractor.value_net = MlpExtractor(
            vf_dim, net_arch=self.net_arch, activation_fn=self.activation_fn,
            device=self.device).value_net


class AsymmetricSACPolicy(SACPolicy):
    """SAC's policy with the actor on ``"actor"`` and the twin critics (and their targets) on
    ``"actor"`` and ``"privileged"`` (module docstring)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs["share_features_extractor"] = False
        super().__init__(*args, **kwargs)

    def make_actor(self, features_extractor: BaseFeaturesExtractor | None = None) -> Any:
        return super().make_actor(KeySelect(self.observation_space, ACTOR_KEYS))

    def make_critic(self, features_extractor: BaseFeaturesExtractor | None = None) -> Any:
        return super().make_critic(KeySelect(self.observation_space, CRITIC_KEYS))


def policy_class(config: RLConfig) -> type[BasePolicy]:
    """SB3's ``MlpPolicy`` of the algorithm, or its asymmetric subclass."""
    if config.privileged_critic:
        return AsymmetricActorCriticPolicy if config.algo == "ppo" else AsymmetricSACPolicy
    return ALGORITHMS[config.algo].policy_aliases["MlpPolicy"]


def policy_kwargs(config: RLConfig) -> dict[str, Any]:
    """The policy's constructor arguments: PPO's actor-critic (tanh MLPs, Gaussian with
    ``log_std_init``), SAC's squashed-Gaussian actor and twin critics (ReLU MLPs); gSDE with
    ``use_sde``."""
    arch = list(config.net_arch)
    if config.algo == "ppo":
        out = {"net_arch": {"pi": arch, "vf": arch}, "log_std_init": config.log_std_init,
               "activation_fn": torch.nn.Tanh}
    else:
        out = {"net_arch": arch, "activation_fn": torch.nn.ReLU}
    if config.use_sde:
        out["use_sde"] = True
    return out


def action_noise(config: RLConfig) -> Any:
    """SAC's added action noise (None unless ``action_noise="pink"``)."""
    if config.action_noise != "pink":
        return None
    from baselines.rl.noise import pink_noise

    return pink_noise(config.noise_sigma, 4, config.n_envs, config.seed)


def build_model(config: RLConfig, env: Any) -> Any:
    """A fresh PPO or SAC (SB3) on the vectorised ``env``, on CPU, seeded by ``config.seed``."""
    kwargs = {k: v for k, v in policy_kwargs(config).items() if k != "use_sde"}
    common = dict(learning_rate=config.learning_rate, gamma=config.gamma, seed=config.seed,
                  device="cpu", policy_kwargs=kwargs, verbose=0, use_sde=config.use_sde,
                  sde_sample_freq=config.sde_sample_freq)
    policy = policy_class(config)
    if config.algo == "ppo":
        return PPO(policy, env, n_steps=config.n_steps, batch_size=config.batch_size,
                   n_epochs=config.n_epochs, ent_coef=config.ent_coef, **common)
    return SAC(policy, env, batch_size=config.batch_size, learning_starts=config.n_steps,
               buffer_size=max(1, min(config.steps, 1_000_000)),
               action_noise=action_noise(config), **common)


def build_policy(
    config: RLConfig, observation_space: gym.spaces.Space, action_space: gym.spaces.Box,
    initialise: bool = True,
) -> BasePolicy:
    """The policy :func:`build_model` makes, without an env or an algorithm (for loading).

    ``initialise=False`` skips PPO's orthogonal initialisation (a QR decomposition per layer, the
    bulk of the build's time for wide layers), for a policy whose every weight is then loaded
    from a checkpoint (its state dict's keys and shapes are the same)."""
    kwargs = policy_kwargs(config)
    if not initialise and config.algo == "ppo":
        kwargs["ortho_init"] = False
    policy = policy_class(config)(observation_space, action_space,
                                  lambda _: config.learning_rate, **kwargs)
    policy.set_training_mode(False)
    return policy
