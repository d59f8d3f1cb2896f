"""Checkpoint folders of the learned baselines: written as one unit, read back only after
validation.

**Atomic writes.** :func:`staged_write` gives the caller an empty ``<out>/.staging`` folder to write
a whole checkpoint into (weights, optimizer, RNG, ``state.json``, configs). When the caller is done
the file list is recorded in ``.staging/COMMIT.json`` (written to a temporary name and renamed,
after every file was flushed to disk), and only then are the files renamed over the old ones. A
reader first calls :func:`recover`: a staging folder without ``COMMIT.json`` is an interrupted
write and is deleted (the previous checkpoint is intact); one with it is a commit that was
interrupted half way and is finished. So a kill at any moment leaves either the previous or the
new checkpoint, never files of two different epochs.

**Validated reads.** :func:`read_json` (size-bounded, one error naming the file),
:func:`load_tensors` (keys, shapes, dtypes and finiteness against what the model expects),
:func:`config_from_dict` (every field present, of its exact JSON type: ``"no"`` is not a bool, a
float is not an int) and :func:`load_optimizer` (LeRobot's optimizer format, checked against the
optimizer being resumed) raise :class:`CheckpointError` naming the file and
the problem; nothing raw (``SafetensorError``, ``JSONDecodeError``, ``KeyError``...) escapes.

**Output folders.** :func:`check_out_dir` decides whether ``train.py`` may write into ``--out``.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import re
import shutil
import typing
from collections.abc import Iterator
from dataclasses import fields
from pathlib import Path
from typing import Any

from handover_env.extras import missing_extra
from handover_env.paths import OUTPUT_LOCK, UnsafePathError, output_folder

try:
    import torch
except ModuleNotFoundError as _exc:
    raise missing_extra("baselines", _exc, __name__) from None



class CheckpointError(ValueError):
    """A checkpoint folder is missing, incomplete or does not match what is asked of it."""


STAGING = ".staging"
COMMIT = "COMMIT.json"
MAX_JSON_BYTES = 16 << 20
_SAFE_REL = re.compile(r"[A-Za-z0-9_.-]+(/[A-Za-z0-9_.-]+)*", re.ASCII)

# ---------------------------------------------------------------------- atomic writes


def _fsync_path(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextlib.contextmanager
def staged_write(out: str | os.PathLike) -> Iterator[Path]:
    """Write a checkpoint into ``out`` as one unit (see the module docstring).

    Yields the empty staging folder; every file written under it replaces the file of the same
    relative path in ``out`` when the block exits normally. On an exception the staging folder is
    deleted and ``out`` is left as it was.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    recover(out)
    stage = out / STAGING
    stage.mkdir()
    try:
        yield stage
        files = sorted(p.relative_to(stage).as_posix() for p in stage.rglob("*") if p.is_file())
        for rel in files:
            _fsync_path(stage / rel)
        tmp = stage / (COMMIT + ".tmp")
        tmp.write_text(json.dumps({"files": files}))
        _fsync_path(tmp)
        os.replace(tmp, stage / COMMIT)
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
    _apply(out)


def recover(out: str | os.PathLike) -> None:
    """Finish (``COMMIT.json`` present) or discard (absent) an interrupted :func:`staged_write`."""
    out = Path(out)
    stage = out / STAGING
    if not stage.exists():
        return
    if (stage / COMMIT).is_file():
        _apply(out)
    else:
        shutil.rmtree(stage, ignore_errors=True)


def _apply(out: Path) -> None:
    stage = out / STAGING
    try:
        files = json.loads((stage / COMMIT).read_text())["files"]
        if not isinstance(files, list) or not all(isinstance(f, str) and _SAFE_REL.fullmatch(f)
                                                  and ".." not in f.split("/") for f in files):
            raise ValueError("bad file list")
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise CheckpointError(
            f"{stage / COMMIT}: unreadable commit record ({exc}); delete {stage}"
        ) from None
    for rel in files:
        src = stage / rel
        if src.exists():  # files already moved by an interrupted earlier pass are gone
            dst = out / rel
            dst.parent.mkdir(parents=True, exist_ok=True)
            os.replace(src, dst)
    (stage / COMMIT).unlink()
    shutil.rmtree(stage, ignore_errors=True)


# ---------------------------------------------------------------------- validated reads
def read_json(path: str | os.PathLike, what: str = "JSON file") -> Any:
    """Parse the JSON file at ``path`` (at most :data:`MAX_JSON_BYTES`), or a CheckpointError."""
    path = Path(path)
    try:
        if not path.is_file():
            raise CheckpointError(f"{path}: missing {what}")
        if path.stat().st_size > MAX_JSON_BYTES:
            raise CheckpointError(f"{path}: larger than {MAX_JSON_BYTES:,} bytes")
        return json.loads(path.read_text(encoding="utf-8"))
    except CheckpointError:
        raise
    except (ValueError, OSError, RecursionError) as exc:  # JSONDecodeError, UnicodeDecodeError
        raise CheckpointError(f"{path}: not valid JSON ({type(exc).__name__}: {exc})") from None


