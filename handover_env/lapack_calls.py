"""numpy's own LAPACK ``dgesv``, callable from a compiled kernel (:data:`dgesv`).

``numpy.linalg.solve`` of a real system is one call of LAPACK's ``dgesv`` (LU with partial
pivoting, then the triangular solves) on column-major copies of ``a`` and ``b``. A kernel
(:func:`handover_env.compiled.kernel`) that calls the same function of the same library gets
numpy's bits by construction. numpy's wheels ship that library beside the package
(``numpy.libs`` on Linux and Windows, ``numpy/.dylibs`` on macOS): scipy-openblas built with 64-bit
integers, whose symbol is ``scipy_dgesv_64_`` (numpy 2.x wheels) or ``dgesv_64_`` (the
``openblas64_`` builds of numpy 1.26). The library is already loaded by numpy; it is loaded here
once more by path (the same handle) so that numba can link the symbol by name, and a kernel that
calls it is cached on disk like any other (:mod:`handover_env.mujoco_calls` binds MuJoCo the same
way).

Where no such library is found (a numpy built against the system's or conda's LAPACK, whose
symbol and integer size this module cannot know), :data:`dgesv` is ``None`` and the callers keep
numpy's ``solve`` in Python. :data:`LIBRARY` names the library that was bound.

Fortran convention: every argument is a pointer (``intp``), the integers are int64:
``dgesv(n, nrhs, a[lda*n], lda, ipiv[n], b[ldb*nrhs], ldb, info)``; ``info > 0``: ``U[info-1,
info-1]`` is exactly zero (numpy raises ``LinAlgError("Singular matrix")``).
"""

from __future__ import annotations

import ctypes
from pathlib import Path

import llvmlite.binding as llvm
import numpy as np
from numba import types

#: the symbols of numpy's ILP64 builds, newest first
SYMBOLS = ("scipy_dgesv_64_", "dgesv_64_")
#: the folders numpy's wheels keep their shared libraries in
_PKG = Path(np.__file__).parent
_FOLDERS = (_PKG.parent / "numpy.libs", _PKG / ".dylibs", _PKG.parent / "numpy" / ".libs")
_PATTERNS = ("*openblas64*.so*", "*openblas64*.dylib", "*openblas64*.dll")


def _find() -> tuple[str, str] | None:
    """(library path, symbol) of numpy's bundled ILP64 OpenBLAS, or None."""
    for folder in _FOLDERS:
        if not folder.is_dir():
            continue
        for pattern in _PATTERNS:
            for path in sorted(folder.glob(pattern)):
                try:
                    lib = ctypes.CDLL(str(path))
                except OSError:
                    continue
                for symbol in SYMBOLS:
                    if hasattr(lib, symbol):
                        return str(path), symbol
    return None


_FOUND = _find()
#: the bound library (None: not found, :data:`dgesv` is None)
LIBRARY: str | None = None
#: ``dgesv(n, nrhs, a, lda, ipiv, b, ldb, info)`` of numpy's LAPACK, or None
dgesv: types.ExternalFunction | None = None
if _FOUND is not None:
    LIBRARY = _FOUND[0]
    llvm.load_library_permanently(LIBRARY)
    _P = types.intp
    dgesv = types.ExternalFunction(_FOUND[1], types.void(_P, _P, _P, _P, _P, _P, _P, _P))
