"""The code that ran a command: its git commit, whether the tree was dirty, the command line.

A trained checkpoint records it (``train.py rl`` into ``config.json``'s ``versions``) so that a
shipped policy says which commit and which command made it. Outside a git checkout (an installed
wheel) or without git, ``commit`` is ``""`` and ``dirty`` is False; nothing here fails a run.
"""

from __future__ import annotations

import shlex
import subprocess
import sys
from pathlib import Path

#: The checkout this package lives in (``handover_eval/..``).
ROOT = Path(__file__).resolve().parents[1]


def _git(*args: str) -> str | None:
    """``git args`` in :data:`ROOT`'s checkout, its stripped output; None if git fails."""
    if not (ROOT / ".git").exists():
        return None
    try:
        done = subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True,
                              timeout=10, check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout.strip() if done.returncode == 0 else None


def command_line(argv: list[str] | None = None) -> str:
    """The command as typed: ``python SCRIPT ARGS`` (the script by its file name), shell-quoted."""
    argv = list(sys.argv if argv is None else argv)
    return shlex.join(["python", Path(argv[0]).name if argv else "", *argv[1:]])


def code_provenance(argv: list[str] | None = None) -> dict:
    """``{"commit", "dirty", "command"}`` of the running code (module docstring)."""
    commit = _git("rev-parse", "HEAD") or ""
    status = _git("status", "--porcelain", "--untracked-files=no") if commit else None
    return {"commit": commit, "dirty": bool(status), "command": command_line(argv)}
