"""The training machinery BC-MLP and ACT share: the optimisation loop, state, best validation,
checkpoints, resume, progress.

* **Loop** (:func:`run`): drives the progress counter (``"epoch"`` for BC-MLP, ``"step"`` for ACT),
  calls the baseline's ``step`` (one epoch's batches, or one optimisation step) and, every
  ``every`` units and at the end, its ``validate``; keeps the best weights, counts the passes
  without improvement against ``patience`` (early stopping, where configured), writes a
  checkpoint after every validation pass and resumes from one. A baseline keeps only its step and
  validation functions.
* **Training state** (:func:`new_state`): a JSON-able dict with a progress counter, the loss
  curves, the best validation loss and when it was reached, the wall time and the train/validation
  split (episode ids). :func:`record_validation` appends one validation pass and says whether it
  is the new best.
* **Checkpoint** (:func:`save_checkpoint`): written as one unit by
  :func:`~baselines.checkpoint_io.staged_write`: the model files (the caller's ``write_model``:
  best weights and configs), ``training_state/`` (last weights, optimizer in LeRobot's format,
  optionally the torch RNG, ``state.json``) and the JSON-lines log :data:`LOG_FILE`.
* **Resume** (:func:`load_training_state`): the one reader that finishes an interrupted commit
  (checked, :func:`~baselines.checkpoint_io.recover`), then every file validated before it is
  used (a config that differs in a field the run may not change, a state inconsistent with its
  loss curves, a different split, weights of other shapes, a foreign optimizer state, a file
  linked out of the folder: each a :class:`~baselines.checkpoint_io.CheckpointError` naming the
  file). Loading a model (:func:`baselines.checkpoint_meta.read_checkpoint_json`) never
  recovers: it writes nothing.
* **Checkpoint JSON**: the record each checkpoint carries is :mod:`baselines.checkpoint_meta`'s.
* **Progress** (:class:`TrainingProgress`): one tqdm bar, the caller's ``log`` line per validation
  pass, and the same record as a JSON line (``train_log.jsonl``: ``{"epoch"|"step", "train_loss",
  "val_loss", "best_val", "best_epoch"|"best_step", "wall_time_s"}``), the TensorBoard-style scalar
  log a plotting script reads line by line.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from handover_env.extras import missing_extra

try:
    import torch
    from safetensors.torch import save_file
except ModuleNotFoundError as _exc:
    raise missing_extra("baselines", _exc, __name__) from None

from baselines.checkpoint_io import (
    MAX_JSON_BYTES,
    CheckpointError,
    check_loadable,
    expected_of,
    load_tensors,
    read_json,
    recover,
    staged_write,
    write_json,
)
from baselines.config_json import json_type_ok
from baselines.optimizer_state import (
    OPTIMIZER_PARAM_GROUPS,
    OPTIMIZER_STATE,
    load_optimizer,
    save_optimizer,
)

TRAINING_STATE = "training_state"
LOG_FILE = "train_log.jsonl"


def clone_weights(module: torch.nn.Module) -> dict[str, torch.Tensor]:
    """A detached copy of ``module``'s state dict (the best weights so far)."""
    return {k: v.detach().clone() for k, v in module.state_dict().items()}


def new_state(counter: str, split: dict[str, list[str]], **extra: Any) -> dict:
    """A fresh training state; ``counter`` is ``"epoch"`` or ``"step"``, ``extra`` adds fields."""
    return {
        counter: 0,
        "best_val": math.inf,
        f"best_{counter}": -1,
        "train_loss": [],
        "val_loss": [],
        "wall_time_s": 0.0,
        "split": split,
        **extra,
    }


def record_validation(state: dict, counter: str, train_loss: float, val_loss: float) -> bool:
    """Append one validation pass at the state's current ``counter``; True if it is the best so
    far."""
    state["train_loss"].append(train_loss)
    state["val_loss"].append(val_loss)
    if val_loss < state["best_val"]:
        state["best_val"], state[f"best_{counter}"] = val_loss, state[counter]
        return True
    return False


