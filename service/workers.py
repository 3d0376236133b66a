"""Worker processes that heal: each one warmed before it takes a job, killed and replaced when
its job overruns, replaced when it dies.

Each worker is a spawned process with its own pipe (no lock shared between workers, so a worker
killed at any instant cannot leave another one stuck). Its life:

1. **start**: it configures its JSON logs, imports everything a job needs, renders a tiny mesh
   and loads the operators' kernels (:func:`service.http.worker.warm_worker`), then says
   ``ready``. Only then is it handed a job, so a time limit never interrupts an import or an
   initialisation half-way.
2. **jobs**: it receives ``(function, args, request id)``, runs it and sends the result back.
   Once no job has come for :data:`IDLE_S` seconds it runs the pool's ``on_idle`` function
   (the HTTP workers give their freed memory back to the system then, not after every job:
   jobs that come one after the other, such as the viewer's previews while a slider moves,
   reuse it without faulting it in again).
3. **end**: at the job's deadline the server kills it (``SIGKILL``) rather than interrupting the
   job inside the process; when it dies on its own (a signal, the out-of-memory killer) the job
   on it is answered with what happened; after an unexpected error it is retired, in case it was
   left in a bad state. In every case a fresh worker is started in its place.

A worker that dies before it is ready counts as a failed start; the next start waits a little
longer each time (:data:`BACKOFF_S`). After :data:`UNHEALTHY_AFTER` failed starts in a row the
pool reports itself unhealthy (``/healthz`` answers 503, so an orchestrator restarts the
service), and it keeps trying; one successful start makes it healthy again.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import multiprocessing
import os
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess
from typing import Any

import anyio

from service.logs import REQUEST_ID, configure_logging, end_process

log = logging.getLogger("depict.workers")

#: Seconds a worker may take to import and warm up before it counts as a failed start.
START_TIMEOUT_S = 180.0
#: Failed starts in a row after which the pool reports itself unhealthy.
UNHEALTHY_AFTER = 3
#: Delay before a start, by the number of failed starts before it (the last value repeats).
BACKOFF_S = (0.0, 0.5, 1.0, 2.0, 5.0, 10.0)
#: How often idle workers are checked for a death that no job noticed.
WATCH_S = 0.5
#: Seconds without a job after which a worker runs the pool's ``on_idle`` function.
IDLE_S = 1.0


def describe_exit(code: int | None) -> str:
    """``"killed by signal 9 (SIGKILL ...)"``, ``"exited with status 1"``, ... of an exit code."""
    if code is None:
        return "stopped answering"
    if code < 0:
        try:
            name = signal.Signals(-code).name
        except ValueError:
            name = f"signal {-code}"
        hint = "; the out-of-memory killer sends it" if -code == signal.SIGKILL else ""
        return f"was killed by signal {-code} ({name}{hint})"
    return f"exited with status {code}"


# -- inside a worker ---------------------------------------------------------------------------


def worker_process(
    conn: Connection,
    log_level: str,
    warm: Callable[[], dict[str, Any]],
    on_idle: Callable[[], None] | None = None,
) -> None:
    """A worker process: :func:`worker_main`, then the process ends without the interpreter's
    teardown (nothing is left to write; the teardown would print the OpenImageIO binding's
    "nanobind: leaked ..." lines, some 40 of them per worker, on every server stop)."""
    try:
        worker_main(conn, log_level, warm, on_idle)
        code = 0
    except BaseException:  # a fault of the loop itself: logged; the server replaces the worker
        log.exception("worker failed", extra={"pid": os.getpid()})
        code = 1
    end_process(code)


def worker_main(
    conn: Connection,
    log_level: str,
    warm: Callable[[], dict[str, Any]],
    on_idle: Callable[[], None] | None = None,
) -> None:
    """The worker's loop: warm up, say ready, then run jobs until the pipe closes; ``on_idle``
    each time no job has come for :data:`IDLE_S` seconds (once per pause)."""
    configure_logging(log_level)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # ^C is for the server, which stops the pool
    try:
        info = warm()
    except Exception as exc:  # a worker that cannot warm up says why, then exits
        log.error("worker start failed", exc_info=exc, extra={"pid": os.getpid()})
        conn.send(("failed", f"{type(exc).__name__}: {exc}"))
        return
    conn.send(("ready", info))
    while True:
        try:
            paused = on_idle is not None and not conn.poll(IDLE_S)
        except (EOFError, OSError):  # the server went away
            return
        if paused and on_idle is not None:  # (its own failure is the worker's, not the pipe's)
            on_idle()
        try:
            message = conn.recv()
        except (EOFError, OSError):
            return
        if message is None:
            return
        fn, args, request_id = message
        token = REQUEST_ID.set(request_id)
        try:
            out = fn(*args)
        finally:
            REQUEST_ID.reset(token)
        conn.send(out)


# -- in the server -----------------------------------------------------------------------------


@dataclass(eq=False)
class Worker:
    """A worker process and the server's end of its pipe."""

    process: BaseProcess
    conn: Connection
    state: str = "starting"  # starting, idle, busy, gone

    @property
    def pid(self) -> int:
        return self.process.pid or 0


