"""What ``depict enhance`` of several files says, and where, when its standard streams are closed,
gone or full, or when it is stopped while it reads the next input ahead (whose decode points the
process's descriptors 1 and 2 elsewhere: :mod:`gbuffer.capture`). Real ``depict`` processes,
real descriptors, real signals."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from gbuffer.atomic import partial_files

ROOT = Path(__file__).resolve().parents[1]
FRAME = ROOT / "tests" / "fixtures" / "blender" / "cycles_multilayer.exr"
ENV = dict(os.environ, PYOPENGL_PLATFORM="osmesa")
#: ``depict`` whose reads of every input but the first hold the terminal for 3 s first, as the
#: decode of a large frame does (the capture around a call, then the read).
SLOW_NEXT_READ = """
import time
import service.enhance as enhance
from gbuffer.capture import captured_output
read_for, seen = enhance.read_for, []
def reading(path, *args, **kwargs):
    if seen:
        with captured_output():
            time.sleep(3)
    seen.append(path)
    return read_for(path, *args, **kwargs)
enhance.read_for = reading
from service.cli import run; run()
"""

#: ``depict`` stopped by ``signal`` as the second input's read has started (it holds the
#: terminal for 3 s), before the caller has the read in hand to wait for: the stop comes inside
#: the read's constructor.
STOP_AS_NEXT_READ_STARTS = """
import os, signal, sys, threading, time
import service.cli.frames as frames
import service.enhance as enhance
from gbuffer.capture import captured_output
read_for, capturing = enhance.read_for, threading.Event()
stop = int(sys.argv.pop(1))
def reading(path, *args, **kwargs):
    if path.endswith("b.exr"):
        with captured_output():
            capturing.set()
            time.sleep(3)
    return read_for(path, *args, **kwargs)
enhance.read_for = reading
class Stopped(frames.ReadAhead):
    def __init__(self, path, *args, **kwargs):
        super().__init__(path, *args, **kwargs)
        if path.endswith("b.exr"):
            capturing.wait()
            os.kill(os.getpid(), stop)
            time.sleep(1)