class TrainingProgress:
    """A tqdm bar (when ``enabled``), a log line and a JSON record per validation pass.

    Args:
        desc: the bar's label (``"bc-mlp"``, ``"act"``).
        total: the counter's final value; initial: its value now (a resumed run).
        unit: ``"epoch"`` or ``"step"``.
        enabled: show the bar.
        log: called with one line per validation pass (e.g. ``print``).
        previous: the JSON-lines log of the run being resumed (its text, kept as it is).
    """

    def __init__(self, desc: str, total: int, initial: int, unit: str, enabled: bool,
                 log: Callable[[str], None] | None = None, previous: str = "") -> None:
        self.unit = unit
        self.log = log
        self.lines = [line for line in previous.splitlines() if line.strip()]
        self.bar = None
        if enabled:
            from tqdm.auto import tqdm

            self.bar = tqdm(total=total, initial=initial, desc=desc, unit=unit, dynamic_ncols=True)

    def advance(self, n: int = 1, loss: float | None = None) -> None:
        """``n`` more epochs or steps; ``loss`` is shown beside the bar."""
        if self.bar is not None:
            self.bar.update(n)
            if loss is not None:
                self.bar.set_postfix(loss=f"{loss:.4f}", refresh=False)

    def validation(self, state: dict, text: str) -> None:
        """Record the validation pass just appended to ``state``; ``text`` is the log line."""
        best = f"best_{self.unit}"
        record = {
            self.unit: state[self.unit],
            "train_loss": state["train_loss"][-1],
            "val_loss": state["val_loss"][-1],
            "best_val": state["best_val"],
            best: state[best],
            "wall_time_s": round(state["wall_time_s"], 3),
        }
        self.lines.append(json.dumps(record))
        if self.log is not None:
            if self.bar is not None and self.log is print:
                self.bar.write(text)
            else:
                self.log(text)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def previous_log(out: Path) -> str:
    """The JSON-lines log of the checkpoint in ``out`` (as text, never parsed), or ``""``."""
    path = out / LOG_FILE
    if not path.is_file() or path.stat().st_size > MAX_JSON_BYTES:
        return ""
    return path.read_text(encoding="utf-8", errors="replace")


def save_checkpoint(
    out: Path,
    write_model: Callable[[Path], None],
    module: torch.nn.Module,
    opt: torch.optim.Optimizer,
    state: dict,
    progress: TrainingProgress | None = None,
    rng: bool = False,
) -> None:
    """One training checkpoint, written as a unit.

    Args:
        out: the checkpoint folder.
        write_model: writes the model files (best weights, configs) into the staging folder it is
            given.
        module: the model being trained (its current weights go to
            ``training_state/last.safetensors``).
        opt: its optimizer (LeRobot's safetensors + JSON format).
        state: the training state (``training_state/state.json``).
        progress: its JSON lines become :data:`LOG_FILE`.
        rng: also save the torch RNG (``training_state/rng.safetensors``).
    """
    with staged_write(out) as stage:
        write_model(stage)
        ts = stage / TRAINING_STATE
        ts.mkdir()
        save_file(
            {k: v.contiguous().cpu() for k, v in module.state_dict().items()},
            ts / "last.safetensors",
        )
        if rng:
            save_file({"torch_rng": torch.get_rng_state()}, ts / "rng.safetensors")
        save_optimizer(opt, ts)
        write_json(ts / "state.json", state)
        if progress is not None:
            (stage / LOG_FILE).write_text(
                "".join(line + "\n" for line in progress.lines), encoding="utf-8"
            )


@dataclass(frozen=True)
class ResumeChecks:
    """What a resumed run's checkpoint is validated against (see :func:`load_training_state`).

    Args:
        config: this run's config as JSON.
        saved_config: reads the checkpoint's config (validated).
        resumable: config fields a resumed run may change.
        check_state: validates ``state.json``.
        check_best: further checks of the best weights (e.g. positive normalisation scales).
    """

    config: dict
    saved_config: Callable[[Path], dict]
    resumable: frozenset[str]
    check_state: Callable[[Any, Path], dict]
    check_best: Callable[[dict[str, torch.Tensor], Path], None] | None = None


