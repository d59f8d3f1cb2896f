"""One closed-loop episode: one receiver meets one agent in a Θ-keyed env, and its row.

The one runner of the closed loop's families: ``evaluate.py closed-loop`` and its sweeps
(:mod:`handover_eval.closedloop.worker`), the benchmark's closed-loop track
(:mod:`handover_eval.benchmark.closed_loop`) and CoSpar's episodes
(:mod:`handover_eval.preference.tuning`).

* **Envs** (:func:`env_for`): each process keeps its own envs, one per (env kind, Θ, further
  ``gym.make`` keywords), made on first use with Θ as one ``params=``, the
  :data:`ENV_CACHE_SIZE` most recently used kept open, never pickled. Every episode is seeded
  and resets the env's full state, so a row does not depend on which process ran it or on what
  ran before in that env.
* **An episode** (:func:`play`): :func:`handover_env.rollout.run_episode` with the env steps
  counted, the wall time and MuJoCo's instability warnings (:func:`instabilities`).
* **A receiver** (:func:`run_receiver`): a :class:`~handover_eval.receivers.ReceiverSpec`
  as the env's reset options (a scripted walker, or a replayed recording), the episode, and its
  row (:func:`episode_row`: who met whom, Θ, the final ``info`` flattened).
"""

from __future__ import annotations

import json
import math
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from agents.base import Policy
from handover_env.config import HandoverParams
from handover_env.data.dataset import HandoverDataset
from handover_eval import roster
from handover_eval.receivers import ReceiverSpec, replay_source

ENV_IDS = {"dynamic": "handover_env/DynamicHandover-v0", "static": "handover_env/StaticHandover-v0"}
#: Envs kept open per process.
ENV_CACHE_SIZE = 4
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
    "transfer_object_body": ("transfer_object", ("fwd", "lat", "up")),
}


# ------------------------------------------------------------------------ envs
def make_env(kind: str, params: HandoverParams, env_kwargs: str = "") -> Any:
    """A new env of ``kind`` (``"dynamic"`` / ``"static"``) with Θ = ``params`` and the JSON
    object ``env_kwargs`` of further ``gym.make`` keywords ("" for none: e.g. ``sensing``)."""
    import gymnasium as gym

    import handover_env  # noqa: F401 - registers the envs

    if kind not in ENV_IDS:
        raise ValueError(f"env kind must be one of {list(ENV_IDS)}, got {kind!r}")
    return gym.make(ENV_IDS[kind], params=params,
                    **(json.loads(env_kwargs) if env_kwargs else {}))


_ENVS: OrderedDict[tuple, Any] = OrderedDict()


def env_for(kind: str, params: HandoverParams, env_kwargs: str = "") -> Any:
    """This process's env of ``kind``, Θ = ``params`` and ``env_kwargs`` (:func:`make_env` on
    first use, kept for the next episodes; the least recently used is closed past
    :data:`ENV_CACHE_SIZE`)."""
    key = (kind, params.as_array(), env_kwargs)
    if key in _ENVS:
        _ENVS.move_to_end(key)
        return _ENVS[key]
    env = make_env(kind, params, env_kwargs)
    _ENVS[key] = env
    while len(_ENVS) > ENV_CACHE_SIZE:
        _ENVS.popitem(last=False)[1].close()
    return env


def clear_envs() -> None:
    """Close this process's envs (end of an in-process run, or after an episode was stopped
    mid-step: the next episode gets a fresh env)."""
    while _ENVS:
        _ENVS.popitem()[1].close()


# ------------------------------------------------------------------------ one episode
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


@dataclass(frozen=True)
class Played:
    """One episode's end: the final ``info``, the env steps, the wall seconds and MuJoCo's
    instability warnings (:func:`instabilities`)."""

    info: dict
    steps: int
    wall_s: float
    sim_unstable: int


def play(env: Any, agent: Policy, seed: int, options: dict[str, Any],
         on_step: Callable[[int, dict], None] | None = None) -> Played:
    """Run one episode of ``agent`` in ``env`` from ``reset(seed, options)``
    (:func:`handover_env.rollout.run_episode`; ``on_step(step, info)`` after every step)."""
    from handover_env.rollout import run_episode

    steps = [0]

    def count(step: int, info: dict) -> None:
        steps[0] = step + 1
        if on_step is not None:
            on_step(step, info)

    t0 = time.perf_counter()
    info = run_episode(env, agent, seed=seed, options=options, on_step=count)
    wall = time.perf_counter() - t0
    return Played(info, steps[0], wall, instabilities(env.unwrapped.data))


