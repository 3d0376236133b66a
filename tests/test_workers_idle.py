"""A worker process runs its pool's ``on_idle`` function in its pauses, never between jobs that
wait for it (:func:`service.workers.worker_main`): the HTTP workers give their memory back then
(:func:`service.http.worker.give_back_memory`), so that jobs coming one after the other, as the
viewer's previews while a slider moves, reuse it instead of faulting it in again."""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import psutil
import pytest

from service import workers
from service.http.worker import give_back_memory

LOG = "DEPICT_TEST_IDLE_LOG"


def warm() -> dict[str, Any]:
    return {}


def on_idle() -> None:
    with open(os.environ[LOG], "a") as f:
        f.write("idle\n")


def hold(mib: int) -> dict[str, Any]:
    """A job that touches ``mib`` MiB in blocks a heap keeps (below the mmap threshold) and
    frees them."""
    from service import allocator

    allocator.tune()
    blocks = [bytearray(8 << 20) for _ in range(mib // 8)]
    for block in blocks:
        block[::4096] = b"x" * len(block[::4096])
    del blocks
    return {"pid": os.getpid()}


def pauses(path: Path) -> int:
    return len(path.read_text().splitlines()) if path.exists() else 0


def wait_for(what: str, check: Any, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while not check():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.05)


@contextlib.contextmanager
def started(
    idle: Callable[[], None], start: Callable[[], dict[str, Any]] = warm
) -> Iterator[tuple[Any, int]]:
    """A real worker process (spawned as the pool spawns them) with ``idle`` as its pool's
    ``on_idle`` and ``start`` as its warm-up, once ready: its end of the pipe and its pid."""
    context = multiprocessing.get_context("spawn")
    here, there = context.Pipe(duplex=True)
    process = context.Process(
        target=workers.worker_process, args=(there, "warning", start, idle), daemon=True
    )
    process.start()
    there.close()
    try:
        assert here.recv()[0] == "ready"
        assert process.pid is not None
        yield here, process.pid
    finally:
        here.send(None)
        process.join(30)
        if process.is_alive():
            process.kill()


@pytest.fixture
def worker(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[tuple[Any, Path]]:
    """A worker whose pauses are written to a file, and that file."""
    log = tmp_path / "idle.log"
    monkeypatch.setenv(LOG, str(log))
    with started(on_idle) as (conn, _):
        yield conn, log


def test_on_idle_runs_once_a_pause_and_never_between_waiting_jobs(worker: tuple[Any, Path]) -> None:
    conn, log = worker
    wait_for("the pause after the start", lambda: pauses(log) == 1)
    for _ in range(3):  # three jobs waiting for the worker at once: no pause between them
        conn.send((hold, (64,), "request"))
    results = [conn.recv() for _ in range(3)]
    assert all(r["pid"] == results[0]["pid"] for r in results)
    assert pauses(log) == 1
    wait_for("the pause after the jobs", lambda: pauses(log) == 2)
    time.sleep(3 * workers.IDLE_S)
    assert pauses(log) == 2  # once a pause, not every IDLE_S


def test_the_memory_of_a_job_is_given_back_in_the_next_pause() -> None:
    """The HTTP workers' ``on_idle``: the heap a job left (kept for the next job) goes back to
    the system in the pause."""
    with started(give_back_memory) as (conn, pid):
        child = psutil.Process(pid)
        time.sleep(2 * workers.IDLE_S)  # (its first pause: what the start left, given back)
        before = child.memory_info().rss
        conn.send((hold, (256,), "request"))
        conn.recv()
        peak = int(Path(f"/proc/{pid}/status").read_text().split("VmHWM:")[1].split()[0])
        assert peak * 1024 > before + (200 << 20)  # the job did hold its 256 MiB
        wait_for(
            "the job's memory given back",
            lambda: child.memory_info().rss < before + (32 << 20),
        )


class _Marked:
    """Part of a cycle of garbage; says on disk when the collector frees it."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.me = self

    def __del__(self) -> None:
        Path(self.path).write_text("freed")


def cyclic_garbage(path: str, seconds: float) -> dict[str, Any]:
    """A job that leaves a cycle of garbage among the old objects (as a long job's first
    objects become), then runs ``seconds``."""
    import gc

    marked = _Marked(path)
    gc.collect(1)  # (it survives two generations: the oldest one now)
    del marked
    time.sleep(seconds)
    return {}


def test_a_long_job_is_followed_by_a_full_collection(tmp_path: Path) -> None:
    """After a job of seconds, even its oldest cycles of garbage are freed before its answer:
    a service that never pauses does not keep them."""
    from service.http.worker import FULL_COLLECTION_AFTER_S, run_job

    marker = tmp_path / "freed"
    with started(give_back_memory) as (conn, _):
        conn.send((run_job, (cyclic_garbage, str(marker), FULL_COLLECTION_AFTER_S + 0.1), "r"))
        assert conn.recv()["ok"]
        assert marker.read_text() == "freed"


def kernels_loaded_by(fn: Callable[..., dict[str, Any]], *args: Any) -> dict[str, Any]:
    """A job: ``fn(*args)``, and the Numba kernels that had no compiled version before it."""
    import sys

    from numba.core.registry import CPUDispatcher

    def loaded() -> set[str]:  # (the kernels are module attributes: frozen, gc does not list them)
        return {
            f"{d.py_func.__module__}.{d.py_func.__qualname__}"
            for module in list(sys.modules.values())
            for d in list(vars(module).values())
            if isinstance(d, CPUDispatcher) and d.overloads
        }

    before = loaded()
    out = fn(*args)
    return {"new": sorted(loaded() - before), "out": out}


def test_a_fresh_http_worker_loads_no_kernel_for_its_first_preview(tmp_path: Path) -> None:
    """The HTTP workers' warm-up runs every operator once: the first preview of a frame on a
    fresh worker (Radiance Scaling, the congruence score, a picture) loads no kernel that the
    warm-up did not."""
    from service import pipeline
    from service.enhance import ReadRequest
    from service.http.worker import warm_worker
    from service.viewer.work import preview_job
    from tests import exr_factory

    folder = tmp_path / "frame"
    folder.mkdir()
    exr_factory.write_canonical(folder / "in.exr", exr_factory.make_scene(h=240, w=320))
    steps = pipeline.compile([{"op": "radiance_scaling"}])
    args = (str(folder), 1, steps, ReadRequest(), 0.0, True)
    with started(give_back_memory, warm_worker) as (conn, _):
        conn.send((kernels_loaded_by, (preview_job, *args), "request"))
        answer = conn.recv()
    assert answer["out"]["score"] is not None  # (the preview ran, scored)
    assert answer["new"] == []
