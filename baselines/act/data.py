"""ACT's training data through LeRobot: the export read back as a ``LeRobotDataset``, its samples,
their normalisation and statistics, and the episode split.

:func:`open_export` opens an export of :func:`handover_env.data.lerobot_export.export_lerobot`
with ``delta_timestamps`` for the action chunk; :func:`lerobot_samples` turns the frames of some
episodes into LeRobot training samples in one vectorised pass; :func:`feature_stats` gives the
``get_feature_stats`` statistics ``make_act_pre_post_processors`` normalises with, and
:func:`normalise_samples` applies that preprocessor once to all samples. :func:`split_from_export`
is BC-MLP's stratified train/validation split of whole episodes, from the export's ID/OOD flags.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from handover_env.extras import missing_extra

try:
    import torch
except ModuleNotFoundError as _exc:
    raise missing_extra("baselines", _exc, __name__) from None

from baselines.checkpoint_io import CheckpointError
from handover_env.data.dataset import Episode, HandoverDataset
from handover_env.data.features import (
    ACTION,
    ACTION_DIM,
    OBS_ENV_STATE,
    OBS_STATE,
    STATE_DIM,
    FeatureSpec,
    split_train_val,
)


def open_export(root: str | os.PathLike, repo_id: str, spec: FeatureSpec):
    """``LeRobotDataset(repo_id, root, delta_timestamps=...)`` after checking its features fit
    ``spec``."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from handover_env.data.lerobot_export import action_delta_timestamps, read_sidecar

    sidecar = read_sidecar(root)
    ds = LeRobotDataset(
        repo_id, root=root, delta_timestamps=action_delta_timestamps(spec.horizon, spec.rate_hz)
    )
    want = {OBS_ENV_STATE: (spec.env_dim,), OBS_STATE: (STATE_DIM,), ACTION: (ACTION_DIM,)}
    for key, shape in want.items():
        if key not in ds.features:
            raise ValueError(
                f"LeRobot dataset at {root} has no feature {key!r} (features: "
                f"{sorted(ds.features)})"
            )
        got = tuple(ds.features[key]["shape"])
        if got != shape:
            raise ValueError(
                f"LeRobot dataset at {root}: feature {key!r} has shape {got}, this ACT config "
                f"needs {shape} "
                f"(history W={spec.history}; the export used W={sidecar.get('history')})"
            )
    if int(ds.fps) != int(round(spec.rate_hz)):
        raise ValueError(f"LeRobot dataset at {root} is at {ds.fps} fps, expected {spec.rate_hz}")
    return ds, sidecar


def lerobot_samples(ds, episode_indices: np.ndarray) -> dict[str, torch.Tensor]:
    """Every frame of ``episode_indices`` as LeRobot training samples, vectorised.

    Reads the parquet columns once and applies ``ds.delta_indices`` exactly as
    ``LeRobotDataset.__getitem__`` does (indices clamped to the episode, ``action_is_pad`` outside
    it); ``tests/baselines/test_act.py`` checks the result equals ``ds[i]`` item by item. The
    columns are read as one numpy batch (``datasets``' lazy column objects convert row by row).
    """
    cols = ds.hf_dataset.with_format("numpy")[:]  # one batch read, not an iteration over rows
    env = np.asarray(cols[OBS_ENV_STATE], dtype=np.float32)
    state = np.asarray(cols[OBS_STATE], dtype=np.float32)
    action = np.asarray(cols[ACTION], dtype=np.float32)
    index = np.asarray(cols["index"], dtype=np.int64)
    if not np.array_equal(index, np.arange(index.size)):
        raise ValueError("LeRobot dataset rows are not in index order; re-export it")
    deltas = np.asarray(ds.delta_indices[ACTION], dtype=np.int64)
    out: dict[str, list[np.ndarray]] = {
        k: [] for k in (OBS_ENV_STATE, OBS_STATE, ACTION, "action_is_pad")
    }
    for e in np.asarray(episode_indices, dtype=np.int64):
        ep = ds.meta.episodes[int(e)]
        start, end = int(ep["dataset_from_index"]), int(ep["dataset_to_index"])
        rows = np.arange(start, end)
        q = rows[:, None] + deltas[None, :]
        out[OBS_ENV_STATE].append(env[rows])
        out[OBS_STATE].append(state[rows])
        out[ACTION].append(action[np.clip(q, start, end - 1)])
        out["action_is_pad"].append((q < start) | (q >= end))
    return {k: torch.as_tensor(np.concatenate(v)) for k, v in out.items()}


def normalise_samples(
    preprocessor, samples: dict[str, torch.Tensor], chunk: int = 32_768
) -> dict[str, torch.Tensor]:
    """``samples`` passed through LeRobot's ``preprocessor`` once, instead of once per batch.

    The pipeline (rename, batch dim, device, ``NormalizerProcessorStep``) is elementwise over rows,
    so normalising all rows up front and indexing a batch afterwards gives bitwise the same tensors
    as indexing first and normalising the batch (``tests/baselines/test_act.py`` checks it).
    ``chunk`` rows at a time bound the pipeline's temporaries.
    """
    n = int(next(iter(samples.values())).shape[0])
    parts = [
        preprocessor({k: v[i : i + chunk] for k, v in samples.items()})
        for i in range(0, max(n, 1), chunk)
    ]
    return {k: torch.cat([part[k] for part in parts]) if parts else samples[k] for k in samples}


