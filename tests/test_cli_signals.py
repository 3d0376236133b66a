"""The command line stopped by a real signal while it writes: SIGTERM and SIGHUP end it as
Ctrl-C does (exit 128 + the signal), the file it was writing is removed and the output it was to
replace is left as it was; a batch stopped so leaves no partial frame behind. Real ``depict``
processes, real signals, real files."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest
import trimesh

from gbuffer.atomic import partial_files
from gbuffer.io import write as write_exr
from gbuffer.render import render

SPOT = Path(__file__).resolve().parents[1] / "examples" / "spot.obj"
#: The same, with each file's rename into place 2 s late: the temporary file a signal must
#: remove is there long enough to be seen (the encoded bytes take milliseconds to copy).
SLOW_RENAME = """
import os, time
rename = os.replace
os.replace = lambda a, b: (time.sleep(2), rename(a, b))[1]
from service.cli import run; run()
"""
KEEP = b"the output before this run\n"


@pytest.fixture(scope="module")
def frame(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 1080p render of spot: writing it takes long enough to be caught in the act."""
    path = tmp_path_factory.mktemp("frame") / "spot.exr"
    write_exr(render(trimesh.load(SPOT, force="mesh"), 1920, 1080), path)
    return path


def _stop_while_writing(
    argv: list[str], folder: Path, signum: int, group: bool, ignore: int | None = None
) -> subprocess.CompletedProcess[str]:
    """Run ``depict argv`` (its renames slowed, :data:`SLOW_RENAME`); as soon as a temporary
    output (or, for a batch, whose workers' renames are not slowed, any output) appears in
    ``folder``, send ``signum`` (to the whole process group with ``group``, as a terminal or a
    farm does; ``ignore``: a signal the command starts with ignored, as ``nohup`` starts it);
    the exit code and what it printed on stderr."""
    env = dict(os.environ, PYOPENGL_PLATFORM="osmesa")
    proc = subprocess.Popen(
        [sys.executable, "-c", SLOW_RENAME, *argv],
        env=env,
        start_new_session=True,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=None if ignore is None else lambda: signal.signal(ignore, signal.SIG_IGN),
    )
    deadline = time.monotonic() + 300
    try:
        pattern = "*.exr" if argv[0] == "batch" else ".*.tmp.exr"
        while not (folder.is_dir() and any(folder.glob(pattern))):
            assert proc.poll() is None, f"ended before writing: {proc.stderr.read()}"  # type: ignore[union-attr]
            assert time.monotonic() < deadline, "no temporary file appeared"
            time.sleep(0.001)
        if group:
            os.killpg(proc.pid, signum)
        else:
            proc.send_signal(signum)
        _, err = proc.communicate(timeout=120)
        return subprocess.CompletedProcess(argv, proc.returncode, "", err)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP])
def test_a_signal_during_the_write_leaves_the_output_as_it_was(
    frame: Path, tmp_path: Path, signum: int
) -> None:
    out = tmp_path / "out.exr"
    out.write_bytes(KEEP)
    argv = ["enhance", str(frame), "-o", str(out), "--layout", "same"]
    assert _stop_while_writing(argv, tmp_path, signum, group=False).returncode == 128 + signum
    assert partial_files([out]) == []
    assert out.read_bytes() == KEEP


def test_a_hangup_the_command_started_ignoring_is_ignored(frame: Path, tmp_path: Path) -> None:
    """As under ``nohup``: the command finishes and writes its output."""
    out = tmp_path / "out.exr"
    out.write_bytes(KEEP)
    argv = ["enhance", str(frame), "-o", str(out)]
    hup = signal.SIGHUP
    assert _stop_while_writing(argv, tmp_path, hup, group=False, ignore=hup).returncode == 0
    assert partial_files([out]) == [] and out.read_bytes() != KEEP


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_a_batch_stopped_by_a_signal_leaves_no_partial_frame(
    frame: Path, tmp_path: Path, signum: int
) -> None:
    """To the whole process group, as a farm's SIGTERM or a terminal's Ctrl-C: no partial
    frame, and nothing on stderr (the Dask workers printed KeyboardInterrupt tracebacks, and
    multiprocessing's resource tracker a warning of leaked semaphores, two lines, where the
    process ended without running multiprocessing's exit handlers)."""
    shots = tmp_path / "shots"
    shots.mkdir()
    for i in range(1, 5):  # (stopped after the first output appears: three still to do)
        (shots / f"shot.{i:04d}.exr").symlink_to(frame)
    outs = tmp_path / "out"
    argv = ["batch", str(shots / "shot.####.exr"), "-o", str(outs / "o.####.exr")]
    argv += ["--workers", "1", "--no-progress"]
    done = _stop_while_writing(argv, outs, signum, group=True)
    assert done.returncode == 128 + signum, done.stderr
    assert [p.name for p in outs.iterdir() if ".tmp" in p.name] == []
    assert done.stderr == ""  # (no traceback, no "leaked semaphore objects" warning)


