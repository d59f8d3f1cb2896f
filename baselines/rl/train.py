"""Training an RL handover policy with Stable-Baselines3: the loop, the learning curve, the
checkpoints and resume.

:func:`train_policy` builds ``config.n_envs`` training envs (:class:`~baselines.rl.envs.
HandoverTrainingEnv`; ``SubprocVecEnv`` when more than one, else ``DummyVecEnv``), PPO or SAC
(:func:`baselines.rl.policy.build_model`, CPU, one torch thread, seeded), and learns in chunks of
``config.eval_every`` env steps. Before the first chunk and after each, the deterministic policy
is scored on the fixed learning-curve set of training receivers (:func:`curve_receivers`: seeds
from :func:`~baselines.rl.config.curve_seed`, ID and OOD walkers and, if any, training replays):
success rate, mean handover time of the successes and mean return (HandoverReward, unshaped);
then a checkpoint is written as one unit (:func:`baselines.checkpoint_io.staged_write`).

Same seed and the same number of envs give the same weights bit for bit on CPU: every receiver
is seeded (:mod:`baselines.rl.envs`), SB3 seeds torch, numpy and the action space, the vector
env returns results in env order, and the curve evaluations draw no random number.

**Resume** continues from the last checkpoint: the policy weights, the optimiser states, the
step counter, the curve and each env's receiver stream (its episode counter; its kind generator
is reseeded from it). The episodes under way when the run stopped start afresh, the sampling's
random stream starts afresh and SAC's replay buffer refills from empty, so a resumed run is a
valid continuation but not bit-identical to an uninterrupted one. ``steps`` and ``eval_every``
may change on resume (to extend a run); any other config field may not. Nothing is restored
before all of it is checked: ``config.json`` (bounded fields, :mod:`baselines.rl.files`),
``state.json`` against it (:func:`check_state`), the weights against the policy's tensors and
the optimiser files' sizes against its parameters (before they are read).
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from baselines.checkpoint_io import (
    CheckpointError,
    check_loadable,
    expected_of,
    read_json,
    recover,
    staged_write,
    write_json,
)
from baselines.optimizer_state import OPTIMIZER_STATE, load_optimizer, save_optimizer
from baselines.rl.agent import RLAgent, make_base
from baselines.rl.config import (
    CURVE_SEEDS,
    EVAL_SEED_LIMIT,
    RUN_STRIDE,
    TRAIN_SEED_START,
    RLConfig,
    curve_seed,
    warm_start_seed,
)
from baselines.rl.envs import PolicyIO, make_handover_env, training_env
from baselines.rl.files import (
    HEADER_BYTES_PER_KEY,
    MAX_WALL_S,
    TRAINING_STATE,
    WEIGHTS,
    check_training,
    read_record,
    read_weights,
    record_of,
    write_checkpoint,
)
from baselines.rl.layout import observation_size
from baselines.rl.policy import build_model

RESUMABLE = frozenset({"steps", "eval_every"})
CURVE_KEYS = ("steps", "success_rate", "handover_time", "return", "episodes", "wall_time_s")
#: Bounds of a learning-curve point read back on resume: a mean handover time (s; an episode
#: lasts seconds) and a mean return (HandoverReward: ±10 at the end, small per-step costs).
MAX_HANDOVER_S = 3600.0
MAX_RETURN = 1e6


@dataclass
class TrainingData:
    """What a run may train on besides the scripted walkers.

    Args:
        replays: episodes (or recordings) of the training folds, replayed as receivers.
        replay_ids: their source ids (recorded in the checkpoint; refused as test receivers).
        folds: the training folds they come from (of ``config.folds``, ``config.split_seed``).
        dataset: the dataset's name.
        base_fit: the episodes the SPGP base (``--base ours``) is fitted on.
        provenance: the code that trains (``commit``, ``dirty``, ``command``), recorded in the
            checkpoint's ``versions`` (:func:`baselines.rl.files.record_of`).
    """

    replays: list = field(default_factory=list)
    replay_ids: list[str] = field(default_factory=list)
    folds: tuple[int, ...] = ()
    dataset: str = ""
    base_fit: Any = None
    provenance: dict = field(default_factory=dict)


@dataclass(frozen=True)
class CurveReceiver:
    """One receiver of the fixed learning-curve set."""

    kind: str
    key: str
    seed: int
    replay: int | None = None


def curve_receivers(config: RLConfig, n_replays: int) -> list[CurveReceiver]:
    """The fixed learning-curve set: ``config.curve_episodes`` training receivers, every 5th an
    OOD walker and every 5th (offset) a training replay when there are any, the rest ID walkers;
    seeds :func:`~baselines.rl.config.curve_seed`."""
    out = []
    for k in range(config.curve_episodes):
        seed = curve_seed(k)
        if n_replays and k % 5 == 4:
            i = (k // 5 * 7919) % n_replays
            out.append(CurveReceiver("replay", f"replay-{i}", seed, i))
        elif k % 5 == 3:
            out.append(CurveReceiver("ood", f"ood-{k}", seed))
        else:
            out.append(CurveReceiver("id", f"id-{k}", seed))
    return out


def evaluate_curve(agent: RLAgent, env: Any, receivers: list[CurveReceiver],
                   replays: list) -> dict[str, float]:
    """Success rate, mean handover time of the successes (NaN without one) and mean return of
    ``agent`` on ``receivers`` (deterministic actions)."""
    from handover_env.rollout import run_episode

    successes, times, returns = [], [], []
    for r in receivers:
        options: dict[str, Any] = {"receiver": r.kind}
        if r.replay is not None:
            options["episode"] = replays[r.replay]
        total = [0.0]

        def add(step: int, info: dict, total: list = total) -> None:
            total[0] += sum(float(info.get(f"reward_{t}", 0.0)) for t in ("time", "force",
                                                                          "outcome"))

        info = run_episode(env, agent, seed=r.seed, options=options, on_step=add)
        ok = bool(info.get("is_success"))
        successes.append(ok)
        if ok and info.get("handover_time") is not None:
            times.append(float(info["handover_time"]))
        returns.append(total[0])
    return {"success_rate": float(np.mean(successes)),
            "handover_time": float(np.mean(times)) if times else math.nan,
            "return": float(np.mean(returns))}


def training_vec_env(config: RLConfig, base: Any, data: TrainingData) -> Any:
    """The run's ``config.n_envs`` training envs (SubprocVecEnv when more than one)."""
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

    fns = [functools.partial(training_env, config, i, base, data.replays)
           for i in range(config.n_envs)]
    return SubprocVecEnv(fns) if config.n_envs > 1 else DummyVecEnv(fns)