def feature_stats(samples: dict[str, torch.Tensor]) -> dict[str, dict[str, np.ndarray]]:
    """LeRobot ``get_feature_stats`` of the training samples (action over its per-frame values)."""
    from lerobot.datasets.compute_stats import get_feature_stats

    per_frame_action = samples[ACTION][
        :, 0
    ].numpy()  # the action column itself, as LeRobot's stats.json
    return {
        OBS_ENV_STATE: get_feature_stats(samples[OBS_ENV_STATE].numpy(), axis=0, keepdims=False),
        OBS_STATE: get_feature_stats(samples[OBS_STATE].numpy(), axis=0, keepdims=False),
        ACTION: get_feature_stats(per_frame_action, axis=0, keepdims=False),
    }


def check_episodes(episodes: np.ndarray | None, n_export: int) -> np.ndarray:
    """Export episode indices to train on (all of them for None), validated: 1-D, unique, in
    range."""
    if episodes is None:
        return np.arange(n_export, dtype=np.int64)
    arr = np.asarray(episodes)
    if arr.ndim != 1 or (arr.size and not np.issubdtype(arr.dtype, np.integer)):
        raise ValueError(
            f"episodes must be a 1-D array of export episode indices, got dtype {arr.dtype}, "
            f"shape {arr.shape}"
        )
    arr = arr.astype(np.int64)
    if arr.size < 2:
        raise ValueError(f"need at least 2 episodes for a train/validation split, got {arr.size}")
    if arr.min() < 0 or arr.max() >= n_export:
        raise ValueError(
            f"episode indices must lie in [0, {n_export - 1}] (the export has {n_export} episodes)"
        )
    if np.unique(arr).size != arr.size:
        raise ValueError("episode indices must be unique")
    return arr


def split_from_export(
    sidecar: dict, val_fraction: float, seed: int, episodes: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The same stratified episode split as BC-MLP's, from the export's ID/OOD flags.

    With ``episodes`` (export indices) only those are split, in the given order, so training on
    ``episodes`` of a whole-dataset export splits exactly like training on an export of just those
    episodes. Returns export episode indices (train, val).
    """
    chosen = check_episodes(episodes, len(sidecar["source_id"]))
    stub = HandoverDataset(
        [
            Episode(
                np.zeros((2, 2)),
                np.zeros((2, 3)),
                np.zeros((2, 3)),
                np.tile([1.0, 0, 0, 0], (2, 1)),
                bool(sidecar["is_ood"][i]),
                sidecar["source_id"][i],
            )
            for i in chosen
        ]
    )
    train, val = split_train_val(stub, val_fraction, seed)
    return chosen[train], chosen[val]


def training_samples(
    root: str | os.PathLike,
    repo_id: str,
    spec: FeatureSpec,
    val_fraction: float,
    seed: int,
    episodes: np.ndarray | None = None,
) -> tuple[dict[str, torch.Tensor], dict[str, torch.Tensor], dict, dict[str, list[str]]]:
    """(training samples, validation samples, :func:`feature_stats` of the training samples, the
    split as episode ids) of the export at ``root`` (``episodes``: see
    :func:`split_from_export`)."""
    ds, sidecar = open_export(root, repo_id, spec)
    train_ep, val_ep = split_from_export(sidecar, val_fraction, seed, episodes)
    train = lerobot_samples(ds, train_ep)
    val = lerobot_samples(ds, val_ep)
    split = {"train": [sidecar["source_id"][i] for i in train_ep],
             "val": [sidecar["source_id"][i] for i in val_ep]}
    return train, val, feature_stats(train), split


@contextlib.contextmanager
def prepared_export(
    dataset: HandoverDataset,
    export_root: str | os.PathLike | None,
    spec: FeatureSpec,
    rebuild: bool = True,
    progress: bool = False,
    log: Callable[[str], None] | None = None,
) -> Iterator[Path]:
    """A LeRobot export of ``dataset`` at ``export_root``, or in a temporary folder removed on
    exit.

    An existing export at ``export_root`` is reused only if it holds exactly ``dataset`` (its
    fingerprint, frames and the windows W, H). Otherwise it is rebuilt when ``rebuild`` (only a
    folder that is an export of ours is replaced), or a CheckpointError says why not.
    """
    from handover_env.data.lerobot_export import export_lerobot, export_matches

    with contextlib.ExitStack() as stack:
        if export_root is None:
            export_root = Path(stack.enter_context(tempfile.TemporaryDirectory())) / "lerobot"
        export_root = Path(export_root)
        if export_root.exists() or export_root.is_symlink():
            why = export_matches(export_root, dataset, spec.history, spec.horizon)
            if why is not None:
                if not rebuild:
                    raise CheckpointError(
                        f"{why}; pass --overwrite to rebuild it, or another --export-root"
                    )
                if log is not None:
                    log(f"rebuilding the LeRobot export: {why}")
                export_lerobot(dataset, export_root, history=spec.history, horizon=spec.horizon,
                               overwrite=True, progress=progress)
        else:
            export_lerobot(dataset, export_root, history=spec.history, horizon=spec.horizon,
                           progress=progress)
        yield export_root
