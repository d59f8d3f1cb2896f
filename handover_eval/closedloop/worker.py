"""The worker side of the closed-loop runs: one chunk of episodes of one agent, and its rows.

Each worker process keeps its own envs (one per env kind and Θ, made on first use, never
pickled) and its fold models (:func:`handover_eval.closedloop.roster.fold_model`).
Every episode is seeded and the agent reset, so a row does not depend on which worker ran it or
what ran before in that env. :func:`episode_row` flattens the final ``info`` into one CSV row.
"""

from __future__ import annotations

import json
import math
import time
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from handover_env.config import HandoverParams
from handover_env.data.dataset import HandoverDataset
from handover_eval.closedloop.receivers import ReceiverSpec, replay_source
from handover_eval.closedloop.roster import (
    LEARNING,
    RL_AGENTS,
    ModelRecord,
    clear_models,
    env_kind,
    fold_model,
    make_agent,
    rl_model,
)
from handover_eval.methods import MethodOptions

ENV_IDS = {"dynamic": "handover_env/DynamicHandover-v0", "static": "handover_env/StaticHandover-v0"}
#: The info keys first in every row (the rest follow in the env's order).
LEADING_INFO = (
    "outcome",
    "is_success",
    "handover_time",
    "handover_time_with_delay",
    "departure_time",
    "reach_onset_time",
    "transfer_time",
    "release_time",
    "release_force",
    "peak_wrist_force",
    "peak_contact_force",
    "body_contact_force",
    "penetration",
)
#: Tuple-valued info keys and the columns they are split into.
SPLIT = {
    "transfer_pelvis_xy": ("transfer_pelvis", "xy"),
    "transfer_object_pos": ("transfer_object", "xyz"),
}
ENV_CACHE_SIZE = 4


@dataclass(frozen=True)
class EpisodeJob:
    """A chunk of receivers for one agent, Θ and model, run by :func:`run_job` in a worker.

    ``extra`` columns are copied into every row (the Θ sweep's parameter and value);
    ``env_kwargs`` (a JSON object, "" for none) are further ``gym.make`` keyword arguments (the
    sensing sweep's ``sensing`` and ``sensors``).
    """

    token: str
    agent: str
    receivers: tuple[ReceiverSpec, ...]
    params: HandoverParams
    hand_mode: str
    options: MethodOptions
    cache_dir: Path
    model_fold: int | None = None
    train_idx: np.ndarray | None = None
    extra: tuple[tuple[str, Any], ...] = ()
    env_kwargs: str = ""


_ENVS: OrderedDict[tuple, Any] = OrderedDict()


def _env(kind: str, params: HandoverParams, env_kwargs: str = ""):
    """This worker's env of ``kind`` with Θ = ``params`` and the JSON ``env_kwargs`` (made once,
    kept for the next jobs)."""
    key = (kind, params.as_array(), env_kwargs)
    if key in _ENVS:
        _ENVS.move_to_end(key)
        return _ENVS[key]
    import gymnasium as gym

    import handover_env  # noqa: F401 - registers the envs

    env = gym.make(
        ENV_IDS[kind],
        stiffness=params.stiffness,
        damping=params.damping,
        forecast_time=params.forecast_time,
        release_force=params.release_force,
        **(json.loads(env_kwargs) if env_kwargs else {}),
    )
    _ENVS[key] = env
    while len(_ENVS) > ENV_CACHE_SIZE:
        _ENVS.popitem(last=False)[1].close()
    return env


def clear_worker_state() -> None:
    """Close this process's envs and forget its fold models (end of an in-process run)."""
    while _ENVS:
        _ENVS.popitem()[1].close()
    clear_models()


