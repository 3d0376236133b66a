"""Compiled per-pixel kernels: the one set of Numba options every kernel in ``ops/`` uses.

A chain of NumPy/cv2 calls reads and writes a whole plane per operation; a kernel compiled with
:func:`kernel` does the chain in one pass over each row, with the row in registers and L1, and
vectorised by LLVM. Kernels are serial and release the GIL: they run on the row strips of
:func:`ops.parallel.run_strips`, which gives them every core and keeps them safe to call from
several threads (a Numba ``parallel=True`` kernel would not be, with the default threading layer).

Options:

* ``error_model="numpy"``: a float division by zero gives inf/NaN as in NumPy instead of a
  branch that raises (and stops vectorisation);
* ``fastmath`` with contraction (fused multiply-add) and no signed zeros only: NaN and inf keep
  their meaning, and divisions stay exact (no reciprocal approximation);
* ``cache=True``: compiled code is kept beside the module (or in Numba's cache directory when
  that is read-only), so only the first process to use a kernel compiles it.

Constants inside kernels must be ``np.float32``: a Python float literal promotes the arithmetic
to float64. Transcendental functions are not vectorised by Numba here (no SVML): kernels take
their results (cv2.phase, ...) as inputs computed on the strip, or use a polynomial such as
:func:`expf` inlined into their loops.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar, cast

import numba
import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

F = TypeVar("F", bound=Callable[..., Any])

#: LLVM fast-math flags of every kernel (see the module docstring).
FASTMATH = frozenset({"contract", "nsz"})


def kernel(fn: F) -> F:
    """Compile ``fn`` as a serial, GIL-free, cached Numba kernel with the options above."""
    jit = numba.njit(nogil=True, cache=True, fastmath=set(FASTMATH), error_model="numpy")
    return cast(F, jit(fn))


def inline_kernel(fn: F) -> F:
    """:func:`kernel` for a small piece of other kernels, inlined into each caller (so that a
    loop in it is vectorised with the caller's knowledge of its arrays)."""
    jit = numba.njit(
        nogil=True, cache=True, fastmath=set(FASTMATH), error_model="numpy", inline="always"
    )
    return cast(F, jit(fn))


@intrinsic
def _float32_from_bits(typingctx, bits):  # type: ignore[no-untyped-def]
    """The float32 whose IEEE-754 bit pattern is the int32 ``bits`` (a bit cast, no conversion)."""
    sig = types.float32(types.int32)

    def codegen(context, builder, signature, args):  # type: ignore[no-untyped-def]
        return builder.bitcast(args[0], ir.FloatType())

    return sig, codegen


# Cephes expf (S. L. Moshier, "Methods and Programs for Mathematical Functions", 1989): ln 2 in
# two parts for the reduction, and the degree-6 minimax polynomial of e^r on |r| <= ln(2)/2.
_LOG2E = np.float32(1.44269504088896341)
_LN2_HI, _LN2_LO = np.float32(0.693359375), np.float32(-2.12194440e-4)
_EXPF_P = tuple(
    np.float32(c)
    for c in (1.9875691500e-4, 1.3981999507e-3, 8.3334519073e-3, 4.1665795894e-2, 1.6666665459e-1)
)
_EXPF_P5 = np.float32(5.0000001201e-1)
#: Arguments of :func:`expf` are clamped to ± this (e^±87 stays a normal float32).
EXPF_MAX = np.float32(87.0)


@inline_kernel
def expf(x):  # type: ignore[no-untyped-def]
    """e^x in float32 for |x| <= :data:`EXPF_MAX` (clamped there), within 2 ulp of the exact
    value, vectorisable (no library call): x = n ln 2 + r, e^r from Cephes' polynomial and 2^n
    from its bits. NaN must be handled by the caller (it gives an undefined value)."""
    one = np.float32(1.0)
    x = min(max(x, -EXPF_MAX), EXPF_MAX)
    z = np.floor(x * _LOG2E + np.float32(0.5))
    r = x - z * _LN2_HI - z * _LN2_LO
    p = _EXPF_P[0]
    for c in _EXPF_P[1:]:
        p = p * r + c
    y = (p * r + _EXPF_P5) * (r * r) + r + one
    return y * _float32_from_bits((np.int32(z) + np.int32(127)) << np.int32(23))  # type: ignore[call-arg]
