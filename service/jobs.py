"""The service's job pool: CPU work in worker processes, a bounded queue, a time limit per job.

Requests never decode pixels on the event loop: a route saves the upload to a temporary file and
submits a job (:func:`enhance_job`, :func:`render_job`, ...) that receives *paths*, reads, runs
and writes to another temporary path, and returns a small dict. :class:`JobPool` admits at most
``workers + queue`` jobs at a time (one more is refused: 429 with ``Retry-After``) and gives each a
deadline of ``timeout_s`` from its submission (queue wait included). The processes are those of
:class:`service.workers.WorkerPool`: warmed up before their first job, killed and replaced when a
job passes its deadline (504), replaced when they die (503 ``worker-lost`` for the job that was on
it); the next requests go to the fresh worker.

Job functions return ``{"ok": True, ...}`` or ``{"ok": False, "kind": KIND, "detail": TEXT}``
(:mod:`service.problems` kinds), so no exception has to survive pickling.
"""

from __future__ import annotations

import contextlib
import ctypes
import gc
import json
import logging
import math
import os
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from service import allocator
from service.problems import Problem, from_exception
from service.workers import WorkerPool

log = logging.getLogger("depict.jobs")


# -- inside the worker processes ---------------------------------------------------------------


def warm_worker() -> dict[str, Any]:
    """A worker's start, before its first job: allocator settings (:mod:`service.allocator`),
    every module a job imports, the operator registry, and a tiny OSMesa render.

    Returns ``{"osmesa": bool, "detail": ...}`` for ``/readyz``.
    """
    os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")
    allocator.tune()
    import trimesh

    import analysis.compare  # noqa: F401
    import gbuffer.io
    import gbuffer.preview  # noqa: F401
    import service.pipeline  # noqa: F401
    from gbuffer.render import render
    from service.registry import operators

    operators()
    try:
        render(trimesh.creation.icosahedron(), 8, 8)
    except Exception as exc:
        return {"osmesa": False, "detail": f"cannot render with OSMesa: {exc}"}
    return {"osmesa": True}


def _trim_memory() -> None:
    """Give freed memory back to the system (glibc keeps large freed arenas otherwise)."""
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
        _trim_memory()
    out["job_s"] = time.perf_counter() - t0
    return out


def read_frame(path: str, read: dict[str, Any], limits: dict[str, int] | None = None) -> Any:
    """Read a frame exactly as the CLI does (same preset, camera, mapping).

    ``read``: ``preset``, ``camera`` (path of a camera JSON file), ``mapping`` (buffer ->
    channels), ``normal_space``. ``limits``: the keyword arguments of
    :class:`gbuffer.limits.Limits` (default: the ``DEPICT_MAX_*`` variables when set).
    """
    from gbuffer.io import ReadOptions
    from gbuffer.io import read as read_exr
    from gbuffer.limits import Limits

    options = ReadOptions(
        mapping=read.get("mapping") or {},
        normal_space=read.get("normal_space"),
    )
    return read_exr(
        path,
        preset=read.get("preset") or "auto",
        camera=read.get("camera"),
        options=options,
        limits=Limits(**limits) if limits else None,
    )


def run_steps(frame: Any, spec: Any, context: Any) -> tuple[Any, list[tuple[str, float]]]:
    """Run a pipeline one step at a time, timing each operator: (frame, [(op, seconds)])."""
    from service import pipeline

    op_s: list[tuple[str, float]] = []
    for step in spec.steps:
        t0 = time.perf_counter()
        frame = pipeline.run(frame, pipeline.PipelineSpec(steps=[step]), context=context)
        op_s.append((step.op, time.perf_counter() - t0))
    return frame, op_s


