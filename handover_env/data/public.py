"""Safe loader of the public Dynamic Handover Dataset (a folder of pickles) into the canonical
format.

The public dataset of the paper (Sec. IV-A, "Data Collection": 1,000 human-to-human handovers,
900 in-distribution + 100 out-of-distribution) is published as one Python pickle per recording:
``motion_normal_<i>.pkl`` (ID) and ``motion_variation_<i>.pkl`` (OOD, the receiver wanders or
pauses). Each holds a ``dict`` of float64 arrays:

=================  ==========  ==========================================================
key                shape       meaning
=================  ==========  ==========================================================
``pose_receiver``  (T, 34, 3)  receiver body joints, ZED SDK BODY_34 layout, metres
``pose_giver``     (T, 34, 3)  giver body joints, same layout
``pose_object``    (T, 3)      object position (OptiTrack), metres; the paper's giver wrist
``quat_object``    (T, 4)      object orientation, scalar first (w, x, y, z), unit norm
=================  ==========  ==========================================================

A pickle can run arbitrary code when it is loaded, so :class:`SafeUnpickler` resolves only the
globals numpy needs to rebuild arrays (``_reconstruct``, ``ndarray``, ``dtype``, ``scalar``, and
at protocol 5 ``_frombuffer``) and
refuses every other one *before* anything is called, with an error naming the file and the global.
A pickle can also crash or exhaust the loader without naming any global (a deeply nested key, a
declared 2 GiB array, a huge memo index), so before unpickling, a file is read only if it is a
regular file within :data:`~handover_env.data.limits.MAX_PICKLE_BYTES` (links must stay inside the
dataset folder) and its opcode stream passes :func:`~handover_env.data.pickle_scan.scan_pickle`.
Every problem with one file is a :class:`DatasetError` naming it, so ``skip_bad`` can skip it.

Mapping to :class:`~handover_env.data.dataset.Episode`:

* ``receiver_xy`` = ``pose_receiver[:, 0, :2]`` (pelvis, the paper's receiver input x^r);
* ``receiver_hand_xyz`` = ``pose_receiver[:, 15]`` (BODY_34 right hand: in most recordings the
  joint closest to the object at the moment of transfer);
* ``giver_xyz`` = ``pose_object`` (the paper uses the object position as the giver wrist x^g);
* ``object_quat`` = ``quat_object``. The files store the scalar part first: at the start of every
  recording the object rests in its calibrated pose and the first component is +-1, and the
  rotation that follows is mostly about z (the giver turns the object). The loader renormalises
  each quaternion and fixes the sign so that w >= 0 in the first frame and consecutive frames
  lie in the same hemisphere (q and -q are the same rotation).
"""

from __future__ import annotations

import io
import os
import pickle
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tqdm.auto import tqdm

from handover_env.data.dataset import DEFAULT_RATE_HZ, Episode, HandoverDataset
from handover_env.data.errors import DatasetError
from handover_env.data.limits import MAX_FRAMES, MAX_PICKLE_BYTES
from handover_env.data.pickle_scan import UnsafePickleError, scan_pickle
from handover_env.regular_file import read_regular_file, shown

try:  # numpy >= 2
    from numpy._core import multiarray as _multiarray
    from numpy._core import numeric as _numeric
except ImportError:  # pragma: no cover - numpy 1.x
    from numpy.core import multiarray as _multiarray  # type: ignore[no-redef]
    from numpy.core import numeric as _numeric  # type: ignore[no-redef]

#: The only globals a public-dataset pickle may reference: numpy's array-rebuilding machinery.
#: Both module spellings map to the same objects, so files written with numpy 1.x (``numpy.core``)
#: and 2.x (``numpy._core``) load, without importing the deprecated ``numpy.core`` alias.
ALLOWED_GLOBALS: dict[tuple[str, str], Any] = {
    ("numpy.core.multiarray", "_reconstruct"): _multiarray._reconstruct,
    ("numpy._core.multiarray", "_reconstruct"): _multiarray._reconstruct,
    ("numpy.core.multiarray", "scalar"): _multiarray.scalar,
    ("numpy._core.multiarray", "scalar"): _multiarray.scalar,
    ("numpy.core.numeric", "_frombuffer"): _numeric._frombuffer,
    ("numpy._core.numeric", "_frombuffer"): _numeric._frombuffer,
    ("numpy", "ndarray"): np.ndarray,
    ("numpy", "dtype"): np.dtype,
}

