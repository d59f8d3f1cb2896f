"""Export a :class:`HandoverDataset` to a local LeRobotDataset (lerobot 0.4.x, no network).

One LeRobot frame per dataset frame, with the baselines' shared features
(:mod:`baselines.features`):

| key                              | dtype   | shape   | content                                         |
|----------------------------------|---------|---------|-------------------------------------------------|
| ``observation.environment_state`` | float32 | (2 W,)  | receiver base xy history (current xy + offsets)  |
| ``observation.state``            | float32 | (3,)    | giver wrist xyz at this frame (m)               |
| ``action``                       | float32 | (3,)    | giver wrist xyz at this frame (m)               |

``action`` at frame t is the giver position at t. A policy reads the future chunk through
LeRobot's ``delta_timestamps``: ``{"action": [k / 30 for k in range(H)]}`` gives the giver positions
for frames t .. t+H-1 with ``action_is_pad`` past the episode end (see :func:`action_delta_timestamps`).
Every frame carries the task string :data:`TASK`. ``meta/handover.json`` beside LeRobot's metadata
records W, H, the source dataset name and each episode's source id and ID/OOD flag.

Reload it with ``LeRobotDataset(repo_id, root=root)`` (offline: the files are all local).
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np

os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("HF_DATASETS_OFFLINE", "1")

from baselines.features import (  # noqa: E402
    ACTION,
    ACTION_DIM,
    OBS_ENV_STATE,
    OBS_STATE,
    STATE_DIM,
    FeatureSpec,
    check_dataset,
    episode_frames,
)
from handover_env.data.dataset import HandoverDataset  # noqa: E402

TASK = "hand the object over to the walking receiver"
SIDECAR = "meta/handover.json"
EXPORT_FORMAT = 1


def lerobot_features(history: int) -> dict[str, dict]:
    """The LeRobot ``features`` dict of an export with a W-frame receiver history."""
    env_names = ["x", "y"] + [f"d{axis}_{k}" for k in range(history - 1, 0, -1) for axis in ("x", "y")]
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
    """Write ``dataset`` as a LeRobotDataset under ``root`` (``use_videos=False``); returns ``root``.

    Args:
        dataset: the canonical dataset (its rate must be an integer number of Hz).
        root: the output folder; it must not exist unless ``overwrite`` is set.
        repo_id: the LeRobot repo id recorded in the metadata (nothing is uploaded).
        history: W, frames of receiver history per environment-state vector.
        horizon: H, the action chunk the export is meant for; checked against episode lengths.
        overwrite: delete an existing ``root`` first.
        progress: show a tqdm bar over episodes.

    Raises:
        ValueError: empty dataset, non-integer rate, horizon longer than an episode.
        FileExistsError: ``root`` exists and ``overwrite`` is False.
    """
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    spec = FeatureSpec(history=history, horizon=horizon, rate_hz=dataset.rate_hz)
    check_dataset(dataset, spec)
    fps = int(round(dataset.rate_hz))
    if abs(fps - dataset.rate_hz) > 1e-9:
        raise ValueError(f"LeRobot needs an integer fps; the dataset rate is {dataset.rate_hz} Hz")
    root = Path(root)
    if root.exists():
        if not overwrite:
            raise FileExistsError(f"{root} already exists; pass overwrite=True (--overwrite) to replace it")
        shutil.rmtree(root)

    out = LeRobotDataset.create(
        repo_id=repo_id,
        fps=fps,
        features=lerobot_features(history),
        root=root,
        robot_type="handover_giver",
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
    }
    (root / SIDECAR).write_text(json.dumps(sidecar, indent=1))
    return root


def read_sidecar(root: str | os.PathLike) -> dict:
    """The ``meta/handover.json`` of an export, or a clear error if ``root`` is not one."""
    path = Path(root) / SIDECAR
    if not path.is_file():
        raise FileNotFoundError(f"{root} is not a handover LeRobot export (no {SIDECAR}); run export-lerobot")
    meta = json.loads(path.read_text())
    if meta.get("export_format") != EXPORT_FORMAT:
        raise ValueError(f"{path}: export format {meta.get('export_format')}, this code reads {EXPORT_FORMAT}")
    return meta