# ------------------------------------------------------------------------ one receiver, one row
class RowSource(Protocol):
    """Who and where: what a row says of its episode besides the receiver and the outcome.

    ``agent`` is the name rows carry, ``env`` the env kind, ``env_kwargs`` the JSON object of
    further ``gym.make`` keywords, ``hand_mode`` the replays' hand, ``model_fold`` the model's
    fold (None: the agent learns nothing), ``extra`` further columns copied into the row."""

    @property
    def agent(self) -> str: ...
    @property
    def params(self) -> HandoverParams: ...
    @property
    def env(self) -> str: ...
    @property
    def env_kwargs(self) -> str: ...
    @property
    def hand_mode(self) -> str: ...
    @property
    def model_fold(self) -> int | None: ...
    @property
    def extra(self) -> tuple[tuple[str, Any], ...]: ...


@dataclass(frozen=True)
class Setting:
    """A :class:`RowSource` of its own (the benchmark's, whose agent may be a plug-in)."""

    agent: str
    params: HandoverParams
    env: str = "dynamic"
    env_kwargs: str = ""
    hand_mode: str = "reach"
    model_fold: int | None = None
    extra: tuple[tuple[str, Any], ...] = ()


def receiver_options(spec: ReceiverSpec, dataset: HandoverDataset, hand_mode: str,
                     walker: dict[str, Any] | None = None) -> dict[str, Any]:
    """The env's reset options for ``spec``: a scripted walker of its set (``walker``: further
    walker options, e.g. the far-pass line), or the replayed recording with ``hand_mode``."""
    if spec.set == "replay":
        return {"receiver": "replay", "hand_mode": hand_mode,
                "episode": replay_source(spec, dataset)}
    options: dict[str, Any] = {"receiver": spec.set}
    if walker:
        options["walker"] = walker
    return options


def run_receiver(setting: RowSource, agent: Policy, spec: ReceiverSpec,
                 dataset: HandoverDataset, builtin: roster.AgentEntry | None = None,
                 walker: dict[str, Any] | None = None,
                 on_step: Callable[[int, dict], None] | None = None, env: Any = None) -> dict:
    """``spec`` meets ``agent`` in this process's env of ``setting`` (or in ``env``); the
    episode's row.

    ``builtin`` is the agent's roster entry (None: not a built-in). An agent with a
    ``check_receiver`` (an RL policy) first refuses a receiver it trained on; the giver-replay
    agent (``replays_only``) is given the recording it replays. ``walker``: further walker reset
    options; ``on_step(step, info)`` runs after every env step."""
    found = builtin
    check = getattr(agent, "check_receiver", None)  # an RL policy, built-in, shipped or plug-in
    if check is not None:
        check(spec.set, spec.key, spec.seed)
    options = receiver_options(spec, dataset, setting.hand_mode, walker)
    if found is not None and found.replays_only and spec.set == "replay":
        source = options["episode"]
        agent.set_episode(getattr(source, "episode", source))  # type: ignore[attr-defined]
    if env is None:
        env = env_for(setting.env, setting.params, setting.env_kwargs)
    played = play(env, agent, spec.seed, options, on_step)
    row = episode_row(setting, spec, played.info, played.steps, played.wall_s)
    row["sim_unstable"] = played.sim_unstable
    return row


def _none_to_nan(value: Any) -> float:
    return math.nan if value is None else float(value)


def episode_row(setting: RowSource, spec: ReceiverSpec, info: dict, steps: int,
                wall: float) -> dict:
    """One CSV row: who met whom, Θ, the final info (tuples split into _x/_y/_z), replay deltas."""
    p = setting.params
    row: dict[str, Any] = {
        "agent": setting.agent,
        "set": spec.set,
        "receiver": spec.key,
        "seed": spec.seed,
        "fold": "" if spec.fold is None else spec.fold,
        "model_fold": "" if setting.model_fold is None else setting.model_fold,
        "is_ood": spec.is_ood,
        "env": setting.env,
        "hand_mode": setting.hand_mode if spec.set == "replay" else "",
        "K": p.stiffness,
        "B": p.damping,
        "t_f": p.forecast_time,
        "f_r": p.release_force,
        **dict(setting.extra),
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