def run_job(dataset: HandoverDataset, job: EpisodeJob) -> tuple[list[dict], list[ModelRecord]]:
    """Run ``job``'s episodes; returns the rows and the fold models fitted or loaded for it."""
    from handover_env.rollout import run_episode

    fits: list[ModelRecord] = []
    model = None
    if job.agent in LEARNING:
        assert job.model_fold is not None and job.train_idx is not None
        model, record = fold_model(
            job.agent, job.model_fold, dataset, job.train_idx, job.options, job.cache_dir, job.token
        )
        fits += [record] if record is not None else []
    elif job.agent in RL_AGENTS:
        model, record = rl_model(job.agent, dataset, job.options, job.cache_dir, job.token)
        fits += [record] if record is not None else []
    agent = make_agent(job.agent, job.params, model)
    env = _env(env_kind(job.agent), job.params, job.env_kwargs)
    rows = []
    for spec in job.receivers:
        if job.agent in RL_AGENTS:  # never a receiver the policy trained on
            agent.check_receiver(spec.set, spec.key, spec.seed)  # type: ignore[attr-defined]
        options: dict[str, Any] = {"receiver": spec.set}
        if spec.set == "replay":
            source = replay_source(spec, dataset)
            options = {"receiver": "replay", "episode": source, "hand_mode": job.hand_mode}
            if job.agent == "giver-replay":
                agent.set_episode(getattr(source, "episode", source))  # type: ignore[attr-defined]
        t0 = time.perf_counter()
        steps = _StepCounter()
        info = run_episode(env, agent, seed=spec.seed, options=options, on_step=steps)
        row = episode_row(job, spec, info, steps.n, time.perf_counter() - t0)
        row["sim_unstable"] = instabilities(env.unwrapped.data)
        rows.append(row)
    return rows, fits


class _StepCounter:
    """``on_step`` callback of :func:`handover_env.rollout.run_episode` that counts env steps."""

    def __init__(self) -> None:
        self.n = 0

    def __call__(self, step: int, info: dict) -> None:
        self.n = step + 1


def instabilities(data: Any) -> int:
    """MuJoCo's bad-qpos/qvel/qacc warnings since the reset: each one means MuJoCo found the
    simulation unstable and reset its state mid-episode (auto-reset), so the episode's outcome
    cannot be trusted. Counted here: the env does not report it."""
    import mujoco

    kinds = (
        mujoco.mjtWarning.mjWARN_BADQPOS,
        mujoco.mjtWarning.mjWARN_BADQVEL,
        mujoco.mjtWarning.mjWARN_BADQACC,
    )
    return int(sum(data.warning[int(k)].number for k in kinds))


def _none_to_nan(value: Any) -> float:
    return math.nan if value is None else float(value)


def episode_row(job: EpisodeJob, spec: ReceiverSpec, info: dict, steps: int, wall: float) -> dict:
    """One CSV row: who met whom, Θ, the final info (tuples split into _x/_y/_z), replay deltas."""
    p = job.params
    row: dict[str, Any] = {
        "agent": job.agent,
        "set": spec.set,
        "receiver": spec.key,
        "seed": spec.seed,
        "fold": "" if spec.fold is None else spec.fold,
        "model_fold": "" if job.model_fold is None else job.model_fold,
        "is_ood": spec.is_ood,
        "env": env_kind(job.agent),
        "hand_mode": job.hand_mode if spec.set == "replay" else "",
        "K": p.stiffness,
        "B": p.damping,
        "t_f": p.forecast_time,
        "f_r": p.release_force,
        **dict(job.extra),
    }
    for key in list(LEADING_INFO) + [k for k in info if k not in LEADING_INFO]:
        value = info.get(key)
        if key in SPLIT:
            stem, axes = SPLIT[key]
            for axis, v in zip(
                axes, value if value is not None else (None,) * len(axes), strict=True
            ):
                row[f"{stem}_{axis}"] = _none_to_nan(v)
        elif key == "outcome":
            row[key] = "timeout" if value == "running" else value
        elif value is None or (isinstance(value, (int, float)) and not isinstance(value, bool)):
            row[key] = _none_to_nan(value)
        else:
            row[key] = value
    row["body_contact"] = _none_to_nan(info.get("body_contact_force")) > 0  # any robot-body contact
    t_release = _none_to_nan(info.get("release_time"))
    t_grasp = _none_to_nan(info.get("transfer_time"))
    row["release_before_grasp"] = bool(info.get("released")) and not (t_grasp <= t_release)
    row["hold_time"] = t_release - t_grasp  # the shared hold: grasp to release (NaN without both)
    if spec.set == "replay":
        row["recorded_transfer_time"] = spec.recorded_transfer_time
        row["recorded_pelvis_x"] = spec.recorded_pelvis_x
        row["delta_t"] = row["transfer_time"] - spec.recorded_transfer_time
        row["delta_x"] = row["transfer_pelvis_x"] - spec.recorded_pelvis_x
    row["steps"] = steps
    row["wall_s"] = wall
    return row
