"""One bounded read of a file we did not write: a regular file, inside its folder, read once.

Every loader of outside input (the public dataset's pickles, checkpoints' JSON and safetensors)
reads through :func:`read_regular_file`. It refuses FIFOs, sockets, devices and folders (a read
that could block or never end), files over a size limit (checked on what the file system reports
and again on what is read, so a sparse or growing file cannot slip through), dangling or looping
symbolic links, and links that resolve outside ``root``. The check and the read use the same open
file: the opened descriptor itself is checked (``fstat``, and on Linux the path the kernel gives
for it in ``/proc/self/fd``), so swapping the file for a link between a caller's checks and this
read gains nothing. Nothing is written and nothing in the file is run.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path


class UnsafeFileError(ValueError):
    """A file that a loader must not read; the message names it and says why."""


def shown(path: Path | str) -> str:
    """A path for a one-line message: as is, or quoted when it holds control characters."""
    text = str(path)
    return text if text.isprintable() else repr(text)


def _opened_path(fd: int) -> Path | None:
    """The path the kernel gives for an open descriptor (Linux), or None where it gives none."""
    try:
        return Path(os.readlink(f"/proc/self/fd/{fd}"))
    except OSError:
        return None


def _check_size(path: Path, size: int, limit: int, kind: str) -> None:
    if size > limit:
        raise UnsafeFileError(
            f"{shown(path)}: {size:,} bytes, more than the {limit:,} a {kind} may have"
        )


def read_regular_file(path: str | os.PathLike, limit: int, root: str | os.PathLike | None = None,
                      *, inside: str = "folder", kind: str = "file",
                      error: type[Exception] = UnsafeFileError) -> bytes:
    """The bytes of ``path``, refusing anything but a regular file of at most ``limit`` bytes.

    Args:
        path: the file.
        limit: the largest size accepted, bytes.
        root: when given, the file (after any symbolic link) must lie inside this folder.
        inside: what ``root`` is, for the message (``"dataset folder"``).
        kind: what the file is, for the message on its size (``"recording"``).
        error: the exception raised (the caller's own, e.g. ``DatasetError``).

    Raises:
        UnsafeFileError (or ``error``): a folder, FIFO, device or socket, a dangling or looping
            link, a file outside ``root``, a file over the limit, or an unreadable file.
    """
    try:
        return _read(Path(path), limit, root, inside, kind)
    except UnsafeFileError as exc:
        if error is UnsafeFileError:
            raise
        raise error(str(exc)) from None


def _read(path: Path, limit: int, root: str | os.PathLike | None, inside: str, kind: str) -> bytes:
    real_root = Path(root).resolve() if root is not None else None
    try:
        st = os.lstat(path)
        target = path
        if stat.S_ISLNK(st.st_mode):
            try:
                target = path.resolve(strict=True)
            except RuntimeError:
                raise UnsafeFileError(f"{shown(path)}: symbolic link loop") from None
            except FileNotFoundError:
                raise UnsafeFileError(f"{shown(path)}: dangling symbolic link") from None
            if real_root is not None and not target.is_relative_to(real_root):
                raise UnsafeFileError(
                    f"{shown(path)}: symbolic link to {shown(target)}, outside the {inside}"
                )
        st = os.stat(target)
        if stat.S_ISDIR(st.st_mode):
            raise UnsafeFileError(f"{shown(path)}: a folder, not a file")
        if not stat.S_ISREG(st.st_mode):  # refused before opening: a socket cannot be opened
            raise UnsafeFileError(f"{shown(path)}: not a regular file (a FIFO, socket or device)")
        _check_size(path, st.st_size, limit, kind)
        # O_NONBLOCK: opening a FIFO does not wait for a writer; O_NOFOLLOW: the name opened is
        # the file itself, not a link put there since the checks above.
        fd = os.open(target, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0)
                     | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0))
        with os.fdopen(fd, "rb") as f:
            fst = os.fstat(f.fileno())
            if not stat.S_ISREG(fst.st_mode):  # swapped since the checks above
                raise UnsafeFileError(
                    f"{shown(path)}: not a regular file (a FIFO, socket, device or folder)"
                )
            opened = _opened_path(f.fileno()) if real_root is not None else None
            if opened is not None and not opened.is_relative_to(real_root):
                raise UnsafeFileError(
                    f"{shown(path)}: opened {shown(opened)}, outside the {inside} (a folder on "
                    "its path was replaced by a link)"
                )
            _check_size(path, fst.st_size, limit, kind)
            data = f.read(limit + 1)
    except OSError as exc:
        raise UnsafeFileError(f"{shown(path)}: cannot read ({exc.strerror or exc})") from None
    if len(data) > limit:
        raise UnsafeFileError(f"{shown(path)}: more than the {limit:,} bytes a {kind} may have")
    return data
