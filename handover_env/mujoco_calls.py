"""MuJoCo's own C functions, callable from a compiled kernel.

A kernel (:func:`handover_env.compiled.kernel`) that needs what a MuJoCo function computes calls
that function itself, so its result has MuJoCo's bits by construction: the functions here are
numba external functions bound by symbol name to the ``libmujoco`` shipped in the ``mujoco``
wheel (loaded into the process once, at import). A symbol is resolved when the machine code is
linked, so a kernel that calls one is cached on disk like any other.

Pointers are passed as integers (``intp``; a pointer and an ``intp`` are passed alike on the
64-bit platforms MuJoCo's wheels exist for): ``MjModel._address`` / ``MjData._address`` for the
model and data, ``array.ctypes.data + 8 * i`` for element ``i`` of a float64 array. MuJoCo reports
a bad argument through its error handler, which in Python raises an exception; a kernel has no
such path, so its caller passes only ids and arrays it has checked (valid object ids, arrays of
the documented sizes).
"""

from __future__ import annotations

from pathlib import Path

import llvmlite.binding as llvm
import mujoco
from numba import types

#: the wheel's shared library, next to the mujoco package (Linux, macOS, Windows names)
_CANDIDATES = (f"libmujoco.so.{mujoco.__version__}", f"libmujoco.{mujoco.__version__}.dylib",
               "mujoco.dll")
_DIR = Path(mujoco.__file__).parent
_FOUND = [_DIR / name for name in _CANDIDATES if (_DIR / name).exists()]
if not _FOUND:
    raise ImportError(f"no MuJoCo library ({', '.join(_CANDIDATES)}) in {_DIR}")
llvm.load_library_permanently(str(_FOUND[0]))

_P, _I = types.intp, types.intc

#: ``mj_objectVelocity(m, d, objtype, objid, res[6], flg_local)``
mj_object_velocity = types.ExternalFunction(
    "mj_objectVelocity", types.void(_P, _P, _I, _I, _P, _I)
)
#: ``mj_applyFT(m, d, force[3], torque[3], point[3], body, qfrc_target[nv])``
mj_apply_ft = types.ExternalFunction("mj_applyFT", types.void(_P, _P, _P, _P, _P, _I, _P))
#: ``mju_mat2Quat(quat[4], mat[9])``
mju_mat2quat = types.ExternalFunction("mju_mat2Quat", types.void(_P, _P))
#: ``mj_solveM(m, d, x[n*nv], y[n*nv], n)``: x = M^-1 y for the n rows of y
mj_solve_m = types.ExternalFunction("mj_solveM", types.void(_P, _P, _P, _P, _I))
#: ``mju_cholSolve(res[n], mat[n*n], vec[n], n)``: solve with a Cholesky factor (mju_cholFactor)
mju_chol_solve = types.ExternalFunction("mju_cholSolve", types.void(_P, _P, _P, _I))
