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

:func:`exact_kernel` leaves out the contraction: every product and sum is rounded on its own, as
NumPy and OpenCV round them, for kernels that replace a chain of their calls bit for bit.

Constants inside kernels must be ``np.float32``: a Python float literal promotes the arithmetic
to float64. Transcendental functions are not vectorised by Numba here (no SVML): kernels take
their results (cv2.phase, ...) as inputs computed on the strip, or use a polynomial of
:mod:`ops.numerics` inlined into their loops.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any, TypeVar, cast

import numba

__all__ = [
    "EXACT_FASTMATH",
    "FASTMATH",
    "exact_kernel",
    "inline_kernel",
    "kernel",
    "prepare",
    "prepare_in_background",
]

F = TypeVar("F", bound=Callable[..., Any])

#: LLVM fast-math flags of every kernel (see the module docstring).
FASTMATH = frozenset({"contract", "nsz"})
#: Those of :func:`exact_kernel`: no contraction.
EXACT_FASTMATH = frozenset({"nsz"})


def kernel(fn: F) -> F:
    """Compile ``fn`` as a serial, GIL-free, cached Numba kernel with the options above."""
    jit = numba.njit(nogil=True, cache=True, fastmath=set(FASTMATH), error_model="numpy")
    return cast(F, jit(fn))


def exact_kernel(fn: F) -> F:
    """:func:`kernel` without contraction (no fused multiply-add): the result of each operation
    rounded as NumPy and OpenCV round it."""
    jit = numba.njit(nogil=True, cache=True, fastmath=set(EXACT_FASTMATH), error_model="numpy")
    return cast(F, jit(fn))


def inline_kernel(fn: F) -> F:
    """:func:`kernel` for a small piece of other kernels, inlined into each caller (so that a
    loop in it is vectorised with the caller's knowledge of its arrays)."""
    jit = numba.njit(
        nogil=True, cache=True, fastmath=set(FASTMATH), error_model="numpy", inline="always"
    )
    return cast(F, jit(fn))


@kernel
def _ready(x):  # type: ignore[no-untyped-def]
    return x + 1


def prepare() -> None:
    """Make Numba's compiler ready in this process: the first kernel a process loads, even from
    the cache, first loads Numba's registries of NumPy support (~0.3 s, a third of it importing
    SciPy's linear algebra to find a BLAS); this loads a trivial kernel to pay that now."""
    _ready(0)


def prepare_in_background() -> threading.Thread:
    """:func:`prepare` on a thread of its own (join it before the first kernel runs, or not:
    a kernel loaded meanwhile waits for it), so that the registries load while this thread does
    other work, e.g. decode a frame (the OpenEXR library does that without Python's lock).
    A failure is left for the kernels themselves to raise."""

    def run() -> None:
        try:
            prepare()
        except Exception:  # (best effort: the kernels will say what is wrong)
            return

    thread = threading.Thread(target=run, name="depict-jit-prepare", daemon=True)
    thread.start()
    return thread
