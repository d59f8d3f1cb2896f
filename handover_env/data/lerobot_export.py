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
folder under ``root`` (the next run removes the temporary one). ``overwrite`` replaces only a folder
that is an export of this project (:func:`is_export`); the paths of
:func:`handover_env.paths.check_replaceable_root` are refused outright. The sidecar records the
dataset's :meth:`~handover_env.data.dataset.HandoverDataset.fingerprint`, so a reuse can check that
an export holds exactly the episodes it is about to train on (:func:`export_matches`).
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np

from handover_env.data.dataset import HandoverDataset
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
EXPORT_FORMAT = 2
ROBOT_TYPE = "handover_giver"
_MAX_SIDECAR_BYTES = 64 << 20


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
) -> Path:
    """Write ``dataset`` as a LeRobotDataset under ``root`` (``use_videos=False``); returns
    ``root``.

    Args:
        dataset: the canonical dataset (its rate must be an integer number of Hz).
        root: the output folder; it must not exist unless ``overwrite`` is set.
        repo_id: the LeRobot repo id recorded in the metadata (nothing is uploaded).
        history: W, frames of receiver history per environment-state vector.
        horizon: H, the action chunk the export is meant for; checked against episode lengths.
        overwrite: replace an existing ``root`` that holds an earlier export (only then).
        progress: show a tqdm bar over episodes.

    Raises:
        ValueError: empty dataset, non-integer rate, horizon longer than an episode; a ``root``
            that is ``""``, ``.``, ``/``, home or holds the current folder
            (:class:`~handover_env.paths.UnsafePathError`); ``overwrite`` of a folder that is
            not an export of this project.
        FileExistsError: ``root`` exists and ``overwrite`` is False.
    """
    spec = FeatureSpec(history=history, horizon=horizon, rate_hz=dataset.rate_hz)
    check_dataset(dataset, spec)
    fps = int(round(dataset.rate_hz))
    if abs(fps - dataset.rate_hz) > 1e-9:
        raise ValueError(f"LeRobot needs an integer fps; the dataset rate is {dataset.rate_hz} Hz")
    root = check_replaceable_root(root)
    if root.exists() or root.is_symlink():
        if not overwrite:
            raise FileExistsError(
                f"{root} already exists; pass overwrite=True (--overwrite) to replace it"
            )
        if not is_export(root):
            raise ValueError(
                f"refusing to overwrite {root}: it is not a handover LeRobot export (no {SIDECAR} "
                "or "
                f"LeRobot metadata of ours); delete it yourself or choose another folder"
            )
    root.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_siblings(root)
    tmp = sibling(root, "partial")
    try:
        _write_export(dataset, tmp, repo_id, spec, fps, progress)
        replace_dir(tmp, root)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return root


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
    }
    (root / SIDECAR).write_text(json.dumps(sidecar, indent=1))


def is_export(root: str | os.PathLike) -> bool:
    """True when ``root`` is a real folder holding an export of this project: our sidecar, or
    (an export interrupted by older code) LeRobot metadata with our robot type."""
    root = Path(root)
    if root.is_symlink() or not root.is_dir():
        return False
    if (root / SIDECAR).is_file():
        return True
    info = root / "meta" / "info.json"
    try:
        return info.is_file() and json.loads(info.read_text()).get("robot_type") == ROBOT_TYPE
    except (OSError, ValueError, AttributeError):
        return False


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
    types = {"history": int, "horizon": int, "rate_hz": float, "name": str, "source_id": list,
             "is_ood": list, "n_frames": int, "fingerprint": str}
    for key, kind in types.items():
        value = meta.get(key)
        accepted = (int, float) if kind is float else kind
        if not isinstance(value, accepted) or isinstance(value, bool):
            raise ValueError(f"{path}: {key} must be a {kind.__name__}, got {type(value).__name__}")
    n = len(meta["source_id"])
    if len(meta["is_ood"]) != n or not all(isinstance(v, bool) for v in meta["is_ood"]) \
            or not all(isinstance(v, str) for v in meta["source_id"]):
        raise ValueError(f"{path}: source_id and is_ood must be {n} strings and {n} booleans")
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