#: Expected arrays: key -> shape after the time axis.
REQUIRED_ARRAYS: dict[str, tuple[int, ...]] = {
    "pose_receiver": (34, 3),
    "pose_giver": (34, 3),
    "pose_object": (3,),
    "quat_object": (4,),
}
PELVIS_JOINT = 0
RIGHT_HAND_JOINT = 15
ID_PREFIX = "motion_normal_"
OOD_PREFIX = "motion_variation_"
#: Canonical file names: ASCII digits, no leading zeros, nothing after ``.pkl`` (``fullmatch``).
FILE_NAME_RE = re.compile(r"(motion_normal|motion_variation)_(0|[1-9][0-9]{0,8})\.pkl", re.ASCII)


class SafeUnpickler(pickle.Unpickler):
    """An unpickler that resolves only numpy's array-rebuilding globals.

    ``find_class`` is the single place a pickle can name a callable; every name outside
    :data:`ALLOWED_GLOBALS` is refused before it is imported, let alone called. Persistent ids
    are refused too. :func:`safe_load_pickle` runs it only on a stream that
    :func:`~handover_env.data.pickle_scan.scan_pickle` has checked (opcodes, calls, sizes, depth,
    memo), so this is the second line of defence, not the only one.

    Args:
        file: a binary file object.
        source: the file's name, used in error messages.
    """

    def __init__(self, file: io.BufferedIOBase | io.BytesIO, source: str) -> None:
        super().__init__(file)
        self.source = source

    def find_class(self, module: str, name: str) -> Any:
        try:
            return ALLOWED_GLOBALS[(module, name)]
        except KeyError:
            raise UnsafePickleError(
                f"{self.source}: refused to load: the pickle references the global "
                f"{module}.{name}, which is not one of numpy's array-rebuilding functions; "
                f"nothing in the file was run"
            ) from None

    def persistent_load(self, pid: Any) -> Any:
        raise UnsafePickleError(f"{self.source}: refused to load: the pickle uses persistent ids")


def safe_load_pickle(path: str | os.PathLike, root: Path | None = None) -> Any:
    """Unpickle ``path`` safely: bounded read, static scan, then :class:`SafeUnpickler`.

    Raises:
        UnsafePickleError: the file references a forbidden global.
        DatasetError: the file is not a regular file, is too large, empty, truncated, not a
            pickle, or declares more than :mod:`handover_env.data.limits` allows.
    """
    path = Path(path)
    data = read_regular_file(path, MAX_PICKLE_BYTES, root, inside="dataset folder",
                             kind="recording", error=DatasetError)
    if not data:
        raise DatasetError(f"{shown(path)}: empty file (0 bytes)")
    scan_pickle(data, shown(path))
    try:
        return SafeUnpickler(io.BytesIO(data), shown(path)).load()
    except UnsafePickleError:
        raise
    except EOFError as exc:
        raise DatasetError(
            f"{shown(path)}: truncated pickle ({len(data)} bytes; ended early)"
        ) from exc
    except (
        Exception
    ) as exc:  # UnpicklingError, ValueError, TypeError, MemoryError from a corrupt stream
        raise DatasetError(
            f"{shown(path)}: not a readable pickle ({type(exc).__name__}: {exc})"
        ) from exc


