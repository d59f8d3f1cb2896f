"""Optimizer state of a training checkpoint in LeRobot's format, checked before it is restored.

:func:`save_optimizer` writes ``optimizer_state.safetensors`` (flat ``state/<i>/<name>`` tensors)
and ``optimizer_param_groups.json``; :func:`load_optimizer` reads them back only after checking
them against the optimizer being resumed (same param groups, finite tensors of the parameters'
shapes), raising :class:`~baselines.checkpoint_io.CheckpointError` naming the file.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

from handover_env.extras import missing_extra

try:
    import torch
except ModuleNotFoundError as _exc:
    raise missing_extra("baselines", _exc, __name__) from None

from baselines.checkpoint_io import CheckpointError, load_tensors, read_json, write_json

OPTIMIZER_STATE = "optimizer_state.safetensors"
OPTIMIZER_PARAM_GROUPS = "optimizer_param_groups.json"


def save_optimizer(opt: torch.optim.Optimizer, folder: Path) -> None:
    """LeRobot's optimizer format: flat ``state/<i>/<name>`` tensors + the param groups as JSON."""
    from safetensors.torch import save_file

    state = opt.state_dict()
    flat = {
        f"state/{i}/{name}": t.contiguous()
        for i, s in state["state"].items()
        for name, t in s.items()
    }
    save_file(flat, folder / OPTIMIZER_STATE)
    write_json(folder / OPTIMIZER_PARAM_GROUPS, state["param_groups"])


def load_optimizer(opt: torch.optim.Optimizer, folder: Path) -> None:
    """Restore ``opt`` from :func:`save_optimizer`'s files after checking them against ``opt``.

    The param groups must equal those of ``opt`` (built from the same config: same learning rate,
    betas, weight decay and parameter indices); every state tensor must be finite and match its
    parameter's shape.
    """
    current = opt.state_dict()
    groups_file = folder / OPTIMIZER_PARAM_GROUPS
    groups = read_json(groups_file, "optimizer param groups")
    want = current["param_groups"]
    if not isinstance(groups, list) or len(groups) != len(want):
        raise CheckpointError(f"{groups_file}: expected {len(want)} param group(s)")
    if json.loads(json.dumps(want)) != groups:  # the optimizer was built from the same config
        raise CheckpointError(
            f"{groups_file}: param groups (learning rate, betas, weight decay, ...) differ from "
            "the "
            f"optimizer this config builds"
        )
    params = [p for group in opt.param_groups for p in group["params"]]
    flat = load_tensors(folder / OPTIMIZER_STATE)
    state: dict[int, dict[str, torch.Tensor]] = {}
    for key, tensor in flat.items():
        m = re.fullmatch(r"state/([0-9]+)/(exp_avg|exp_avg_sq|step|max_exp_avg_sq)", key)
        if m is None or int(m.group(1)) >= len(params):
            raise CheckpointError(f"{folder / OPTIMIZER_STATE}: unexpected key {key!r}")
        index, name = int(m.group(1)), m.group(2)
        want_shape = () if name == "step" else tuple(params[index].shape)
        if tuple(tensor.shape) != want_shape or not tensor.is_floating_point():
            raise CheckpointError(
                f"{folder / OPTIMIZER_STATE}: {key} has shape {tuple(tensor.shape)}, "
                f"expected {want_shape}"
            )
        if name == "step" and float(tensor) < 0:
            raise CheckpointError(f"{folder / OPTIMIZER_STATE}: {key} is negative")
        state.setdefault(index, {})[name] = tensor
    try:
        opt.load_state_dict({"state": state, "param_groups": groups})
    except (ValueError, KeyError, TypeError, RuntimeError) as exc:
        raise CheckpointError(f"{folder}: optimizer state does not fit ({exc})") from None
