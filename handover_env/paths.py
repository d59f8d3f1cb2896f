"""Path safety for the tools that write or replace folders: nothing outside our outputs is deleted.

* :func:`output_folder` is the one check of every output-folder option (``--out``,
  ``--checkpoints``, ``--export-root``, ...): empty or blank is refused (an unset shell variable),
  ``~`` is expanded, and a path that exists but is not a folder is refused. Each running command
  locks its ``--out`` with the file :data:`OUTPUT_LOCK` in it (``handover_eval.output_lock``).
* :func:`check_replaceable_root` refuses the paths an ``--overwrite`` must never touch: the empty
  string (an unset shell variable), ``.``, the file-system root, the home folder, and any folder
  that holds the current one or the home folder.
* :func:`replace_dir` moves a finished temporary folder into place: the old folder (if any) is
  renamed aside, the new one renamed in, and only then is the old one deleted. An interrupt leaves
  either the old or the new folder under the final name, never a mix, plus at most one hidden
  sibling that the next run removes (:func:`remove_stale_siblings`) once the caller's check says
  it holds only what the tool writes; anything else named like one is left alone, with a warning.
"""

from __future__ import annotations

import os
import re
import shutil
import warnings
from collections.abc import Callable
from pathlib import Path

#: Hidden siblings written while a folder is being replaced: ``.<name>.partial-<pid>-<n>``
#: (being written) and ``.<name>.old-<pid>-<n>`` (about to be deleted).
_SIBLING = re.compile(r"\.(?P<name>.+)\.(?P<kind>partial|old)-(?P<pid>[0-9]+)-[0-9a-f]+", re.ASCII)


#: The lock file a running command holds in its output folder (never a result; always ignored).
OUTPUT_LOCK = ".lock"


class UnsafePathError(ValueError):
    """An output path that a tool must not use or replace; the message names it."""


def output_folder(path: str | os.PathLike, flag: str = "--out") -> Path:
    """``path`` (the value of option ``flag``) as the Path of an output folder, ``~`` expanded.

    Raises :class:`UnsafePathError` naming ``flag`` if it is empty or blank, holds a NUL byte, or
    names something that exists (or a dangling symbolic link) and is not a folder. The folder
    itself need not exist yet.
    """
    text = os.fsdecode(path)
    if not text.strip():
        raise UnsafePathError(f"{flag} is empty (an unset shell variable?)")
    if "\0" in text:
        raise UnsafePathError(f"{flag} {text!r}: a path cannot hold a NUL byte")
    try:
        folder = Path(text).expanduser()
    except RuntimeError as exc:  # ~user that does not exist, or no home folder
        raise UnsafePathError(f"{flag} {text}: {exc}") from None
    if folder.exists() and not folder.is_dir():
        raise UnsafePathError(f"{flag} {folder}: exists and is not a folder")
    if folder.is_symlink() and not folder.exists():
        raise UnsafePathError(f"{flag} {folder}: a symbolic link to nothing")
    return folder


def check_replaceable_root(path: str | os.PathLike) -> Path:
    """``path`` with ``~`` expanded, or :class:`UnsafePathError` if replacing it could delete a
    user's files.

    The returned path is the one that was checked: callers write there (not to ``path``), so a
    quoted ``"~/x"`` is the folder ``x`` in the home folder, never a folder named ``~``.

    Refused: ``""`` (and whitespace), ``.``, ``/``, the home folder, the current folder and every
    folder above the current or the home folder.
    """
    text = os.fspath(path)
    if not text.strip():
        raise UnsafePathError("refusing an empty output path (an unset shell variable?)")
    try:
        p = Path(text).expanduser()
    except RuntimeError as exc:  # "~nobody/x": no such user
        raise UnsafePathError(f"refusing {text!r}: cannot expand it ({exc})") from None
    resolved = p.resolve()
    home = Path.home().resolve()
    cwd = Path.cwd().resolve()
    if text.strip() in (".", "./", "~") or resolved == Path(resolved.anchor):
        raise UnsafePathError(f"refusing to replace {text!r}: it is {resolved}")
    for protected, what in ((home, "the home folder"), (cwd, "the current folder")):
        if resolved == protected or protected.is_relative_to(resolved):
            raise UnsafePathError(
                f"refusing to replace {text!r}: it is or holds {what} ({protected})"
            )
    return p


def new_file_mode() -> int:
    """The mode ``open()`` would give a new file under the current umask (temporary files get
    0600)."""
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def sibling(path: Path, kind: str) -> Path:
    """A fresh hidden sibling of ``path`` for a temporary (``partial``) or outgoing (``old``)
    folder."""
    return path.with_name(f".{path.name}.{kind}-{os.getpid()}-{os.urandom(4).hex()}")


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_siblings(path: Path, check: Callable[[Path, str], str | None]) -> list[Path]:
    """Delete the hidden ``partial``/``old`` siblings of ``path`` left by processes that died, if
    ``check`` accepts them.

    Args:
        path: the folder whose siblings are looked for.
        check: ``check(sibling, kind)`` with kind ``"partial"`` or ``"old"`` returns None when the
            sibling holds only what the tool writes (so deleting it loses nothing of a user's),
            else why not. A sibling it refuses is left in place and named in a warning.

    Returns:
        The siblings deleted.
    """
    removed = []
    parent = path.parent
    if not parent.is_dir():
        return removed
    for entry in sorted(parent.iterdir()):
        m = _SIBLING.fullmatch(entry.name)
        if not (m and m.group("name") == path.name and not _alive(int(m.group("pid")))):
            continue
        why = check(entry, m.group("kind"))
        if why is not None:
            warnings.warn(
                f"left {entry} in place: it is named like a temporary folder of {path.name} but "
                f"{why}; delete it yourself if it is not yours",
                stacklevel=2,
            )
            continue
        shutil.rmtree(entry, ignore_errors=True)  # what cannot be deleted is retried next run
        if not entry.exists():
            removed.append(entry)
    return removed


def replace_dir(new: Path, final: Path) -> None:
    """Move the finished folder ``new`` to ``final``, replacing (then deleting) the old one."""
    old = None
    if final.exists() or final.is_symlink():
        old = sibling(final, "old")
        final.rename(old)
    try:
        new.rename(final)
    except BaseException:
        if old is not None and not final.exists():
            old.rename(final)  # put the old folder back
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
