"""A planted checkpoint commit that points out of its folder, and the check that nothing moved.

The attack of issue 20 (``folder/lnk`` -> a folder outside, with a complete staged commit of files
under ``lnk/``), shared by the checkpoint families' security tests (BC-MLP, ACT, RL).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

ENTRIES = ["lnk/x.pth", "lnk/victim.pth", "lnk/new/y.pth"]
PAYLOAD = "import os; open('MARKER', 'w').write('pwned')\n"


def snapshot(root: Path) -> dict[str, tuple]:
    """Every entry under ``root`` (links not followed): kind, size, mtime, link target."""
    found = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            st = p.lstat()
            found[str(p.relative_to(root))] = (
                st.st_mode >> 12, st.st_size, st.st_mtime_ns,
                os.readlink(p) if p.is_symlink() else None)
    return found


def plant(folder: Path, outside: Path, entries: list[str] = ENTRIES) -> None:
    """The issue's attack: ``folder/lnk`` -> ``outside`` and a complete commit staging files under
    ``lnk/`` (a new file, one over an existing file, one in a folder that does not exist yet)."""
    (folder / "lnk").symlink_to(outside, target_is_directory=True)
    stage = folder / ".staging"
    for rel in entries:
        (stage / rel).parent.mkdir(parents=True, exist_ok=True)
        (stage / rel).write_text(PAYLOAD)
    (stage / "COMMIT.json").write_text(json.dumps({"files": entries}))


class Untouched:
    """Snapshots ``folders`` now; :meth:`check` asserts nothing in them changed since, and that
    no payload landed outside."""

    def __init__(self, outside: Path, *folders: Path) -> None:
        self.outside, self.folders = outside, (outside, *folders)
        self.before = [snapshot(f) for f in self.folders]

    def check(self) -> None:
        assert [snapshot(f) for f in self.folders] == self.before
        assert not (self.outside / "x.pth").exists() and not (self.outside / "new").exists()
        assert (self.outside / "victim.pth").read_text() == "ORIGINAL"
        assert not list(self.outside.parent.rglob("MARKER"))
