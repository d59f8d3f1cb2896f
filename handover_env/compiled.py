"""The one way a per-step kernel is compiled: :func:`kernel`.

Every compiled piece of the env's per-step work (the person's targets, the controller tick, the
wrist sensor) is a numba ``@njit`` function built by :func:`kernel`, so that all of them share the
same settings:

- ``cache=True``: the machine code is kept on disk and a new process loads it instead of compiling.
  numba writes the cache next to the source (``__pycache__``); where the installed package is
  read-only it falls back on its own to a user cache folder (``NUMBA_CACHE_DIR`` if set, else the
  platform's user cache directory), so a read-only install still starts warm after its first run.
  Where no folder at all is writable numba refuses ``cache=True``; the kernel is then compiled
  without a cache (in every new process) and a warning says so.
- ``fastmath=False``: IEEE arithmetic, in the order the source writes it, so a kernel gives the same
  bits as the numpy or Python expression it replaced, apart from the transcendental functions
  where numpy uses its own vectorised code (each kernel says where that applies).
- ``error_model="numpy"``: a division by zero gives inf/nan as numpy does, and the kernel carries no
  Python exception path (a check that matters is made before the kernel is called).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import Any, TypeVar

from numba import njit

F = TypeVar("F", bound=Callable[..., Any])

#: the options every per-step kernel is compiled with
KERNEL_OPTIONS: dict[str, Any] = {
    "cache": True,
    "fastmath": False,
    "nogil": True,
    "error_model": "numpy",
}


def kernel(fn: F) -> F:
    """Compile ``fn`` with :data:`KERNEL_OPTIONS` (used as a decorator)."""
    try:
        return njit(**KERNEL_OPTIONS)(fn)
    except RuntimeError as err:  # numba: "cannot cache function ...: no locator available"
        if "no locator available" not in str(err):
            raise
        warnings.warn(f"{err}: compiled without a cache (set NUMBA_CACHE_DIR to a writable "
                      "folder to keep the machine code)", RuntimeWarning, stacklevel=2)
        return njit(**{**KERNEL_OPTIONS, "cache": False})(fn)