@dataclass
class Outcome:
    """How a job on a worker ended: ``result`` (its dict), ``timeout`` or ``died``."""

    status: str
    result: dict[str, Any] = field(default_factory=dict)
    detail: str = ""


def _receive_ready(worker: Worker, timeout: float) -> tuple[str, Any]:
    """Wait (in a thread) for a starting worker's first message."""
    try:
        if worker.conn.poll(timeout):
            kind, value = worker.conn.recv()
            return str(kind), value
        return "failed", f"not ready after {timeout:g} s"
    except (EOFError, OSError):
        worker.process.join(1.0)
        return "failed", f"the worker {describe_exit(worker.process.exitcode)} while starting"


def _exchange(worker: Worker, payload: Any, deadline: float) -> Outcome:
    """Send a job and wait (in a thread) for its result, the deadline or the worker's death."""
    try:
        worker.conn.send(payload)
        while True:
            remaining = deadline - time.time()
            if remaining <= 0:
                return Outcome("timeout")
            if worker.conn.poll(min(remaining, 1.0)):
                return Outcome("result", worker.conn.recv())
    except (EOFError, OSError):  # the pipe closed: the process is gone
        worker.process.join(1.0)
        return Outcome("died", detail=describe_exit(worker.process.exitcode))


class WorkerPool:
    """``size`` worker processes, kept at that number; see the module docstring."""

    def __init__(
        self,
        size: int,
        warm: Callable[[], dict[str, Any]],
        log_level: str = "info",
        start_timeout: float = START_TIMEOUT_S,
        on_replace: Callable[[str], None] | None = None,
        on_idle: Callable[[], None] | None = None,
    ) -> None:
        self.size = size
        self.on_replace = on_replace
        self.on_idle = on_idle  # (run in the workers: a module-level function)
        self.warm = warm
        self.log_level = log_level
        self.start_timeout = start_timeout
        self.context = multiprocessing.get_context("spawn")
        self.workers: set[Worker] = set()
        self.failed_starts = 0  # in a row
        self.last_failure = ""
        self.ready_info: dict[str, Any] | None = None
        self.closed = False
        self._idle: asyncio.Queue[Worker] | None = None
        self._tasks: set[asyncio.Task[Any]] = set()
        self._threads = anyio.CapacityLimiter(2 * size + 2)

    # -- state ---------------------------------------------------------------------------------

    @property
    def ready_workers(self) -> int:
        """Workers that finished warming up and are alive (idle or on a job)."""
        return sum(1 for w in self.workers if w.state in ("idle", "busy"))

    def health(self) -> tuple[bool, str]:
        """(healthy, why not): unhealthy when closed or after repeated failed starts."""
        if self.closed:
            return False, "the worker pool is stopped"
        if self.failed_starts >= UNHEALTHY_AFTER:
            return False, (
                f"worker processes fail to start ({self.failed_starts} in a row; last: "
                f"{self.last_failure})"
            )
        return True, ""

    # -- life cycle ----------------------------------------------------------------------------

    def start(self) -> None:
        """Start the workers (they warm up in the background) and the watcher of idle ones."""
        self._idle = asyncio.Queue()
        for _ in range(self.size):
            self._spawn()
        self._keep(asyncio.create_task(self._watch(), name="watch"))

    def _keep(self, task: asyncio.Task[Any]) -> None:
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    def _spawn(self) -> None:
        if not self.closed:
            self._keep(asyncio.create_task(self._start_one(), name="start"))

    async def _start_one(self) -> None:
        delay = BACKOFF_S[min(self.failed_starts, len(BACKOFF_S) - 1)]
        if delay:
            await asyncio.sleep(delay)
        if self.closed:
            return
        here, there = self.context.Pipe(duplex=True)
        process = self.context.Process(
            target=worker_process,
            args=(there, self.log_level, self.warm, self.on_idle),
            name="depict-worker",
            daemon=True,
        )
        try:
            process.start()
        except OSError as exc:
            self._failed_start(f"cannot start a process: {exc}")
            self._spawn()
            return
        finally:
            there.close()
        worker = Worker(process, here)
        self.workers.add(worker)
        kind, value = await anyio.to_thread.run_sync(
            _receive_ready, worker, self.start_timeout, limiter=self._threads
        )
        if self.closed:
            self._stop(worker)
            return
        if kind != "ready":
            self._stop(worker)
            self._failed_start(str(value))
            self._spawn()
            return
        self.failed_starts = 0
        self.ready_info = dict(value)
        log.info("worker ready", extra={"pid": worker.pid})
        self._release(worker)

    def _release(self, worker: Worker) -> None:
        assert self._idle is not None
        worker.state = "idle"
        self._idle.put_nowait(worker)

    def _failed_start(self, reason: str) -> None:
        self.failed_starts += 1
        self.last_failure = reason
        log.error("worker start failed", extra={"reason": reason})

    def _stop(self, worker: Worker) -> None:
        """Kill ``worker`` (if alive) and forget it; its zombie is reaped."""
        worker.state = "gone"
        self.workers.discard(worker)
        with contextlib.suppress(OSError, ValueError):
            worker.process.kill()
            worker.process.join(5.0)
        worker.conn.close()

    def _replace(self, worker: Worker, cause: str, reason: str) -> None:
        """Stop ``worker`` and start another; ``cause``: timeout, died, idle-died or error."""
        if self.on_replace is not None:
            self.on_replace(cause)
        log.warning("worker replaced", extra={"pid": worker.pid, "reason": reason})
        self._stop(worker)
        self._spawn()

    async def _watch(self) -> None:
        """Replace idle workers that died with no job to notice it."""
        while not self.closed:
            await asyncio.sleep(WATCH_S)
            for worker in list(self.workers):
                if worker.state == "idle" and worker.process.exitcode is not None:
                    self._replace(
                        worker, "idle-died", f"idle worker {describe_exit(worker.process.exitcode)}"
                    )

    async def shutdown(self) -> None:
        """Stop every worker: idle ones are asked to leave, the others killed."""
        self.closed = True
        for task in list(self._tasks):
            task.cancel()
        await anyio.to_thread.run_sync(self._stop_all)

    def _stop_all(self) -> None:
        for worker in list(self.workers):
            if worker.state == "idle":
                with contextlib.suppress(OSError, ValueError):
                    worker.conn.send(None)
        deadline = time.monotonic() + 5.0
        for worker in list(self.workers):
            if worker.state == "idle":
                worker.process.join(max(0.0, deadline - time.monotonic()))
            self._stop(worker)

    # -- jobs ----------------------------------------------------------------------------------

    async def _take(self, deadline: float) -> Worker | None:
        """An idle, live worker, or None when the deadline passes first."""
        assert self._idle is not None
        while True:
            remaining = deadline - time.time()
            if remaining <= 0:
                return None
            try:
                worker = await asyncio.wait_for(self._idle.get(), remaining)
            except TimeoutError:
                return None
            if worker.state == "gone":
                continue
            if worker.process.exitcode is not None:
                why = f"idle worker {describe_exit(worker.process.exitcode)}"
                self._replace(worker, "idle-died", why)
                continue
            return worker

    async def run(self, fn: Callable[..., Any], args: tuple[Any, ...], deadline: float) -> Outcome:
        """Run ``fn(*args)`` on a worker before ``deadline`` (``time.time()``)."""
        if self._idle is None or self.closed:
            return Outcome("unavailable", detail="the worker pool is not running")
        worker = await self._take(deadline)
        if worker is None:
            return Outcome("timeout", detail="no worker was free before the deadline")
        worker.state = "busy"
        outcome = await anyio.to_thread.run_sync(
            _exchange, worker, (fn, args, REQUEST_ID.get()), deadline, limiter=self._threads
        )
        if outcome.status == "timeout":
            self._replace(worker, "timeout", "killed: its job passed the time limit")
        elif outcome.status == "died":
            self._replace(worker, "died", f"died during a job: it {outcome.detail}")
        elif outcome.result.get("kind") == "internal":
            self._replace(worker, "error", "retired after an unexpected error")
        elif not self.closed:
            self._release(worker)
        return outcome
