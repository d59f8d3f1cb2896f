"""What an RL training run of the handover policy is: :class:`RLConfig`, and the receivers it may
meet (seed ranges disjoint from the closed-loop evaluation's, by construction).

**Seeds.** The closed-loop evaluation (``handover_eval/receivers.py``) resets its
scripted walkers with seeds ``0 .. N-1`` (ID) and ``10000 .. 10000+N-1`` (OOD), N at most 10 000
(``evaluate.py``'s ``--walkers`` bound), so every evaluation seed is below
:data:`EVAL_SEED_LIMIT`. Every training episode is reset with its own explicit seed from
:func:`episode_seed`, and the fixed learning-curve set from :func:`curve_seed`; both are at least
:data:`TRAIN_SEED_START` > :data:`EVAL_SEED_LIMIT`. No walker an evaluation scores on is ever
trained on (``tests/baselines/test_rl.py`` checks both bounds against the evaluation's constants).

**Replays.** Training replays come only from the folds :func:`training_folds` of Table I's
stratified split: the complement of the evaluation's held-out half (folds ``k//2 .. k-1``). The
checkpoint lists the recordings it trained on, and the RL agent refuses to be scored on any of
them (:meth:`baselines.rl.agent.RLAgent.check_receiver`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: Every closed-loop evaluation seed is below this (ID 0.., OOD 10000.., at most 10 000 each).
EVAL_SEED_LIMIT = 100_000
#: The first seed of any training receiver (the learning-curve set, then the training episodes).
TRAIN_SEED_START = 1_000_000
#: Seeds reserved for the fixed learning-curve set, from TRAIN_SEED_START on.
CURVE_SEEDS = 1_000
#: Training episode seeds of one run seed (and env): a run never reaches the next run's block.
RUN_STRIDE = 1_000_000_000

ALGOS = ("ppo", "sac")
FORMS = ("residual", "scratch")
BASES = ("reactive", "ours", "cv")
#: Teachers of the behaviour-cloning warm start of a scratch policy ("" = none).
WARM_STARTS = ("", "reactive", "ours", "cv")
#: Added exploration noise of SAC ("" = SAC's own Gaussian sampling only).
ACTION_NOISES = ("", "pink")
RECEIVER_KINDS = ("id", "ood", "replay")


def training_folds(folds: int) -> tuple[int, ...]:
    """The folds of a ``folds``-fold split RL may train on: ``0 .. k//2 - 1``, the complement of
    the closed-loop evaluation's held-out half (``receivers.held_out_folds``)."""
    if folds < 2:
        raise ValueError(f"folds must be >= 2, got {folds}")
    return tuple(range(folds // 2))


def episode_seed(run_seed: int, n_envs: int, env_index: int, episode: int) -> int:
    """The reset seed of training episode ``episode`` of env ``env_index`` (always >=
    :data:`TRAIN_SEED_START` + :data:`CURVE_SEEDS`, distinct across envs, episodes and run
    seeds)."""
    if not 0 <= env_index < n_envs or episode < 0 or run_seed < 0:
        raise ValueError("episode_seed needs 0 <= env_index < n_envs, episode >= 0, run_seed >= 0")
    if episode * n_envs + env_index >= RUN_STRIDE:
        raise ValueError(f"more than {RUN_STRIDE} training episodes in one run")
    return TRAIN_SEED_START + CURVE_SEEDS + run_seed * RUN_STRIDE + episode * n_envs + env_index


def curve_seed(k: int) -> int:
    """The reset seed of the ``k``-th receiver of the fixed learning-curve set."""
    if not 0 <= k < CURVE_SEEDS:
        raise ValueError(f"the learning-curve set has at most {CURVE_SEEDS} receivers")
    return TRAIN_SEED_START + k


def warm_start_seed(run_seed: int, k: int) -> int:
    """The reset seed of the ``k``-th teacher episode of a warm start: counted down from the top
    of the run's block of :data:`RUN_STRIDE` episode seeds, which training episodes fill from the
    bottom (a run has at most ``2 * MAX_STEPS + MAX_ENVS`` episodes, far below the
    ``RUN_STRIDE - MAX_WARM_START_EPISODES`` where the teacher's begin)."""
    if not 0 <= k < MAX_WARM_START_EPISODES or run_seed < 0:
        raise ValueError(f"a warm start has at most {MAX_WARM_START_EPISODES} episodes")
    return TRAIN_SEED_START + CURVE_SEEDS + run_seed * RUN_STRIDE + RUN_STRIDE - 1 - k


#: Upper bounds of an :class:`RLConfig`, far above any real run (the defaults: 200 000 steps,
#: 2 envs, a 64 x 64 network of 20 809 parameters, 30 frames of history) but low enough that a
#: crafted ``config.json`` cannot make a load allocate more than about 40 MB or take more than a
#: few seconds (tests/security/test_security_rl.py). Steps, envs and widths are train.py's own
#: flag bounds.
MAX_STEPS = 10_000_000
MAX_ENVS = 64
MAX_WIDTH = 4096
MAX_LAYERS = 16
#: The checkpoint's float32 values (2**23: 32 MiB; a 64 x 64 policy has 20 809 (PPO), 53 004 (SAC)).
MAX_POLICY_PARAMS = 2**23
#: 30 s of 30 Hz camera frames (the paper's observation holds 1 s, 30 frames).
MAX_HISTORY = 900
MAX_SEED = 2**32 - 1
#: The most past actions in the observation (1 s at 30 Hz).
MAX_LAST_ACTIONS = 30
#: The most teacher episodes of a warm start (their seeds: :func:`warm_start_seed`).
MAX_WARM_START_EPISODES = 10_000
#: (low, high) of each integer field.
INT_LIMITS = {
    "steps": (1, MAX_STEPS), "n_envs": (1, MAX_ENVS), "seed": (0, MAX_SEED),
    "n_steps": (1, 100_000), "batch_size": (1, 100_000), "n_epochs": (1, 1000),
    "folds": (2, 100), "split_seed": (0, MAX_SEED), "curve_episodes": (1, CURVE_SEEDS),
    "eval_every": (1, MAX_STEPS), "history": (2, MAX_HISTORY),
    "sde_sample_freq": (-1, 100_000), "last_actions": (0, MAX_LAST_ACTIONS),
    "warm_start_episodes": (0, MAX_WARM_START_EPISODES), "warm_start_epochs": (1, 1000),
}
#: (low, high, low excluded) of each float field: m, rad, and plain numbers.
FLOAT_LIMITS = {
    "residual_xyz": (0.0, 2.0, True), "residual_yaw": (0.0, math.pi, True),
    "learning_rate": (0.0, 1.0, True), "gamma": (0.0, 1.0, True),
    "log_std_init": (-20.0, 2.0, False), "ent_coef": (-10.0, 10.0, False),
    "shaping": (0.0, 1000.0, False), "action_tau": (0.0, 10.0, False),
    "noise_sigma": (0.0, 1.0, False), "action_change": (0.0, 1000.0, False),
    "contact_penalty": (0.0, 1000.0, False),
    "p_id": (0.0, 1.0, False), "p_ood": (0.0, 1.0, False), "p_replay": (0.0, 1.0, False),
}


def _short(arch: tuple) -> str:
    """``net_arch`` for a message (a crafted one may hold millions of widths)."""
    return repr(tuple(arch)) if len(arch) <= 8 else f"({', '.join(map(str, arch[:8]))}, ...)"


#: A ``--quick`` run's settings (tests, smoke runs): never for reported numbers.
QUICK = {"steps": 256, "n_envs": 1, "n_steps": 64, "batch_size": 32, "n_epochs": 2,
         "net_arch": (16, 16), "eval_every": 128, "curve_episodes": 2, "p_replay": 0.0}
#: The env's sensing profiles a policy may train on ('' = the env's own default).
SENSING = ("randomized", "paper", "ideal", "")


@dataclass(frozen=True)
class RLConfig:
    """One RL training run (recorded in the checkpoint's ``config.json``).

    Args:
        algo: ``"ppo"`` (default) or ``"sac"``, Stable-Baselines3's implementations.
        form: ``"residual"``: the policy's action in [-1, 1]^4 times (residual_xyz, residual_yaw)
            is added to the base agent's Cartesian target; ``"scratch"``: the action maps affinely
            onto the env's whole action box.
        base: the residual's base agent, ``"reactive"``, ``"ours"`` (SPGP, fitted on the
            training folds) or ``"cv"`` (constant velocity); ignored (``""``) for ``scratch``.
        residual_xyz: m, bound of the correction of x, y and z (default ±0.15 m).
        residual_yaw: rad, bound of the correction of the yaw (default ±0.3 rad).
        net_arch: hidden widths of the policy and value (critic) networks.
        steps: env steps of training (all envs together).
        n_envs: parallel envs (SubprocVecEnv when > 1).
        seed: seeds the policy's initialisation, the sampling and the training receivers.
        learning_rate, gamma: the optimiser's step size and the discount.
        n_steps, batch_size, n_epochs: PPO's rollout length per env, minibatch and epochs;
            for SAC ``batch_size`` is its minibatch and ``n_steps`` its ``learning_starts``.
        log_std_init: initial log standard deviation of the Gaussian policy (PPO; small for the
            residual, so the first rollouts stay near the base agent).
        ent_coef: PPO's entropy bonus.
        shaping: weight (reward per metre) of the potential-based shaping term
            ``gamma * phi(s') - phi(s)`` with ``phi = -shaping * |bottle - person's hand|`` while
            the robot holds the bottle (:mod:`baselines.rl.envs`); 0 disables it.
        p_id, p_ood, p_replay: the probabilities of a training episode's receiver: an ID walker,
            an OOD walker or a replay of the training folds (dropped when there are none).
        folds, split_seed: the stratified split whose :func:`training_folds` give the replays.
        curve_episodes: receivers of the fixed learning-curve set (ID, OOD, and replays if any).
        eval_every: env steps between learning-curve evaluations and checkpoints.
        sensing: the env's sensing profile for training: ``"randomized"`` (default: every sensor,
            controller and latency parameter drawn per episode from its documented range, so the
            policy meets the robot's imperfections, not one fixed world), ``"paper"``, ``"ideal"``,
            or ``""`` for the env's own default.
        history: camera frames of receiver history in the observation (the env's ``history``).
        use_sde, sde_sample_freq: SB3's generalised state-dependent exploration (gSDE, Raffin et
            al. 2022) for PPO or SAC: the exploration noise is a function of the policy's
            features, its matrix redrawn every ``sde_sample_freq`` steps (-1: once a rollout).
        action_noise, noise_sigma: SAC only: ``"pink"`` adds 1/f ("pink") noise of standard
            deviation ``noise_sigma`` (action units) to SAC's sampled action
            (:mod:`baselines.rl.noise`); ``""`` none.
        action_tau: s, time constant of the first-order filter through which the action reaches
            the robot (:mod:`baselines.rl.action_filter`); 0 = no filter.
        last_actions: the policy also sees its ``last_actions`` last actions (as they reached
            the robot, after the filter); 0 = none.
        privileged_critic: asymmetric actor-critic: the critic also sees the true person state
            and the true wrist force (:mod:`baselines.rl.privileged`), the actor only the sensed
            observation.
        warm_start, warm_start_episodes, warm_start_epochs: scratch only: behaviour cloning of
            the actor on a teacher agent's actions (``"reactive"``, ``"ours"`` or ``"cv"``) over
            ``warm_start_episodes`` training-receiver episodes, ``warm_start_epochs`` passes,
            before RL (:mod:`baselines.rl.warm_start`); ``""`` none.
        action_change: weight of the penalty on the change of the action between steps
            (:mod:`baselines.rl.penalties`); 0 = none.
        contact_penalty: weight of the penalty on body contact force beyond the receiving hand,
            per second at each region's ISO/TS 15066 limit (:mod:`baselines.rl.penalties`).
    """

    algo: str = "ppo"
    form: str = "residual"
    base: str = "reactive"
    residual_xyz: float = 0.15
    residual_yaw: float = 0.3
    net_arch: tuple[int, ...] = (64, 64)
    steps: int = 200_000
    n_envs: int = 2
    seed: int = 0
    learning_rate: float = 3e-4
    gamma: float = 0.99
    n_steps: int = 512
    batch_size: int = 128
    n_epochs: int = 10
    log_std_init: float = -1.0
    ent_coef: float = 0.0
    shaping: float = 1.0
    p_id: float = 0.6
    p_ood: float = 0.2
    p_replay: float = 0.2
    folds: int = 10
    split_seed: int = 0
    curve_episodes: int = 10
    eval_every: int = 20_000
    sensing: str = "randomized"
    history: int = 30
    use_sde: bool = False
    sde_sample_freq: int = -1
    action_noise: str = ""
    noise_sigma: float = 0.1
    action_tau: float = 0.0
    last_actions: int = 0
    privileged_critic: bool = False
    warm_start: str = ""
    warm_start_episodes: int = 0
    warm_start_epochs: int = 20
    action_change: float = 0.0
    contact_penalty: float = 0.0

    def __post_init__(self) -> None:
        if self.algo not in ALGOS:
            raise ValueError(f"algo must be one of {list(ALGOS)}, got {self.algo!r}")
        if self.form not in FORMS:
            raise ValueError(f"form must be one of {list(FORMS)}, got {self.form!r}")
        if self.form == "residual" and self.base not in BASES:
            raise ValueError(f"base must be one of {list(BASES)}, got {self.base!r}")
        if self.form == "scratch" and self.base != "":
            object.__setattr__(self, "base", "")
        self._check_levers()
        if self.sensing not in SENSING:
            raise ValueError(f"sensing must be one of {list(SENSING)}, got {self.sensing!r}")
        for name, (low, high, open_low) in FLOAT_LIMITS.items():
            v = getattr(self, name)
            if not (math.isfinite(v) and (v > low if open_low else v >= low) and v <= high):
                raise ValueError(f"{name} must be a finite number in {'(' if open_low else '['}"
                                 f"{low:g}, {high:g}], got {v!r}")
        if not self.gamma < 1:
            raise ValueError(f"gamma must be in (0, 1), got {self.gamma!r}")
        for name, (low, high) in INT_LIMITS.items():
            v = getattr(self, name)
            if not low <= v <= high:
                raise ValueError(f"{name} must be in [{low:,}, {high:,}], got {v!r}")
        if not 1 <= len(self.net_arch) <= MAX_LAYERS or any(
                not 1 <= w <= MAX_WIDTH for w in self.net_arch):
            raise ValueError(f"net_arch must be 1 to {MAX_LAYERS} positive widths of at most "
                             f"{MAX_WIDTH}, got {_short(self.net_arch)}")
        training_folds(self.folds)
        probs = (self.p_id, self.p_ood, self.p_replay)
        if sum(probs) <= 0:
            raise ValueError(f"p_id, p_ood, p_replay must be >= 0 and not all 0, got {probs}")
        from baselines.rl.layout import parameter_count

        n = parameter_count(self)
        if n > MAX_POLICY_PARAMS:
            raise ValueError(f"net_arch {_short(self.net_arch)} with history {self.history} makes "
                             f"a policy of {n:,} parameters, more than {MAX_POLICY_PARAMS:,}")

    def _check_levers(self) -> None:
        """The exploration, observation and warm-start fields fit together."""
        if self.action_noise not in ACTION_NOISES:
            raise ValueError(f"action_noise must be one of {list(ACTION_NOISES)}, got "
                             f"{self.action_noise!r}")
        if self.action_noise and self.algo != "sac":
            raise ValueError("action_noise (pink) is for SAC; PPO explores with its policy's "
                             "own noise (use_sde for time-correlated noise)")
        if self.sde_sample_freq != -1 and not self.use_sde:
            raise ValueError("sde_sample_freq is gSDE's: set use_sde too")
        if self.warm_start not in WARM_STARTS:
            raise ValueError(f"warm_start must be one of {list(WARM_STARTS)}, got "
                             f"{self.warm_start!r}")
        if self.warm_start and self.form != "scratch":
            raise ValueError("warm_start is for the scratch form (a residual starts at its base)")
        if bool(self.warm_start) != (self.warm_start_episodes > 0):
            raise ValueError("warm_start and warm_start_episodes > 0 go together")

    def probabilities(self, with_replays: bool) -> dict[str, float]:
        """Each receiver kind's probability (normalised; ``replay`` dropped without replays)."""
        p = {"id": self.p_id, "ood": self.p_ood}
        if with_replays:
            p["replay"] = self.p_replay
        total = sum(p.values())
        if total <= 0:
            raise ValueError("no training receivers: every kind left has probability 0")
        return {k: v / total for k, v in p.items()}
