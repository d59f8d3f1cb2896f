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
is reseeded from it). The episodes under way when the run stopped start afresh, and SAC's replay
buffer refills from empty, so a resumed run is a valid continuation but not bit-identical to an
uninterrupted one. ``steps`` and ``eval_every`` may change on resume (to extend a run); any
other config field may not.
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
    load_tensors,
    read_json,
    recover,
    staged_write,
    write_json,
)
from baselines.optimizer_state import load_optimizer, save_optimizer
from baselines.rl.agent import RLAgent, make_base
from baselines.rl.config import (
    CURVE_SEEDS,
    EVAL_SEED_LIMIT,
    RUN_STRIDE,
    TRAIN_SEED_START,
    RLConfig,
    curve_seed,
)
from baselines.rl.envs import PolicyIO, make_handover_env, training_env
from baselines.rl.files import TRAINING_STATE, WEIGHTS, read_record, record_of, write_checkpoint
from baselines.rl.policy import build_model

RESUMABLE = frozenset({"steps", "eval_every"})
CURVE_KEYS = ("steps", "success_rate", "handover_time", "return", "episodes", "wall_time_s")


@dataclass
class TrainingData:
    """What a run may train on besides the scripted walkers.

    Args:
        replays: episodes (or recordings) of the training folds, replayed as receivers.
        replay_ids: their source ids (recorded in the checkpoint; refused as test receivers).
        folds: the training folds they come from (of ``config.folds``, ``config.split_seed``).
        dataset: the dataset's name.
        base_fit: the episodes the SPGP base (``--base ours``) is fitted on.
    """

    replays: list = field(default_factory=list)
    replay_ids: list[str] = field(default_factory=list)
    folds: tuple[int, ...] = ()
    dataset: str = ""
    base_fit: Any = None


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


def _vec_env(config: RLConfig, base: Any, data: TrainingData) -> Any:
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
    """The final reward weights: the env task's HandoverReward fields, the shaping weight and
    gamma."""
    reward = asdict(env.unwrapped.task.reward)
    return {**{k: float(v) for k, v in reward.items()}, "shaping": config.shaping,
            "gamma": config.gamma}


def receivers_record(config: RLConfig, data: TrainingData, state: dict) -> dict:
    """What the policy trained on, for the checkpoint (seed ranges, folds, recordings)."""
    last = TRAIN_SEED_START + CURVE_SEEDS + config.seed * RUN_STRIDE + sum(state["episodes"])
    return {
        "eval_seed_limit": EVAL_SEED_LIMIT,
        "curve_seeds": [TRAIN_SEED_START, TRAIN_SEED_START + config.curve_episodes],
        "episode_seeds": [TRAIN_SEED_START + CURVE_SEEDS + config.seed * RUN_STRIDE, last],
        "dataset": data.dataset,
        "folds": [int(f) for f in data.folds],
        "replay_ids": sorted(data.replay_ids),
        "base_fit_ids": sorted(ep.source_id for ep in data.base_fit)
        if data.base_fit is not None and config.base == "ours" else [],
    }


def check_state(state: Any, source: Path, config: RLConfig) -> dict:
    """A ``training_state/state.json`` of this run, or a CheckpointError naming the file."""
    keys = {"steps", "episodes", "curve", "wall_time_s"}
    if not isinstance(state, dict) or set(state) != keys:
        raise CheckpointError(f"{source}: expected the fields {sorted(keys)}")
    eps = state["episodes"]
    ok = (isinstance(state["steps"], int) and not isinstance(state["steps"], bool)
          and state["steps"] >= 0 and isinstance(eps, list) and len(eps) == config.n_envs
          and all(isinstance(e, int) and not isinstance(e, bool) and e >= 0 for e in eps)
          and isinstance(state["wall_time_s"], (int, float)) and state["wall_time_s"] >= 0
          and isinstance(state["curve"], list)
          and all(isinstance(r, dict) and set(r) == set(CURVE_KEYS) for r in state["curve"]))
    if not ok:
        raise CheckpointError(f"{source}: inconsistent RL training state")
    return state


def save(out: Path, model: Any, io: PolicyIO, config: RLConfig, data: TrainingData,
         state: dict, reward: dict) -> None:
    """One checkpoint of the run, written as a unit."""
    record = record_of(config, io, reward, receivers_record(config, data, state),
                       {"steps": state["steps"], "episodes": sum(state["episodes"]),
                        "wall_time_s": state["wall_time_s"]})
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


def restore(out: Path, model: Any, config: RLConfig) -> dict:
    """Load the last checkpoint in ``out`` into ``model`` (weights, optimisers); its state."""
    recover(out)  # --resume is the command that wrote it: finish its interrupted commit (checked)
    check_loadable(out, [WEIGHTS, f"{TRAINING_STATE}/state.json"], "RL training")
    _, saved = read_record(out)
    diff = sorted(k for k, v in asdict(config).items()
                  if k not in RESUMABLE and asdict(saved)[k] != v)
    if diff:
        raise CheckpointError(f"cannot resume from {out}: its config differs in {diff}")
    ts = out / TRAINING_STATE
    state_file = ts / "state.json"
    state = check_state(read_json(state_file, "RL training state", root=out), state_file, config)
    expected = {f"policy.{k}": v for k, v in expected_of(model.policy.state_dict()).items()}
    n = model.observation_space.shape[0]
    expected["io.offset"] = expected["io.scale"] = ((n,), torch.float32)
    tensors = load_tensors(out / WEIGHTS, expected)
    model.policy.load_state_dict({k[7:]: v for k, v in tensors.items() if k.startswith("policy.")})
    for name, opt in _optimizers(model).items():
        load_optimizer(opt, ts / name)
    if hasattr(model, "log_ent_coef"):
        shape = tuple(model.log_ent_coef.shape)
        saved_coef = load_tensors(ts / "sac.safetensors", {"log_ent_coef": (shape, torch.float32)},
                                  root=out)
        with torch.no_grad():
            model.log_ent_coef.copy_(saved_coef["log_ent_coef"])
    return state


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
    vec = _vec_env(config, base, data)
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
