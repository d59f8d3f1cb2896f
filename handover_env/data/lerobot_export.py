"""Export a :class:`HandoverDataset` to a local LeRobotDataset (lerobot 0.4.x, no network).

One LeRobot frame per dataset frame, with the baselines' shared features
(:mod:`handover_env.data.features`):

| key | dtype | shape | content |
|---|---|---|---|
| ``observation.environment_state`` | float32 | (2 W,) | receiver base xy history (xy + offsets) |
| ``observation.state`` | float32 | (3,) | giver wrist xyz at this frame (m) |
| ``action`` | float32 | (3,) | giver wrist xyz at this frame (m) |

``action`` at frame t is the giver position at t. A policy reads the future chunk through
LeRobot's ``delta_timestamps``: ``{"action": [k / 30 for k in range(H)]}`` gives the giver positions
for frames t .. t+H-1 with ``action_is_pad`` past the episode end (see
:func:`action_delta_timestamps`).
Every frame carries the task string :data:`TASK`. ``meta/handover.json`` beside LeRobot's metadata
records W, H, the source dataset name and each episode's source id and ID/OOD flag.

Reload it with ``LeRobotDataset(repo_id, root=root)`` (offline: the files are all local).

The export is written to a hidden temporary sibling of ``root`` and renamed into place when it is
complete (:func:`handover_env.paths.replace_dir`), so an interrupted export never leaves a half
folder under ``root``. ``root`` is ``~``-expanded once
(:func:`handover_env.paths.check_replaceable_root`) and that path is both checked and written;
``""``, ``.``, ``/``, home and their parents are refused outright.

``overwrite`` deletes ``root`` only when :func:`export_problem` finds nothing to lose in it:

* its ``meta/handover.json`` parses and validates (:func:`read_sidecar`: format
  :data:`EXPORT_FORMAT`, exactly the fields :func:`export_lerobot` writes, with their types and
  ranges) and agrees with LeRobot's ``meta/info.json`` (robot type, fps, episodes, frames,
  features);
* it holds nothing but what LeRobot and this module write (:data:`EXPORT_FILES`,
  :data:`EXPORT_DIRS`): no other file or folder, no symbolic link;
* every file in it is one the sidecar's ``files`` lists, with the size and SHA-256 the export
  wrote (:func:`manifest_problem`): a file named like an export's
  (``data/chunk-000/file-999.parquet``) that the export did not write, or one changed since, is
  not the export's to delete (an export of format 2, which has no such list, is refused: delete
  it yourself);
* it does not hold the input the dataset is read from.

Anything else is refused with a one-line error saying why, and nothing is deleted. The hidden
siblings a killed export leaves (``.<root>.partial-<pid>-<hex>``, ``.<root>.old-<pid>-<hex>``) are
deleted by the next run only when they pass the same check (a ``partial`` one need not have its
sidecar yet); any other folder of that name is left in place with a warning.

The sidecar records the dataset's :meth:`~handover_env.data.dataset.HandoverDataset.fingerprint`,
so a reuse can check that an export holds exactly the episodes it is about to train on
(:func:`export_matches`).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from handover_env.data.dataset import HandoverDataset, rate_problem
from handover_env.data.features import (
    ACTION,
    ACTION_DIM,
    OBS_ENV_STATE,
    OBS_STATE,
    STATE_DIM,
    FeatureSpec,
    check_dataset,
    episode_frames,
)
from handover_env.paths import (
    check_replaceable_root,
    remove_stale_siblings,
    replace_dir,
    sibling,
)

TASK = "hand the object over to the walking receiver"
SIDECAR = "meta/handover.json"
EXPORT_FORMAT = 3
ROBOT_TYPE = "handover_giver"
_MAX_SIDECAR_BYTES = 64 << 20
#: The sidecar's fields and their JSON types, exactly what :func:`export_lerobot` writes.
SIDECAR_FIELDS: dict[str, type] = {
    "export_format": int, "history": int, "horizon": int, "rate_hz": float, "name": str,
    "source_id": list, "is_ood": list, "n_frames": int, "fingerprint": str, "files": dict,
}
_FINGERPRINT = re.compile(r"[0-9a-f]{32}", re.ASCII)
_SHA256 = re.compile(r"[0-9a-f]{64}", re.ASCII)
#: Every file an export holds, relative to its root: LeRobot 0.4's metadata, episode index and
#: frame tables with ``use_videos=False`` and no image features (``lerobot.datasets.utils``:
#: ``INFO_PATH``, ``STATS_PATH``, ``DEFAULT_TASKS_PATH``, ``DEFAULT_EPISODES_PATH``,
#: ``DEFAULT_DATA_PATH``), and our :data:`SIDECAR`.
EXPORT_FILES = re.compile(
    r"meta/(info\.json|stats\.json|tasks\.parquet|handover\.json)"
    r"|(meta/episodes|data)/chunk-[0-9]{3,}/file-[0-9]{3,}\.parquet",
    re.ASCII,
)
#: Every folder an export holds, relative to its root.
EXPORT_DIRS = re.compile(r"meta|data|meta/episodes|(meta/episodes|data)/chunk-[0-9]{3,}", re.ASCII)
#: Entries looked at before a folder is called too big to be an export (a real one has ~10).
_MAX_EXPORT_ENTRIES = 100_000


def lerobot_features(history: int) -> dict[str, dict]:
    """The LeRobot ``features`` dict of an export with a W-frame receiver history."""
    env_names = ["x", "y"] + [
        f"d{axis}_{k}" for k in range(history - 1, 0, -1) for axis in ("x", "y")
    ]
    return {
        OBS_ENV_STATE: {"dtype": "float32", "shape": (2 * history,), "names": env_names},
        OBS_STATE: {"dtype": "float32", "shape": (STATE_DIM,), "names": ["x", "y", "z"]},
        ACTION: {"dtype": "float32", "shape": (ACTION_DIM,), "names": ["x", "y", "z"]},
    }


def action_delta_timestamps(horizon: int, fps: float) -> dict[str, list[float]]:
    """``delta_timestamps`` that make a LeRobotDataset return the H-frame action chunk."""
    return {ACTION: [k / fps for k in range(horizon)]}


def export_lerobot(
    dataset: HandoverDataset,
    root: str | os.PathLike,
    repo_id: str = "local/handover",
    history: int = 10,
    horizon: int = 30,
    overwrite: bool = False,
    progress: bool = False,
    inputs: Sequence[str | os.PathLike] = (),
) -> Path:
    """Write ``dataset`` as a LeRobotDataset under ``root`` (``use_videos=False``); returns
    ``root`` (``~`` expanded).

    Args:
        dataset: the canonical dataset (its rate must be an integer number of Hz).
        root: the output folder; it must not exist unless ``overwrite`` is set.
        repo_id: the LeRobot repo id recorded in the metadata (nothing is uploaded).
        history: W, frames of receiver history per environment-state vector.
        horizon: H, the action chunk the export is meant for; checked against episode lengths.
        overwrite: replace an existing ``root``, only if :func:`export_problem` finds it is an
            earlier export with nothing else in it.
        progress: show a tqdm bar over episodes.
        inputs: the files or folders ``dataset`` was read from; a ``root`` holding one is never
            replaced.

    Raises:
        ValueError: empty dataset, non-integer rate, horizon longer than an episode; a ``root``
            that is ``""``, ``.``, ``/``, home or holds the current folder
            (:class:`~handover_env.paths.UnsafePathError`); ``overwrite`` of a folder that is
            not an export of this project alone (checked before and again after the export is
            written; nothing is deleted).
        FileExistsError: ``root`` exists and ``overwrite`` is False.
    """
    spec = FeatureSpec(history=history, horizon=horizon, rate_hz=dataset.rate_hz)
    check_dataset(dataset, spec)
    fps = int(round(dataset.rate_hz))
    if abs(fps - dataset.rate_hz) > 1e-9:
        raise ValueError(f"LeRobot needs an integer fps; the dataset rate is {dataset.rate_hz} Hz")
    root = check_replaceable_root(root)
    inputs = list(inputs)
    check_overwrite(root, overwrite, inputs)
    root.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_siblings(
        root, lambda entry, kind: export_problem(entry, inputs, complete=kind == "old")
    )
    tmp = sibling(root, "partial")
    try:
        _write_export(dataset, tmp, repo_id, spec, fps, progress)
        check_overwrite(root, overwrite, inputs)  # again: the export may have taken minutes
        replace_dir(tmp, root)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return root


def check_overwrite(
    root: str | os.PathLike, overwrite: bool, inputs: Sequence[str | os.PathLike] = ()
) -> None:
    """Raise unless writing an export to ``root`` (already ``~``-expanded) deletes nothing but an
    earlier export.

    Raises:
        FileExistsError: ``root`` exists and ``overwrite`` is False.
        ValueError: ``root`` exists and :func:`export_problem` says why it is not replaceable.
    """
    root = Path(root)
    if not (root.exists() or root.is_symlink()):
        return
    if not overwrite:
        raise FileExistsError(
            f"{root} already exists; pass overwrite=True (--overwrite) to replace it"
        )
    why = export_problem(root, inputs)
    if why is not None:
        raise ValueError(
            f"refusing to overwrite {root}: {why}; nothing was deleted (delete it yourself or "
            "choose another folder)"
        )


def export_problem(
    root: str | os.PathLike, inputs: Sequence[str | os.PathLike] = (), complete: bool = True
) -> str | None:
    """None when deleting ``root`` would delete an export of this project and nothing else; else
    why not (a phrase: "it ...").

    Args:
        root: the folder.
        inputs: paths that must survive (the dataset being exported): ``root`` must not hold one.
        complete: require the sidecar (False for an export still being written, whose sidecar
            comes last: then only a sidecar or LeRobot ``meta/info.json`` that exists is checked).
    """
    root = Path(root)
    if root.is_symlink():
        return "it is a symbolic link"
    if not root.is_dir():
        return "it is not a folder"
    real = root.resolve()
    for item in inputs:
        path = Path(item).expanduser()
        if path.resolve() == real or path.resolve().is_relative_to(real):
            return f"it holds {item}, the dataset being exported"
    why = f"no {SIDECAR}" if complete and not (root / SIDECAR).is_file() else _unknown_entry(root)
    if why is None and (complete or (root / SIDECAR).exists()):
        try:
            meta = read_sidecar(root)
        except (OSError, ValueError) as exc:
            why = str(exc)
        else:
            why = _info_problem(root, meta) or manifest_problem(root, meta)
    elif why is None and (root / "meta" / "info.json").exists():
        why = _info_problem(root, None)
    return None if why is None else f"it is not a handover LeRobot export ({why})"


def _unknown_entry(root: Path) -> str | None:
    """The first entry under ``root`` that an export does not write (or a link), described."""
    pending = [("", root)]
    seen = 0
    while pending:
        prefix, folder = pending.pop()
        try:
            with os.scandir(folder) as it:
                entries = sorted(it, key=lambda e: e.name)
        except OSError as exc:
            return f"{prefix or './'} cannot be listed: {exc.strerror or exc}"
        for entry in entries:
            seen += 1
            if seen > _MAX_EXPORT_ENTRIES:
                return f"it holds more than {_MAX_EXPORT_ENTRIES:,} entries"
            rel = prefix + entry.name
            if entry.is_symlink():
                return f"{rel!r} is a symbolic link"
            if entry.is_dir(follow_symlinks=False):
                if not EXPORT_DIRS.fullmatch(rel):
                    return f"it holds {rel + '/'!r}, which an export does not write"
                pending.append((rel + "/", Path(entry.path)))
            elif not entry.is_file(follow_symlinks=False):
                return f"{rel!r} is not a regular file"
            elif not EXPORT_FILES.fullmatch(rel):
                return f"it holds {rel!r}, which an export does not write"
    return None


def file_manifest(root: str | os.PathLike) -> dict[str, list]:
    """``{relative path: [size in bytes, SHA-256 hex]}`` of every file under ``root`` but the
    sidecar (what the sidecar's ``files`` records; sorted by path)."""
    root = Path(root)
    out: dict[str, list] = {}
    for path in sorted(p for p in root.rglob("*") if p.is_file() and not p.is_symlink()):
        rel = path.relative_to(root).as_posix()
        if rel != SIDECAR:
            out[rel] = [path.stat().st_size, _sha256(path)]
    return out


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def manifest_problem(root: str | os.PathLike, meta: dict) -> str | None:
    """Why ``root`` holds a file its sidecar ``meta`` (:func:`read_sidecar`) does not list with
    this size and SHA-256, i.e. one the export did not write or that changed since; None when
    every file is the export's own. A listed file that is gone is no loss and is not a problem.
    """
    root = Path(root)
    listed = meta["files"]
    for path in sorted(p for p in root.rglob("*") if p.is_file() or p.is_symlink()):
        rel = path.relative_to(root).as_posix()
        if rel == SIDECAR:
            continue
        if rel not in listed:
            return f"it holds {rel!r}, which this export did not write (not in {SIDECAR} files)"
        size, digest = listed[rel]
        if path.is_symlink() or path.stat().st_size != size or _sha256(path) != digest:
            return f"{rel!r} changed since this export wrote it (size or SHA-256 differ from " \
                f"{SIDECAR} files)"
    return None


def _info_problem(root: Path, meta: dict | None) -> str | None:
    """Why LeRobot's ``meta/info.json`` is not the one of the export ``meta`` describes (or, when
    ``meta`` is None, not one of ours at all); None if it is."""
    path = root / "meta" / "info.json"
    try:
        if path.stat().st_size > _MAX_SIDECAR_BYTES:
            return f"{path}: larger than {_MAX_SIDECAR_BYTES:,} bytes"
        info = json.loads(path.read_text())
    except FileNotFoundError:
        return f"no {path.relative_to(root)} (LeRobot metadata)"
    except (OSError, ValueError) as exc:
        return f"{path}: not readable JSON ({exc})"
    if not isinstance(info, dict):
        return f"{path}: expected a JSON object"
    if info.get("robot_type") != ROBOT_TYPE:
        return f"{path}: robot_type {info.get('robot_type')!r}, an export has {ROBOT_TYPE!r}"
    if meta is None:
        return None
    wanted = {
        "fps": int(round(meta["rate_hz"])),
        "total_episodes": len(meta["source_id"]),
        "total_frames": meta["n_frames"],
    }
    for key, value in wanted.items():
        if info.get(key) != value or isinstance(info.get(key), bool):
            return f"{path}: {key} {info.get(key)!r}, but {SIDECAR} says {value!r}"
    features = info.get("features")
    ours = lerobot_features(meta["history"])
    if not isinstance(features, dict) or any(
        not isinstance(features.get(k), dict) or features[k].get("shape") != list(v["shape"])
        for k, v in ours.items()
    ):
        return f"{path}: its features are not those of a W={meta['history']} export"
    return None


def _write_export(
    dataset: HandoverDataset, root: Path, repo_id: str, spec: FeatureSpec, fps: int, progress: bool
) -> None:
    """The export itself, into the fresh folder ``root``."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    history, horizon = spec.history, spec.horizon
    out = LeRobotDataset.create(
        repo_id=repo_id,
        fps=fps,
        features=lerobot_features(history),
        root=root,
        robot_type=ROBOT_TYPE,
        use_videos=False,
    )
    episodes = dataset.episodes
    if progress:
        from tqdm import tqdm

        episodes = tqdm(episodes, desc="export-lerobot", unit="ep")
    import datasets

    bars_were_on = datasets.is_progress_bar_enabled()
    datasets.disable_progress_bars()  # one "Map" bar per saved episode otherwise
    try:
        for ep in episodes:
            f = episode_frames(ep, spec)
            giver = ep.giver_xyz.astype(np.float32)
            for t in range(ep.length):
                out.add_frame(
                    {
                        OBS_ENV_STATE: f.env_state[t],
                        OBS_STATE: f.state[t],
                        ACTION: giver[t],
                        "task": TASK,
                    }
                )
            out.save_episode()
    finally:
        out.finalize()
        if bars_were_on:
            datasets.enable_progress_bars()
    sidecar = {
        "export_format": EXPORT_FORMAT,
        "history": int(history),
        "horizon": int(horizon),
        "rate_hz": float(dataset.rate_hz),
        "name": dataset.name,
        "source_id": [ep.source_id for ep in dataset],
        "is_ood": [bool(ep.is_ood) for ep in dataset],
        "n_frames": int(dataset.n_frames),
        "fingerprint": dataset.fingerprint(),
        "files": file_manifest(root),
    }
    (root / SIDECAR).write_text(json.dumps(sidecar, indent=1))


def is_export(root: str | os.PathLike) -> bool:
    """True when ``root`` is a complete export of this project and nothing else
    (:func:`export_problem`)."""
    return export_problem(root) is None


def read_sidecar(root: str | os.PathLike) -> dict:
    """The ``meta/handover.json`` of an export, validated, or a clear error if ``root`` is not
    one."""
    path = Path(root) / SIDECAR
    if not path.is_file():
        raise FileNotFoundError(
            f"{root} is not a handover LeRobot export (no {SIDECAR}); run export-lerobot"
        )
    if path.stat().st_size > _MAX_SIDECAR_BYTES:
        raise ValueError(f"{path}: larger than {_MAX_SIDECAR_BYTES:,} bytes")
    try:
        meta = json.loads(path.read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(meta, dict):
        raise ValueError(f"{path}: expected a JSON object")
    if meta.get("export_format") != EXPORT_FORMAT:
        raise ValueError(
            f"{path}: export format {meta.get('export_format')}, this code reads {EXPORT_FORMAT}"
        )
    if set(meta) != set(SIDECAR_FIELDS):
        odd = sorted(set(meta) ^ set(SIDECAR_FIELDS))
        raise ValueError(f"{path}: fields {odd} differ from those an export writes")
    for key, kind in SIDECAR_FIELDS.items():
        value = meta[key]
        accepted = (int, float) if kind is float else kind
        if not isinstance(value, accepted) or isinstance(value, bool):
            raise ValueError(f"{path}: {key} must be a {kind.__name__}, got {type(value).__name__}")
    for key in ("history", "horizon", "n_frames"):
        if meta[key] < (0 if key == "n_frames" else 1):
            raise ValueError(f"{path}: {key} is {meta[key]}")
    problem = rate_problem(meta["rate_hz"])
    if problem:
        raise ValueError(f"{path}: {problem}")
    if not _FINGERPRINT.fullmatch(meta["fingerprint"]):
        raise ValueError(f"{path}: fingerprint is not 32 hexadecimal digits")
    n = len(meta["source_id"])
    if len(meta["is_ood"]) != n or not all(isinstance(v, bool) for v in meta["is_ood"]) \
            or not all(isinstance(v, str) for v in meta["source_id"]):
        raise ValueError(f"{path}: source_id and is_ood must be {n} strings and {n} booleans")
    files = meta["files"]
    if len(files) > _MAX_EXPORT_ENTRIES:
        raise ValueError(f"{path}: files lists more than {_MAX_EXPORT_ENTRIES:,} entries")
    for rel, entry in files.items():
        if rel == SIDECAR or not EXPORT_FILES.fullmatch(rel):
            raise ValueError(f"{path}: files lists {rel[:80]!r}, which an export does not write")
        if not (
            isinstance(entry, list) and len(entry) == 2
            and isinstance(entry[0], int) and not isinstance(entry[0], bool) and entry[0] >= 0
            and isinstance(entry[1], str) and _SHA256.fullmatch(entry[1])
        ):
            raise ValueError(
                f"{path}: files[{rel!r}] must be [size in bytes >= 0, SHA-256 as 64 hex digits]"
            )
    return meta


def export_matches(
    root: str | os.PathLike, dataset: HandoverDataset, history: int, horizon: int
) -> str | None:
    """None when the export at ``root`` holds exactly ``dataset`` with windows W, H; else why
    not."""
    try:
        meta = read_sidecar(root)
    except (OSError, ValueError) as exc:
        return str(exc)
    wanted = {
        "fingerprint": dataset.fingerprint(),
        "history": int(history),
        "horizon": int(horizon),
        "n_frames": int(dataset.n_frames),
        "episodes": len(dataset),
    }
    got = {**meta, "episodes": len(meta["source_id"])}
    diff = [key for key, value in wanted.items() if got.get(key) != value]
    if diff:
        details = ", ".join(f"{k} {got.get(k)!r} vs {wanted[k]!r}" for k in diff)
        return f"{root} was exported from other data or windows ({details})"
    if not (Path(root) / "meta" / "info.json").is_file():
        return f"{root} has no LeRobot metadata (meta/info.json)"
    return None
