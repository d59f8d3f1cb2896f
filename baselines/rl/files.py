"""The RL checkpoint folder: policy weights in safetensors, everything else in JSON, loaded
without unpickling and without writing anything.

* ``config.json``: ``{"type": "rl", "format", "config"`` (:class:`RLConfig`), ``"reward"`` (the
  final reward weights: HandoverReward's fields, the shaping weight, gamma), ``"io"`` (the
  observation normalisation per part, the action box), ``"receivers"`` (seed ranges, training
  folds, the recordings trained on, the base agent's fit), ``"training"`` (env steps, episodes,
  wall time), ``"versions"}``.
* ``model.safetensors``: ``policy.<key>``, the SB3 policy's state dict; ``io.offset``,
  ``io.scale``.
* ``training_state/``: ``state.json`` (steps, episodes per env, the learning curve), the
  optimisers (:mod:`baselines.optimizer_state`), SAC's ``log_ent_coef``.

Loading (:func:`read_checkpoint`): :func:`~baselines.checkpoint_io.check_loadable` (no
interrupted commit, no file linked out of the folder), :func:`~baselines.checkpoint_io.read_json`,
:func:`~baselines.config_json.config_from_dict` for the config, then the policy is rebuilt from
that config (:func:`baselines.rl.policy.build_policy`) and its weights are read by
:func:`~baselines.checkpoint_io.load_tensors` against the rebuilt policy's keys, shapes and dtypes
(finite), and the normalisation against this code's constants. Any problem is one
:class:`~baselines.checkpoint_io.CheckpointError` naming the file; nothing is run or written. SB3's
own ``.zip`` is never written nor read.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
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
    write_json,
)
from baselines.config_json import config_from_dict
from baselines.rl.config import RLConfig
from baselines.rl.envs import PART_SCALES, PolicyIO, normalisation
from baselines.rl.policy import build_policy

KIND = "rl"
FORMAT = 1
CONFIG = "config.json"
WEIGHTS = "model.safetensors"
TRAINING_STATE = "training_state"
#: The sections of config.json besides type, format and config, and their JSON types.
SECTIONS = {"reward": dict, "io": dict, "receivers": dict, "training": dict, "versions": dict}
REWARD_KEYS = ("time_cost", "force_threshold", "force_scale", "success", "failure", "shaping",
               "gamma")


@dataclass
class RLCheckpoint:
    """A loaded RL checkpoint: its config, the rebuilt policy (weights loaded), its I/O and the
    JSON record (``record["receivers"]["replay_ids"]``: the recordings trained on)."""

    config: RLConfig
    policy: Any
    io: PolicyIO
    record: dict


def env_action_space() -> Any:
    """The handover envs' action Box (x, y, z, yaw), from their declared bounds."""
    import gymnasium as gym

    from handover_env.envs.base_handover import ACTION_HIGH, ACTION_LOW

    return gym.spaces.Box(ACTION_LOW.copy(), ACTION_HIGH.copy(), dtype=np.float32)


def weights_of(policy: Any, io: PolicyIO) -> dict[str, torch.Tensor]:
    """The tensors of ``model.safetensors``."""
    out = {f"policy.{k}": v.detach().contiguous().cpu() for k, v in policy.state_dict().items()}
    out["io.offset"] = torch.from_numpy(io.offset.copy())
    out["io.scale"] = torch.from_numpy(io.scale.copy())
    return out


def record_of(config: RLConfig, io: PolicyIO, reward: dict, receivers: dict,
              training: dict) -> dict:
    """The ``config.json`` record (module docstring)."""
    import stable_baselines3

    from handover_env.envs.observation import ObsLayout

    parts = {name: {"offset": list(off), "scale": scale}
             for name, (off, scale) in PART_SCALES.items()}
    if config.form == "residual":
        n = ObsLayout(config.history).size
        parts["base_target"] = {"offset": io.offset[n:].tolist(), "scale": io.scale[n:].tolist()}
    return {
        "type": KIND,
        "format": FORMAT,
        "config": asdict(config),
        "reward": reward,
        "io": {"obs_size": int(io.offset.shape[0]), "normalisation": parts,
               "action_low": io.low.tolist(), "action_high": io.high.tolist()},
        "receivers": receivers,
        "training": training,
        "versions": {"stable_baselines3": stable_baselines3.__version__,
                     "torch": torch.__version__},
    }


