"""Inside the worker processes of the HTTP service (:class:`service.workers.WorkerPool`).

:func:`warm_worker` runs once, before a worker's first job: every module a job needs is imported
with this one (so a time limit never interrupts an import half-way), a tiny OSMesa render
proves the worker can render, and every operator runs once so that its kernels are loaded
(:func:`load_kernels`). :func:`give_back_memory` runs in the worker's pauses.
:func:`run_job` runs around each job: job functions return a small
dict, and errors come back as ``{"ok": False, "kind": KIND, "detail": TEXT}``
(:mod:`service.problems` kinds), so no exception has to survive pickling.

The jobs are :func:`enhance_job` and :func:`render_job` here, the analysis jobs of
:mod:`service.jobs` (the same functions the CLI runs) and the viewer's (:mod:`service.viewer.work`).
"""

from __future__ import annotations

import contextlib
import ctypes
import gc
import logging
import os
import time
from collections.abc import Callable
from typing import Any

# the jobs' modules, imported before the first job: the analysis jobs and the viewer's
import service.jobs
import service.viewer.work
from service import allocator
from service.enhance import ReadRequest, WriteRequest, enhance
from service.pipeline import Pipeline
from service.problems import Problem, from_exception
from service.scene import RenderRequest, render_to_file

log = logging.getLogger("depict.jobs")


def enhance_job(
    in_path: str,
    out_path: str,
    steps: Pipeline,
    read: ReadRequest,
    write: WriteRequest,
) -> dict[str, Any]:
    """``POST /v1/enhance`` on a worker: :func:`service.enhance.enhance` with no file named by
    a parameter read."""
    return dict(enhance(in_path, out_path, steps, read, write, files=False))


def render_job(mesh_path: str, out_path: str, scene: RenderRequest) -> dict[str, Any]:
    """``POST /v1/render`` on a worker: :func:`service.scene.render_to_file`."""
    return render_to_file(mesh_path, out_path, scene)


def warm_worker() -> dict[str, Any]:
    """A worker's start, before its first job: allocator settings (:mod:`service.allocator`),
    a tiny OSMesa render (the modules a job needs are imported with this one) and, when it
    renders, the operators' kernels loaded (:func:`load_kernels`).

    Returns ``{"osmesa": bool, "detail": ...}`` for ``/readyz``.
    """
    os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")
    allocator.tune()
    # The renderer (OpenGL) is imported here, in the workers, not in the server's process.
    import trimesh

    from gbuffer.render import render

    try:
        render(trimesh.creation.icosahedron(), 8, 8)
    except Exception as exc:
        return {"osmesa": False, "detail": f"cannot render with OSMesa: {exc}"}
    else:
        load_kernels()
    finally:
        # What exists now (modules, compiled kernels) lives as long as the worker: kept out of
        # the full collection of each pause (:func:`give_back_memory`), which would walk it
        # every time (about 200 ms, as long as a preview's operators).
        gc.freeze()
    return {"osmesa": True}


def load_kernels() -> None:
    """Every operator once on a small render (:func:`service.warmup.warm`, about 1 s where the
    kernels are compiled on disk), so that no job waits for Numba to load its kernels: a fresh
    worker's first preview took 0.55-0.79 s where the next took 0.06 s. Where that fails the
    jobs load what they need themselves; the worker still starts."""
    from service.warmup import warm

    try:
        warm()
    except Exception as exc:
        log.warning("kernels not loaded ahead: %s", exc, extra={"pid": os.getpid()})


#: Jobs at least this long (seconds) are followed by a full garbage collection, which takes
#: 8-10 ms: a preview's job takes 40-100 ms, an enhance of a 1080p frame seconds.
FULL_COLLECTION_AFTER_S = 0.5


def give_back_memory() -> None:
    """A worker's pause (:data:`service.workers.IDLE_S` without a job): its freed memory back
    to the system (glibc keeps it in the heap for reuse otherwise). Not after every job: the
    next job would fault every page in again, as one preview of the viewer does while a slider
    moves (a 960x540 preview of a 1080p render took 177 ms with it after each job, 105 ms
    without). What the viewer kept of frames deleted since goes first, then every cycle of
    garbage (after a short job only the young ones are: a full collection walks the 50 000
    objects the first jobs leave for good, 8-10 ms a preview)."""
    service.viewer.work.forget_deleted()
    gc.collect()
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL("libc.so.6").malloc_trim(0)


def run_job(fn: Callable[..., dict[str, Any]], *args: Any) -> dict[str, Any]:
    """Run ``fn(*args)`` in a worker; errors become problem kinds (tracebacks go to the log)."""
    t0 = time.perf_counter()
    try:
        out = fn(*args)
        out["ok"] = True
    except Exception as exc:  # every error leaves the worker as data, never as a crash
        problem = from_exception(exc)
        if problem.kind == "internal" and type(exc) is ValueError:
            # the project's convention: a plain ValueError names a bad parameter or input
            problem = Problem("invalid-request", str(exc))
        if problem.kind == "internal":
            log.error("job failed", exc_info=exc)
        out = {"ok": False, "kind": problem.kind, "detail": problem.detail}
    finally:
        # the job's cycles of garbage freed now: every one after a long job (a service never
        # idle still collects them), the young ones after a short one (the rest in the pause)
        gc.collect(2 if time.perf_counter() - t0 >= FULL_COLLECTION_AFTER_S else 1)
    out["job_s"] = time.perf_counter() - t0
    return out
