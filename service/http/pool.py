"""The service's job pool: CPU work in worker processes, a bounded queue, a time limit per job.

Requests never decode pixels on the event loop: a route saves the upload to a temporary file and
submits a job (:mod:`service.http.worker`) that receives *paths* and typed requests, reads, runs
and writes to another temporary path, and returns a small dict. :class:`JobPool` admits at most
``workers + queue`` jobs at a time (one more is refused: 429 with ``Retry-After``) and gives each a
deadline of ``timeout_s`` from its submission (queue wait included). The processes are those of
:class:`service.workers.WorkerPool`: warmed up before their first job, killed and replaced when a
job passes its deadline (504), replaced when they die (503 ``worker-lost`` for the job that was on
it); the next requests go to the fresh worker.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

from service.http.worker import give_back_memory, run_job, warm_worker
from service.metrics import Metrics
from service.problems import Problem
from service.workers import Outcome, WorkerPool


class JobPool:
    """Worker processes with admission control: ``workers`` running + ``queue`` waiting."""

    def __init__(
        self,
        workers: int,
        queue: int,
        timeout_s: float,
        metrics: Metrics | None = None,
        log_level: str = "info",
    ) -> None:
        self.workers = workers
        self.capacity = workers + queue
        self.timeout_s = timeout_s
        self.metrics = metrics
        self.active = 0  # admitted jobs not finished (waiting or running)
        self.recent_s = 1.0  # running mean of job times, for Retry-After
        self.pool = WorkerPool(
            workers, warm_worker, log_level, on_replace=self._replaced, on_idle=give_back_memory
        )

    def _replaced(self, cause: str) -> None:
        if self.metrics is not None:
            self.metrics.workers_replaced.labels(cause).inc()

    def start(self) -> None:
        """Start the workers; they take jobs once warmed up."""
        self.pool.start()

    def _gauges(self) -> None:
        if self.metrics is not None:
            self.metrics.running.set(min(self.active, self.workers))
            self.metrics.queued.set(max(0, self.active - self.workers))
            self.metrics.workers_ready.set(self.pool.ready_workers)

    def retry_after(self) -> int:
        """Seconds a refused client should wait: the queue ahead divided by the throughput."""
        waits = self.active / self.workers * self.recent_s
        return max(1, min(60, math.ceil(waits)))

    async def submit(
        self, kind: str, fn: Callable[..., dict[str, Any]], *args: Any
    ) -> dict[str, Any]:
        """Run ``fn(*args)`` on a worker; :class:`Problem` 429 / 503 / 504 / 4xx on failure."""
        if self.active >= self.capacity:
            if self.metrics is not None:
                self.metrics.jobs.labels(kind, "refused").inc()
            raise Problem(
                "busy",
                f"all {self.workers} workers are busy and the queue of "
                f"{self.capacity - self.workers} jobs is full; retry after the delay given",
                headers={"Retry-After": str(self.retry_after())},
            )
        deadline = time.time() + self.timeout_s
        self.active += 1
        self._gauges()
        try:
            outcome = await self.pool.run(run_job, (fn, *args), deadline)
        finally:
            self.active -= 1
            self._gauges()
        out = self._answer(outcome)
        if "job_s" in out:
            self.recent_s = 0.8 * self.recent_s + 0.2 * float(out["job_s"])
        self._count(kind, out)
        if not out["ok"]:
            raise Problem(out["kind"], out["detail"], headers=out.get("headers"))
        return out

    def _answer(self, outcome: Outcome) -> dict[str, Any]:
        """The job's dict, or the problem a timeout, a dead worker or no pool stands for."""
        if outcome.status == "result":
            return dict(outcome.result)
        if outcome.status == "timeout":
            detail = (
                f"the job did not finish within DEPICT_TIMEOUT_S={self.timeout_s:g} s "
                "(queue wait included); retry later, or send a smaller frame"
            )
            return {"ok": False, "kind": "timeout", "detail": detail}
        if outcome.status == "died":
            detail = (
                f"the worker process running this job {outcome.detail}; a fresh worker replaces "
                "it: retry, or send a smaller frame if it ran out of memory"
            )
            return {
                "ok": False,
                "kind": "worker-lost",
                "detail": detail,
                "headers": {"Retry-After": "1"},
            }
        return {"ok": False, "kind": "unavailable", "detail": outcome.detail}

    def _count(self, kind: str, out: dict[str, Any]) -> None:
        if self.metrics is None:
            return
        self.metrics.jobs.labels(kind, "ok" if out["ok"] else out["kind"]).inc()
        if "job_s" in out:
            self.metrics.job_time.labels(kind).observe(out["job_s"])
        for op, seconds in out.get("op_s", []):
            self.metrics.operator_time.labels(op).observe(seconds)

    def ready(self) -> dict[str, Any]:
        """``/readyz``: a warmed-up worker exists and could render with OSMesa."""
        info = self.pool.ready_info
        if self.pool.ready_workers == 0 or info is None:
            why = self.pool.last_failure or "the workers are starting"
            return {"osmesa": False, "detail": f"no worker is ready: {why}"}
        return info

    async def shutdown(self) -> None:
        await self.pool.shutdown()