def validate_record(record: Any, source: str) -> dict[str, np.ndarray]:
    """Check one recording's dict: keys, dtypes, shapes, finite values and equal lengths."""
    if not isinstance(record, dict):
        raise DatasetError(f"{source}: expected a dict of arrays, got {type(record).__name__}")
    missing = [key for key in REQUIRED_ARRAYS if key not in record]
    if missing:
        raise DatasetError(f"{source}: missing key(s) {missing}; found {sorted(map(str, record))}")
    arrays: dict[str, np.ndarray] = {}
    lengths: dict[str, int] = {}
    for key, tail in REQUIRED_ARRAYS.items():
        value = record[key]
        if not isinstance(value, np.ndarray):
            raise DatasetError(
                f"{source}: {key} is a {type(value).__name__}, expected a numpy array"
            )
        if not (np.issubdtype(value.dtype, np.floating) or np.issubdtype(value.dtype, np.integer)):
            raise DatasetError(f"{source}: {key} has dtype {value.dtype}, expected real numbers")
        if value.ndim != 1 + len(tail) or value.shape[1:] != tail:
            expected = "(T, " + ", ".join(map(str, tail)) + ")"
            raise DatasetError(f"{source}: {key} has shape {value.shape}, expected {expected}")
        bad = ~np.isfinite(value)
        if bad.any():
            frames = np.flatnonzero(bad.reshape(bad.shape[0], -1).any(axis=1))
            raise DatasetError(
                f"{source}: {key} has {int(bad.sum())} NaN/inf value(s) in {frames.size} frame(s), "
                f"first at frame {int(frames[0])}"
            )
        arrays[key] = value.astype(np.float64, copy=False)
        lengths[key] = value.shape[0]
    if len(set(lengths.values())) != 1:
        raise DatasetError(f"{source}: arrays disagree in length (frames): {lengths}")
    if next(iter(lengths.values())) > MAX_FRAMES:
        raise DatasetError(
            f"{source}: {lengths['pose_object']:,} frames, more than the {MAX_FRAMES:,} a "
            "recording may have"
        )
    if next(iter(lengths.values())) < 2:
        raise DatasetError(f"{source}: needs at least 2 frames, got {lengths['pose_object']}")
    norms = np.linalg.norm(arrays["quat_object"], axis=1)
    if np.any(norms < 1e-6):
        raise DatasetError(f"{source}: quat_object has a zero-norm quaternion")
    return arrays


def canonical_quaternions(quat: np.ndarray) -> np.ndarray:
    """Unit quaternions (w, x, y, z), sign-continuous over time, w >= 0 in the first frame."""
    q = quat / np.linalg.norm(quat, axis=1, keepdims=True)
    dots = np.einsum("ij,ij->i", q[1:], q[:-1])
    flips = np.concatenate([[q[0, 0] < 0], dots < 0])
    sign = np.where(np.cumsum(flips) % 2 == 1, -1.0, 1.0)
    return q * sign[:, None]


def episode_from_record(record: dict[str, np.ndarray], source_id: str, is_ood: bool) -> Episode:
    """Map one validated public recording to a canonical :class:`Episode`."""
    receiver = record["pose_receiver"]
    return Episode(
        receiver_xy=receiver[:, PELVIS_JOINT, :2].copy(),
        receiver_hand_xyz=receiver[:, RIGHT_HAND_JOINT, :].copy(),
        giver_xyz=record["pose_object"].copy(),
        object_quat=canonical_quaternions(record["quat_object"]),
        is_ood=is_ood,
        source_id=source_id,
    )


def load_public_file(path: str | os.PathLike, root: str | os.PathLike | None = None) -> Episode:
    """Load and validate one ``motion_normal_<i>.pkl`` / ``motion_variation_<i>.pkl``.

    Args:
        path: the file.
        root: the dataset folder; a symbolic link must resolve inside it.

    Raises:
        UnsafePickleError: the file references a global outside numpy's array rebuilding.
        DatasetError: the file is not a regular file, is empty, truncated, not a pickle, too
            large, or has bad keys, dtypes, shapes, NaN/inf, lengths or coordinates; the message
            names the file and the problem. Nothing else escapes (a ``MemoryError`` or a numpy
            error on a crafted file becomes a DatasetError naming it).
    """
    path = Path(path)
    match = FILE_NAME_RE.fullmatch(path.name)
    if match is None:
        raise DatasetError(
            f"{shown(path)}: not a public-dataset file name (expected {ID_PREFIX}<i>.pkl or "
            f"{OOD_PREFIX}<i>.pkl, <i> in ASCII digits without leading zeros)"
        )
    try:
        record = validate_record(safe_load_pickle(path, Path(root) if root else None), shown(path))
        return episode_from_record(record, path.stem, is_ood=match.group(1) == "motion_variation")
    except DatasetError as exc:
        message = str(exc)
        if not message.startswith(shown(path)):  # Episode's own checks name the episode only
            raise DatasetError(f"{shown(path)}: {message}") from exc
        raise
    except Exception as exc:  # outside the contract: still one error naming the file
        raise DatasetError(f"{shown(path)}: cannot load ({type(exc).__name__}: {exc})") from exc