def load_training_state(
    out: Path,
    module: torch.nn.Module,
    opt: torch.optim.Optimizer,
    *,
    split: dict,
    checks: ResumeChecks,
    rng: bool = False,
) -> tuple[dict, dict[str, torch.Tensor]]:
    """Validated (state, best weights) of the checkpoint in ``out``; restores ``module``, ``opt``
    (and the RNG).

    Args:
        out: the checkpoint folder.
        module, opt: built from ``checks.config``; they receive the last weights and the optimizer
            state.
        split: the train/validation split of this run (must equal the checkpoint's).
        checks: what the checkpoint is validated against.
        rng: restore the torch RNG saved by :func:`save_checkpoint`.
    """
    recover(out)  # --resume is the command that wrote it: finish its interrupted commit (checked)
    ts = out / TRAINING_STATE
    saved = ("state.json", "last.safetensors", "rng.safetensors", OPTIMIZER_STATE,
             OPTIMIZER_PARAM_GROUPS)
    check_loadable(out, [f"{TRAINING_STATE}/{n}" for n in saved] + ["model.safetensors", LOG_FILE],
                   "training")
    if not (ts / "state.json").is_file() or not (ts / "last.safetensors").is_file():
        raise CheckpointError(f"cannot resume: no training state in {ts}")
    theirs, config = checks.saved_config(out), checks.config
    diff = sorted(k for k in config if k not in checks.resumable and theirs.get(k) != config[k])
    if diff:
        raise CheckpointError(f"cannot resume from {out}: its config differs in {diff}")
    state_file = ts / "state.json"
    state = checks.check_state(read_json(state_file, "training state", root=out), state_file)
    if state["split"] != split:
        raise CheckpointError(
            f"cannot resume from {out}: it was trained on a different dataset/split"
        )
    expected = expected_of(module.state_dict())
    module.load_state_dict(load_tensors(ts / "last.safetensors", expected, root=out))
    best = load_tensors(out / "model.safetensors", expected)
    if checks.check_best is not None:
        checks.check_best(best, out / "model.safetensors")
    load_optimizer(opt, ts)
    if rng:
        saved = load_tensors(ts / "rng.safetensors",
                             {"torch_rng": (tuple(torch.get_rng_state().shape), torch.uint8)},
                             root=out)
        try:
            torch.set_rng_state(saved["torch_rng"])
        except (RuntimeError, ValueError) as exc:
            raise CheckpointError(
                f"{ts / 'rng.safetensors'}: not a torch RNG state ({exc})"
            ) from None
    return state, best


# ---------------------------------------------------------------------- the loop
def run(
    module: torch.nn.Module,
    opt: torch.optim.Optimizer,
    step: Callable[[int], float],
    validate: Callable[[], float],
    *,
    counter: str,
    total: int,
    split: dict[str, list[str]],
    describe: Callable[[dict], str],
    write_model: Callable[[Path, dict[str, torch.Tensor], dict], None],
    checks: ResumeChecks,
    out_dir: str | os.PathLike | None = None,
    resume: bool = False,
    every: int = 1,
    patience: int | None = None,
    diverged: str | None = None,
    rng: bool = False,
    desc: str = "train",
    progress: bool = False,
    log: Callable[[str], None] | None = None,
    loss_every: int = 1,
) -> tuple[dict, dict[str, torch.Tensor]]:
    """Train ``module`` from ``state[counter]`` to ``total``; returns (state, best weights).

    Each unit calls ``step(n)`` (``n`` = the counter before it; returns its training loss); after
    every ``every`` units and after the last, ``validate()`` gives the validation loss, the pass is
    recorded (the train loss is the mean of the units since the previous pass), the best weights
    kept, the log written and, with ``out_dir``, a checkpoint saved. The caller loads the best
    weights into ``module`` once it returns.

    Args:
        module, opt: the model being trained and its optimizer.
        step: one unit of training (one epoch's batches, or one optimisation step).
        validate: the validation loss of ``module``'s current weights.
        counter: ``"epoch"`` or ``"step"``; total: its final value.
        split: the train/validation split (episode ids), kept in the state.
        describe: the log line of the validation pass just recorded in the state.
        write_model: writes the model files (best weights, state) into a staging folder.
        checks: what a resumed checkpoint is validated against.
        out_dir: checkpoint folder, rewritten after every validation pass.
        resume: continue from the training state in ``out_dir``.
        every: units between validation passes.
        patience: stop after this many passes without a better validation loss (the state then
            holds ``bad_epochs`` and ``stopped_early``); None trains to ``total``.
        diverged: the baseline's name; a train or validation loss that is not finite then raises
            FloatingPointError at the validation pass.
        rng: checkpoints hold the torch RNG, restored on resume.
        desc, progress, log: the tqdm bar's label, whether it shows, the per-pass log callback.
        loss_every: units between loss updates beside the bar.
    """
    early = {"bad_epochs": 0, "stopped_early": False} if patience is not None else {}
    state = new_state(counter, split, **early)
    best = clone_weights(module)
    out = None if out_dir is None else Path(out_dir)
    if resume:
        if out is None:
            raise CheckpointError("resume needs the checkpoint folder (out_dir)")
        state, best = load_training_state(out, module, opt, split=split, checks=checks, rng=rng)
    report = TrainingProgress(desc, total, state[counter], counter, progress, log,
                              previous_log(out) if resume and out is not None else "")
    t_start = time.perf_counter() - state["wall_time_s"]
    running, count = 0.0, 0
    try:
        while state[counter] < total and (patience is None or state["bad_epochs"] < patience):
            n = state[counter]
            running += step(n)
            count += 1
            state[counter] = n + 1
            report.advance(1, running / count if count % loss_every == 0 else None)
            if state[counter] % every and state[counter] != total:
                continue
            train_loss, val_loss = running / max(count, 1), validate()
            if diverged is not None and not (math.isfinite(train_loss) and math.isfinite(val_loss)):
                raise FloatingPointError(
                    f"{diverged} training diverged at {counter} {n + 1} (train loss {train_loss}, "
                    f"validation loss {val_loss}); check the data's coordinates and the learning "
                    "rate"
                )
            running, count = 0.0, 0
            improved = record_validation(state, counter, train_loss, val_loss)
            if improved:
                best = clone_weights(module)
            if patience is not None:
                state["bad_epochs"] = 0 if improved else state["bad_epochs"] + 1
                state["stopped_early"] = state["bad_epochs"] >= patience
            state["wall_time_s"] = time.perf_counter() - t_start
            report.validation(state, describe(state))
            if out is not None:
                save_checkpoint(out, lambda stage, best=best: write_model(stage, best, state),
                                module, opt, state, report, rng=rng)
    finally:
        report.close()
    return state, best


