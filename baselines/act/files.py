"""Validation of the LeRobot files of an ACT checkpoint, before anything in them is used.

LeRobot 0.4's ``PolicyProcessorPipeline.from_pretrained`` imports and instantiates whatever class a
processor step's ``"class"`` field names, before it checks the type (LeRobot issue #4219, open):
a checkpoint whose ``policy_preprocessor.json`` starts with
``{"class": "subprocess.Popen", "config": {"args": [...]}}`` runs a command on load. So an ACT
checkpoint is read here first, and LeRobot never parses its JSON at all:

* ``policy_preprocessor.json`` / ``policy_postprocessor.json``: the steps must be exactly the
  registry names we write (:data:`PREPROCESSOR_STEPS`, :data:`POSTPROCESSOR_STEPS`), in order,
  with no ``"class"`` field, each with exactly the config our own ACT config produces, and the
  normaliser steps' ``state_file`` must be the file name LeRobot gives it, inside the folder.
  Anything else is refused with an error naming the file and the step.
* ``config.json`` (LeRobot's ``ACTConfig``) must equal what our ``handover_act.json`` config
  writes: this cross-checks ``use_giver_state`` (the ``observation.state`` input feature), the
  sizes, the chunk and the normalisation.
* the normalisation statistics (the steps' safetensors) must be finite float32 of the feature
  shapes, within what the data can produce (:mod:`baselines.norm_bounds`: means, extrema and
  quantiles within the features' ±100 m / ±200 m, standard deviations positive and at most that).

:func:`validated_stats` runs these checks and returns the statistics;
:meth:`baselines.act.agent.ACTAgent.load` then builds the policy and the processors from our
validated config (``ACTPolicy(config)``, ``make_act_pre_post_processors``) and loads only tensors
into them.
"""

from __future__ import annotations

import json
import re
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from handover_env.extras import missing_extra

try:
    import torch
except ModuleNotFoundError as _exc:
    raise missing_extra("baselines", _exc, __name__) from None

from baselines.checkpoint_io import CheckpointError, check_loadable, load_tensors, read_json
from baselines.norm_bounds import check_stat, feature_limits
from handover_env.data.features import ACTION, ACTION_DIM, OBS_ENV_STATE, OBS_STATE, STATE_DIM

if TYPE_CHECKING:
    from baselines.act.config import ACTAgentConfig

PREPROCESSOR_JSON = "policy_preprocessor.json"
POSTPROCESSOR_JSON = "policy_postprocessor.json"
#: The processor steps ``make_act_pre_post_processors`` writes, by LeRobot registry name, in order.
PREPROCESSOR_STEPS = ("rename_observations_processor", "to_batch_processor", "device_processor",
                      "normalizer_processor")
POSTPROCESSOR_STEPS = ("unnormalizer_processor", "device_processor")
ALLOWED_STEPS = frozenset(PREPROCESSOR_STEPS + POSTPROCESSOR_STEPS)
#: Steps that carry normalisation statistics in a state file.
STATEFUL_STEPS = frozenset({"normalizer_processor", "unnormalizer_processor"})
_STEP_KEYS = frozenset({"registry_name", "config", "state_file"})
_STATS = frozenset({"mean", "std", "min", "max", "count", "q01", "q10", "q50", "q90", "q99"})


def _normalised(obj: Any) -> Any:
    """``obj`` as JSON would give it back (tuples -> lists, enums -> values)."""
    return json.loads(json.dumps(obj, default=lambda o: getattr(o, "value", str(o))))


def expected_steps(pipeline) -> list[dict]:
    """The step entries LeRobot's ``save_pretrained`` writes for ``pipeline`` (without state
    files)."""
    entries = []
    for step in pipeline.steps:
        name = getattr(type(step), "_registry_name", None)
        if name not in ALLOWED_STEPS:  # our own pipelines are built from these steps only
            raise CheckpointError(
                f"internal: processor step {type(step).__name__} is not allow-listed"
            )
        entries.append({"registry_name": name, "config": _normalised(step.get_config())})
    return entries