frames.ReadAhead = Stopped
from service.cli import run; run()
"""


def _inputs(folder: Path, count: int = 3) -> list[Path]:
    names = [folder / f"{chr(ord('a') + i)}.exr" for i in range(count)]
    for name in names:
        name.write_bytes(FRAME.read_bytes())
    return names


def _depict(*args: str | Path) -> list[str]:
    return [sys.executable, "-m", "service.cli", *map(str, args)]


@pytest.mark.parametrize(
    ("signum", "layout"),
    [(signal.SIGINT, "part"), (signal.SIGTERM, "part"), (signal.SIGINT, "same")],
)
def test_a_stop_while_the_next_input_decodes_says_the_file_written(
    tmp_path: Path, signum: int, layout: str
) -> None:
    """Ctrl-C (or SIGTERM) once the first output is in place, while the second input decodes:
    the first file's ``wrote`` line was never said (it waited for that decode, which the stop
    cut short). Now it is said once the decode gives the terminal back, with how many files
    were enhanced. ``--layout same`` reads no input ahead (the second is read once the first is
    written), and its stop line went into that read's capture."""
    inputs, out = _inputs(tmp_path), tmp_path / "out"
    out.mkdir()
    argv = ["enhance", *map(str, inputs), "-o", str(out), "--layout", layout]
    proc = subprocess.Popen(
        [sys.executable, "-c", SLOW_NEXT_READ, *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=ENV,
        cwd=ROOT,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    deadline = time.monotonic() + 120
    while not (out / "a.exr").exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    proc.send_signal(signum)
    stdout, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signum, stderr
    assert stdout.splitlines() == [f"wrote {out / 'a.exr'}"]
    assert stderr.splitlines() == ["depict: stopped: 1 of 3 files enhanced"]
    assert sorted(p.name for p in out.iterdir()) == ["a.exr"]
    assert not partial_files(out)


@pytest.mark.parametrize(
    ("signum", "layout", "enhanced"),
    [(signal.SIGINT, "part", 0), (signal.SIGTERM, "part", 0), (signal.SIGINT, "same", 1)],
)
def test_a_stop_as_the_next_read_starts_is_said(
    tmp_path: Path, signum: int, layout: str, enhanced: int
) -> None:
    """A stop that comes as the next input's read starts, before ``depict enhance`` holds the
    read to wait for it: the stop line went into the temporary file the read's capture points
    the terminal at (1 run in 8 or so of the test above on a busy machine). Now it waits for
    the terminal. ``part`` starts the next read before the first output is written, ``same``
    after."""
    inputs, out = _inputs(tmp_path), tmp_path / "out"
    out.mkdir()
    argv = ["enhance", *map(str, inputs), "-o", str(out), "--layout", layout]
    run = subprocess.run(
        [sys.executable, "-c", STOP_AS_NEXT_READ_STARTS, str(int(signum)), *argv],
        capture_output=True,
        text=True,
        env=ENV,
        cwd=ROOT,
        timeout=120,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    assert run.returncode == 128 + signum, run.stderr
    written = [out / "a.exr"][:enhanced]
    assert run.stdout.splitlines() == [f"wrote {path}" for path in written]
    assert run.stderr.splitlines() == [f"depict: stopped: {enhanced} of 3 files enhanced"]
    assert sorted(out.iterdir()) == written
    assert not partial_files(out)


def _alone(tmp_path: Path, src: Path) -> bytes:
    """The output of ``depict enhance`` of ``src`` alone (it records the input's name)."""
    folder = tmp_path / "alone"
    folder.mkdir(exist_ok=True)
    subprocess.run(_depict("enhance", src, "-o", folder), check=True, env=ENV, cwd=ROOT)
    return (folder / src.name).read_bytes()


def test_closed_standard_descriptors_take_nothing_over(tmp_path: Path) -> None:
    """``depict enhance a b c -o out 2>&-``: the read's capture left the process's stdout in a
    temporary file (every ``wrote`` line lost), and an output opened on a free descriptor 2
    could be taken over by the next read's capture (the Depict renders of 1080p came out
    truncated). Now the closed descriptors are /dev/null from the start: the lines are said and
    the outputs are whole. With stdout closed (``>&-``), the end of the process raised a
    traceback (Python has no ``sys.stdout`` then)."""
    inputs, out = _inputs(tmp_path), tmp_path / "out"
    out.mkdir()
    run = subprocess.run(
        _depict("enhance", *inputs, "-o", out),
        stdout=subprocess.PIPE,
        text=True,
        env=ENV,
        cwd=ROOT,
        preexec_fn=lambda: os.close(2),
    )
    assert run.returncode == 0
    assert run.stdout.splitlines() == [f"wrote {out / p.name}" for p in inputs]
    want = {p.name: _alone(tmp_path, p) for p in inputs}
    assert all((out / name).read_bytes() == data for name, data in want.items())
    closed_out = tmp_path / "closed_out"
    closed_out.mkdir()
    run = subprocess.run(
        _depict("enhance", *inputs[:2], "-o", closed_out),
        stderr=subprocess.PIPE,
        text=True,
        env=ENV,
        cwd=ROOT,
        preexec_fn=lambda: os.close(1),
    )
    assert (run.returncode, run.stderr) == (0, "")
    assert all((closed_out / p.name).read_bytes() == want[p.name] for p in inputs[:2])


def _reader_gone(argv: list[str], stderr: int) -> tuple[int, str]:
    """Run ``argv`` with its stdout (and, with ``stderr`` STDOUT, its stderr) to a pipe whose
    reader is gone before the first line; the exit code and stderr (with ``stderr`` PIPE)."""
    proc = subprocess.Popen(
        argv, stdout=subprocess.PIPE, stderr=stderr, text=True, env=ENV, cwd=ROOT
    )
    assert proc.stdout is not None
    proc.stdout.close()
    _, err = proc.communicate(timeout=120)
    return proc.returncode, err or ""


def test_a_reader_gone_or_a_full_stdout_is_no_files_failure(tmp_path: Path) -> None:
    """``depict enhance *.exr -o out | head -1`` and ``> /dev/full``: the failed ``wrote`` line
    was taken for the file's failure (``depict: error: a.exr: Broken pipe`` for every file,
    exit 2 or 141, though every output was written). Now the lines stop and the files go on:
    exit 0, every output written; a full disk is said once."""
    inputs = _inputs(tmp_path)
    gone, full = tmp_path / "gone", tmp_path / "full"
    gone.mkdir()
    full.mkdir()
    assert _reader_gone(_depict("enhance", *inputs, "-o", gone), subprocess.PIPE) == (0, "")
    assert sorted(p.name for p in gone.iterdir()) == [p.name for p in inputs]
    with open("/dev/full", "w") as dev_full:
        run = subprocess.run(
            _depict("enhance", *inputs, "-o", full),
            stdout=dev_full,
            stderr=subprocess.PIPE,
            text=True,
            env=ENV,
            cwd=ROOT,
        )
    assert run.returncode == 0
    assert run.stderr.splitlines() == [
        "depict: warning: standard output: No space left on device; its lines are dropped"
    ]
    assert sorted(p.name for p in full.iterdir()) == [p.name for p in inputs]


def test_a_reader_gone_from_both_streams_stops_no_file(tmp_path: Path) -> None:
    """``depict enhance a b c -o out 2>&1 | head -1`` with b damaged: b's error line met the
    closed pipe and stopped the run (exit 141, c never enhanced). Now b fails alone."""
    inputs, out = _inputs(tmp_path), tmp_path / "out"
    out.mkdir()
    inputs[1].write_bytes(b"not an EXR" * 100)
    assert _reader_gone(_depict("enhance", *inputs, "-o", out), subprocess.STDOUT)[0] == 2
    assert sorted(p.name for p in out.iterdir()) == ["a.exr", "c.exr"]


def test_an_unknown_preset_is_refused_before_any_file_is_read(tmp_path: Path) -> None:
    """It was refused by each file's read: one line per file, then a tally."""
    inputs, out = _inputs(tmp_path, 2), tmp_path / "out"
    out.mkdir()
    run = subprocess.run(
        _depict("enhance", *inputs, "--preset", "nope", "-o", out),
        capture_output=True,
        text=True,
        env=ENV,
        cwd=ROOT,
    )
    assert run.returncode == 2
    assert run.stdout == ""
    assert len(run.stderr.splitlines()) == 1
    assert run.stderr.startswith("depict: error: preset='nope' is not known; valid: auto, ")
    assert not list(out.iterdir())


#: ``depict`` that gets Ctrl-C just as its first output is renamed into place.
STOP_AT_RENAME = """
import os, signal
rename, done = os.replace, []
def replacing(a, b):
    rename(a, b)
    if not done:
        done.append(b)
        os.kill(os.getpid(), signal.SIGINT)
os.replace = replacing
from service.cli import run; run()
"""


@pytest.mark.parametrize("count", [1, 2])
def test_a_stop_just_as_an_output_is_put_in_place_says_it(tmp_path: Path, count: int) -> None:
    """The output is there: it is said (and counted), and the command still ends as stopped
    (130); with one file it went on to exit 0."""
    inputs, out = _inputs(tmp_path, count), tmp_path / "out"
    out.mkdir()
    run = subprocess.run(
        [sys.executable, "-c", STOP_AT_RENAME, "enhance", *map(str, inputs), "-o", str(out)],
        capture_output=True,
        text=True,
        env=ENV,
        cwd=ROOT,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    assert run.returncode == 130, run.stderr
    assert run.stdout.splitlines() == [f"wrote {out / 'a.exr'}"]
    stopped = [f"depict: stopped: 1 of {count} files enhanced"] if count > 1 else []
    assert run.stderr.splitlines() == stopped
    assert sorted(p.name for p in out.iterdir()) == ["a.exr"]
