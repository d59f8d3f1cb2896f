"""The record a BC-MLP or ACT checkpoint carries: what it is, in which format, its config.

:func:`checkpoint_json` builds the ``{"type", "format", "config", "features", "training"}``
record both baselines write beside their weights (``"training"``: the run's summary,
:data:`SUMMARY_KEYS`, when the training state holds them); :func:`read_checkpoint_json` reads it
back, every config field present and of its JSON type, older formats upgraded, or raises a
:class:`~baselines.checkpoint_io.CheckpointError` naming the file. The training loop that writes
it is :mod:`baselines.trainer`.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import Any

from baselines.checkpoint_io import CheckpointError, check_loadable, read_json
from baselines.config_json import config_from_dict

#: The summary of a run kept in the checkpoint JSON (``"training"``), when present in the state.
SUMMARY_KEYS = (
    "epoch",
    "step",
    "best_epoch",
    "best_step",
    "best_val",
    "stopped_early",
    "wall_time_s",
)


def checkpoint_json(kind: str, fmt: int, config: Any, state: dict | None) -> dict:
    """The record a checkpoint carries: type, format, config (a dataclass), features, run
    summary."""
    d = {"type": kind, "format": fmt, "config": json.loads(json.dumps(asdict(config))),
         "features": config.spec.to_dict()}
    if state:
        d["training"] = {k: state[k] for k in SUMMARY_KEYS if k in state}
    return d


def read_checkpoint_json(
    path: Path,
    file: str,
    kind: str,
    fmt: int,
    config_cls: type,
    label: str,
    upgrades: dict[int, Callable[[Any, str], dict]] | None = None,
) -> dict:
    """``path/file`` as written by :func:`checkpoint_json`, validated; raises CheckpointError naming
    the file.

    Args:
        path: the checkpoint folder.
        file: the record's file name in it.
        kind, fmt: the checkpoint type and format this code reads.
        config_cls: the config dataclass (every field present and of its JSON type).
        label: the baseline's name, for messages.
        upgrades: {older format: function(config, source) -> the config in this format}; the
            function validates the old config and raises CheckpointError if it cannot.
    """
    check_loadable(path, [file], label)
    f = path / file
    if not f.is_file():
        raise CheckpointError(f"{path}: missing {file} (not a {label} checkpoint of this project)")
    saved = read_json(f, file)
    if not isinstance(saved, dict):
        raise CheckpointError(f"{f}: expected a JSON object")
    if saved.get("type") != kind:
        raise CheckpointError(f"{path} holds a {saved.get('type')!r} checkpoint, not {kind!r}")
    old = saved.get("format")
    if old != fmt and not (isinstance(old, int) and old in (upgrades or {})):
        raise CheckpointError(f"{path}: checkpoint format {old}, this code reads {fmt}")
    if old != fmt:
        saved = {**saved, "format": fmt, "config": upgrades[old](saved.get("config"), str(f))}
    cfg = config_from_dict(config_cls, saved.get("config"), str(f))
    if saved.get("features") != cfg.spec.to_dict():
        raise CheckpointError(f"{f}: features {saved.get('features')!r} disagree with its config")
    if not isinstance(saved.get("training", {}), dict):
        raise CheckpointError(f"{f}: training must be a JSON object")
    return saved