def _optimizers(model: Any) -> dict[str, torch.optim.Optimizer]:
    if hasattr(model, "actor"):  # SAC
        opts = {"actor_optimizer": model.actor.optimizer,
                "critic_optimizer": model.critic.optimizer}
        if getattr(model, "ent_coef_optimizer", None) is not None:
            opts["ent_coef_optimizer"] = model.ent_coef_optimizer
        return opts
    return {"optimizer": model.policy.optimizer}


def reward_record(config: RLConfig, env: Any) -> dict:
    """The final reward weights: the env task's HandoverReward fields, the shaping weight,
    gamma and the penalties' weights (:mod:`baselines.rl.penalties`)."""
    reward = asdict(env.unwrapped.task.reward)
    return {**{k: float(v) for k, v in reward.items()}, "shaping": config.shaping,
            "gamma": config.gamma, "action_change": config.action_change,
            "contact_penalty": config.contact_penalty}


def receivers_record(config: RLConfig, data: TrainingData, state: dict) -> dict:
    """What the policy trained on, for the checkpoint (seed ranges, folds, recordings)."""
    last = TRAIN_SEED_START + CURVE_SEEDS + config.seed * RUN_STRIDE + sum(state["episodes"])
    return {
        "eval_seed_limit": EVAL_SEED_LIMIT,
        "curve_seeds": [TRAIN_SEED_START, TRAIN_SEED_START + config.curve_episodes],
        "episode_seeds": [TRAIN_SEED_START + CURVE_SEEDS + config.seed * RUN_STRIDE, last],
        "warm_start_seeds": [warm_start_seed(config.seed, config.warm_start_episodes - 1),
                             warm_start_seed(config.seed, 0)] if config.warm_start else [],
        "dataset": data.dataset,
        "folds": [int(f) for f in data.folds],
        "replay_ids": sorted(data.replay_ids),
        "base_fit_ids": sorted(ep.source_id for ep in data.base_fit)
        if data.base_fit is not None and "ours" in (config.base, config.warm_start) else [],
    }


