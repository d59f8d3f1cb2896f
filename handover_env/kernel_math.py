"""Small products for compiled kernels, summed in a fixed, stated order.

A compiled kernel gives the same bits as the code it stands for only if it adds and multiplies
in the same order. The per-step products of the env come from two libraries, each with its own
order, and the kernels here reproduce them exactly (compiled with
:func:`handover_env.compiled.kernel`: IEEE arithmetic, no reassociation):

- :func:`mj_dot`: MuJoCo's ``mju_dot`` (``mju_mulMatVec``, ``mju_mulMatMatT``) with its AVX
  reduction: four lane sums over blocks of four, reduced as ``(l0 + l2) + (l1 + l3)``, then the
  remaining one to three products summed among themselves and added (MuJoCo's
  ``engine_util_blas.c``; its plain-C fallback keeps the same order).
- :func:`fma`: a fused multiply-add (``a * b + c`` rounded once), as OpenBLAS's Haswell kernels
  compute numpy's small ``matmul``: a 3x3 by 3x3 product is ``fma(a2, b2, fma(a1, b1, a0 b0))``
  per entry, a 3x3 matrix times a vector ``fma(a2, x2, fma(a0, x0, a1 x1))`` per row, and a
  transposed 3x3 matrix times a vector the plain ``a0 x0 + a1 x1 + a2 x2``
  (:func:`mat3_mul`, :func:`mat3_vec`, :func:`mat3t_vec`). On a CPU without FMA instructions
  LLVM calls the C library's ``fma``, which rounds the same way.

The kernels' bits are the same on every CPU; numpy's are not: on a CPU with AVX-512, OpenBLAS
takes its SkylakeX kernels and numpy its AVX-512 loops, whose sums are in another order, so
there numpy differs from these orders in the last bits. The test session pins numpy and OpenBLAS
to their AVX2 paths before they load (``tests/conftest.py``), so the tests compare against the
orders stated here on any x86-64 CPU with AVX2 and FMA.
"""

from __future__ import annotations

from llvmlite import ir
from numba.core import types
from numba.extending import intrinsic

from handover_env.compiled import kernel


@intrinsic
def fma(typingctx, a, b, c):  # type: ignore[no-untyped-def]
    """``a * b + c`` with one rounding (LLVM's ``llvm.fma.f64``)."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
        dbl = ir.DoubleType()
        fn = builder.module.declare_intrinsic(
            "llvm.fma", [dbl], ir.FunctionType(dbl, [dbl, dbl, dbl])
        )
        return builder.call(fn, args)

    return sig, codegen


@kernel
def mj_dot(a, ia, b, ib, n):  # type: ignore[no-untyped-def]
    """``a[ia:ia+n] · b[ib:ib+n]`` in ``mju_dot``'s order (see the module docstring)."""
    res = 0.0
    i = 0
    if n >= 4:
        s0 = a[ia] * b[ib]
        s1 = a[ia + 1] * b[ib + 1]
        s2 = a[ia + 2] * b[ib + 2]
        s3 = a[ia + 3] * b[ib + 3]
        i = 4
        while i <= n - 4:
            s0 = s0 + a[ia + i] * b[ib + i]
            s1 = s1 + a[ia + i + 1] * b[ib + i + 1]
            s2 = s2 + a[ia + i + 2] * b[ib + i + 2]
            s3 = s3 + a[ia + i + 3] * b[ib + i + 3]
            i += 4
        res = (s0 + s2) + (s1 + s3)
    r = n - i
    if r == 3:
        res += (a[ia + i] * b[ib + i] + a[ia + i + 1] * b[ib + i + 1]
                + a[ia + i + 2] * b[ib + i + 2])
    elif r == 2:
        res += a[ia + i] * b[ib + i] + a[ia + i + 1] * b[ib + i + 1]
    elif r == 1:
        res += a[ia + i] * b[ib + i]
    return res


@kernel
def mat3_mul(out, io, a, ia, b, ib, b_transposed):  # type: ignore[no-untyped-def]
    """``out[io:io+9] = A @ B`` (or ``A @ Bᵀ``), 3x3 row-major, in numpy's matmul order."""
    for r in range(3):
        a0, a1, a2 = a[ia + 3 * r], a[ia + 3 * r + 1], a[ia + 3 * r + 2]
        for c in range(3):
            if b_transposed:
                b0, b1, b2 = b[ib + 3 * c], b[ib + 3 * c + 1], b[ib + 3 * c + 2]
            else:
                b0, b1, b2 = b[ib + c], b[ib + 3 + c], b[ib + 6 + c]
            out[io + 3 * r + c] = fma(a2, b2, fma(a1, b1, a0 * b0))


@kernel
def mat3_vec(a, ia, x0, x1, x2):  # type: ignore[no-untyped-def]
    """``A @ x`` (3x3 row-major at ``a[ia:]``) in numpy's matmul order, as three floats."""
    return (fma(a[ia + 2], x2, fma(a[ia], x0, a[ia + 1] * x1)),
            fma(a[ia + 5], x2, fma(a[ia + 3], x0, a[ia + 4] * x1)),
            fma(a[ia + 8], x2, fma(a[ia + 6], x0, a[ia + 7] * x1)))


@kernel
def mat3t_vec(a, ia, x0, x1, x2):  # type: ignore[no-untyped-def]
    """``Aᵀ @ x`` (3x3 row-major at ``a[ia:]``) in numpy's matmul order, as three floats."""
    return (a[ia] * x0 + a[ia + 3] * x1 + a[ia + 6] * x2,
            a[ia + 1] * x0 + a[ia + 4] * x1 + a[ia + 7] * x2,
            a[ia + 2] * x0 + a[ia + 5] * x1 + a[ia + 8] * x2)
