"""Reinforcement learning of the handover in the env (Stable-Baselines3 PPO / SAC).

* :mod:`baselines.rl.config`: :class:`RLConfig`, and the training receivers' seed ranges and
  folds, disjoint from the closed-loop evaluation's by construction.
* :mod:`baselines.rl.envs`: the policy's observation and action (:class:`PolicyIO`: residual on a
  base agent's Cartesian target, or from scratch), the training env wrapper and the reward
  shaping.
* :mod:`baselines.rl.action_filter`: the first-order action filter and the memory of the last
  actions; :mod:`baselines.rl.noise`: pink action noise for SAC; :mod:`baselines.rl.privileged`:
  the true state an asymmetric critic sees; :mod:`baselines.rl.penalties`: the action-change and
  body-contact penalties; :mod:`baselines.rl.warm_start`: behaviour cloning of a scratch actor.
* :mod:`baselines.rl.policy`: the SB3 algorithm and policy built from a config (gSDE, the
  asymmetric actor-critic).
* :mod:`baselines.rl.benchmark`: a checkpoint as a benchmark plug-in (closed-loop track).
* :mod:`baselines.rl.files`: the safe checkpoint (safetensors + JSON, never SB3's pickled zip).
* :mod:`baselines.rl.agent`: :class:`RLAgent`, the policy as an :class:`agents.base.Policy`.
* :mod:`baselines.rl.train`: the training loop, learning curve, checkpoints and resume.
"""

from baselines.rl.config import TRAIN_SEED_START, RLConfig

__all__ = ["RLConfig", "TRAIN_SEED_START"]
