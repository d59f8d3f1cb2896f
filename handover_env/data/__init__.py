"""Handover demonstrations: the canonical dataset and the safe public-dataset loader.

>>> from handover_env.data import load_public_dataset
>>> demos = load_public_dataset("path/to/whole_motions")   # a download of the public dataset

The synthetic default and :func:`~handover_env.person.demos.load_any` (a ``.npz``, a folder or
the synthetic default) are the person's: :mod:`handover_env.person.synthetic`,
:mod:`handover_env.person.demos`.
"""

from __future__ import annotations

from handover_env.data.dataset import Episode, HandoverDataset
from handover_env.data.errors import DatasetError
from handover_env.data.public import UnsafePickleError, load_public_dataset

__all__ = [
    "DatasetError",
    "Episode",
    "HandoverDataset",
    "UnsafePickleError",
    "load_public_dataset",
]
