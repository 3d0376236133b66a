"""Ctrl-C held back for a while: SIGINT blocked in the main thread, and so in every thread
started meanwhile (a thread keeps the signal mask it starts with), then given back.

A signal every thread blocks is neither delivered nor dropped: it waits, and comes to the handler
once the block is lifted. The command line imports its command so (:func:`service.cli.command`):
the threads those imports start (OpenBLAS's) block SIGINT for good, so a Ctrl-C always comes to
the main thread. ``depict batch`` ignores SIGINT too while its local cluster starts its worker
processes, which keep that disposition (:func:`service.batch._sigint_ignored`): a Ctrl-C then
waits instead of being dropped by the ignoring, and stops the batch once the handler is back.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from typing import Any

__all__ = ["sigint_held"]

_SIGMASK = hasattr(signal, "pthread_sigmask")  # (POSIX)


@contextlib.contextmanager
def sigint_held(*, ignored: bool = False) -> Iterator[None]:
    """SIGINT blocked in the main thread meanwhile (see the module docstring), and with
    ``ignored`` also ignored (what processes started meanwhile inherit); the handler is put back
    before the block is lifted, so that a Ctrl-C held comes to it. Off the main thread: nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous: Any = signal.signal(signal.SIGINT, signal.SIG_IGN) if ignored else None
    before = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT}) if _SIGMASK else None
    try:
        yield
    finally:
        if ignored:
            signal.signal(signal.SIGINT, previous)
        if before is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, before)