def test_a_batch_worker_killed_while_it_writes_leaves_no_partial_frame(
    frame: Path, tmp_path: Path
) -> None:
    """SIGKILL to the batch's worker process the moment a frame's temporary file appears: the
    worker is replaced and the frame written again, the batch ends with exit 0 and every
    output, and the killed worker's half-written file is not left beside them."""
    shots = tmp_path / "shots"
    shots.mkdir()
    for i in range(1, 4):
        (shots / f"shot.{i:04d}.exr").symlink_to(frame)
    outs = tmp_path / "out"
    argv = ["batch", str(shots / "shot.####.exr"), "-o", str(outs / "o.####.exr")]
    env = dict(os.environ, PYOPENGL_PLATFORM="osmesa")
    proc = subprocess.Popen(
        [sys.executable, "-m", "service.cli", *argv, "--workers", "1", "--no-progress"],
        env=env,
        start_new_session=True,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 300
        while not (outs.is_dir() and any(outs.glob(".*.tmp.exr"))):
            assert proc.poll() is None, f"ended before writing: {proc.stderr.read()}"  # type: ignore[union-attr]
            assert time.monotonic() < deadline, "no temporary file appeared"
            time.sleep(0.001)
        killed = [
            child.kill()
            for child in psutil.Process(proc.pid).children(recursive=True)
            if "spawn_main" in " ".join(child.cmdline())
        ]
        assert killed, "no worker process found"
        _, err = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 0, err
    assert sorted(p.name for p in outs.iterdir()) == [f"o.{i:04d}.exr" for i in range(1, 4)]


def test_partial_files_are_exactly_the_temporary_outputs(tmp_path: Path) -> None:
    names = [
        ".o.0001.0a1b2c3d.tmp.exr",  # o.0001.exr's
        ".o.5e6f7a8b.tmp.exr",  # o.exr's
        ".o.mybackup.tmp.exr",  # a user's
        ".o.0001.exr",
        "o.0001.exr",
        ".o.0002.0a1b2c3d.tmp.exr",  # another output's
    ]
    for name in names:
        (tmp_path / name).write_bytes(b"")
    found = partial_files([tmp_path / "o.0001.exr", tmp_path / "o.exr", tmp_path / "gone/x.exr"])
    assert [p.name for p in found] == [".o.0001.0a1b2c3d.tmp.exr", ".o.5e6f7a8b.tmp.exr"]
    # an output through a link is written beside its target; one path alone is one path
    (tmp_path / "link.exr").symlink_to(tmp_path / "o.exr")
    assert [p.name for p in partial_files(tmp_path / "link.exr")] == [".o.5e6f7a8b.tmp.exr"]


def _ignores_sigint(pid: int) -> bool:
    """Whether process ``pid`` has SIGINT ignored now (``SigIgn`` in /proc/PID/status)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("SigIgn:"):
            return bool(int(line.split()[1], 16) >> (signal.SIGINT - 1) & 1)
    return False


def test_a_ctrl_c_while_the_batch_starts_its_workers_stops_it(frame: Path, tmp_path: Path) -> None:
    """SIGINT is ignored while the local cluster starts its worker processes (they keep that, so
    that Ctrl-C reaches them through this process); a Ctrl-C in that second was lost and the
    batch ran to its end with exit 0. Sent the moment the batch ignores SIGINT, it now stops it
    before any frame, with 130 and nothing on stderr."""
    shots, outs = tmp_path / "shots", tmp_path / "out"
    shots.mkdir()
    for i in range(1, 4):
        (shots / f"shot.{i:04d}.exr").symlink_to(frame)
    argv = ["batch", str(shots / "shot.####.exr"), "-o", str(outs / "o.####.exr")]
    proc = subprocess.Popen(
        [sys.executable, "-c", "from service.cli import run; run()", *argv, "--no-progress"],
        env=dict(os.environ, PYOPENGL_PLATFORM="osmesa"),
        start_new_session=True,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 300
    try:
        while not _ignores_sigint(proc.pid):
            assert proc.poll() is None, f"ended first: {proc.stderr.read()}"  # type: ignore[union-attr]
            assert time.monotonic() < deadline, "SIGINT was never ignored"
            time.sleep(0.0005)
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, err
    assert err == ""
    assert not outs.exists() or list(outs.iterdir()) == []


#: A process that ends as the ``depict`` executable does while it holds a semaphore of
#: multiprocessing's (as Dask's nannies hold their workers' queues while a stopped batch ends).
HOLDS_A_SEMAPHORE = """
import multiprocessing
from service.logs import end_process
lock = multiprocessing.get_context("spawn").Lock()
end_process(0)
"""


def test_a_process_ended_without_teardown_leaves_no_semaphore_behind() -> None:
    """The ``depict`` executable ends without the interpreter's teardown; it skipped
    multiprocessing's exit handlers too, and the resource tracker printed "There appear to be 6
    leaked semaphore objects to clean up at shutdown" (two lines) after some stopped batches."""
    done = subprocess.run(
        [sys.executable, "-c", HOLDS_A_SEMAPHORE], capture_output=True, text=True, timeout=120
    )
    assert (done.returncode, done.stderr) == (0, "")