def write_json(path: Path, obj: Any) -> None:
    """Write ``obj`` as indented JSON (no NaN: a NaN in a checkpoint is a bug)."""
    path.write_text(json.dumps(obj, indent=1))


def load_tensors(
    path: str | os.PathLike,
    expected: dict[str, tuple[tuple[int, ...], torch.dtype]] | None = None,
    finite: bool = True,
) -> dict[str, torch.Tensor]:
    """The tensors of a safetensors file, checked against ``expected`` {key: (shape, dtype)}.

    Raises:
        CheckpointError: missing, unreadable or truncated file; missing or unexpected keys; a
            shape, dtype or (with ``finite``) NaN/inf that does not fit; the message names the
            file and the key.
    """
    from safetensors.torch import load_file

    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"{path}: missing")
    try:
        tensors = load_file(path)
    except Exception as exc:  # noqa: BLE001 - SafetensorError, OSError, ValueError on a damaged file
        raise CheckpointError(
            f"{path}: not a readable safetensors file ({type(exc).__name__}: {exc})"
        ) from None
    if expected is not None:
        missing = sorted(set(expected) - set(tensors))
        extra = sorted(set(tensors) - set(expected))
        if missing or extra:
            raise CheckpointError(
                f"{path}: keys do not match the model (missing {missing[:5]}, unexpected "
                f"{extra[:5]})"
            )
        for key, (shape, dtype) in expected.items():
            t = tensors[key]
            if tuple(t.shape) != tuple(shape) or t.dtype != dtype:
                raise CheckpointError(
                    f"{path}: {key} is {t.dtype} {tuple(t.shape)}, expected {dtype} {tuple(shape)}"
                )
    if finite:
        for key, t in tensors.items():
            if t.is_floating_point() and not bool(torch.isfinite(t).all()):
                raise CheckpointError(f"{path}: {key} holds NaN or inf")
    return tensors


def expected_of(
    state_dict: dict[str, torch.Tensor],
) -> dict[str, tuple[tuple[int, ...], torch.dtype]]:
    """{key: (shape, dtype)} of a module's state dict, for :func:`load_tensors`."""
    return {k: (tuple(v.shape), v.dtype) for k, v in state_dict.items()}


def json_type_ok(value: Any, hint: Any) -> bool:
    """Is ``value`` (read from JSON) of the type ``hint``: bool, int, float (finite), str, a JSON
    object (``dict``), ``tuple[X, ...]`` (a JSON list) or ``X | None``? A bool is not an int."""
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if type(None) in args:
        return value is None or any(json_type_ok(value, a) for a in args if a is not type(None))
    if hint is bool:
        return isinstance(value, bool)
    if hint is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if hint is float:
        return (
            isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
        )
    if hint is str:
        return isinstance(value, str)
    if origin is dict or hint is dict:  # a JSON object; its contents are the config's to check
        return isinstance(value, dict) and all(isinstance(k, str) for k in value)
    if origin is tuple:  # tuple[int, ...] stored as a JSON list
        return isinstance(value, (list, tuple)) and all(json_type_ok(v, args[0]) for v in value)
    return False


def config_from_dict(cls: type, d: Any, source: str, ignore: frozenset[str] = frozenset()) -> Any:
    """``cls(**d)`` for a config dataclass, refusing missing, unknown or mistyped fields.

    Args:
        cls: the dataclass (its fields are int, float, bool, str or tuple[int, ...]).
        d: the dict read from JSON.
        source: the file, for messages.
        ignore: fields that may be absent (filled by the caller).
    """
    if not isinstance(d, dict):
        raise CheckpointError(f"{source}: config must be a JSON object, got {type(d).__name__}")
    hints = typing.get_type_hints(cls)
    names = [f.name for f in fields(cls)]
    unknown = sorted(set(d) - set(names))
    missing = sorted(set(names) - set(d) - ignore)
    if unknown or missing:
        raise CheckpointError(
            f"{source}: config fields do not match (unknown {unknown}, missing {missing})"
        )
    for name in names:
        if name in d and not json_type_ok(d[name], hints[name]):
            raise CheckpointError(
                f"{source}: config field {name} = {d[name]!r} is not a "
                f"{getattr(hints[name], '__name__', hints[name])}"
            )
    try:
        return cls(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items()})
    except (ValueError, TypeError) as exc:
        raise CheckpointError(f"{source}: invalid config ({exc})") from None


