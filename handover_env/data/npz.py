"""Bounded reading of ``.npz`` members: only the members asked for, each size checked before it is
read.

``np.load(path)[key]`` trusts the archive: every member a caller touches is decompressed to the
size its zip entry declares, and the ``.npy`` header inside may declare a shape far larger than
the data that follows, which numpy allocates before reading. A 2.5 MB crafted file asked for
2.2 GB this way. :func:`read_npz_members` instead

* refuses a file over :data:`~handover_env.data.limits.MAX_NPZ_BYTES`, or whose zip directory
  lists more than :data:`~handover_env.data.limits.MAX_NPZ_MEMBERS` members, before parsing it;
* reads only the requested members and never decompresses the others;
* checks each member's declared (uncompressed) size against
  :data:`~handover_env.data.limits.MAX_NPZ_MEMBER_BYTES` and the total against
  :data:`~handover_env.data.limits.MAX_NPZ_TOTAL_BYTES`;
* parses the ``.npy`` header, refuses object dtypes, and requires header + shape x itemsize to
  equal the declared member size exactly, before allocating anything.
"""

from __future__ import annotations

import math
import os
import stat
import zipfile
from pathlib import Path

import numpy as np

from handover_env.data.errors import DatasetError
from handover_env.data.limits import (
    MAX_NPZ_BYTES,
    MAX_NPZ_MEMBER_BYTES,
    MAX_NPZ_MEMBERS,
    MAX_NPZ_TOTAL_BYTES,
)

_HEADER_LIMIT = 10_000  # numpy's own default max_header_size


def _directory_entries(path: Path) -> int | None:
    """Entries the zip's end-of-central-directory record declares (None if it cannot be read)."""
    try:
        with open(path, "rb") as f:
            end = zipfile._EndRecData(f)  # the stdlib's own EOCD parser (private)
    except (OSError, AttributeError, zipfile.BadZipFile):
        return None
    return None if end is None else int(end[zipfile._ECD_ENTRIES_TOTAL])


def read_npz_members(
    path: str | os.PathLike, required: set[str], optional: set[str] = frozenset()
) -> dict[str, np.ndarray]:
    """The arrays ``required`` (and those of ``optional`` that exist) of the ``.npz`` at ``path``.

    Raises:
        FileNotFoundError: no file at ``path``.
        DatasetError: not a regular file, too large, not a zip, a member missing, over a bound,
            of an object dtype, or whose header disagrees with its size; the message names the
            file and the member.
    """
    path = Path(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise FileNotFoundError(f"no dataset file at {path}") from None
    if not stat.S_ISREG(st.st_mode):
        raise DatasetError(f"{path}: not a regular file")
    if st.st_size > MAX_NPZ_BYTES:
        raise DatasetError(
            f"{path}: {st.st_size:,} bytes, more than the {MAX_NPZ_BYTES:,} a dataset may have"
        )
    entries = _directory_entries(path)
    if entries is not None and entries > MAX_NPZ_MEMBERS:
        raise DatasetError(
            f"{path}: the archive lists {entries:,} members (at most {MAX_NPZ_MEMBERS})"
        )
    try:
        archive = zipfile.ZipFile(path)
    except (zipfile.BadZipFile, OSError, ValueError, EOFError) as exc:
        raise DatasetError(f"{path}: not a readable .npz dataset ({exc})") from exc
    out: dict[str, np.ndarray] = {}
    total = 0
    with archive:
        names = set(archive.namelist())
        if len(names) > MAX_NPZ_MEMBERS:
            raise DatasetError(
                f"{path}: the archive lists {len(names):,} members (at most {MAX_NPZ_MEMBERS})"
            )
        missing = sorted(key for key in required if f"{key}.npy" not in names)
        if missing:
            raise DatasetError(f"{path}: missing keys {missing}")
        for key in sorted(required | {k for k in optional if f"{k}.npy" in names}):
            info = archive.getinfo(f"{key}.npy")
            if info.file_size > MAX_NPZ_MEMBER_BYTES:
                raise DatasetError(
                    f"{path}: member {key} declares {info.file_size:,} bytes "
                    f"(at most {MAX_NPZ_MEMBER_BYTES:,})"
                )
            total += info.file_size
            if total > MAX_NPZ_TOTAL_BYTES:
                raise DatasetError(
                    f"{path}: the members declare more than {MAX_NPZ_TOTAL_BYTES:,} bytes in all"
                )
            if info.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED):
                raise DatasetError(
                    f"{path}: member {key} uses compression method {info.compress_type}"
                )
            try:
                out[key] = _read_member(archive, info)
            except DatasetError as exc:
                raise DatasetError(f"{path}: member {key}: {exc}") from None
            except (zipfile.BadZipFile, OSError, ValueError, EOFError, MemoryError) as exc:
                raise DatasetError(
                    f"{path}: member {key} is not readable ({type(exc).__name__}: {exc})"
                ) from exc
    return out


def _read_member(archive: zipfile.ZipFile, info: zipfile.ZipInfo) -> np.ndarray:
    with archive.open(info) as f:
        version = np.lib.format.read_magic(f)
        if version == (1, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_1_0(
                f, max_header_size=_HEADER_LIMIT
            )
        elif version in ((2, 0), (3, 0)):
            shape, fortran, dtype = np.lib.format.read_array_header_2_0(
                f, max_header_size=_HEADER_LIMIT
            )
        else:  # pragma: no cover - read_magic only returns these
            raise DatasetError(f"unsupported .npy version {version}")
        if dtype.hasobject:
            raise DatasetError(f"object dtype {dtype} (datasets hold numbers and strings only)")
        if any(int(n) < 0 for n in shape):
            raise DatasetError(f"negative shape {shape}")
        nbytes = math.prod(int(n) for n in shape) * dtype.itemsize
        header = f.tell()
        if header + nbytes != info.file_size:
            raise DatasetError(
                f"its header declares shape {shape} of {dtype} ({nbytes:,} bytes), but the member "
                f"holds {info.file_size - header:,}"
            )
        data = f.read(nbytes)
        if len(data) != nbytes:
            raise DatasetError(f"truncated: {len(data):,} of {nbytes:,} bytes")
        array = np.frombuffer(data, dtype=dtype)
    return array.reshape(shape, order="F" if fortran else "C")
