"""Allocator settings of Depict's processes: frame-sized arrays reuse memory instead of faulting.

An operator allocates and frees many frame-sized arrays (a 1080p RGB float32 plane is 25 MB).
With glibc's defaults, blocks that size are mapped fresh from the kernel and unmapped on free,
or trimmed from the top of the heap, so every new array pays its page faults and the zeroing of
its pages again: on a 2-core machine that made ``light_alignment`` through ``pipeline.run`` take
114 ms instead of 77. :func:`tune` keeps such blocks in the heap (``M_MMAP_THRESHOLD`` at
glibc's maximum, 32 MiB) and keeps freed memory for reuse (``M_TRIM_THRESHOLD`` 1 GiB).

It also asks NumPy not to advise transparent huge pages for its arrays (``NUMPY_MADVISE_HUGEPAGE``
= 0 unless the user set it; children inherit it): where the kernel compacts memory on such a
fault (``defrag`` = ``madvise``, Debian's default), a 2 MiB page is found and zeroed per fault,
in the kernel. On a 2-core machine ``depict enhance`` of a 1080p render spent 1.6–2.1 s of system
time with them and 0.9–1.0 s without (wall 3.58 s -> 2.89–3.01 s).

Memory kept that way stays the process's: after a frame is read, the decoded channels its buffers
were made from (a 1080p Cycles frame: ~380 MiB) sit freed in the heap, and an operator's arrays
would be laid beside them rather than in them. :func:`release_free` gives the free pages back
(``malloc_trim``, ~15 ms; :func:`service.enhance.read_for` calls it after reading).

So that freed memory is kept once, every thread allocates from one heap (``M_ARENA_MAX`` 1):
glibc otherwise gives each thread that allocates its own arena, and each keeps its own free
memory (an operator's row strips run on every core). ``depict enhance`` of a 1080p Cycles frame
peaked at 855–880 MiB before both, 805–830 MiB with the memory given back after the read (and
the buffers let go before the result is written), 760–765 MiB with one arena too, in the same
time. The shared lock is within a 2-core machine's noise: Light Alignment through
``pipeline.run`` (the operator whose threads allocate the most) took 280–356 ms with one arena
and 271–319 ms with eight (five alternated runs each).

The CLI, the HTTP service's workers, batch workers and the benchmarks call :func:`tune` at start; a
program that uses the Python API may call it too. ``DEPICT_MALLOC=system`` leaves the process's
allocator as it is. Elsewhere than on glibc it does nothing.
"""

from __future__ import annotations

import ctypes
import os
import sys

_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
_M_ARENA_MAX = -8
MMAP_THRESHOLD = 32 << 20  # glibc's upper limit on 64-bit (HEAP_MAX_SIZE / 2)
TRIM_THRESHOLD = 1 << 30
ARENA_MAX = 1  # one heap for every thread (see the module docstring)

_done = False


def tune() -> bool:
    """Apply the settings above once per process; True when they are in force."""
    global _done
    if _done:
        return True
    if os.environ.get("DEPICT_MALLOC", "tuned") == "system":
        return False
    _no_huge_pages()
    try:  # the C library the process already has (no search for it on disk)
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # not glibc (or no mallopt): leave the allocator as it is
        return False
    ok = mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD) == 1
    ok = mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD) == 1 and ok
    ok = mallopt(_M_ARENA_MAX, ARENA_MAX) == 1 and ok
    _done = ok
    return ok


def release_free() -> None:
    """Give the heap's free pages back to the system (glibc's ``malloc_trim``), where
    :func:`tune` is in force: at a point where much was freed and less will be needed again."""
    if _done:
        ctypes.CDLL(None).malloc_trim(0)


def _no_huge_pages() -> None:
    """NumPy's arrays without the huge-page advice, unless ``NUMPY_MADVISE_HUGEPAGE`` says."""
    if os.environ.setdefault("NUMPY_MADVISE_HUGEPAGE", "0") != "0":
        return
    numpy = sys.modules.get("numpy")  # read when NumPy is imported; if it already was:
    setter = getattr(getattr(numpy, "_core", None), "multiarray", None)
    if setter is not None and hasattr(setter, "_set_madvise_hugepage"):
        setter._set_madvise_hugepage(False)
