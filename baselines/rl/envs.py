"""The RL policy's view of the handover env, and the env wrapper it is trained in.

**Observation** (:class:`PolicyIO`). The env's flat observation (``ObsLayout``), each part
shifted and scaled by fixed constants of the task (:func:`normalisation`: positions about the
robot's ready pose in units of 0.5-2 m, forces in 20 N, torques in 5 N m, time in 15 s) and
clipped to ±10; the residual policy also sees its base agent's target (about the ready pose),
and with ``last_actions`` = k its k last actions (:mod:`baselines.rl.action_filter`). With
``privileged_critic`` the training env's observation is a Dict of that (``"actor"``) and the
true state the critic alone sees (``"privileged"``, :mod:`baselines.rl.privileged`). The
constants are stored in the checkpoint and checked on loading; no running statistics, so a
seed gives the same policy whatever the number of evaluations.

**Action.** The policy acts in [-1, 1]^4. Residual: the target is the base agent's target plus
``(a_x, a_y, a_z) * residual_xyz`` and ``a_yaw * residual_yaw`` (default ±0.15 m, ±0.3 rad);
scratch: the action maps affinely onto the env's action box. Both are clipped to that box. With
``action_tau`` > 0 the action first passes a first-order filter of that time constant
(:mod:`baselines.rl.action_filter`), in training and deployed alike.

**Training env** (:class:`HandoverTrainingEnv`). Every reset draws the receiver from the
training receivers only: its kind (ID walker, OOD walker, a replay of the training folds) from a
generator of (run seed, env index), and its reset seed from
:func:`baselines.rl.config.episode_seed` (never an evaluation seed); the seed SB3 passes is
ignored. The reward is the env's :class:`~handover_env.envs.tasks.base.HandoverReward` plus,
with ``shaping > 0``, the potential-based term ``F = gamma * phi(s') - phi(s)`` (Ng, Harada and
Russell 1999: it leaves the optimal policy unchanged) with ``phi(s) = -shaping * min(d, 2 m)``,
``d`` the distance between the bottle and the person's right hand as the camera sees it, while
the gripper holds the bottle (0 otherwise and at the end). A handover happens only where the
bottle meets the hand, so ``phi`` says how far the task is from its precondition; it names no
agent's target (the residual is the place for that). ``info["reward_shaping"]`` holds ``F``
beside the env's ``reward_time``, ``reward_force`` and ``reward_outcome``, and
``info["reward_action_change"]`` and ``info["reward_contact"]`` the penalties of
:mod:`baselines.rl.penalties` (0 with their weights at 0); the reward is the sum of all six.
Mid-episode a step's info holds only these six terms, and a reset's only the receiver drawn
(``train_receiver``, ``train_seed``): SB3 reads an info only at an episode's end (success,
terminal observation), and a ``SubprocVecEnv`` worker pickles every step's info and the last
reset's through its pipe (2.9 kB a step with the env's 48-key infos, 0.7 kB without). The step
that ends an episode carries the env's whole info.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from baselines.rl.action_filter import ActionMemory
from baselines.rl.config import RLConfig, episode_seed
from baselines.rl.penalties import action_change_cost, contact_cost, segment_forces
from baselines.rl.privileged import PRIVILEGED_SIZE, privileged_observation
from handover_env.envs.end_info import reward_info
from handover_env.envs.observation import ObsLayout

ENV_ID = "handover_env/DynamicHandover-v0"
READY = (0.3, -0.4, 1.15, -math.pi / 2)
OBS_CLIP = 10.0
MAX_HAND_DISTANCE = 2.0
#: (offset, scale) of each observation part; a 2-/3-vector offset is a position.
PART_SCALES: dict[str, tuple[tuple[float, ...], float]] = {
    "receiver_xy_history": ((0.3, -0.5), 2.0),
    "receiver_frames_seen": ((0.0,), 450.0),
    "ee_pos": (READY[:3], 0.5),
    "ee_quat": ((0.0,), 1.0),
    "ee_linvel": ((0.0,), 1.0),
    "ee_angvel": ((0.0,), 5.0),
    "object_pos": (READY[:3], 0.5),
    "object_held": ((0.0,), 1.0),
    "wrist_force": ((0.0,), 20.0),
    "wrist_torque": ((0.0,), 5.0),
    "gripper_open": ((0.0,), 1.0),
    "time": ((0.0,), 15.0),
    "receiver_hand_xyz": ((0.3, -0.5, 1.0), 1.0),
    "robot_enabled": ((0.0,), 1.0),
}
TARGET_SCALE = (0.5, 0.5, 0.5, math.pi / 2)


def normalisation(history: int, form: str, last_actions: int = 0
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The fixed ``(offset, scale)`` float32 vectors of the policy's observation: the env's
    parts, the base target (residual) and the ``last_actions`` last actions (already in [-1, 1]:
    offset 0, scale 1)."""
    layout = ObsLayout(history)
    offset, scale = [], []
    for name, shape, _ in layout.fields:
        n = int(np.prod(shape))
        off, s = PART_SCALES[name]
        width = len(off)
        offset.append(np.tile(np.asarray(off, dtype=np.float64), n // width))
        scale.append(np.full(n, s))
    if form == "residual":
        offset.append(np.asarray(READY))
        scale.append(np.asarray(TARGET_SCALE))
    offset.append(np.zeros(4 * last_actions))
    scale.append(np.ones(4 * last_actions))
    return (np.concatenate(offset).astype(np.float32), np.concatenate(scale).astype(np.float32))


@dataclass
class PolicyIO:
    """The policy's observation and the env action of its output (module docstring).

    Args:
        config: the run's config (form, residual bounds, history).
        low, high: the env's action box.
        offset, scale: the observation normalisation (:func:`normalisation`).
    """

    config: RLConfig
    low: np.ndarray
    high: np.ndarray
    offset: np.ndarray
    scale: np.ndarray

    @classmethod
    def for_env(cls, config: RLConfig, action_space: gym.spaces.Box) -> PolicyIO:
        offset, scale = normalisation(config.history, config.form, config.last_actions)
        return cls(config, action_space.low.astype(np.float64),
                   action_space.high.astype(np.float64), offset, scale)

    @property
    def observation_space(self) -> gym.spaces.Box:
        n = self.offset.shape[0]
        return gym.spaces.Box(-OBS_CLIP, OBS_CLIP, (n,), np.float32)

    @property
    def action_space(self) -> gym.spaces.Box:
        return gym.spaces.Box(-1.0, 1.0, (4,), np.float32)

    def observation(self, obs: np.ndarray, base_target: np.ndarray | None,
                    past: np.ndarray | None = None) -> np.ndarray:
        """The normalised policy observation of an env observation, the base target (residual)
        and the last actions (:meth:`baselines.rl.action_filter.ActionMemory.observation`)."""
        x = np.asarray(obs, dtype=np.float64)
        if self.config.form == "residual":
            x = np.concatenate([x, np.asarray(base_target, dtype=np.float64)])
        if self.config.last_actions:
            x = np.concatenate([x, np.asarray(past, dtype=np.float64).reshape(-1)])
        if x.shape != self.offset.shape:
            raise ValueError(f"observation has {x.shape[0]} values, the policy expects "
                             f"{self.offset.shape[0]}")
        z = (x - self.offset) / self.scale
        return np.clip(np.nan_to_num(z, nan=0.0), -OBS_CLIP, OBS_CLIP).astype(np.float32)

    def start_action(self) -> np.ndarray:
        """The action of an episode's start (:mod:`baselines.rl.action_filter`): no correction
        (residual), or the one whose target is the ready pose (scratch)."""
        if self.config.form == "residual":
            return np.zeros(4)
        a = 2.0 * (np.asarray(READY) - self.low) / (self.high - self.low) - 1.0
        return np.clip(a, -1.0, 1.0)

    def action_of(self, target: np.ndarray, base_target: np.ndarray | None) -> np.ndarray:
        """The action in [-1, 1]^4 whose target is nearest ``target`` (the inverse of
        :meth:`target`, clipped): a teacher's target as the policy's action."""
        t = np.asarray(target, dtype=np.float64).reshape(4)
        if self.config.form == "residual":
            c = self.config
            a = (t - np.asarray(base_target, dtype=np.float64)) / np.array(
                [c.residual_xyz] * 3 + [c.residual_yaw])
        else:
            a = 2.0 * (t - self.low) / (self.high - self.low) - 1.0
        return np.clip(a, -1.0, 1.0)

    def memory(self) -> ActionMemory:
        """A fresh :class:`~baselines.rl.action_filter.ActionMemory` of this config."""
        return ActionMemory(self.config.action_tau, self.config.last_actions,
                            self.start_action())

    def target(self, action: np.ndarray, base_target: np.ndarray | None) -> np.ndarray:
        """The env's Cartesian target (x, y, z, yaw) for the policy's action in [-1, 1]^4."""
        a = np.clip(np.asarray(action, dtype=np.float64).reshape(4), -1.0, 1.0)
        if self.config.form == "residual":
            c = self.config
            t = np.asarray(base_target, dtype=np.float64) + a * np.array(
                [c.residual_xyz] * 3 + [c.residual_yaw])
        else:
            t = self.low + (a + 1.0) * 0.5 * (self.high - self.low)
        return np.clip(t, self.low, self.high).astype(np.float32)


def make_handover_env(config: RLConfig, **kwargs: Any) -> gym.Env:
    """The dynamic handover env with the run's history and sensing profile (``config.sensing``;
    ``""`` = the env's default)."""
    import handover_env  # noqa: F401 - registers the envs

    if config.sensing:
        kwargs["sensing"] = config.sensing
    return gym.make(ENV_ID, history=config.history, **kwargs)


class HandoverShaping:
    """The potential ``phi`` of the shaping term (module docstring), read from env observations."""

    def __init__(self, history: int, weight: float, gamma: float) -> None:
        self.layout = ObsLayout(history)
        self.weight, self.gamma = weight, gamma

    def potential(self, obs: np.ndarray) -> float:
        layout = self.layout
        if self.weight == 0 or not layout.object_held(obs) or layout.gripper_open(obs):
            return 0.0
        gap = layout.part(obs, "object_pos") - layout.part(obs, "receiver_hand_xyz")
        d = float(np.linalg.norm(gap))
        return -self.weight * min(d if math.isfinite(d) else MAX_HAND_DISTANCE, MAX_HAND_DISTANCE)

    def term(self, phi: float, obs_next: np.ndarray, terminated: bool) -> tuple[float, float]:
        """``(F, phi(s'))``: the shaping reward of a step and the next potential (0 at the end)."""
        nxt = 0.0 if terminated else self.potential(obs_next)
        return self.gamma * nxt - phi, nxt


class HandoverTrainingEnv(gym.Wrapper):
    """The handover env as the policy trains in it (module docstring).

    Args:
        env: a dynamic handover env (:func:`make_handover_env`).
        config: the run's config.
        env_index: this env's index among ``config.n_envs``.
        base: the residual's base agent (None for scratch); reset with every episode.
        replays: the training folds' episodes (or recordings) a replay episode draws from.
    """

    def __init__(self, env: gym.Env, config: RLConfig, env_index: int = 0,
                 base: Any = None, replays: list | tuple = ()) -> None:
        super().__init__(env)
        if (config.form == "residual") != (base is not None):
            raise ValueError("a residual policy needs its base agent (and scratch none)")
        self.config, self.env_index, self.base = config, env_index, base
        self.replays = list(replays)
        self.io = PolicyIO.for_env(config, env.action_space)
        self.observation_space = training_observation_space(config, self.io)
        self.action_space = self.io.action_space
        self.memory = self.io.memory()
        self.shaping = HandoverShaping(config.history, config.shaping, config.gamma)
        probs = config.probabilities(bool(self.replays))
        self._kinds, self._p = list(probs), np.array(list(probs.values()))
        self.restart(0)
        self._target: np.ndarray | None = None
        self._phi = 0.0

    def restart(self, episodes: int) -> None:
        """Continue the receiver stream at episode ``episodes`` (a fresh run: 0; a resumed one:
        its saved count, so no training seed is drawn twice); the kind generator is reseeded from
        (run seed, env index, episodes)."""
        self.episodes = int(episodes)
        self._rng = np.random.default_rng([self.config.seed, self.env_index, 0x51, self.episodes])

    def next_receiver(self) -> tuple[str, int, dict]:
        """The next training episode's (kind, reset seed, reset options); advances the stream."""
        kind = self._kinds[int(self._rng.choice(len(self._kinds), p=self._p))]
        seed = episode_seed(self.config.seed, self.config.n_envs, self.env_index, self.episodes)
        options: dict[str, Any] = {"receiver": kind}
        if kind == "replay":
            options["episode"] = self.replays[int(self._rng.integers(len(self.replays)))]
        self.episodes += 1
        return kind, seed, options

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        kind, s, opts = self.next_receiver()  # SB3's seed is ignored: see the module docstring
        obs, info = self.env.reset(seed=s, options=opts)
        if self.base is not None:
            self.base.reset()
            self._target = np.asarray(self.base.act(obs), dtype=np.float64)
        self._phi = self.shaping.potential(obs)
        self.memory.reset()
        return self._observation(obs), {"train_receiver": kind, "train_seed": s}

    def _observation(self, obs: np.ndarray) -> Any:
        """The policy's observation (and, for an asymmetric critic, the privileged state)."""
        x = self.io.observation(obs, self._target, self.memory.observation())
        if not self.config.privileged_critic:
            return x
        return {"actor": x, "privileged": privileged_observation(self.env)}

    def step(self, action):
        c = self.config
        before = self.memory.u.copy()
        u = self.memory.apply(action)
        target = self.io.target(u, self._target)
        obs, reward, terminated, truncated, info = self.env.step(target)
        shaping, self._phi = self.shaping.term(self._phi, obs, terminated)
        change = action_change_cost(c.action_change, u, before) if c.action_change else 0.0
        contact = contact_cost(c.contact_penalty, segment_forces(self.env)) \
            if c.contact_penalty else 0.0
        terms = {"reward_shaping": shaping, "reward_action_change": change,
                 "reward_contact": contact}
        info = {**(info if terminated or truncated else reward_info(info)), **terms}
        if self.base is not None and not (terminated or truncated):
            self._target = np.asarray(self.base.act(obs), dtype=np.float64)
        return (self._observation(obs), float(reward) + shaping + change + contact, terminated,
                truncated, info)


def training_observation_space(config: RLConfig, io: PolicyIO) -> gym.spaces.Space:
    """The training env's observation space: the policy's Box, or with ``privileged_critic`` a
    Dict of it (``"actor"``) and the privileged state (``"privileged"``)."""
    if not config.privileged_critic:
        return io.observation_space
    return gym.spaces.Dict({"actor": io.observation_space, "privileged": gym.spaces.Box(
        -OBS_CLIP, OBS_CLIP, (PRIVILEGED_SIZE,), np.float32)})


def training_env(config: RLConfig, env_index: int, base: Any, replays: list | tuple) -> gym.Env:
    """One training env (module-level, so SubprocVecEnv's workers can build it)."""
    import copy

    base = copy.deepcopy(base)  # each env its own base agent state
    return HandoverTrainingEnv(make_handover_env(config), config, env_index, base, replays)
