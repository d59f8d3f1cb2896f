"""Checkpoint folders of the learned baselines: written as one unit, read back only after
validation, and loaded without writing anything.

**Atomic writes.** :func:`staged_write` gives the caller an empty ``<out>/.staging`` folder to write
a whole checkpoint into (weights, optimizer, RNG, ``state.json``, configs). When the caller is done
the file list is recorded in ``.staging/COMMIT.json`` (written by
:func:`handover_env.atomic_write.atomic_write_bytes`, after every file was flushed to disk), and
only then are the files renamed over the old ones. So a kill at any moment leaves either the
previous or the new checkpoint, never files of two epochs. The staging folder is made afresh
(``mkdir``, which fails on anything already there), so no link can be planted at a name inside it;
the JSON files go through the atomic writer all the same (:func:`write_json`), and a destination
in ``<out>`` is replaced by a rename, never written through: a symbolic link there is refused
(:func:`check_commit`) and a hard link keeps the other file's bytes.

**Recovery, by the writer only.** :func:`recover` discards a staging folder without
``COMMIT.json`` (the previous checkpoint is intact) and finishes one with it. Only the command
that wrote it calls it (the next :func:`staged_write`, ``--resume``), and only after
:func:`pending_commit` / :func:`check_commit` checked every entry: a plain relative path, no
symbolic link in the destination or the staged source, the destination inside the resolved
folder, the source a regular file. A refused entry is a CheckpointError naming it, with nothing
changed. Loading never recovers (:func:`check_loadable`): it writes nothing at all.

**Validated reads.** :func:`read_json` (size-bounded, one error naming the file) and
:func:`load_tensors` (keys, shapes, dtypes and finiteness against what the model expects), each
one read of a regular file inside its folder (:mod:`handover_env.regular_file`), and
:func:`baselines.config_json.config_from_dict` raise :class:`CheckpointError` naming the file and
the problem; nothing raw (``SafetensorError``, ``JSONDecodeError``, ``KeyError``...) escapes.
Optimizer and training state: :mod:`baselines.optimizer_state`, :mod:`baselines.trainer`.

**Output folders.** :func:`check_out_dir` decides whether ``train.py`` may write into ``--out``.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import stat
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

from handover_env.atomic_write import atomic_write_bytes
from handover_env.extras import missing_extra
from handover_env.paths import OUTPUT_LOCK, UnsafePathError, output_folder
from handover_env.regular_file import read_regular_file

try:
    import torch
except ModuleNotFoundError as _exc:
    raise missing_extra("baselines", _exc, __name__) from None


class CheckpointError(ValueError):
    """A checkpoint folder is missing, incomplete or does not match what is asked of it."""


STAGING = ".staging"
COMMIT = "COMMIT.json"
MAX_JSON_BYTES = 16 << 20
MAX_TENSOR_BYTES = 4 << 30  # ACT's optimizer state, the largest file we write, is ~0.4 GB
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

    An interrupted commit of an earlier write into ``out`` is finished first (:func:`recover`).
    Yields the empty staging folder; every file written under it replaces the file of the same
    relative path in ``out`` when the block exits normally, after every destination was checked
    to lie inside ``out`` (:func:`check_commit`). On an exception (or a refused destination) the
    staging folder is deleted and ``out`` is left as it was.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    recover(out)
    stage = out / STAGING
    stage.mkdir()
    try:
        yield stage
        files = sorted(p.relative_to(stage).as_posix() for p in stage.rglob("*") if p.is_file())
        check_commit(out, files)
        for rel in files:
            _fsync_path(stage / rel)
        atomic_write_bytes(stage / COMMIT, json.dumps({"files": files}).encode())
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
    _apply(out, files)


def recover(out: str | os.PathLike) -> None:
    """Finish (``COMMIT.json`` present) or discard (absent) an interrupted :func:`staged_write`.

    Only the writers call this: :func:`staged_write` (the next write of the same run) and
    ``--resume`` (:func:`baselines.trainer.load_training_state`); loading a checkpoint never does
    (:func:`check_loadable`). A commit is finished only after :func:`pending_commit` checked every
    entry; a refused one raises :class:`CheckpointError` naming the entry, with nothing changed.
    """
    out = Path(out)
    files = pending_commit(out)
    if files is not None:
        _apply(out, files)
    elif os.path.lexists(out / STAGING):
        shutil.rmtree(out / STAGING, ignore_errors=True)


def pending_commit(out: str | os.PathLike) -> list[str] | None:
    """The files of the interrupted commit in ``out/.staging`` (all checked), or None if none.

    None when there is no staging folder or it holds no ``COMMIT.json`` (a write interrupted
    before its commit record: the committed files are the previous checkpoint, whole).

    Raises:
        CheckpointError: ``.staging`` or ``COMMIT.json`` is a symbolic link or not a folder /
            file, the record is unreadable, or an entry fails :func:`check_commit`.
    """
    out = Path(out)
    stage, record = out / STAGING, out / STAGING / COMMIT
    if not os.path.lexists(stage):
        return None
    if stage.is_symlink() or not stage.is_dir():
        raise CheckpointError(f"{stage}: not a folder (a symbolic link?); refused, nothing changed "
                              f"(delete {stage} to discard the interrupted write)")
    if not os.path.lexists(record):
        return None
    if not stat.S_ISREG(record.lstat().st_mode):
        raise CheckpointError(f"{record}: not a regular file; refused, nothing changed (delete "
                              f"{stage} to discard the interrupted write)")
    saved = read_json(record, "commit record")
    files = saved.get("files") if isinstance(saved, dict) else None
    if set(saved if isinstance(saved, dict) else ()) != {"files"} or not isinstance(files, list):
        raise CheckpointError(f"{record}: expected {{'files': [...]}}; delete {stage}")
    check_commit(out, files, staged=True)
    return files


def check_commit(out: Path, files: list, staged: bool = False) -> None:
    """May the staged ``files`` (paths relative to ``out``) be renamed into ``out``?

    Each entry must be a plain relative path (ASCII letters, digits, ``_.-``; no ``..``, ``.``,
    ``.staging`` or empty component); no existing component of its destination under ``out`` may
    be a symbolic link, or a file where a folder is needed, or a folder where the file goes; the
    destination must resolve inside the resolved ``out``. With ``staged`` the source
    ``.staging/<entry>`` must be a regular file reached through no symbolic link, or be gone with
    the destination a regular file already (moved by an earlier, interrupted pass).

    Raises:
        CheckpointError: naming ``out``, the entry and the reason; nothing is changed.
    """
    for rel in files:
        why = _commit_problem(out, rel, staged)
        if why is not None:
            hint = f" (delete {out / STAGING} to discard the interrupted write)" if staged else ""
            raise CheckpointError(
                f"{out}: commit entry {rel!r}: {why}; refused, nothing changed{hint}")


def _commit_problem(out: Path, rel: Any, staged: bool) -> str | None:
    """Why the commit entry ``rel`` may not be renamed into ``out`` (see :func:`check_commit`)."""
    if not isinstance(rel, str) or not _SAFE_REL.fullmatch(rel) or any(
            part in ("..", ".", STAGING) for part in rel.split("/")):
        return "not a plain relative path"
    parts = rel.split("/")
    prefixes = [Path(*parts[:i]) for i in range(1, len(parts) + 1)]
    for p in prefixes:
        if (out / p).is_symlink():
            return f"{out / p} is a symbolic link"
        if p != prefixes[-1] and (out / p).exists() and not (out / p).is_dir():
            return f"{out / p} is not a folder"
    dst, stage = out / rel, out / STAGING
    if dst.is_dir():
        return f"{dst} is a folder"
    if not dst.resolve().is_relative_to(out.resolve()):
        return f"{dst} resolves outside {out.resolve()}"
    if staged:
        for p in prefixes:
            if (stage / p).is_symlink():
                return f"the staged {stage / p} is a symbolic link"
        src = stage / rel
        if os.path.lexists(src) and not stat.S_ISREG(src.lstat().st_mode):
            return f"the staged {src} is not a regular file"
        if not os.path.lexists(src) and not dst.is_file():
            return f"neither the staged {src} nor {dst} exists"
    return None


def _apply(out: Path, files: list[str]) -> None:
    """Rename the checked staged ``files`` into ``out``; then delete the staging folder."""
    stage = out / STAGING
    for rel in files:
        src = stage / rel
        if os.path.lexists(src):  # files already moved by an interrupted earlier pass are gone
            dst = out / rel
            dst.parent.mkdir(parents=True, exist_ok=True)
            os.replace(src, dst)
    (stage / COMMIT).unlink()
    shutil.rmtree(stage, ignore_errors=True)


def check_loadable(folder: str | os.PathLike, files: Iterable[str], label: str) -> Path:
    """A checkpoint folder checked for a read-only load (any loader, present or future).

    Loading writes nothing, so an interrupted write is never finished here: a ``.staging`` folder
    without a commit record is ignored (the committed files are the previous checkpoint, whole);
    one with a record is refused, since the folder may then hold files of two checkpoints and only
    the run that wrote it may finish it. Each of ``files`` (relative paths the loader reads) must
    not resolve outside the folder (a symbolic link leaving it); a missing file is the loader's to
    report.

    Returns:
        ``folder`` as a Path.

    Raises:
        CheckpointError: no such folder, an interrupted commit, or a file leaving the folder.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise CheckpointError(f"no {label} checkpoint folder at {folder}")
    stage = folder / STAGING
    if os.path.lexists(stage) and (
            stage.is_symlink() or not stage.is_dir() or os.path.lexists(stage / COMMIT)):
        raise CheckpointError(
            f"{stage}: an interrupted checkpoint write (its commit record is there, so some files "
            "may be of the next checkpoint); loading changes nothing: finish it with the command "
            f"that wrote it (train.py ... --resume --out {folder}) or delete {stage}"
        )
    root = folder.resolve()
    for rel in files:
        path = folder / rel
        if not path.resolve().is_relative_to(root):
            raise CheckpointError(f"{path}: a symbolic link out of the checkpoint folder {root}")
    return folder


