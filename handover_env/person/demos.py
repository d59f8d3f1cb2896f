"""Handover demonstrations from anywhere: a dataset file, a public-dataset folder, or the
synthetic person's walks (the embedded default).

>>> from handover_env.person.demos import load_any
>>> demos = load_any(None)                        # embedded synthetic default (900 ID + 100 OOD)
>>> demos = load_any("path/to/whole_motions")     # a download of the public dataset
>>> demos = load_any("demos.npz")                 # a file written by HandoverDataset.save
"""

from __future__ import annotations

import os
from pathlib import Path

from handover_env.data.dataset import HandoverDataset
from handover_env.data.errors import DatasetError
from handover_env.data.public import load_public_dataset
from handover_env.person.synthetic import default_dataset


def load_any(
    path: str | os.PathLike | None = None, *, skip_bad: bool = False, progress: bool = False
) -> HandoverDataset:
    """The canonical dataset from a ``.npz``, a public-dataset folder, or the synthetic default.

    Args:
        path: a ``.npz`` written by :meth:`HandoverDataset.save`, a folder of public-dataset
            pickles (``motion_normal_*.pkl`` / ``motion_variation_*.pkl``), or None for the
            embedded default ``generate_synthetic()`` (cached per process).
        skip_bad: for a folder, skip bad files instead of raising.
        progress: for a folder, show a progress bar.

    Raises:
        FileNotFoundError: ``path`` does not exist.
        DatasetError: the file or folder is not a valid dataset (the message says why).
    """
    if path is None:
        return default_dataset()
    path = Path(path)
    if path.is_dir():
        return load_public_dataset(path, skip_bad=skip_bad, progress=progress)
    if path.is_file():
        if path.suffix != ".npz":
            raise DatasetError(f"{path}: expected a .npz dataset file or a public-dataset folder")
        return HandoverDataset.load(path)
    raise FileNotFoundError(
        f"no dataset at {path} (expected a .npz file or a public-dataset folder)"
    )