# ---------------------------------------------------------------------- state.json
def check_state(
    state: Any, source: Path, counter: str, extra: dict[str, type] | None = None
) -> dict:
    """A ``state.json`` of :func:`new_state`'s fields (plus ``extra``: further fields and their
    types), of their JSON types and consistent with each other.

    Args:
        state: the parsed JSON.
        source: the file, for messages.
        counter: the progress field (``"epoch"``: one validation pass each; ``"step"``: at most
            one); ``best_<counter>`` holds its value at the best validation pass.

    Raises:
        CheckpointError: a field is missing, unknown or mistyped, the counter is negative, the loss
            curves are not finite or do not fit the counter, or the best pass disagrees with them.
    """
    best = f"best_{counter}"
    keys = {counter: int, "best_val": float, best: int, "train_loss": list, "val_loss": list,
            "wall_time_s": float, "split": dict, **(extra or {})}
    if not isinstance(state, dict) or set(state) != set(keys):
        got = sorted(state) if isinstance(state, dict) else type(state).__name__
        raise CheckpointError(f"{source}: expected the fields {sorted(keys)}, got {got}")
    for key, kind in keys.items():
        value = state[key]
        if kind is float:  # best_val is inf until the first validation pass
            ok = isinstance(value, (int, float)) and not isinstance(value, bool) and not (
                math.isnan(value))
        else:
            ok = isinstance(value, kind) if kind in (list, dict) else json_type_ok(value, kind)
        if not ok:
            raise CheckpointError(f"{source}: {key} = {value!r} is not a {kind.__name__}")
    n, losses, train = state[counter], state["val_loss"], state["train_loss"]
    problems = []
    if n < 0:
        problems.append(f"{counter} {n} is negative")
    if len(train) != len(losses) or (len(losses) != n if counter == "epoch" else len(losses) > n):
        problems.append(f"{len(train)}/{len(losses)} loss values at {counter} {n}")
    if not all(json_type_ok(v, float) for v in train + losses):
        problems.append("a loss value is not a finite number")
    elif losses and state["best_val"] != min(losses):
        problems.append("best_val disagrees with val_loss")
    elif counter == "epoch" and losses and state[best] != losses.index(min(losses)) + 1:
        problems.append(f"{best} disagrees with val_loss")
    if not -1 <= state[best] <= max(n, 0) or state["wall_time_s"] < 0:
        problems.append(f"{best} or wall_time_s out of range")
    if "bad_epochs" in state and not 0 <= state["bad_epochs"] <= max(n, 0):
        problems.append("bad_epochs out of range")
    split = state["split"]
    if set(split) != {"train", "val"} or not all(
            isinstance(v, list) and all(isinstance(x, str) for x in v) for v in split.values()):
        problems.append("split must hold 'train' and 'val' lists of episode ids")
    if problems:
        raise CheckpointError(f"{source}: inconsistent training state: {'; '.join(problems)}")
    return state
