"""One atomic write of a file we produce: a fresh temporary file beside it, renamed over it.

Every writer of the project (the CSV, text, JSON and PNG writers of
:mod:`handover_eval.reporting`, the checkpoint files of :mod:`baselines.checkpoint_io`) goes
through :func:`atomic_write`, the counterpart of :mod:`handover_env.regular_file`'s one bounded
read:

* The temporary file is created in the target's own folder under a fresh, unpredictable name
  (``.<name>.<random>.tmp``) with ``O_CREAT | O_EXCL | O_NOFOLLOW``: a link or a file already at
  that name (a symbolic link or a hard link planted there) makes the creation fail and another
  name is drawn; nothing that exists is ever opened, truncated or followed. Its mode is what
  ``open()`` would give (``0666`` less the umask).
* It is written, flushed to disk (``fsync``, then the folder's too) and renamed over the target
  (``os.replace``), so a killed run leaves the previous file or the new one, never half of one.
  On any failure the temporary file is removed and the target is left as it was.
* The rename replaces the directory entry, never what it points to: a hard link at the target
  keeps the outside file's bytes. The target itself is refused (:class:`UnsafeTargetError`, one
  line naming it) when it is a symbolic link that resolves outside its folder (or a loop), or
  anything but a regular file (a folder, FIFO, socket or device, directly or behind a link);
  nothing is written then. A symbolic link inside the folder is replaced by the new file.
"""

from __future__ import annotations

import os
import secrets
import stat
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO

from handover_env.regular_file import shown

_CREATE = (os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
           | getattr(os, "O_CLOEXEC", 0))
_DIRECTORY = os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | getattr(os, "O_CLOEXEC", 0)
_ATTEMPTS = 100
_NAME_CHARS = 200  # of the target's name kept in the temporary name (NAME_MAX is 255)


class UnsafeTargetError(ValueError):
    """A file that a writer must not replace; the message names it and says why."""


def check_target(path: str | os.PathLike, root: str | os.PathLike | None = None) -> None:
    """Raise :class:`UnsafeTargetError` unless ``path`` is absent, a regular file, or a symbolic
    link resolving to a regular (or absent) file inside ``root`` (default: ``path``'s folder)."""
    path = Path(path)
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return
    if stat.S_ISREG(st.st_mode):
        return
    if not stat.S_ISLNK(st.st_mode):
        raise UnsafeTargetError(
            f"{shown(path)}: exists and is not a regular file (a folder, FIFO, socket or "
            "device); refusing to replace it"
        )
    folder = Path(path.parent if root is None else root).resolve()
    try:
        target = path.resolve()
    except (RuntimeError, OSError):  # a loop (RuntimeError before Python 3.13)
        raise UnsafeTargetError(f"{shown(path)}: a symbolic link loop; refusing to replace it")\
            from None
    if not target.is_relative_to(folder):
        raise UnsafeTargetError(
            f"{shown(path)}: a symbolic link to {shown(target)}, outside the folder "
            f"{shown(folder)}; refusing to write there (remove the link)"
        )
    if os.path.lexists(target) and not target.is_file():
        raise UnsafeTargetError(
            f"{shown(path)}: a symbolic link to {shown(target)}, which is not a regular file; "
            "refusing to replace it"
        )


def atomic_write(path: str | os.PathLike, fill: Callable[[BinaryIO], None],
                 root: str | os.PathLike | None = None) -> Path:
    """Write the file ``path`` by calling ``fill`` on a fresh temporary file beside it, then
    rename it over ``path`` (see the module docstring). Parent folders are created.

    Args:
        path: the file to write.
        fill: writes the file's bytes into the open binary file it is given.
        root: the folder a symbolic link at ``path`` must stay inside (default: its folder).

    Returns:
        ``path`` as a Path.

    Raises:
        UnsafeTargetError: ``path`` is a link out of ``root``, a loop, or not a regular file.
        Whatever ``fill`` raises, and OSError; the temporary file is removed either way.
    """
    path = Path(path)
    folder = path.parent
    folder.mkdir(parents=True, exist_ok=True)
    check_target(path, root)
    dir_fd = os.open(folder, _DIRECTORY)
    try:
        fd, tmp = _create(path.name, dir_fd)
        try:
            with os.fdopen(fd, "wb") as f:
                fill(f)
                f.flush()
                os.fsync(f.fileno())
            check_target(path, root)  # the last look before the rename, which follows nothing
            os.replace(folder / tmp, path)
        except BaseException:
            try:
                os.unlink(tmp, dir_fd=dir_fd)
            except FileNotFoundError:
                pass
            raise
        try:
            os.fsync(dir_fd)  # the rename itself on disk
        except OSError:
            pass
    finally:
        os.close(dir_fd)
    return path


def atomic_write_bytes(path: str | os.PathLike, data: bytes,
                       root: str | os.PathLike | None = None) -> Path:
    """Write ``data`` to ``path`` with :func:`atomic_write`."""
    return atomic_write(path, lambda f: f.write(data), root)


def _create(name: str, dir_fd: int) -> tuple[int, str]:
    """A new, empty file ``.<name>.<random>.tmp`` in the folder ``dir_fd``: (descriptor, name)."""
    for _ in range(_ATTEMPTS):
        tmp = f".{name[:_NAME_CHARS]}.{secrets.token_hex(8)}.tmp"
        try:
            return os.open(tmp, _CREATE, 0o666, dir_fd=dir_fd), tmp
        except FileExistsError:  # a file or link at that name: never reused, draw again
            continue
    raise FileExistsError(f"no free temporary name for {shown(name)} after {_ATTEMPTS} tries")