def enhance_file(
    in_path: str,
    out_path: str,
    spec_json: str,
    read: dict[str, Any],
    write: dict[str, Any],
    limits: dict[str, int] | None = None,
    pinned: dict[str, float] | None = None,
    files: bool = True,
) -> dict[str, Any]:
    """Read ``in_path``, run the pipeline, write the EXR (or a PNG preview) to ``out_path``.

    The same steps as ``depict enhance``, so the output is bit for bit the CLI's.
    ``write``: ``debug_layers``, ``output_layer``, ``preview`` (bool), ``exposure``,
    ``input_name`` (the input's name recorded in the output; default: ``in_path``'s).
    ``pinned``: statistics pinned for a sequence (:class:`service.registry.Context`).
    ``files``: whether parameters may name image files (False for the HTTP service).
    Returns ``op_s`` (seconds per operator), ``size``, the statistics ``measured`` and the
    writer's ``warnings`` (e.g. a compression it could not keep).
    """
    from gbuffer.io import write as write_exr
    from service import pipeline
    from service.registry import Context

    spec = pipeline.checked(spec_json)
    frame = read_frame(in_path, read, limits)
    context = Context(
        debug_layers=bool(write.get("debug_layers")), pinned=dict(pinned or {}), files=files
    )
    out, op_s = run_steps(frame, spec, context)
    out = pipeline.finish(out, write.get("output_layer"), write.get("input_name"))
    warnings: list[str] = []
    if write.get("preview"):
        from gbuffer.preview import picture, write_png

        write_png(picture(out, "beauty", exposure=float(write.get("exposure", 0.0))), out_path)
    else:
        warnings = write_exr(out, out_path)
    h, w = out.shape
    return {
        "op_s": op_s,
        "size": [w, h],
        "measured": dict(context.measured),
        "warnings": warnings,
    }


def enhance_job(
    in_path: str,
    out_path: str,
    spec_json: str,
    read: dict[str, Any],
    write: dict[str, Any],
    limits: dict[str, int],
) -> dict[str, Any]:
    """``POST /v1/enhance`` on a worker: :func:`enhance_file` under the pixel limit, with no
    file named by a parameter read."""
    return enhance_file(in_path, out_path, spec_json, read, write, limits, files=False)


def render_job(mesh_path: str, out_path: str, scene: dict[str, Any]) -> dict[str, Any]:
    """Render a mesh to a canonical G-buffer EXR, as ``depict render`` does."""
    from gbuffer.camera import Camera
    from gbuffer.io import write
    from gbuffer.render import auto_camera, load_mesh, render
    from ops.shading import parse_light

    mesh = load_mesh(mesh_path)
    try:
        lights = [parse_light(text) for text in scene.get("lights") or []] or None
    except ValueError as exc:
        raise Problem("invalid-request", f"scene.lights: {exc}") from None
    width, height = int(scene["width"]), int(scene["height"])
    if scene.get("camera") is not None:
        camera = Camera.from_dict(scene["camera"])
    else:
        camera = auto_camera(
            mesh,
            width=width,
            height=height,
            azimuth_deg=float(scene.get("azimuth", 30.0)),
            elevation_deg=float(scene.get("elevation", 20.0)),
        )
    frame = render(mesh, width, height, camera=camera, lights=lights)
    write(frame, out_path)
    return {"size": [width, height]}


def score_job(
    in_path: str,
    spec_json: str | None,
    read: dict[str, Any],
    options: dict[str, Any],
    limits: dict[str, int] | None = None,
    files: bool = False,
) -> dict[str, Any]:
    """``depict score``: the congruence score (LLA Eq. 2) of the frame's beauty
    (:func:`analysis.score.score_frame`), after the pipeline ``spec_json`` when given."""
    from analysis.score import score_frame
    from service import pipeline
    from service.registry import Context

    frame = read_frame(in_path, read, limits)
    op_s: list[tuple[str, float]] = []
    if spec_json:
        frame, op_s = run_steps(frame, pipeline.checked(spec_json), Context(files=files))
    out = score_frame(frame, maps=False, **options)
    return {
        "score": float(out["score"]),
        "shading_norm": float(out["shading_norm"]),
        "analysis_shape": [int(v) for v in out["analysis_shape"]],
        "image_shape": [int(v) for v in out["image_shape"]],
        "params": {k: v if isinstance(v, str) else float(v) for k, v in out["params"].items()},
        "op_s": op_s,
    }