def list_public_files(folder: str | os.PathLike) -> list[Path]:
    """The entries of ``folder`` named like dataset files: ID first, then OOD, in index order.

    Every entry whose name starts with ``motion_normal_`` or ``motion_variation_`` is listed,
    whatever it is: folders, FIFOs, dangling or looping links and non-canonical names (a trailing
    newline, non-ASCII digits, leading zeros) come last, so that :func:`load_public_file` refuses
    each one by name (and ``skip_bad`` reports it) instead of passing over it in silence.

    Raises:
        FileNotFoundError: ``folder`` does not exist or is not a directory.
        DatasetError: it holds no entry named like a dataset file.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"no public-dataset folder at {folder}")
    entries = [p for p in folder.iterdir() if p.name.startswith((ID_PREFIX, OOD_PREFIX))]
    if not entries:
        raise DatasetError(
            f"{folder}: no {ID_PREFIX}<i>.pkl or {OOD_PREFIX}<i>.pkl files; point at the "
            f"dataset's data/whole_motions folder"
        )

    def key(p: Path) -> tuple[int, int, str]:
        m = FILE_NAME_RE.fullmatch(p.name)
        if m is None:
            return (2, 0, p.name)
        return (0 if m.group(1) == "motion_normal" else 1, int(m.group(2)), p.name)

    return sorted(entries, key=key)


@dataclass
class LoadReport:
    """What :func:`load_public_dataset` did with each file.

    Attributes:
        loaded: number of files converted.
        skipped: ``(file name, reason)`` for every file refused with ``skip_bad=True``.
    """

    loaded: int = 0
    skipped: list[tuple[str, str]] = field(default_factory=list)

    def summary(self) -> str:
        """One line, plus one line per skipped file."""
        lines = [f"loaded {self.loaded} file(s), skipped {len(self.skipped)}"]
        lines += [f"  skipped {name}: {reason}" for name, reason in self.skipped]
        return "\n".join(lines)


def load_public_dataset(
    folder: str | os.PathLike,
    *,
    skip_bad: bool = False,
    progress: bool = True,
    report: LoadReport | None = None,
    on_skip: Callable[[str, str], None] | None = None,
) -> HandoverDataset:
    """Load a folder of public-dataset pickles safely into a :class:`HandoverDataset`.

    Args:
        folder: the dataset's ``data/whole_motions`` folder (or any folder of its files).
        skip_bad: skip files that fail to load or validate instead of raising; each skip is
            recorded in ``report`` and passed to ``on_skip`` (default: a warning).
        progress: show a tqdm progress bar.
        report: filled with the counts and the skipped files.
        on_skip: called as ``on_skip(file_name, reason)`` for each skipped file.

    Raises:
        FileNotFoundError: the folder does not exist.
        DatasetError: no dataset files, every file was bad, or (without ``skip_bad``) the first
            bad file; the message names the file and the problem. Forbidden globals raise
            :class:`UnsafePickleError`, a subclass.
    """
    files = list_public_files(folder)
    report = report if report is not None else LoadReport()
    episodes: list[Episode] = []
    for path in tqdm(files, desc=f"loading {Path(folder).name}", unit="file", disable=not progress):
        try:
            episodes.append(load_public_file(path, root=folder))
        except (DatasetError, OSError) as exc:
            if not skip_bad:
                raise
            reason = str(exc).removeprefix(f"{shown(path)}: ")
            report.skipped.append((shown(path.name), reason))
            if on_skip is not None:
                on_skip(shown(path.name), reason)
            else:
                import warnings

                warnings.warn(f"skipping {shown(path)}: {reason}", stacklevel=2)
    report.loaded = len(episodes)
    if not episodes:
        raise DatasetError(f"{folder}: none of the {len(files)} dataset file(s) could be loaded")
    return HandoverDataset(
        episodes, rate_hz=DEFAULT_RATE_HZ, name=f"public:{Path(folder).resolve()}"
    )