def check_state(state: Any, source: Path, config: RLConfig, training: dict) -> dict:
    """A ``training_state/state.json`` of this run, or a CheckpointError naming the file and the
    field: ``steps``, ``episodes`` (one whole count per env) and ``wall_time_s`` within what a
    run of ``config`` reaches (:func:`~baselines.rl.files.check_training`) and equal to the
    checkpoint's ``training`` record; every curve point's numbers finite and in range (a
    handover time NaN when no curve episode succeeded), its steps rising to ``steps``."""
    keys = {"steps", "episodes", "curve", "wall_time_s"}
    if not isinstance(state, dict) or set(state) != keys:
        raise CheckpointError(f"{source}: expected the fields {sorted(keys)}")
    eps = state["episodes"]
    if not (isinstance(eps, list) and len(eps) == config.n_envs
            and all(_whole(e) and 0 <= e < RUN_STRIDE // config.n_envs for e in eps)):
        raise CheckpointError(f"{source}: episodes must be {config.n_envs} whole counts in "
                              f"[0, {RUN_STRIDE // config.n_envs:,})")
    mine = {"steps": state["steps"], "episodes": sum(eps), "wall_time_s": state["wall_time_s"]}
    check_training(mine, config, source)
    if mine != training:
        raise CheckpointError(f"{source}: steps, episodes or wall_time_s differ from the "
                              f"checkpoint's config.json ({mine} != {training})")
    curve = state["curve"]
    if not isinstance(curve, list) or not curve:
        raise CheckpointError(f"{source}: curve must be a non-empty list of points")
    last = 0
    for i, row in enumerate(curve):
        why = _curve_problem(row, last, state["steps"])
        if why is not None:
            raise CheckpointError(f"{source}: curve[{i}]: {why}")
        last = row["steps"]
    if last != state["steps"]:
        raise CheckpointError(f"{source}: the curve ends at step {last}, not at steps "
                              f"{state['steps']}")
    return state


def _whole(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _number(v: Any, low: float, high: float) -> bool:
    return (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
            and low <= v <= high)


def _curve_problem(row: Any, previous: int, steps: int) -> str | None:
    """Why ``row`` is not a learning-curve point after step ``previous`` of a run at ``steps``."""
    if not isinstance(row, dict) or set(row) != set(CURVE_KEYS):
        return f"expected the fields {sorted(CURVE_KEYS)}"
    if not _whole(row["steps"]) or not previous <= row["steps"] <= steps:
        return f"steps must be a whole number in [{previous}, {steps}]"
    if not _whole(row["episodes"]) or row["episodes"] < 0:
        return "episodes must be a whole number >= 0"
    checks = {"success_rate": (0.0, 1.0), "return": (-MAX_RETURN, MAX_RETURN),
              "wall_time_s": (0.0, MAX_WALL_S)}
    for key, (low, high) in checks.items():
        if not _number(row[key], low, high):
            return f"{key} must be a finite number in [{low:g}, {high:g}]"
    t = row["handover_time"]
    if not (isinstance(t, float) and math.isnan(t)) and not _number(t, 0.0, MAX_HANDOVER_S):
        return f"handover_time must be NaN (no success) or in [0, {MAX_HANDOVER_S:g}] s"
    return None


def save(out: Path, model: Any, io: PolicyIO, config: RLConfig, data: TrainingData,
         state: dict, reward: dict) -> None:
    """One checkpoint of the run, written as a unit."""
    record = record_of(config, io, reward, receivers_record(config, data, state),
                       {"steps": state["steps"], "episodes": sum(state["episodes"]),
                        "wall_time_s": state["wall_time_s"]}, data.provenance)
    with staged_write(out) as stage:
        write_checkpoint(stage, model.policy, io, record)
        ts = stage / TRAINING_STATE
        ts.mkdir()
        write_json(ts / "state.json", state)
        for name, opt in _optimizers(model).items():
            (ts / name).mkdir()
            save_optimizer(opt, ts / name)
        if hasattr(model, "log_ent_coef"):
            from safetensors.torch import save_file

            save_file({"log_ent_coef": model.log_ent_coef.detach().clone()}, ts / "sac.safetensors")


def read_state(out: Path, config: RLConfig, record: dict) -> dict:
    """``out``'s ``training_state/state.json``, checked against its config and its
    ``config.json`` record (:func:`check_state`); read only."""
    state_file = out / TRAINING_STATE / "state.json"
    return check_state(read_json(state_file, "RL training state", root=out), state_file, config,
                       record["training"])


def restore(out: Path, model: Any, config: RLConfig) -> dict:
    """Load the last checkpoint in ``out`` into ``model`` (weights, optimisers); its state."""
    recover(out)  # --resume is the command that wrote it: finish its interrupted commit (checked)
    check_loadable(out, [WEIGHTS, f"{TRAINING_STATE}/state.json"], "RL training")
    record, saved = read_record(out)
    diff = sorted(k for k, v in asdict(config).items()
                  if k not in RESUMABLE and asdict(saved)[k] != v)
    if diff:
        raise CheckpointError(f"cannot resume from {out}: its config differs in {diff}")
    state = read_state(out, saved, record)
    ts = out / TRAINING_STATE
    layout = {k: shape for k, (shape, _) in expected_of(model.policy.state_dict()).items()}
    n = observation_size(config.history, config.form, config.last_actions)
    layout = {**{f"policy.{k}": v for k, v in layout.items()}, "io.offset": (n,), "io.scale": (n,)}
    tensors = read_weights(out / WEIGHTS, layout)
    model.policy.load_state_dict({k[7:]: v for k, v in tensors.items() if k.startswith("policy.")})
    for name, opt in _optimizers(model).items():
        check_optimizer_size(ts / name / OPTIMIZER_STATE, opt)
        load_optimizer(opt, ts / name)
    if hasattr(model, "log_ent_coef"):
        shape = tuple(model.log_ent_coef.shape)
        saved_coef = read_weights(ts / "sac.safetensors", {"log_ent_coef": shape})
        with torch.no_grad():
            model.log_ent_coef.copy_(saved_coef["log_ent_coef"])
    return state


def check_optimizer_size(path: Path, opt: torch.optim.Optimizer) -> None:
    """Refuse an optimiser state file larger than Adam's state of ``opt``'s parameters can be
    (two moments a value and a step a tensor, 8 bytes each, plus a header of at most
    :data:`~baselines.rl.files.HEADER_BYTES_PER_KEY` a key), from its size on disk, before it is
    read (its contents are checked by :func:`~baselines.optimizer_state.load_optimizer`)."""
    params = [p for group in opt.param_groups for p in group["params"]]
    values = sum(p.numel() for p in params)
    limit = 8 + HEADER_BYTES_PER_KEY * 3 * len(params) + 8 * (2 * values + len(params))
    if path.is_file() and path.stat().st_size > limit:
        raise CheckpointError(f"{path}: {path.stat().st_size:,} bytes, more than the {limit:,} "
                              "an optimiser state of this policy may have")


def train_policy(
    config: RLConfig,
    out: str | Path,
    data: TrainingData | None = None,
    *,
    resume: bool = False,
    progress: bool = True,
    log: Callable[[str], None] | None = None,
    on_checkpoint: Callable[[dict], None] | None = None,
) -> dict:
    """Train (or continue) the policy of ``config`` into the checkpoint folder ``out``; returns
    the final training state (``steps``, ``episodes``, ``curve``, ``wall_time_s``).

    Args:
        data: training replays and the base fit (None: scripted walkers only).
        resume: continue from the checkpoint in ``out``.
        progress: a tqdm bar over env steps.
        log: one line per learning-curve point.
        on_checkpoint: called with the state after every checkpoint (the CSV/PNG writers).
    """
    from stable_baselines3.common.callbacks import BaseCallback
    from tqdm.auto import tqdm

    data = data or TrainingData()
    out = Path(out)
    torch.set_num_threads(1)
    base = make_base(config, None, data.base_fit)
    vec = training_vec_env(config, base, data)
    eval_env = make_handover_env(config)
    try:
        model = build_model(config, vec)
        io = PolicyIO.for_env(config, eval_env.action_space)
        reward = reward_record(config, eval_env)
        state = {"steps": 0, "episodes": [0] * config.n_envs, "curve": [], "wall_time_s": 0.0}
        if resume:
            state = restore(out, model, config)
            model.num_timesteps = state["steps"]
            for i, n in enumerate(state["episodes"]):
                vec.env_method("restart", n, indices=[i])
        if config.warm_start and not resume:
            from baselines.rl.agent import build_agent
            from baselines.rl.warm_start import warm_start

            teacher = build_agent(config.warm_start, None, data.base_fit)
            errors = warm_start(model, config, teacher, data.replays)
            if log is not None:
                log(f"[rl] warm start on {config.warm_start}: {config.warm_start_episodes} "
                    f"episodes, action MSE {errors[0]:.4f} -> {errors[-1]:.4f}")
        receivers = curve_receivers(config, len(data.replays))
        agent = RLAgent(model.policy, io, make_base(config, None, data.base_fit))
        t0 = time.perf_counter() - state["wall_time_s"]

        def point() -> None:
            state["episodes"] = [int(n) for n in vec.get_attr("episodes")]
            state["wall_time_s"] = time.perf_counter() - t0
            row = {"steps": int(model.num_timesteps),
                   **evaluate_curve(agent, eval_env, receivers, data.replays),
                   "episodes": sum(state["episodes"]), "wall_time_s": state["wall_time_s"]}
            state["curve"].append(row)
            state["steps"] = int(model.num_timesteps)
            save(out, model, io, config, data, state, reward)
            if log is not None:
                log(f"[rl] step {row['steps']}: success {row['success_rate']:.2f}, handover "
                    f"time {row['handover_time']:.2f} s, return {row['return']:.2f} "
                    f"({len(receivers)} training receivers)")
            if on_checkpoint is not None:
                on_checkpoint(state)

        bar = tqdm(total=config.steps, initial=min(state["steps"], config.steps), unit="step",
                   desc=f"rl {config.algo} {config.form} seed {config.seed}",
                   disable=not progress, dynamic_ncols=True)

        class Bar(BaseCallback):
            def _on_step(self) -> bool:
                bar.update(self.training_env.num_envs)
                return True

        try:
            if not state["curve"]:
                point()
            while model.num_timesteps < config.steps:
                chunk = min(config.eval_every, config.steps - model.num_timesteps)
                model.learn(chunk, reset_num_timesteps=False, callback=Bar(), progress_bar=False)
                point()
        finally:
            bar.close()
        return state
    finally:
        vec.close()
        eval_env.close()
