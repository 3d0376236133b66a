"""What C and C++ libraries print on the terminal, captured instead of shown.

The OpenEXR library reports a damaged file by printing to the process's file descriptors 1 and 2
directly (``std::cout``, ``std::cerr``, below Python's ``sys.stdout``) and through Python's
``sys.stdout`` (its binding's warnings). :func:`captured_output` points both descriptors at a
temporary file, and both Python streams at a buffer, around a call and gives back the lines
written, so the caller can put them in its one-line error (or its warnings) instead of the
terminal.

The descriptors and streams are the process's, so one capture runs at a time: a second one (a
program reading frames on several threads) waits for the first to end. Two at once would each
restore what the other had put in place, and the one ending last would leave the process's
output in the other's temporary file. For the same reason nothing the process says while a
capture runs reaches the terminal: ``depict enhance`` holds its lines back while a read it
started ahead decodes.
"""

from __future__ import annotations

import contextlib
import ctypes
import fcntl
import io
import os
import sys
import tempfile
import threading
from collections.abc import Iterator

#: Most bytes of captured output kept.
MAX_CAPTURED = 64 << 10

_ONE_AT_A_TIME = threading.Lock()  # (see the module docstring)

try:
    _LIBC: ctypes.CDLL | None = ctypes.CDLL(None)
except OSError:  # no C library to flush: only Python's streams are flushed
    _LIBC = None


def _flush() -> None:
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    if _LIBC is not None:
        _LIBC.fflush(None)  # C stdio buffers (std::cout writes through them)


@contextlib.contextmanager
def captured_output() -> Iterator[list[str]]:
    """Run the block with descriptors 1 and 2 sent to a temporary file; the non-empty lines
    written there are in the yielded list once the block ends (at most :data:`MAX_CAPTURED`
    bytes). Where the descriptors are closed or cannot be duplicated the block runs
    uncaptured. One capture at a time in the process: another thread's waits for this one to
    end."""
    with _ONE_AT_A_TIME:
        with _captured() as lines:
            yield lines


@contextlib.contextmanager
def terminal() -> Iterator[None]:
    """Run the block once no capture points descriptors 1 and 2 elsewhere (another thread's
    decode), and let none start until it ends: what the block says reaches the terminal. Not
    from inside a capture on the same thread (the two would wait on each other). A stop
    (Ctrl-C) cuts the wait short, as any wait on a lock."""
    with _ONE_AT_A_TIME:
        yield


def _saved_descriptors() -> tuple[int, int] | None:
    """Copies of descriptors 1 and 2 numbered 3 or above, or None where either is closed (or
    cannot be copied). A closed one is never captured: the number is free for any file the
    process opens meanwhile (the output another thread is writing), which pointing it at the
    temporary file and back would take over."""
    try:  # (a closed descriptor cannot be copied: EBADF)
        first = fcntl.fcntl(1, fcntl.F_DUPFD_CLOEXEC, 3)
    except OSError:
        return None
    try:
        return first, fcntl.fcntl(2, fcntl.F_DUPFD_CLOEXEC, 3)
    except OSError:
        os.close(first)
        return None


@contextlib.contextmanager
def _captured() -> Iterator[list[str]]:
    """:func:`captured_output`, without its lock."""
    lines: list[str] = []
    _flush()
    saved = _saved_descriptors()
    if saved is None:
        yield lines
        return
    python = io.StringIO()
    with tempfile.TemporaryFile() as sink:
        try:
            os.dup2(sink.fileno(), 1)
            os.dup2(sink.fileno(), 2)
            with contextlib.redirect_stdout(python), contextlib.redirect_stderr(python):
                yield lines
        finally:
            _flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])
            sink.seek(0)
            text = sink.read(MAX_CAPTURED).decode("utf-8", "replace")
            text += "\n" + python.getvalue()[:MAX_CAPTURED]
            lines.extend(line.strip() for line in text.splitlines() if line.strip())