def write_checkpoint(stage: Path, policy: Any, io: PolicyIO, record: dict) -> None:
    """Write ``config.json`` and ``model.safetensors`` into the staging folder ``stage``."""
    from safetensors.torch import save_file

    save_file(weights_of(policy, io), stage / WEIGHTS)
    write_json(stage / CONFIG, record)


def read_record(folder: str | Path) -> tuple[dict, RLConfig]:
    """``config.json`` of an RL checkpoint folder, validated; (record, config)."""
    folder = check_loadable(folder, [CONFIG, WEIGHTS, TRAINING_STATE], "RL")
    path = folder / CONFIG
    if not path.is_file():
        raise CheckpointError(f"{folder}: missing {CONFIG} (not an RL checkpoint of this project)")
    saved = read_json(path, CONFIG)
    if not isinstance(saved, dict):
        raise CheckpointError(f"{path}: expected a JSON object")
    if saved.get("type") != KIND:
        raise CheckpointError(f"{folder} holds a {saved.get('type')!r} checkpoint, not {KIND!r}")
    if saved.get("format") != FORMAT:
        raise CheckpointError(f"{folder}: checkpoint format {saved.get('format')!r}, this code "
                              f"reads {FORMAT}")
    want = {"type", "format", "config", *SECTIONS}
    if set(saved) != want:
        raise CheckpointError(f"{path}: expected the fields {sorted(want)}, got {sorted(saved)}")
    for key, kind in SECTIONS.items():
        if not isinstance(saved[key], kind):
            raise CheckpointError(f"{path}: {key} must be a JSON object")
    config = config_from_dict(RLConfig, saved["config"], str(path))
    reward = saved["reward"]
    if set(reward) != set(REWARD_KEYS) or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
            for v in reward.values()):
        raise CheckpointError(f"{path}: reward must hold the finite numbers {list(REWARD_KEYS)}")
    if reward["shaping"] != config.shaping or reward["gamma"] != config.gamma:
        raise CheckpointError(f"{path}: reward shaping/gamma disagree with its config")
    ids = saved["receivers"].get("replay_ids")
    if not isinstance(ids, list) or not all(isinstance(i, str) for i in ids):
        raise CheckpointError(f"{path}: receivers.replay_ids must be a list of recording ids")
    return saved, config


def read_checkpoint(folder: str | Path) -> RLCheckpoint:
    """The policy of an RL checkpoint folder, rebuilt and loaded (module docstring)."""
    folder = Path(folder)
    saved, config = read_record(folder)
    io = PolicyIO.for_env(config, env_action_space())
    policy = build_policy(config, io.observation_space, io.action_space)
    expected = {f"policy.{k}": v for k, v in expected_of(policy.state_dict()).items()}
    n = io.offset.shape[0]
    expected["io.offset"] = ((n,), torch.float32)
    expected["io.scale"] = ((n,), torch.float32)
    tensors = load_tensors(folder / WEIGHTS, expected)
    offset, scale = normalisation(config.history, config.form)
    if not (np.array_equal(tensors["io.offset"].numpy(), offset)
            and np.array_equal(tensors["io.scale"].numpy(), scale)):
        raise CheckpointError(f"{folder / WEIGHTS}: io.offset/io.scale differ from this code's "
                              "observation normalisation (a different version or an edited file)")
    state = {k[len("policy."):]: v for k, v in tensors.items() if k.startswith("policy.")}
    try:
        policy.load_state_dict(state, strict=True)
    except (RuntimeError, ValueError) as exc:
        raise CheckpointError(f"{folder / WEIGHTS}: does not fit the policy ({exc})") from None
    policy.set_training_mode(False)
    return RLCheckpoint(config, policy, io, saved)
