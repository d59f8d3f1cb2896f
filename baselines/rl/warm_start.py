"""Behaviour-cloning warm start of a scratch policy's actor on a teacher agent's actions.

A scratch policy (``form="scratch"``: its action is the whole target) starts from random
weights; a residual starts at its base agent by construction and needs no warm start
(:class:`~baselines.rl.config.RLConfig` refuses one). With ``warm_start`` = a teacher
(``"reactive"``, ``"ours"`` or ``"cv"``, :func:`baselines.rl.agent.build_agent`), before RL:

1. **Data.** The teacher acts in ``warm_start_episodes`` episodes of training receivers only:
   the kinds drawn as the training envs draw them, the reset seeds
   :func:`baselines.rl.config.warm_start_seed` (at the top of the run's own block of training
   seeds, never a training episode's, a learning-curve's or an evaluation's seed). Each step
   records the policy's observation (through the same :class:`~baselines.rl.envs.PolicyIO` and
   action memory as training) and the action whose target is the teacher's
   (:meth:`~baselines.rl.envs.PolicyIO.action_of`); the memory is fed the teacher's action, so
   the last actions it remembers are the teacher's.
2. **Fit.** The actor's deterministic action (PPO: the Gaussian's mean; SAC: the squashed mean,
   the label clipped to ±0.999 inside tanh's range) is fitted to it by mean squared error with
   its own Adam (the RL optimiser's state is left fresh), ``warm_start_epochs`` passes of
   minibatches of 256 in an order drawn from the run's seed.

The critic is not fitted (its first rollouts teach it the teacher-like policy's values). The
warm start is recorded in the checkpoint's config; its env steps are not counted in the run's
``steps``; it runs only at a run's start, never on resume.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from baselines.rl.config import RLConfig, warm_start_seed
from baselines.rl.envs import PolicyIO, make_handover_env
from baselines.rl.privileged import privileged_observation

BATCH = 256
LEARNING_RATE = 1e-3


def teacher_data(config: RLConfig, teacher: Any, replays: list | tuple = ()
                 ) -> tuple[Any, np.ndarray]:
    """(observations, actions) of the teacher on the warm start's episodes (module docstring);
    observations a float32 array, or a dict of them with ``privileged_critic``."""
    env = make_handover_env(config)
    io = PolicyIO.for_env(config, env.action_space)
    memory = io.memory()
    probs = config.probabilities(bool(replays))
    kinds, p = list(probs), np.array(list(probs.values()))
    rng = np.random.default_rng([config.seed, 0xB0])
    xs, privs, ys = [], [], []
    try:
        for k in range(config.warm_start_episodes):
            kind = kinds[int(rng.choice(len(kinds), p=p))]
            options: dict[str, Any] = {"receiver": kind}
            if kind == "replay":
                options["episode"] = replays[int(rng.integers(len(replays)))]
            obs, _ = env.reset(seed=warm_start_seed(config.seed, k), options=options)
            teacher.reset()
            memory.reset()
            done = False
            while not done:
                xs.append(io.observation(obs, None, memory.observation()))
                if config.privileged_critic:
                    privs.append(privileged_observation(env))
                target = np.asarray(teacher.act(obs), dtype=np.float64)
                a = io.action_of(target, None)
                ys.append(a.astype(np.float32))
                memory.apply(a)
                obs, _, terminated, truncated, _ = env.step(target)
                done = terminated or truncated
    finally:
        env.close()
    x = np.stack(xs)
    obs_out: Any = {"actor": x, "privileged": np.stack(privs)} if config.privileged_critic else x
    return obs_out, np.stack(ys)


def actor_action(policy: Any, obs: Any) -> torch.Tensor:
    """The actor's deterministic action for a batch of observations (differentiable)."""
    if hasattr(policy, "actor"):  # SAC: tanh of the mean
        return policy.actor(obs, deterministic=True)
    return policy.get_distribution(obs).distribution.mean


def clone(policy: Any, config: RLConfig, obs: Any, actions: np.ndarray) -> list[float]:
    """Fit the actor of ``policy`` to ``actions`` (module docstring); the mean squared error of
    each epoch."""
    if config.algo == "sac":
        actions = np.clip(actions, -0.999, 0.999)
    y = torch.as_tensor(actions, dtype=torch.float32)
    n = y.shape[0]
    # the actor's weights only receive a gradient (PPO's value network has none from this loss)
    params = policy.actor.parameters() if hasattr(policy, "actor") else policy.parameters()
    opt = torch.optim.Adam(list(params), lr=LEARNING_RATE)
    gen = torch.Generator().manual_seed(int(config.seed) * 7919 + 36)
    losses = []
    policy.set_training_mode(True)
    for _ in range(config.warm_start_epochs):
        order = torch.randperm(n, generator=gen)
        total = 0.0
        for i in range(0, n, BATCH):
            idx = order[i:i + BATCH].numpy()
            if isinstance(obs, dict):
                batch = {k: torch.as_tensor(v[idx]) for k, v in obs.items()}
            else:
                batch = torch.as_tensor(obs[idx])
            loss = torch.nn.functional.mse_loss(actor_action(policy, batch), y[idx])
            opt.zero_grad()
            loss.backward()
            opt.step()
            total += loss.item() * len(idx)
        losses.append(total / n)
    policy.set_training_mode(False)
    return losses


def warm_start(model: Any, config: RLConfig, teacher: Any, replays: list | tuple = ()
               ) -> list[float]:
    """Behaviour-clone the actor of ``model`` (PPO or SAC) on ``teacher``; the epochs' errors.
    SAC's target critics are left as they are (the critic is not fitted)."""
    obs, actions = teacher_data(config, teacher, replays)
    return clone(model.policy, config, obs, actions)