# ---------------------------------------------------------------------- validated reads
def read_json(path: str | os.PathLike, what: str = "JSON file",
              root: str | os.PathLike | None = None) -> Any:
    """Parse the JSON file at ``path`` (at most :data:`MAX_JSON_BYTES`), or a CheckpointError.
    Read once by :func:`~handover_env.regular_file.read_regular_file`, inside ``root`` (default:
    the file's own folder)."""
    path = Path(path)
    if not os.path.lexists(path):
        raise CheckpointError(f"{path}: missing {what}")
    raw = read_regular_file(path, MAX_JSON_BYTES, path.parent if root is None else root,
                            inside="checkpoint folder", kind=what, error=CheckpointError)
    try:
        return json.loads(raw.decode("utf-8"))
    except (ValueError, RecursionError) as exc:  # JSONDecodeError, UnicodeDecodeError
        raise CheckpointError(f"{path}: not valid JSON ({type(exc).__name__}: {exc})") from None


def write_json(path: Path, obj: Any) -> None:
    """Write ``obj`` as indented JSON (no NaN: a NaN in a checkpoint is a bug), atomically through
    :func:`handover_env.atomic_write.atomic_write_bytes` (a fresh temporary file, no link
    followed; a target that is a link out of its folder is refused)."""
    atomic_write_bytes(path, json.dumps(obj, indent=1).encode("utf-8"))


