"""What C and C++ libraries print, captured around a call (:mod:`gbuffer.capture`), with real
descriptors and real threads."""

from __future__ import annotations

import os
import threading

from gbuffer.capture import captured_output


def _descriptor(fd: int) -> tuple[int, int]:
    st = os.fstat(fd)
    return st.st_dev, st.st_ino


def _two_captures(got: dict[str, list[str]]) -> None:
    """A first capture, and a second asked for while the first runs; the first ends first, as
    soon as the second has begun or a second has passed."""
    first_in, second_in, first_done = threading.Event(), threading.Event(), threading.Event()

    def first() -> None:
        with captured_output() as lines:
            first_in.set()
            second_in.wait(1.0)
            os.write(2, b"first\n")
        first_done.set()
        got["first"] = lines

    def second() -> None:
        first_in.wait(5.0)
        with captured_output() as lines:
            second_in.set()
            first_done.wait(5.0)
            os.write(2, b"second\n")
        got["second"] = lines

    threads = [threading.Thread(target=first), threading.Thread(target=second)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(10.0)


def test_captures_on_two_threads_take_turns_and_give_the_terminal_back() -> None:
    """A capture that starts while another runs waits for it: else the first to end would give
    the process's descriptors 1 and 2 back, the second would write to the terminal, and on
    ending leave them in the first's temporary file. Each capture gets its own lines."""
    before = (_descriptor(1), _descriptor(2))
    saved = (os.dup(1), os.dup(2))
    got: dict[str, list[str]] = {}
    try:
        _two_captures(got)
        after = (_descriptor(1), _descriptor(2))
    finally:  # (the test process's own output back, whatever happened)
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        os.close(saved[0])
        os.close(saved[1])
    assert got == {"first": ["first"], "second": ["second"]}
    assert after == before
