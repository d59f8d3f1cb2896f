"""The canonical handover dataset: one format for the public recordings and our synthetic demos.

Every learning method in the paper (Sec. IV-A, "Data Collection") learns from pairs
(xi^r_k, xi^g_k): the receiver base xy trajectory and the giver wrist xyz trajectory of demo k,
both sampled at 30 Hz. :class:`HandoverDataset` holds those pairs plus the receiver's hand, the
object orientation, an ID/OOD flag and a source id, and saves them as one compressed ``.npz``
that is read back with ``allow_pickle=False`` (nothing in the file can execute).
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from handover_env.data.errors import DatasetError
from handover_env.data.limits import (
    MAX_ABS_COORD_M,
    MAX_EPISODES,
    MAX_FRAMES,
    MAX_ID_CHARS,
    MAX_TOTAL_FRAMES,
    MIN_QUAT_NORM,
)
from handover_env.data.npz import read_npz_members
from handover_env.paths import new_file_mode

FORMAT_VERSION = 1
DEFAULT_RATE_HZ = 30.0
#: Plausible sampling rates of a recorded or simulated trajectory, Hz. Cameras and motion capture
#: run at about 10 .. 500 Hz (the public data: 30 Hz); outside 1 .. 1000 Hz a rate is a corrupt or
#: crafted value (1e-300 Hz makes every time step 1e300 s), not a recording.
MIN_RATE_HZ = 1.0
MAX_RATE_HZ = 1000.0

_ARRAY_FIELDS: dict[str, int] = {
    "receiver_xy": 2,
    "receiver_hand_xyz": 3,
    "giver_xyz": 3,
    "object_quat": 4,
}
#: The position fields, bounded to +-MAX_ABS_COORD_M (metres).
_POSITION_FIELDS = ("receiver_xy", "receiver_hand_xyz", "giver_xyz")


def rate_problem(rate_hz: object) -> str | None:
    """None when ``rate_hz`` is a real number in [:data:`MIN_RATE_HZ`, :data:`MAX_RATE_HZ`] Hz,
    else why not (a message naming the field ``rate_hz``)."""
    if isinstance(rate_hz, bool) or not isinstance(rate_hz, (int, float, np.integer, np.floating)):
        return f"rate_hz must be a number, got {type(rate_hz).__name__}"
    if not (np.isfinite(rate_hz) and MIN_RATE_HZ <= rate_hz <= MAX_RATE_HZ):
        return (
            f"rate_hz is {float(rate_hz):g} Hz, outside the {MIN_RATE_HZ:g} .. {MAX_RATE_HZ:g} Hz "
            "of a camera or motion-capture recording"
        )
    return None


@dataclass(frozen=True)
class Episode:
    """One handover demonstration, all arrays at the dataset rate and of equal length T.

    Attributes:
        receiver_xy: (T, 2) receiver base (pelvis) xy in metres, the paper's input x^r.
        receiver_hand_xyz: (T, 3) receiver right hand xyz in metres.
        giver_xyz: (T, 3) giver wrist xyz in metres, the paper's x^g (the object position).
        object_quat: (T, 4) object orientation quaternion (w, x, y, z).
        is_ood: True for an out-of-distribution demo (the receiver wanders or pauses).
        source_id: where the episode came from, e.g. ``motion_normal_12`` or ``synth_id_0007``.
    """

    receiver_xy: np.ndarray
    receiver_hand_xyz: np.ndarray
    giver_xyz: np.ndarray
    object_quat: np.ndarray
    is_ood: bool
    source_id: str

    def __post_init__(self) -> None:
        lengths = set()
        for name, width in _ARRAY_FIELDS.items():
            raw = np.asarray(getattr(self, name))
            if raw.dtype.kind not in "iuf":  # strings, objects, bools, complex: never coerced
                raise DatasetError(
                    f"episode {self.source_id!r}: {name} must be a real numeric array, got dtype "
                    f"{raw.dtype}"
                )
            arr = raw.astype(np.float64, copy=False)
            if arr.ndim != 2 or arr.shape[1] != width:
                raise DatasetError(
                    f"episode {self.source_id!r}: {name} must have shape (T, {width}), got "
                    f"{arr.shape}"
                )
            if not np.all(np.isfinite(arr)):
                raise DatasetError(f"episode {self.source_id!r}: {name} contains NaN or inf")
            if name in _POSITION_FIELDS and arr.size and np.abs(arr).max() > MAX_ABS_COORD_M:
                raise DatasetError(
                    f"episode {self.source_id!r}: {name} reaches {np.abs(arr).max():.3g} m, "
                    "outside "
                    f"the +-{MAX_ABS_COORD_M:g} m a recorded position may have"
                )
            if name == "object_quat" and arr.size:
                norms = np.linalg.norm(arr, axis=1)
                if norms.min() < MIN_QUAT_NORM or norms.max() > 1.0 / MIN_QUAT_NORM:
                    frame = int(
                        np.argmin(norms) if norms.min() < MIN_QUAT_NORM else np.argmax(norms)
                    )
                    raise DatasetError(
                        f"episode {self.source_id!r}: object_quat has a zero-norm (or huge) "
                        f"quaternion at frame {frame}"
                    )
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
            lengths.add(arr.shape[0])
        if len(lengths) != 1:
            raise DatasetError(
                f"episode {self.source_id!r}: arrays disagree in length: {sorted(lengths)}"
            )
        if next(iter(lengths)) < 2:
            raise DatasetError(f"episode {self.source_id!r}: needs at least 2 frames")
        if next(iter(lengths)) > MAX_FRAMES:
            raise DatasetError(f"episode {self.source_id!r}: more than {MAX_FRAMES:,} frames")
        if not isinstance(self.is_ood, (bool, np.bool_)):
            raise DatasetError(
                f"episode {self.source_id!r}: is_ood must be a bool, got "
                f"{type(self.is_ood).__name__}"
            )
        object.__setattr__(self, "is_ood", bool(self.is_ood))
        object.__setattr__(self, "source_id", str(self.source_id))

    @property
    def length(self) -> int:
        """Number of frames T."""
        return int(self.receiver_xy.shape[0])


@dataclass
class HandoverDataset:
    """An ordered collection of :class:`Episode` at one sampling rate.

    Args:
        episodes: the demonstrations.
        rate_hz: sampling rate shared by every episode (30 Hz in the public dataset), within
            :data:`MIN_RATE_HZ` .. :data:`MAX_RATE_HZ`.
        name: free-text provenance, e.g. ``"public:/path/to/whole_motions"`` or
            ``"synthetic(seed=0)"``.
    """

    episodes: list[Episode]
    rate_hz: float = DEFAULT_RATE_HZ
    name: str = ""
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        problem = rate_problem(self.rate_hz)
        if problem:
            raise DatasetError(problem)
        self.episodes = list(self.episodes)
        for ep in self.episodes:
            if not isinstance(ep, Episode):
                raise DatasetError(f"expected Episode, got {type(ep).__name__}")

    # ----------------------------------------------------------------- container protocol
    def __len__(self) -> int:
        return len(self.episodes)

    def __iter__(self) -> Iterator[Episode]:
        return iter(self.episodes)

    def __getitem__(self, index: int) -> Episode:
        return self.episodes[index]

    @property
    def n_frames(self) -> int:
        """Total number of frames over all episodes."""
        return int(sum(ep.length for ep in self.episodes))

    @property
    def ood_mask(self) -> np.ndarray:
        """(N,) bool array, True for OOD episodes."""
        return np.array([ep.is_ood for ep in self.episodes], dtype=bool)

    @property
    def lengths(self) -> np.ndarray:
        """(N,) int array of episode lengths."""
        return np.array([ep.length for ep in self.episodes], dtype=np.int64)

    @property
    def dt(self) -> float:
        """Seconds between frames."""
        return 1.0 / self.rate_hz

    def fingerprint(self) -> str:
        """A hash of everything the episodes hold (ids, flags, every array) and the rate.

        Two datasets with the same fingerprint hold the same demonstrations in the same order;
        the LeRobot export records it to tell whether an existing export matches.
        """
        h = hashlib.sha256()
        h.update(repr(float(self.rate_hz)).encode())
        for ep in self.episodes:
            h.update(ep.source_id.encode("utf-8", "surrogatepass") + b"\0")
            h.update(b"\1" if ep.is_ood else b"\0")
            for name in _ARRAY_FIELDS:
                arr = np.ascontiguousarray(getattr(ep, name), dtype=np.float64)
                h.update(str(arr.shape).encode())
                h.update(arr.tobytes())
        return h.hexdigest()[:32]

    def subset(self, indices: Sequence[int] | np.ndarray) -> HandoverDataset:
        """A new dataset holding the episodes at ``indices`` (in that order)."""
        idx = np.asarray(indices, dtype=np.int64).reshape(-1)
        if idx.size and (idx.min() < -len(self) or idx.max() >= len(self)):
            raise IndexError(f"index out of range for a dataset of {len(self)} episodes")
        return HandoverDataset(
            [self.episodes[i] for i in idx], rate_hz=self.rate_hz, name=self.name
        )

    # ----------------------------------------------------------------- splits
    def stratified_kfold(self, k: int, seed: int = 0) -> list[tuple[np.ndarray, np.ndarray]]:
        """Stratified k-fold split by the ID/OOD flag, as in the paper's Table I protocol.

        Each stratum (ID, OOD) is shuffled with ``seed`` and dealt round-robin into ``k`` folds,
        so every fold holds about 1/k of the ID and 1/k of the OOD episodes.

        Returns:
            ``k`` pairs ``(train_indices, test_indices)``; the test sets partition the dataset.
        """
        fold_of = stratified_fold_ids(self.ood_mask, k, seed)
        all_idx = np.arange(len(self))
        return [(all_idx[fold_of != f], all_idx[fold_of == f]) for f in range(k)]

    def subsample(self, ratio: float, seed: int = 0) -> HandoverDataset:
        """A stratified random fraction of the episodes (the sample-efficiency figure).

        Keeps ``max(1, round(ratio * n))`` episodes of each non-empty stratum (ID, OOD).
        """
        if not (0.0 < float(ratio) <= 1.0):
            raise ValueError(f"ratio must be in (0, 1], got {ratio!r}")
        rng = np.random.default_rng(seed)
        mask = self.ood_mask
        keep: list[np.ndarray] = []
        for stratum in (np.flatnonzero(~mask), np.flatnonzero(mask)):
            if stratum.size:
                n = max(1, round(ratio * stratum.size))
                keep.append(np.sort(rng.choice(stratum, size=n, replace=False)))
        return self.subset(np.sort(np.concatenate(keep)) if keep else np.array([], dtype=np.int64))

    # ----------------------------------------------------------------- persistence
    def save(self, path: str | os.PathLike) -> Path:
        """Write one compressed ``.npz`` (format version :data:`FORMAT_VERSION`); returns the path.

        The file is written under a temporary name beside ``path`` and renamed into place, so
        ``path`` is either the old file or the complete new one; the temporary file is removed
        on any error.

        Raises:
            ValueError: ``path`` does not end in ``.npz``.
            DatasetError: the dataset is empty, or ``path`` exists and is not a regular file.
        """
        path = Path(path)
        if path.suffix != ".npz":
            raise ValueError(f"dataset files end in .npz, got {path}")
        if not self.episodes:
            raise DatasetError("refusing to save an empty dataset")
        if path.is_dir() or (path.exists() and not path.is_file()):
            raise DatasetError(f"{path}: exists and is not a file (a folder?); choose a file name")
        lengths = self.lengths
        arrays = {
            name: np.concatenate([getattr(ep, name) for ep in self.episodes])
            for name in _ARRAY_FIELDS
        }
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp_name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        tmp = Path(tmp_name)
        try:
            with os.fdopen(fd, "wb") as f:
                np.savez_compressed(
                    f,
                    format_version=np.array(FORMAT_VERSION, dtype=np.int64),
                    rate_hz=np.array(self.rate_hz, dtype=np.float64),
                    name=np.array(self.name),
                    lengths=lengths,
                    is_ood=self.ood_mask,
                    source_id=np.array([ep.source_id for ep in self.episodes]),
                    **arrays,
                )
                f.flush()
                os.fsync(f.fileno())
            os.chmod(tmp, new_file_mode())
            os.replace(tmp, path)  # never leave a half-written file under the real name
        finally:
            if tmp.exists():
                tmp.unlink()
        return path

    @classmethod
    def load(cls, path: str | os.PathLike) -> HandoverDataset:
        """Read a file written by :meth:`save`, validating every array.

        Only the members :meth:`save` writes are read, each bounded before it is decompressed
        (:mod:`handover_env.data.npz`); every scalar must have its exact dtype and shape
        (``format_version`` an integer equal to :data:`FORMAT_VERSION`, ``rate_hz`` a float
        within :data:`MIN_RATE_HZ` .. :data:`MAX_RATE_HZ` Hz,
        ``is_ood`` booleans, ``source_id`` strings), and every episode passes :class:`Episode`'s
        checks (finite, positions within +-:data:`~handover_env.data.limits.MAX_ABS_COORD_M` m,
        non-zero quaternions).

        Raises:
            FileNotFoundError: the path does not exist.
            DatasetError: the file is not a valid dataset; the message names the file and the
                problem.
        """
        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(f"no dataset file at {path}")
        required = {"format_version", "rate_hz", "lengths", "is_ood", "source_id", *_ARRAY_FIELDS}
        content = read_npz_members(path, required, optional={"name"})

        def scalar(key: str, kinds: str) -> np.ndarray:
            value = content[key]
            if value.shape != () or value.dtype.kind not in kinds:
                raise DatasetError(
                    f"{path}: {key} must be a single {'integer' if kinds == 'iu' else 'number'}, "
                    f"got dtype {value.dtype} shape {value.shape}"
                )
            return value

        version = scalar("format_version", "iu")
        if int(version) != FORMAT_VERSION:
            raise DatasetError(
                f"{path}: format version {int(version)}, this code reads {FORMAT_VERSION}"
            )
        rate = float(scalar("rate_hz", "iuf"))
        problem = rate_problem(rate)
        if problem:
            raise DatasetError(f"{path}: {problem}")
        lengths = content["lengths"]
        if lengths.ndim != 1 or lengths.dtype.kind not in "iu":
            raise DatasetError(
                f"{path}: lengths must be a 1-D integer array, got {lengths.dtype} {lengths.shape}"
            )
        n = lengths.size
        if n == 0:
            raise DatasetError(f"{path}: holds no episodes")
        if n > MAX_EPISODES:
            raise DatasetError(f"{path}: {n:,} episodes (at most {MAX_EPISODES:,})")
        lengths = lengths.astype(np.int64)
        if lengths.min() < 2 or lengths.max() > MAX_FRAMES:
            raise DatasetError(
                f"{path}: invalid episode lengths (each must be 2 .. {MAX_FRAMES:,} frames)"
            )
        total = int(lengths.sum())
        if total > MAX_TOTAL_FRAMES:
            raise DatasetError(f"{path}: {total:,} frames (at most {MAX_TOTAL_FRAMES:,})")
        is_ood, source_id = content["is_ood"], content["source_id"]
        if is_ood.shape != (n,) or is_ood.dtype != np.bool_:
            raise DatasetError(
                f"{path}: is_ood must be {n} booleans, got dtype {is_ood.dtype} shape "
                f"{is_ood.shape}"
            )
        if (
            source_id.shape != (n,)
            or source_id.dtype.kind != "U"
            or source_id.dtype.itemsize > 4 * MAX_ID_CHARS
        ):
            raise DatasetError(
                f"{path}: source_id must be {n} strings of at most {MAX_ID_CHARS} characters, "
                f"got dtype {source_id.dtype} shape {source_id.shape}"
            )
        for name, width in _ARRAY_FIELDS.items():
            arr = content[name]
            if arr.shape != (total, width) or arr.dtype.kind != "f":
                raise DatasetError(
                    f"{path}: {name} has dtype {arr.dtype} shape {arr.shape}, expected floats "
                    f"{(total, width)}"
                )
        name = ""
        if "name" in content:
            value = content["name"]
            if value.shape != () or value.dtype.kind != "U":
                raise DatasetError(
                    f"{path}: name must be one string, got dtype {value.dtype} shape {value.shape}"
                )
            name = str(value)
        bounds = np.concatenate([[0], np.cumsum(lengths)])
        episodes = []
        for i in range(n):
            sl = slice(bounds[i], bounds[i + 1])
            try:
                episodes.append(
                    Episode(
                        **{field_: content[field_][sl] for field_ in _ARRAY_FIELDS},
                        is_ood=bool(is_ood[i]),
                        source_id=str(source_id[i]),
                    )
                )
            except DatasetError as exc:
                raise DatasetError(f"{path}: {exc}") from exc
        try:
            return cls(episodes, rate_hz=rate, name=name)
        except DatasetError as exc:
            raise DatasetError(f"{path}: {exc}") from exc


def stratified_fold_ids(ood_mask: np.ndarray, k: int, seed: int = 0) -> np.ndarray:
    """The fold (0 .. k-1) of every episode in a stratified k-fold split by the ID/OOD flag.

    Each stratum (ID, OOD) is shuffled with ``np.random.default_rng(seed)`` and dealt round-robin
    into ``k`` folds. This is the assignment behind :meth:`HandoverDataset.stratified_kfold` (the
    paper's Table I protocol); other splits (e.g. the receiver calibration's halves) reuse it so
    that they agree with Table I's folds on the same episodes in the same order.

    Args:
        ood_mask: (N,) bool, True for OOD episodes, in dataset order.
        k: number of folds, >= 2.
        seed: seed of the shuffle.

    Raises:
        ValueError: ``k`` < 2, fewer than ``k`` episodes, or a non-empty stratum smaller than ``k``.
    """
    if not isinstance(k, (int, np.integer)) or isinstance(k, bool) or k < 2:
        raise ValueError(f"k must be an integer >= 2, got {k!r}")
    mask = np.asarray(ood_mask, dtype=bool).reshape(-1)
    for label, count in (("ID", int((~mask).sum())), ("OOD", int(mask.sum()))):
        if 0 < count < k:
            raise ValueError(
                f"cannot make {k} stratified folds: only {count} {label} episodes "
                f"(each fold needs at least one); use fewer folds or more data"
            )
    if mask.size < k:
        raise ValueError(f"cannot make {k} folds from {mask.size} episodes")
    rng = np.random.default_rng(seed)
    fold_of = np.empty(mask.size, dtype=np.int64)
    for stratum in (np.flatnonzero(~mask), np.flatnonzero(mask)):
        perm = rng.permutation(stratum)
        fold_of[perm] = np.arange(perm.size) % k
    return fold_of