def validate_processor_json(
    folder: Path, filename: str, pipeline, names: tuple[str, ...]
) -> dict[int, Path]:
    """Check ``folder/filename`` against the steps of ``pipeline`` (built from our config).

    Returns:
        {step index: state file} for the normaliser steps.

    Raises:
        CheckpointError: the file names a class, an unknown or unexpected registry name, a config
            other than ours, or a state file other than LeRobot's name for it; the message names
            the file and the step.
    """
    path = folder / filename
    data = read_json(path, filename)
    if (
        not isinstance(data, dict)
        or set(data) != {"name", "steps"}
        or not isinstance(data["steps"], list)
    ):
        raise CheckpointError(f"{path}: expected {{'name': ..., 'steps': [...]}}")
    expected = expected_steps(pipeline)
    prefix = re.sub(r"[^a-zA-Z0-9_]", "_", pipeline.name.lower())
    if data["name"] != pipeline.name:
        raise CheckpointError(f"{path}: pipeline name {data['name']!r}, expected {pipeline.name!r}")
    state_files: dict[int, Path] = {}
    for i, step in enumerate(data["steps"]):
        where = f"{path}: step {i}"
        if not isinstance(step, dict):
            raise CheckpointError(f"{where} is not a JSON object; refused before loading anything")
        if "class" in step:
            raise CheckpointError(
                f"{where} names the class {step['class']!r}; only the registry steps "
                f"{list(names)} are "
                f"accepted, so nothing was imported or run"
            )
        name = step.get("registry_name")
        if name not in ALLOWED_STEPS:
            raise CheckpointError(
                f"{where} names the processor {name!r}, which is not one of the steps this project "
                f"writes ({sorted(ALLOWED_STEPS)}); refused before loading anything"
            )
        unknown = sorted(set(step) - _STEP_KEYS)
        if unknown:
            raise CheckpointError(f"{where} ({name}) has unexpected fields {unknown}")
        if i >= len(expected) or name != expected[i]["registry_name"]:
            raise CheckpointError(f"{where} is {name!r}; the steps must be exactly {list(names)}")
        if _normalised(step.get("config", {})) != expected[i]["config"]:
            raise CheckpointError(
                f"{where} ({name}) has the config {step.get('config')!r}, expected "
                f"{expected[i]['config']!r} (from handover_act.json)"
            )
        wanted_file = f"{prefix}_step_{i}_{name}.safetensors"
        if name in STATEFUL_STEPS:
            if step.get("state_file") != wanted_file:
                raise CheckpointError(f"{where} ({name}) must have state_file {wanted_file!r}, "
                                      f"got {step.get('state_file')!r}")
            state_files[i] = folder / wanted_file
        elif "state_file" in step:
            raise CheckpointError(f"{where} ({name}) has a state_file, which this step never has")
    if len(data["steps"]) != len(expected):
        raise CheckpointError(f"{path}: {len(data['steps'])} steps, expected {list(names)}")
    return state_files


def load_stats(
    path: Path, features: dict[str, tuple[int, ...]], limits: dict[str, np.ndarray]
) -> dict[str, torch.Tensor]:
    """The normalisation statistics of one normaliser step, validated.

    Args:
        path: the step's safetensors file.
        features: {feature key: shape} the statistics may describe (every key ``<feature>.<stat>``
            must name one of them and one of LeRobot's statistics).
        limits: {feature key: largest |value| per entry}
            (:func:`baselines.norm_bounds.feature_limits`).
    """
    tensors = load_tensors(path)
    if not tensors:
        raise CheckpointError(f"{path}: no statistics")
    for key, t in tensors.items():
        feature, _, stat = key.rpartition(".")
        if feature not in features or stat not in _STATS:
            raise CheckpointError(f"{path}: unexpected statistic {key!r}")
        shape = (1,) if stat == "count" else features[feature]
        if tuple(t.shape) != tuple(shape) or t.dtype != torch.float32:
            raise CheckpointError(
                f"{path}: {key} is {t.dtype} {tuple(t.shape)}, expected float32 {shape}"
            )
        check_stat(path, key, t, stat, limits[feature])
    return tensors


def validate_config_json(folder: Path, policy_config) -> None:
    """``folder/config.json`` must be exactly what ``policy_config`` (from our config) writes."""
    path = folder / "config.json"
    saved = read_json(path, "config.json")
    with tempfile.TemporaryDirectory() as tmp:
        policy_config._save_pretrained(Path(tmp))
        expected = json.loads((Path(tmp) / "config.json").read_text())
    if not isinstance(saved, dict):
        raise CheckpointError(f"{path}: expected a JSON object")
    diff = sorted(k for k in set(saved) | set(expected) if saved.get(k) != expected.get(k))
    if diff:
        details = "; ".join(f"{k}: {saved.get(k)!r} vs {expected.get(k)!r}" for k in diff[:3])
        raise CheckpointError(f"{path} disagrees with handover_act.json in {diff} ({details})")


def validated_stats(
    folder: Path, trained: ACTAgentConfig
) -> tuple[dict[str, torch.Tensor], dict[str, torch.Tensor]]:
    """(normaliser statistics, unnormaliser statistics) of the ACT checkpoint in ``folder``,
    trained with the config ``trained``, after every LeRobot file of it was validated.

    Raises:
        CheckpointError: a file is missing, ``config.json`` or a processor JSON differs from what
            ``trained`` writes, or a statistic is malformed or out of bounds.
    """
    from lerobot.policies.act.processor_act import make_act_pre_post_processors

    for name in ("config.json", "model.safetensors", PREPROCESSOR_JSON, POSTPROCESSOR_JSON):
        if not (folder / name).is_file():
            raise CheckpointError(f"{folder}: missing {name} (incomplete ACT checkpoint)")
    validate_config_json(folder, trained.policy_config())
    saved_pre, saved_post = make_act_pre_post_processors(trained.policy_config(), None)
    pre_state = validate_processor_json(folder, PREPROCESSOR_JSON, saved_pre, PREPROCESSOR_STEPS)
    post_state = validate_processor_json(
        folder, POSTPROCESSOR_JSON, saved_post, POSTPROCESSOR_STEPS
    )
    env_dim = trained.spec.env_dim
    shapes = {OBS_ENV_STATE: (env_dim,), OBS_STATE: (STATE_DIM,), ACTION: (ACTION_DIM,)}
    state_files = {**pre_state, **post_state}
    check_loadable(folder, [f.name for f in state_files.values()], "ACT")
    limits = feature_limits(env_dim)
    stats = {i: load_stats(f, shapes, limits) for i, f in state_files.items()}
    return stats[3], stats[0]  # the normaliser and unnormaliser steps
