"""Row strips on every core: the one thread pool the operators share.

Per-pixel work cut into strips of rows stays in the CPU caches, and OpenCV and NumPy release the
GIL inside their loops, so strips run in parallel on threads. :func:`run_strips` is the only
strip runner in ``ops/``:

* at most ``min(cv2.getNumThreads(), os.cpu_count())`` strips run at once, one of them on the
  calling thread (``cv2.setNumThreads(1)`` makes everything sequential), each worker taking the
  next strip when it is done (strips of unequal cost balance themselves);
* a strip that raises stops the others taking more; the call returns (raising that error) once
  no strip of it runs; a stop (Ctrl-C, SIGTERM) waits :data:`STOP_WAIT_S` at most for them;
* called from inside a strip it runs sequentially, so nested strip work cannot deadlock the pool;
* a forked child (Dask or multiprocessing workers) starts a pool of its own.

``fn(a, b)`` must only write rows ``a`` to ``b`` of its outputs.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor, wait

import cv2

__all__ = ["STRIP_PIXELS", "run_strips", "strip_rows", "workers"]

#: Pixels per strip that keep a few float32 planes of it in the caches (:func:`strip_rows`).
STRIP_PIXELS = 1 << 17

#: The machine's cores, read once (``os.cpu_count()`` reads sysfs: ~8 µs, and :func:`workers` is
#: asked at every strip run).
_CORES = os.cpu_count() or 1

#: The longest a call stopped by Ctrl-C or SIGTERM waits for the strips still running before it
#: raises the stop all the same. The stop is raised wherever the calling thread is, possibly
#: inside a library that holds a lock then (llvmlite's, as Numba loads a kernel): that lock is
#: never released, and a strip waiting for it never ends. The process is ending: it must not wait
#: for ever.
STOP_WAIT_S = 2.0
_POOL: ThreadPoolExecutor | None = None
_POOL_LOCK = threading.Lock()
_IN_STRIP = threading.local()


def _forget_pool() -> None:  # in a forked child: the parent's threads are not there
    global _POOL, _POOL_LOCK
    _POOL, _POOL_LOCK = None, threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_pool)


def workers() -> int:
    """How many strips may run at once."""
    return max(1, min(cv2.getNumThreads(), _CORES))


def strip_rows(width: int, pixels: int = STRIP_PIXELS) -> int:
    """Rows per strip of an image ``width`` pixels wide holding about ``pixels`` pixels."""
    return max(1, pixels // max(width, 1))


def run_strips(n: int, fn: Callable[[int, int], None], rows: int) -> None:
    """Call ``fn(a, b)`` on consecutive ranges ``[a, b)`` of ``rows`` covering ``[0, n)``.

    Parallel on the shared pool; sequential with one range or one worker, or when called from
    inside a strip (see the module docstring).
    """
    global _POOL
    step = max(1, int(rows))
    starts = range(0, n, step)
    count = min(len(starts), workers())
    if count <= 1 or getattr(_IN_STRIP, "active", False):
        for a in starts:
            fn(a, min(n, a + step))
        return
    with _POOL_LOCK:
        if _POOL is None:
            _POOL = ThreadPoolExecutor(max(2, _CORES), "depict-strips")
        pool = _POOL
    todo = iter(starts)
    lock = threading.Lock()
    failed = threading.Event()  # a strip raised: the others take no more

    def worker() -> None:
        _IN_STRIP.active = True
        try:
            while not failed.is_set():
                with lock:
                    a = next(todo, None)
                if a is None:
                    return
                fn(a, min(n, a + step))
        except BaseException:
            failed.set()
            raise
        finally:
            _IN_STRIP.active = False

    # the calling thread takes strips too: one task fewer to hand over, and no wait for a
    # thread to wake when the last strip is done
    futures = [pool.submit(worker) for _ in range(count - 1)]
    stop: BaseException | None = None
    try:
        worker()
    except BaseException as exc:
        stop = exc
    deadline = None if stop is None or isinstance(stop, Exception) else _stop_deadline()
    while True:  # no strip runs once the call returns, even on an interrupt while waiting
        try:  # (stopped: not past the deadline, a strip still running then may never end)
            wait(futures, None if deadline is None else max(0.0, deadline - time.monotonic()))
            break
        except BaseException as exc:  # (a stop: raised before a strip's error, once cut short)
            failed.set()
            if stop is None or (isinstance(stop, Exception) and not isinstance(exc, Exception)):
                stop = exc
            if deadline is None and not isinstance(exc, Exception):
                deadline = _stop_deadline()
    if stop is not None:
        raise stop
    for fut in futures:
        fut.result()


def _stop_deadline() -> float:
    return time.monotonic() + STOP_WAIT_S
