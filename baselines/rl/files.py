"""The RL checkpoint folder: policy weights in safetensors, everything else in JSON, loaded
without unpickling and without writing anything.

* ``config.json``: ``{"type": "rl", "format", "config"`` (:class:`RLConfig`, every lever of
  docs/rl.md included), ``"reward"`` (the final reward weights: HandoverReward's fields, the
  shaping weight, gamma, the action-change and contact penalties' weights), ``"io"`` (the
  observation normalisation per part, the privileged state's for an asymmetric critic, the action
  box), ``"receivers"`` (seed ranges, the warm start's, training folds, the recordings trained on,
  the base agent's fit), ``"training"`` (env steps, episodes, wall time), ``"versions"}``
  (stable_baselines3, torch and handover_env's versions, and the code that trained it: the git
  ``commit``, whether the tree was ``dirty``, the ``command``; strings and flags only, each at most
  :data:`MAX_VERSION_CHARS` characters).
* ``model.safetensors``: ``policy.<key>``, the SB3 policy's state dict; ``io.offset``,
  ``io.scale``.
* ``training_state/``: ``state.json`` (steps, episodes per env, the learning curve), the
  optimisers (:mod:`baselines.optimizer_state`), SAC's ``log_ent_coef``.

Loading (:func:`read_checkpoint`): :func:`~baselines.checkpoint_io.check_loadable` (no
interrupted commit, no file linked out of the folder), :func:`~baselines.checkpoint_io.read_json`,
:func:`~baselines.config_json.config_from_dict` for the config (every field within
:mod:`baselines.rl.config`'s bounds, the policy at most ``MAX_POLICY_PARAMS`` values), the
``training`` and ``receivers`` sections checked; then the weights file is checked against the
tensors that config implies (:func:`baselines.rl.layout.checkpoint_layout`) by
:func:`read_weights`: its size on disk against the layout's exact size before a byte is read, its
header's keys, dtypes, shapes and offsets, every value finite. Only then is the policy rebuilt
from the config (:func:`baselines.rl.policy.build_policy`) and loaded, and the normalisation
compared with this code's constants. Any problem is one
:class:`~baselines.checkpoint_io.CheckpointError` naming the file (and the field or key); nothing
is run or written. SB3's own ``.zip`` is never written nor read.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from baselines.checkpoint_io import (
    CheckpointError,
    check_loadable,
    read_json,
    write_json,
)
from baselines.config_json import config_from_dict
from baselines.rl.config import RLConfig
from baselines.rl.envs import PART_SCALES, PolicyIO, normalisation, training_observation_space
from baselines.rl.layout import DTYPE, Layout, checkpoint_layout
from baselines.rl.policy import build_policy
from handover_env.regular_file import read_regular_file

KIND = "rl"
#: 2: the exploration, observation, warm-start and penalty fields of RLConfig (issue 36).
FORMAT = 2
CONFIG = "config.json"
WEIGHTS = "model.safetensors"
TRAINING_STATE = "training_state"
#: The sections of config.json besides type, format and config, and their JSON types.
SECTIONS = {"reward": dict, "io": dict, "receivers": dict, "training": dict, "versions": dict}
REWARD_KEYS = ("time_cost", "force_threshold", "force_scale", "success", "failure", "shaping",
               "gamma", "action_change", "contact_penalty")
#: The reward record's weights that are the config's own fields.
CONFIG_REWARD_KEYS = ("shaping", "gamma", "action_change", "contact_penalty")
#: A run's wall time may not exceed this (s; ten years); real runs take an hour.
MAX_WALL_S = 3.2e8
#: The ``receivers`` record's walker seed ranges, each ``[]`` or ``[first, last]``.
SEED_RANGE_KEYS = ("curve_seeds", "episode_seeds", "warm_start_seeds")
#: The longest string of the ``versions`` record (a command line with every flag is ~300).
MAX_VERSION_CHARS = 4096
#: Bytes of a safetensors header allowed per tensor (our headers hold about 100 per key).
HEADER_BYTES_PER_KEY = 512


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
              training: dict, provenance: dict | None = None) -> dict:
    """The ``config.json`` record (module docstring); ``provenance`` (the commit, dirty flag and
    command that trained it) goes into ``versions``."""
    import stable_baselines3

    from handover_env import __version__
    from handover_env.envs.observation import ObsLayout

    parts = {name: {"offset": list(off), "scale": scale}
             for name, (off, scale) in PART_SCALES.items()}
    if config.form == "residual":
        n = ObsLayout(config.history).size
        parts["base_target"] = {"offset": io.offset[n:n + 4].tolist(),
                                "scale": io.scale[n:n + 4].tolist()}
    if config.last_actions:
        parts["last_actions"] = {"offset": [0.0], "scale": 1.0}
    if config.privileged_critic:
        from baselines.rl.privileged import PRIVILEGED_PARTS

        parts["privileged"] = {name: {"offset": list(off), "scale": sc}
                               for name, (off, sc, _) in PRIVILEGED_PARTS.items()}
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
                     "torch": torch.__version__, "handover_env": __version__,
                     **(provenance or {})},
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
    if any(reward[k] != getattr(config, k) for k in CONFIG_REWARD_KEYS):
        raise CheckpointError(f"{path}: reward {'/'.join(CONFIG_REWARD_KEYS)} disagree with its "
                              "config")
    for key, value in saved["versions"].items():
        if not (isinstance(value, bool) or isinstance(value, str)
                and len(value) <= MAX_VERSION_CHARS):
            raise CheckpointError(f"{path}: versions.{key} must be a string of at most "
                                  f"{MAX_VERSION_CHARS} characters or a flag")
    for key in SEED_RANGE_KEYS:
        r = saved["receivers"].get(key, [])
        if not (isinstance(r, list) and len(r) in (0, 2)
                and all(_whole(v) and 0 <= v < 2**63 for v in r)):
            raise CheckpointError(f"{path}: receivers.{key} must be [] or two whole seeds")
    for key in ("replay_ids", "base_fit_ids"):
        ids = saved["receivers"].get(key, [])
        if not isinstance(ids, list) or not all(isinstance(i, str) for i in ids):
            raise CheckpointError(f"{path}: receivers.{key} must be a list of recording ids")
    check_training(saved["training"], config, path, "training.")
    return saved, config


def _whole(v: object) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def check_training(training: object, config: RLConfig, path: Path, prefix: str = "") -> dict:
    """The ``training`` record (``steps``, ``episodes``, ``wall_time_s``), each a finite number
    within what a run of ``config`` can reach, or a CheckpointError naming the file ``path`` and
    the field (``prefix`` + its name).

    ``steps`` passes ``config.steps`` by less than one rollout (PPO's ``n_steps`` per env; SAC's
    one step per env); ``episodes`` counts resets, at most two per env step (an episode lasts at
    least one step, and a resumed run resets its envs once more) plus one per env;
    ``wall_time_s`` is at most :data:`MAX_WALL_S`.
    """
    if not isinstance(training, dict) or set(training) != {"steps", "episodes", "wall_time_s"}:
        raise CheckpointError(f"{path}: {prefix.rstrip('.') or 'state'} must hold the fields "
                              "['episodes', 'steps', 'wall_time_s']")
    most = config.steps + config.n_steps * config.n_envs
    steps, episodes, wall = training["steps"], training["episodes"], training["wall_time_s"]
    if not _whole(steps) or not 0 <= steps <= most:
        raise CheckpointError(f"{path}: {prefix}steps must be a whole number in [0, {most:,}], got "
                              f"{_shown(steps)}")
    if not _whole(episodes) or not 0 <= episodes <= 2 * steps + config.n_envs:
        raise CheckpointError(f"{path}: {prefix}episodes must be a whole number in [0, 2 * steps + "
                              f"n_envs = {2 * steps + config.n_envs:,}], got {_shown(episodes)}")
    if (not isinstance(wall, (int, float)) or isinstance(wall, bool) or not math.isfinite(wall)
            or not 0 <= wall <= MAX_WALL_S):
        raise CheckpointError(f"{path}: {prefix}wall_time_s must be a finite number of seconds in "
                              f"[0, {MAX_WALL_S:g}], got {_shown(wall)}")
    return training


def _shown(value: object) -> str:
    """A value from a file, for a one-line message (at most 40 characters)."""
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def read_weights(path: Path, layout: Layout) -> dict[str, torch.Tensor]:
    """The float32 tensors of the weights file ``path``, exactly ``layout`` ({key: shape}).

    The file's size is checked against the layout's before it is read (the data, 4 bytes a
    value, plus a header of at most :data:`HEADER_BYTES_PER_KEY` a key), then the header: its
    length, every key, dtype, shape and offset, the data filling the file exactly. Only then are
    the tensors made (safetensors), each checked finite.

    Raises:
        CheckpointError: naming the file and the key.
    """
    from safetensors.torch import load

    if not path.exists() and not path.is_symlink():
        raise CheckpointError(f"{path}: missing")
    data_bytes = 4 * sum(math.prod(shape) for shape in layout.values())
    header_limit = HEADER_BYTES_PER_KEY * len(layout)
    raw = read_regular_file(path, 8 + header_limit + data_bytes, path.parent,
                            inside="checkpoint folder",
                            kind=f"weights file of its config.json ({data_bytes // 4:,} values)",
                            error=CheckpointError)
    _check_header(path, raw, layout, header_limit)
    try:
        tensors = load(raw)
    except Exception as exc:  # noqa: BLE001 - SafetensorError etc. on a damaged file
        raise CheckpointError(
            f"{path}: not a readable safetensors file ({type(exc).__name__}: {exc})") from None
    for key, t in tensors.items():
        if not bool(torch.isfinite(t).all()):
            raise CheckpointError(f"{path}: {key} holds NaN or inf")
    return tensors


def _check_header(path: Path, raw: bytes, layout: Layout, limit: int) -> None:
    """The safetensors header of ``raw`` describes exactly ``layout`` (read_weights)."""
    def bad(why: str) -> CheckpointError:
        return CheckpointError(f"{path}: not a readable safetensors file ({why})")

    if len(raw) < 8:
        raise bad("shorter than its 8-byte header length")
    n = int.from_bytes(raw[:8], "little")
    if n > limit or 8 + n > len(raw):
        raise bad(f"a header of {n:,} bytes in a file of {len(raw):,}, at most {limit:,} allowed")
    try:
        header = json.loads(raw[8:8 + n].decode("utf-8"))
    except (ValueError, RecursionError) as exc:
        raise bad(f"header is not JSON: {type(exc).__name__}") from None
    if not isinstance(header, dict):
        raise bad("header is not a JSON object")
    header.pop("__metadata__", None)
    missing, extra = sorted(set(layout) - set(header)), sorted(set(header) - set(layout))
    if missing or extra:
        raise CheckpointError(f"{path}: keys do not match the model (missing {missing[:5]}, "
                              f"unexpected [{', '.join(_shown(k) for k in extra[:5])}])")
    spans = []
    for key, shape in layout.items():
        entry = header[key]
        got = entry.get("shape") if isinstance(entry, dict) else None
        dtype = entry.get("dtype") if isinstance(entry, dict) else None
        if dtype != DTYPE or not isinstance(got, list) or tuple(got) != shape:
            raise CheckpointError(f"{path}: {key} is {_shown(dtype)} {_shown(got)}, expected "
                                  f"torch.float32 {shape}")
        offsets = entry.get("data_offsets")
        if (not isinstance(offsets, list) or len(offsets) != 2 or not all(map(_whole, offsets))
                or offsets[1] - offsets[0] != 4 * math.prod(shape)):
            raise bad(f"{key}: data_offsets {_shown(offsets)} do not fit its shape")
        spans.append(tuple(offsets))
    spans.sort()
    end = 0
    for a, b in spans:
        if a != end:
            raise bad("its tensors do not tile the data")
        end = b
    if 8 + n + end != len(raw):
        raise bad(f"{len(raw) - 8 - n:,} bytes of data, its header describes {end:,}")


def read_checkpoint(folder: str | Path) -> RLCheckpoint:
    """The policy of an RL checkpoint folder, rebuilt and loaded (module docstring)."""
    folder = Path(folder)
    saved, config = read_record(folder)
    tensors = read_weights(folder / WEIGHTS, checkpoint_layout(config))
    offset, scale = normalisation(config.history, config.form, config.last_actions)
    if not (np.array_equal(tensors["io.offset"].numpy(), offset)
            and np.array_equal(tensors["io.scale"].numpy(), scale)):
        raise CheckpointError(f"{folder / WEIGHTS}: io.offset/io.scale differ from this code's "
                              "observation normalisation (a different version or an edited file)")
    io = PolicyIO.for_env(config, env_action_space())
    policy = build_policy(config, training_observation_space(config, io), io.action_space,
                          initialise=False)
    state = {k[len("policy."):]: v for k, v in tensors.items() if k.startswith("policy.")}
    try:
        policy.load_state_dict(state, strict=True)
    except (RuntimeError, ValueError) as exc:
        raise CheckpointError(f"{folder / WEIGHTS}: does not fit the policy ({exc})") from None
    policy.set_training_mode(False)
    return RLCheckpoint(config, policy, io, saved)
