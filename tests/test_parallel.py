"""The row strips every operator runs on (ops.parallel.run_strips): each row once, the calling
thread working too, a failing strip stopping the rest, nested calls sequential."""

from __future__ import annotations

import contextlib
import signal
import threading
import time
from collections.abc import Iterator

import pytest

import ops.parallel
from ops.parallel import run_strips, workers

needs_two = pytest.mark.skipif(workers() < 2, reason="one worker: strips run sequentially")


@contextlib.contextmanager
def _ctrl_c_after(seconds: float) -> Iterator[None]:
    """KeyboardInterrupt raised in the calling (main) thread ``seconds`` from now, as Ctrl-C
    is, wherever it is then."""

    def interrupt(*_: object) -> None:
        raise KeyboardInterrupt

    old = signal.signal(signal.SIGALRM, interrupt)
    try:
        signal.setitimer(signal.ITIMER_REAL, seconds)
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


@needs_two
def test_every_row_once_and_the_calling_thread_takes_strips() -> None:
    taken: list[tuple[int, int, int]] = []

    def strip(a: int, b: int) -> None:
        time.sleep(0.002)  # (long enough for every worker to take some)
        taken.append((threading.get_ident(), a, b))

    run_strips(1001, strip, 10)
    rows = sorted(r for _, a, b in taken for r in range(a, b))
    assert rows == list(range(1001))
    threads = {t for t, _, _ in taken}
    assert threading.get_ident() in threads and len(threads) == workers()


@needs_two
def test_a_failing_strip_stops_the_others_and_none_runs_after_the_call() -> None:
    started: list[int] = []

    def strip(a: int, b: int) -> None:
        started.append(a)
        if a == 30:
            raise ValueError("strip 30")
        time.sleep(0.005)

    with pytest.raises(ValueError, match="strip 30"):
        run_strips(1000, strip, 10)
    count = len(started)
    time.sleep(0.05)
    assert len(started) == count < 20  # (of 100 strips)


def test_strips_of_a_strip_run_on_its_thread() -> None:
    inner: list[tuple[int, int]] = []

    def strip(a: int, b: int) -> None:
        me = threading.get_ident()
        run_strips(4, lambda c, d: inner.append((me, threading.get_ident())), 1)

    run_strips(64, strip, 8)
    assert len(inner) == 32 and all(outer == own for outer, own in inner)


@needs_two
def test_an_interrupt_while_the_call_waits_is_raised_once_no_strip_runs() -> None:
    """Ctrl-C while the calling thread, its own strips done, waits for a pool thread's strip:
    the interrupt is raised once that strip has finished, not while it runs on."""
    main = threading.get_ident()
    done: list[int] = []
    pool_started = threading.Event()

    def strip(a: int, b: int) -> None:
        if threading.get_ident() == main:  # (once a pool thread holds a strip)
            pool_started.wait(5.0)
        else:
            pool_started.set()
            time.sleep(0.5)
        done.append(a)

    with _ctrl_c_after(0.2), pytest.raises(KeyboardInterrupt):
        run_strips(40, strip, 1)
    count = len(done)
    time.sleep(0.6)
    assert len(done) == count == 40


@needs_two
def test_a_stop_does_not_wait_for_ever_for_a_strip_that_cannot_end(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Ctrl-C raised in the calling thread while it held a lock (as llvmlite's, when Numba loads
    a kernel): the lock is never released, and a pool thread's strip waiting for it never ends.
    The stop is raised after STOP_WAIT_S all the same, not after the strip."""
    monkeypatch.setattr(ops.parallel, "STOP_WAIT_S", 0.5)
    main = threading.get_ident()
    held = threading.Lock()  # (held by the calling thread, as the lock a stop leaves held)
    held.acquire()
    freed = threading.Timer(10.0, held.release)  # (the code before waited until then)

    pool_started = threading.Event()

    def strip(a: int, b: int) -> None:
        if threading.get_ident() == main:  # (once a pool thread holds a strip)
            pool_started.wait(5.0)
            return
        pool_started.set()
        with held:
            pass

    freed.start()
    try:
        t0 = time.monotonic()
        with _ctrl_c_after(0.2), pytest.raises(KeyboardInterrupt):
            run_strips(40, strip, 1)
        assert time.monotonic() - t0 < 3.0
    finally:
        freed.cancel()
        if held.locked():
            held.release()  # (the pool thread's strip ends)


@needs_two
def test_a_stop_after_a_strip_failed_is_the_stop_raised(monkeypatch: pytest.MonkeyPatch) -> None:
    """The calling thread's strip raised, then Ctrl-C came while a pool strip ran on: the wait
    is cut short, so the stop is what is raised (the strip's error let a caller that catches
    Exception carry on while that strip still wrote)."""
    monkeypatch.setattr(ops.parallel, "STOP_WAIT_S", 0.5)
    main = threading.get_ident()
    pool_started, release = threading.Event(), threading.Event()

    def strip(a: int, b: int) -> None:
        if threading.get_ident() == main:
            pool_started.wait(5.0)
            raise ValueError("strip failed")
        pool_started.set()
        release.wait(10.0)

    try:
        with _ctrl_c_after(0.3), pytest.raises(KeyboardInterrupt):
            run_strips(40, strip, 1)
    finally:
        release.set()
