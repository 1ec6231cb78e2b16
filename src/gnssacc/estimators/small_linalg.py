"""Products of 3 x 3 matrices for the compiled measurement models, computed as numpy computes
them.

The aids' models were numpy expressions (``R @ v``, ``A @ B``); compiled, they keep the same
arithmetic, so that an EKF pass gives the same numbers to the last bit. numpy hands these
products to its BLAS, whose x86-64 kernels sum the three terms with fused multiply-adds (one
rounding each): a matrix product ``A @ B``, whatever the layouts, as
``fma(a2, b2, fma(a1, b1, a0 b0))``; a matrix with contiguous rows (C order) times a vector as
``fma(a2, v2, fma(a0, v0, a1 v1))``; a matrix with contiguous columns (F order: a transpose, or
the settings' mounting rotation) times a vector left to right without fusing. A machine whose
BLAS sums otherwise gets results that differ in the last bits from numpy's (never in accuracy: a
fused multiply-add rounds once where the plain sum rounds twice).
"""

from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.extending import intrinsic


@intrinsic
def fma(typingctx, a, b, c):
    """``a b + c`` rounded once (LLVM's ``llvm.fma``: the CPU's instruction, else a correctly
    rounded library call), for float64 arguments."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        return builder.fma(*args)

    return sig, codegen


@njit(cache=True)
def matmul_into(A, B, out, j0):
    """``out[:, j0:j0 + m] = A @ B`` for ``A`` (3, 3), ``B`` (3, m), summed as numpy's BLAS
    multiplies matrices (module notes)."""
    for r in range(3):
        for c in range(B.shape[1]):
            out[r, j0 + c] = fma(A[r, 2], B[2, c], fma(A[r, 1], B[1, c], A[r, 0] * B[0, c]))


@njit(cache=True)
def matvec(A, v, rows: bool):
    """``A @ v`` for ``A`` (3, 3), summed as numpy's BLAS sums it for a matrix whose rows are
    contiguous (``rows``: C order) or not (F order, a transpose; module notes)."""
    out = np.empty(3)
    if rows:
        for r in range(3):
            out[r] = fma(A[r, 2], v[2], fma(A[r, 0], v[0], A[r, 1] * v[1]))
    else:
        for r in range(3):
            out[r] = A[r, 0] * v[0] + A[r, 1] * v[1] + A[r, 2] * v[2]
    return out


def rows_contiguous(A: np.ndarray) -> bool:
    """Whether numpy takes ``A`` (3, 3) as a matrix in C order (its rows contiguous) when it
    multiplies it with a vector (:func:`matvec`'s ``rows``)."""
    return bool(A.strides[1] < A.strides[0])


@njit(cache=True)
def skew_into(v, out):
    """``out = [v x]`` (3, 3), so that ``[v x] b = v x b``."""
    out[0, 0], out[0, 1], out[0, 2] = 0.0, -v[2], v[1]
    out[1, 0], out[1, 1], out[1, 2] = v[2], 0.0, -v[0]
    out[2, 0], out[2, 1], out[2, 2] = -v[1], v[0], 0.0
