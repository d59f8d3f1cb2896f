"""The exclusive lock a running command holds on its output folder (``--out``).

Two runs writing into one folder at once would mix or silently lose each other's results, so every
command of ``train.py`` and ``evaluate.py`` that writes into an ``--out`` holds
:class:`OutputLock` on it for its whole run: ``flock(LOCK_EX | LOCK_NB)`` on the file
``<out>/.lock`` (:data:`handover_env.paths.OUTPUT_LOCK`), which records the holder's pid.

* A second run refuses at once with :class:`OutputLockError`, one line naming the lock file and
  the pid holding it; nothing in the folder is touched.
* The operating system drops the lock when its process dies, so a killed run never leaves a stale
  lock (only a harmless, unlocked ``.lock`` file, which the next run takes over).
* A lock file that is a symbolic link (or anything but a regular file) is refused, never followed;
  so is one with more than one name (a hard link to a file elsewhere, which writing the pid would
  truncate). Both are checked on the opened descriptor (``O_NOFOLLOW``, ``fstat``) before the
  file is truncated or written, and again just before.
* On release the lock file is deleted (still locked, so that no other run can hold a lock on a
  deleted file: :meth:`OutputLock.acquire` checks that the file it locked is still the one in the
  folder), and the folders the lock created are removed again if the run wrote nothing into them.
* Only the command's own process takes the lock (the CLI entry points); the worker processes of
  the run never do, and the descriptor is not inherited by them.
"""

from __future__ import annotations

import errno
import fcntl
import os
import stat
from pathlib import Path

from handover_env.paths import OUTPUT_LOCK

_OPEN_FLAGS = os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC
_ATTEMPTS = 5


class OutputLockError(ValueError):
    """An output folder that this run cannot lock: in use by another run, or a bad lock file."""


class OutputLock:
    """Exclusive lock on the output folder ``folder`` (given by option ``flag``), as a context
    manager or by :meth:`acquire` / :meth:`release`. The folder is created if missing."""

    def __init__(self, folder: str | os.PathLike, flag: str = "--out") -> None:
        self.folder = Path(folder)
        self.flag = flag
        self.path = self.folder / OUTPUT_LOCK
        self._fd: int | None = None
        self._owner: int | None = None
        self._created: list[Path] = []  # folders the lock made, deepest first

    # ------------------------------------------------------------------ taking and dropping
    def acquire(self) -> OutputLock:
        """Take the lock or raise :class:`OutputLockError` at once (never waits)."""
        if self._fd is not None:
            raise RuntimeError(f"{self.path} is already held by this OutputLock")
        self._created = _missing(self.folder)
        for _ in range(_ATTEMPTS):
            self.folder.mkdir(parents=True, exist_ok=True)
            fd = self._open()
            if fd is None:  # the folder went away between mkdir and open: try again
                continue
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = _read_pid(fd)
                os.close(fd)
                who = f"pid {holder}" if holder else "another process"
                raise OutputLockError(
                    f"{self.flag} {self.folder} is in use by another run: its lock {self.path} is "
                    f"held by {who}; wait for that run to end or choose another {self.flag}"
                ) from None
            except OSError as exc:
                os.close(fd)
                raise OutputLockError(
                    f"{self.flag} {self.folder}: cannot lock {self.path} ({exc.strerror})"
                ) from None
            if _same_file(fd, self.path):
                break
            os.close(fd)  # its last holder deleted it between our open and flock: start again
        else:
            raise OutputLockError(f"{self.flag} {self.folder}: {self.path} keeps being replaced")
        try:
            self._check_opened(fd)  # again, just before the only write
        except OutputLockError:
            os.close(fd)
            raise
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        self._fd, self._owner = fd, os.getpid()
        return self

    def release(self) -> None:
        """Delete the lock file and drop the lock (a no-op if not held, or in a forked child)."""
        fd, self._fd = self._fd, None
        if fd is None or self._owner != os.getpid():
            return
        try:
            if _same_file(fd, self.path):
                os.unlink(self.path)
        finally:
            fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)
        for folder in self._created:  # removed again if the run wrote nothing into them
            try:
                folder.rmdir()
            except OSError:
                break

    @property
    def held(self) -> bool:
        return self._fd is not None and self._owner == os.getpid()

    def __enter__(self) -> OutputLock:
        return self.acquire()

    def __exit__(self, *exc_info: object) -> None:
        self.release()

    # ------------------------------------------------------------------ the lock file
    def _open(self) -> int | None:
        """A descriptor of the regular lock file (created if missing), None if the folder
        vanished; OutputLockError for a symbolic link or anything that is not a regular file."""
        try:
            fd = os.open(self.path, _OPEN_FLAGS, 0o644)
        except FileNotFoundError:
            return None
        except OSError as exc:
            if exc.errno == errno.ELOOP:
                raise OutputLockError(
                    f"{self.flag} {self.folder}: the lock file {self.path} is a symbolic link; "
                    "refusing to follow it (remove it)"
                ) from None
            raise OutputLockError(
                f"{self.flag} {self.folder}: cannot open the lock file {self.path} "
                f"({exc.strerror})"
            ) from None
        try:
            self._check_opened(fd)
        except OutputLockError:
            os.close(fd)
            raise
        return fd

    def _check_opened(self, fd: int) -> None:
        """OutputLockError unless the open lock file ``fd`` is a regular file of at most one
        name."""
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise OutputLockError(
                f"{self.flag} {self.folder}: the lock file {self.path} is not a regular file"
            )
        if st.st_nlink > 1:  # 0: deleted by its last holder since; acquire() opens it again
            raise OutputLockError(
                f"{self.flag} {self.folder}: the lock file {self.path} has {st.st_nlink} names "
                "(a hard link to another file?); refusing to write it (remove it)"
            )


def _missing(folder: Path) -> list[Path]:
    """``folder`` and its ancestors that do not exist yet, deepest first."""
    missing = []
    for p in (folder, *folder.parents):
        if p.exists() or p.is_symlink():
            break
        missing.append(p)
    return missing


def _same_file(fd: int, path: Path) -> bool:
    """Is ``path`` (not followed) still the file open as ``fd``?"""
    try:
        st = os.stat(path, follow_symlinks=False)
    except FileNotFoundError:
        return False
    own = os.fstat(fd)
    return (st.st_dev, st.st_ino) == (own.st_dev, own.st_ino)


def _read_pid(fd: int) -> int | None:
    """The pid recorded in the lock file, or None if it holds none (yet)."""
    try:
        text = os.pread(fd, 32, 0).decode("ascii").strip()
    except (OSError, UnicodeDecodeError):
        return None
    return int(text) if text.isdigit() else None