def compare_job(
    in_path: str,
    read: dict[str, Any] | None,
    options: dict[str, Any],
    sheet: bool = False,
    limits: dict[str, int] | None = None,
) -> dict[str, Any]:
    """``depict compare``: the comparison bench (LLA §7) on an EXR frame (``read`` given) or a
    mesh (``read`` None: rendered at ``options["width"]`` × ``options["height"]``).

    ``options``: ``methods``, ``directions``, ``params``, ``albedo``, ``shading_norm``
    (:func:`analysis.compare.compare`), and for meshes ``width``, ``height``, ``azimuth``,
    ``elevation``. Returns :meth:`ComparisonResult.to_dict`, with ``sheet``, plus
    ``sheet_png``: the contact sheet as a base64 PNG.
    """
    import base64
    import tempfile

    from analysis.compare import compare, frame_from_mesh
    from analysis.methods import METHODS
    from analysis.pictures import SHEET_DIRECTIONS, contact_sheet

    opts = dict(options)
    if read is None:
        width, height = int(opts.pop("width", 512)), int(opts.pop("height", 512))
        max_pixels = (limits or {}).get("max_pixels")
        if max_pixels is not None and width * height > max_pixels:
            from gbuffer.errors import LimitError

            raise LimitError(
                f"{width}x{height} is over the limit of {max_pixels} pixels (DEPICT_MAX_PIXELS)"
            )
        frame = frame_from_mesh(
            in_path,
            width,
            height,
            azimuth_deg=float(opts.pop("azimuth", 30.0)),
            elevation_deg=float(opts.pop("elevation", 20.0)),
        )
    else:
        frame = read_frame(in_path, read, limits)
    result = compare(
        frame,
        methods=opts.get("methods") or METHODS,
        directions=opts.get("directions", 21),
        params=opts.get("params"),
        albedo=opts.get("albedo", "white"),
        keep_images=SHEET_DIRECTIONS if sheet else False,
        label=opts.get("label", ""),
        shading_norm=opts.get("shading_norm", "reference"),
    )
    out = result.to_dict()
    if sheet:
        with tempfile.TemporaryDirectory() as tmp:
            png = contact_sheet(result, Path(tmp) / "sheet.png").read_bytes()
        out["sheet_png"] = base64.b64encode(png).decode("ascii")
    return out


def pick_job(
    in_path: str,
    read: dict[str, Any],
    x: int,
    y: int,
    params: dict[str, Any],
    limits: dict[str, int] | None = None,
) -> dict[str, Any]:
    """``depict relief-pick``: the Apparent Relief descriptor S under pixel (x, y) with the
    ``apparent_relief`` parameters ``params``, its ARM texture coordinates and its region."""
    import numpy as np

    from ops import relief as rl
    from service import pipeline
    from service.registry import Context

    frame = read_frame(in_path, read, limits)
    step = {"op": "apparent_relief", "params": {**params, "style": "cel"}}
    context = Context(files=False)
    out = pipeline.run(frame, [step], context=context)
    s = np.dstack([out.outputs["relief.S.X"], out.outputs["relief.S.Y"]])
    picked = rl.pick(s, x, y)
    region = rl.REGIONS[int(rl.classify(s[y : y + 1, x : x + 1])[0, 0])]
    norm = context.measured.get("apparent_relief.curvedness_norm", params.get("curvedness_norm"))
    return {
        "x": x,
        "y": y,
        "s": [picked.s1, picked.s2],
        "uv": [picked.u, picked.v],
        "region": region,
        "r": float(out.outputs["relief.X"][y, x]),
        "curvedness_norm": float(norm) if norm is not None else None,
    }


# -- in the server -----------------------------------------------------------------------------


class JobPool:
    """Worker processes with admission control: ``workers`` running + ``queue`` waiting."""

    def __init__(
        self,
        workers: int,
        queue: int,
        timeout_s: float,
        metrics: Any = None,
        log_level: str = "info",
    ) -> None:
        self.workers = workers
        self.capacity = workers + queue
        self.timeout_s = timeout_s
        self.metrics = metrics
        self.active = 0  # admitted jobs not finished (waiting or running)
        self.recent_s = 1.0  # running mean of job times, for Retry-After
        self.pool = WorkerPool(workers, warm_worker, log_level, on_replace=self._replaced)

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

    def _answer(self, outcome: Any) -> dict[str, Any]:
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


def dump_json(value: Any, path: Path) -> str:
    """Write ``value`` as JSON to ``path`` (a camera for :func:`gbuffer.read`); its path."""
    path.write_text(json.dumps(value))
    return str(path)