def check_training_state(
    state: Any, source: Path, counter: str, best: str, extra: dict[str, type]
) -> dict:
    """A training ``state.json`` whose fields have their JSON types and agree with each other.

    Args:
        state: the parsed JSON.
        source: the file, for messages.
        counter: the progress field (``"epoch"``: one validation pass each; ``"step"``: at most
            one).
        best: the field holding the counter value of the best validation pass.
        extra: further fields and their types.

    Raises:
        CheckpointError: a field is missing, unknown or mistyped, the counter is negative, the loss
            curves are not finite or do not fit the counter, or the best pass disagrees with them.
    """
    keys = {counter: int, "best_val": float, best: int, "train_loss": list, "val_loss": list,
            "wall_time_s": float, "split": dict, **extra}
    if not isinstance(state, dict) or set(state) != set(keys):
        got = sorted(state) if isinstance(state, dict) else type(state).__name__
        raise CheckpointError(f"{source}: expected the fields {sorted(keys)}, got {got}")
    for key, kind in keys.items():
        value = state[key]
        if kind is float:  # best_val is inf until the first validation pass
            ok = (
                isinstance(value, (int, float))
                and not isinstance(value, bool)
                and not math.isnan(value)
            )
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


# ---------------------------------------------------------------------- optimizer state
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


# ---------------------------------------------------------------------- output folders
#: What each kind of checkpoint writes into its folder (besides ``.staging``).
CHECKPOINT_FILES = {
    "act": (
        "config.json",
        "model.safetensors",
        "handover_act.json",
        "policy_preprocessor.json",
        "policy_postprocessor.json",
        "training_state",
        "train_summary.json",
        "train_log.jsonl",
    ),
    "bc_mlp": (
        "config.json",
        "model.safetensors",
        "training_state",
        "train_summary.json",
        "train_log.jsonl",
    ),
}
_ACT_STATE_FILE = re.compile(
    r"policy_(pre|post)processor_step_[0-9]+_[a-z_]+\.safetensors", re.ASCII
)
#: Entries train.py may find in an --out that holds no checkpoint yet (an export made before the
#: first checkpoint, an interrupted first write, the lock of the run that writes it).
_HARMLESS = {"lerobot_dataset", STAGING, OUTPUT_LOCK}


def checkpoint_kind(folder: str | os.PathLike) -> str | None:
    """``"act"`` or ``"bc_mlp"`` for a checkpoint folder of this project, else None."""
    folder = Path(folder)
    if (folder / "handover_act.json").is_file():
        return "act"
    config = folder / "config.json"
    if config.is_file():
        try:
            saved = read_json(config)
        except CheckpointError:
            return None
        if isinstance(saved, dict) and saved.get("type") == "bc_mlp":
            return "bc_mlp"
    return None


def remove_checkpoint(folder: Path, kind: str) -> None:
    """Delete the files a ``kind`` checkpoint writes (and nothing else) from ``folder``."""
    recover(folder)
    for name in CHECKPOINT_FILES[kind]:
        path = folder / name
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        elif path.exists() or path.is_symlink():
            path.unlink()
    if kind == "act":
        for path in folder.iterdir():
            if _ACT_STATE_FILE.fullmatch(path.name):
                path.unlink()


def check_out_dir(out: str | os.PathLike, kind: str, resume: bool, overwrite: bool) -> None:
    """May ``train.py <kind>`` write into ``out``? Raises CheckpointError saying why not.

    * a new or empty folder (or one holding only an export / an interrupted first write): yes;
    * a checkpoint of the same kind: only with ``resume`` (continue it) or ``overwrite``
      (its files are deleted first);
    * a checkpoint of the other kind: only with ``overwrite`` (never with ``resume``);
    * anything else (a folder of someone's files, a file): never, not even with ``overwrite``.
    """
    try:
        out = output_folder(out, "--out")
    except UnsafePathError as exc:
        raise CheckpointError(str(exc)) from None
    label = {"act": "ACT", "bc_mlp": "BC-MLP"}
    if not out.is_dir():
        if resume:
            raise CheckpointError(f"cannot resume: no checkpoint folder at {out}")
        return
    found = checkpoint_kind(out)
    if found is None:
        others = sorted(p.name for p in out.iterdir() if p.name not in _HARMLESS)
        if others:
            raise CheckpointError(
                f"--out {out} is not empty and holds no checkpoint of this project "
                f"({', '.join(others[:4])}"
                f"{', ...' if len(others) > 4 else ''}); choose a new or empty folder"
            )
        if resume:
            raise CheckpointError(f"cannot resume: no checkpoint in {out}")
        return
    if found != kind:
        if resume or not overwrite:
            raise CheckpointError(
                f"--out {out} holds a {label[found]} checkpoint, not {label[kind]}; pass "
                "--overwrite to "
                f"replace it, or choose another --out"
            )
        remove_checkpoint(out, found)
        return
    if resume:
        return
    if not overwrite:
        raise CheckpointError(
            f"--out {out} already holds a {label[kind]} run; pass --resume to continue it or "
            "--overwrite "
            f"to start again"
        )
    remove_checkpoint(out, found)