def load_tensors(
    path: str | os.PathLike,
    expected: dict[str, tuple[tuple[int, ...], torch.dtype]] | None = None,
    finite: bool = True,
    root: str | os.PathLike | None = None,
) -> dict[str, torch.Tensor]:
    """The tensors of a safetensors file, checked against ``expected`` {key: (shape, dtype)}; read
    once (at most :data:`MAX_TENSOR_BYTES`, inside ``root``) as :func:`read_json` reads.

    Raises:
        CheckpointError: missing, unreadable or truncated file; missing or unexpected keys; a
            shape, dtype or (with ``finite``) NaN/inf that does not fit; the message names the
            file and the key.
    """
    from safetensors.torch import load

    path = Path(path)
    if not os.path.lexists(path):
        raise CheckpointError(f"{path}: missing")
    raw = read_regular_file(path, MAX_TENSOR_BYTES, path.parent if root is None else root,
                            inside="checkpoint folder", kind="safetensors file",
                            error=CheckpointError)
    try:
        tensors = load(raw)
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
    "rl": ("config.json", "model.safetensors", "training_state", "train_summary.json",
           "train_log.csv", "learning_curve.png"),
}
_ACT_STATE_FILE = re.compile(
    r"policy_(pre|post)processor_step_[0-9]+_[a-z_]+\.safetensors", re.ASCII
)
#: Entries train.py may find in an --out that holds no checkpoint yet (an export made before the
#: first checkpoint, an interrupted first write, the lock of the run that writes it).
_HARMLESS = {"lerobot_dataset", STAGING, OUTPUT_LOCK}


def checkpoint_kind(folder: str | os.PathLike) -> str | None:
    """``"act"``, ``"bc_mlp"`` or ``"rl"`` for a checkpoint folder of this project, else None. An
    interrupted commit counts (a kill during the first checkpoint's commit leaves only
    ``.staging``): its files are looked for where they will be once ``--resume`` finishes it,
    after :func:`pending_commit` checked its entries (an unsafe one raises CheckpointError).
    """
    folder = Path(folder)
    pending = pending_commit(folder) or []

    def where(name: str) -> Path:
        staged = folder / STAGING / name
        return staged if name in pending and staged.is_file() else folder / name

    if where("handover_act.json").is_file():
        return "act"
    config = where("config.json")
    if config.is_file():
        try:
            saved = read_json(config)
        except CheckpointError:
            return None
        if isinstance(saved, dict) and saved.get("type") in ("bc_mlp", "rl"):
            return saved["type"]
    return None


def remove_checkpoint(folder: Path, kind: str) -> None:
    """Delete the files a ``kind`` checkpoint writes (and nothing else) from ``folder``.

    An interrupted write in ``.staging`` is discarded, never finished; symbolic links are removed,
    never followed.
    """
    stage = folder / STAGING
    if stage.is_dir() and not stage.is_symlink():
        shutil.rmtree(stage)
    elif os.path.lexists(stage):
        stage.unlink()
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
    label = {"act": "ACT", "bc_mlp": "BC-MLP", "rl": "RL"}
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
        links = sorted(n for n in CHECKPOINT_FILES[kind] if (out / n).is_symlink())
        if links:  # a resumed run rewrites them: never through a link
            raise CheckpointError(f"cannot resume in {out}: {', '.join(links)} is a symbolic link")
        return
    if not overwrite:
        raise CheckpointError(
            f"--out {out} already holds a {label[kind]} run; pass --resume to continue it or "
            "--overwrite "
            f"to start again"
        )
    remove_checkpoint(out, found)
