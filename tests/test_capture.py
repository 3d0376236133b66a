"""What C and C++ libraries print, captured around a call (:mod:`gbuffer.capture`), with real
descriptors and real threads."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from pathlib import Path

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


CLOSED_STDERR = """
import os, threading
from gbuffer.capture import captured_output
os.close(2)
stdout = os.fstat(1)
opened = []
def open_meanwhile():  # (a file another thread opens while the capture runs: an output)
    opened.append(os.open(os.devnull, os.O_WRONLY))
with captured_output() as lines:
    thread = threading.Thread(target=open_meanwhile)
    thread.start()
    thread.join()
    os.write(1, b"said meanwhile\\n")
after = os.fstat(1)
same = (after.st_dev, after.st_ino) == (stdout.st_dev, stdout.st_ino)
kept = os.fstat(opened[0]).st_ino == os.stat(os.devnull).st_ino
print("stdout kept" if same else "stdout moved", "file kept" if kept else "file moved")
"""


def test_a_closed_descriptor_is_not_captured(tmp_path: Path) -> None:
    """With descriptor 2 closed (``depict ... 2>&-``), a capture left the process's stdout in its
    temporary file (its saved copy of descriptor 1 took number 2, which it then pointed at that
    file), and a file another thread opened meanwhile could be given that number and be taken
    over. Now a closed descriptor leaves the capture off: stdout is the process's throughout
    (the line said during it reaches it) and the other file is untouched."""
    run = subprocess.run(
        [sys.executable, "-c", CLOSED_STDERR], capture_output=True, text=True, cwd=tmp_path
    )
    assert run.returncode == 0, run.stderr
    assert run.stdout.splitlines() == ["said meanwhile", "stdout kept file kept"]
