"""The HTTP service (FastAPI on uvicorn): ``create_app(settings)`` and ``serve(settings)``.

Routes (the contract is ``openapi/openapi.json``, regenerated with ``python -m service.openapi``):

==========================  =====================================================================
``POST /v1/enhance``        multipart ``file`` (EXR) + optional ``pipeline`` (JSON), ``preset``,
                            ``camera`` (JSON), ``map`` (JSON), ``normal_space``, ``debug_layers``,
                            ``output_layer`` -> ``image/x-exr``; ``?preview=png`` -> ``image/png``
``POST /v1/render``         multipart ``mesh`` (OBJ/PLY/STL/GLB/GLTF) + ``scene`` (JSON: width,
                            height, camera, azimuth, elevation, lights) -> canonical EXR
``POST /v1/score``          multipart ``file`` (EXR) + options -> JSON congruence score
``POST /v1/compare``        multipart ``file`` (EXR or mesh) + ``options`` -> JSON comparison
``POST /v1/relief/pick``    multipart ``file`` + ``x``, ``y`` -> the Apparent Relief descriptor
``GET /v1/operators``       every operator with its parameter JSON schema
``GET /healthz``            alive (never needs the key, answers while the workers are saturated)
``GET /readyz``             ready: the worker pool is up and an OSMesa context could be created
``GET /metrics``            Prometheus text format (key required unless DEPICT_METRICS_PUBLIC)
==========================  =====================================================================

Errors are ``application/problem+json`` (:mod:`service.problems`). Every answer carries
``X-Request-ID`` (the client's, when it sent a valid one) and one JSON log line is written per
request. Pixel work runs in :class:`service.jobs.JobPool` worker processes, never on the event loop.
The analysis routes live in :mod:`service.api_analysis`.
"""

from __future__ import annotations

import contextlib
import hmac
import json
import logging
import re
import shutil
import tempfile
import time
import uuid
from collections.abc import AsyncIterator, Callable, Iterator
from pathlib import Path
from typing import Annotated, Any, Literal

import anyio
from fastapi import FastAPI, File, Form, Query, Request, UploadFile
from fastapi.exceptions import RequestValidationError
from fastapi.openapi.utils import get_openapi
from fastapi_offline import FastAPIOffline
from pydantic import BaseModel, ConfigDict, Field, ValidationError
from pydantic.json_schema import models_json_schema
from starlette.background import BackgroundTask
from starlette.exceptions import HTTPException
from starlette.responses import FileResponse, Response
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from gbuffer.errors import FrameError
from gbuffer.presets import preset_help
from service import jobs
from service.logs import REQUEST_ID, configure_logging
from service.metrics import Metrics
from service.output import LAYER_PATTERN
from service.problems import (
    PROBLEM_SCHEMA,
    Problem,
    from_exception,
    kind_for_status,
    openapi_responses,
)
from service.registry import PipelineError
from service.settings import Settings
from service.version import version

API_VERSION = "1"
EXR_MAGIC = b"\x76\x2f\x31\x01"
EXR_MEDIA_TYPE = "image/x-exr"
MESH_SUFFIXES = (".obj", ".ply", ".stl", ".glb", ".gltf", ".off")
#: Routes that take an upload: multipart/form-data only.
UPLOAD_PATHS = ("/v1/enhance", "/v1/render", "/v1/score", "/v1/compare", "/v1/relief/pick")
#: Routes open without the API key.
PUBLIC_PATHS = (
    "/healthz",
    "/readyz",
    "/openapi.json",
    "/docs",
    "/docs/oauth2-redirect",
    "/redoc",
)
#: Where the Swagger UI and ReDoc assets are served from (fastapi-offline's copies: no CDN).
DOCS_ASSETS = "/docs-assets"

_REQUEST_ID_RE = re.compile(r"^[A-Za-z0-9._:/+=-]{1,128}$")
#: The command-line flags that messages shared with the CLI name, as the form fields that do
#: the same over HTTP.
HTTP_WORDS = (
    ("--camera CAM.json", "a camera field (JSON)"),
    ("--normal-space", "the normal_space field"),
    ("--preset", "the preset field"),
    ("--map ", "map field "),
    ("--map", "the map field"),
)

log = logging.getLogger("depict.http")


# -- request models ----------------------------------------------------------------------------


class Scene(BaseModel):
    """What to render: the ``scene`` form field of ``POST /v1/render`` (JSON)."""

    model_config = ConfigDict(extra="forbid")
    width: int = Field(960, ge=1, le=16384, description="image width, pixels")
    height: int = Field(720, ge=1, le=16384, description="image height, pixels")
    camera: dict[str, Any] | None = Field(
        None, description="camera JSON (world_to_camera, fov_y_deg, ...); default: auto framing"
    )
    azimuth: float = Field(30.0, ge=-360, le=360, description="auto framing azimuth, degrees")
    elevation: float = Field(20.0, ge=-90, le=90, description="auto framing elevation, degrees")
    lights: list[str] = Field(
        default_factory=list,
        max_length=16,
        description="lights as in `depict render --light`: '-1,1,1', 'point:0,2,1@1,1,1*4'",
    )


class OperatorInfo(BaseModel):
    name: str
    summary: str
    needs: list[str]
    writes: list[str]
    params: dict[str, Any] = Field(description="JSON schema of the parameters")


class Health(BaseModel):
    status: str
    version: str = Field(description="Depict's version")


class Ready(BaseModel):
    status: str
    osmesa: bool
    workers: int
    queue: int


def _json_field(name: str, text: str | None, expected: type | tuple[type, ...]) -> Any:
    """A form field holding JSON (size and nesting bounded), or a 422 problem naming it."""
    from service.pipeline import loads

    if text is None or text == "":
        return None
    try:
        value = loads(text, f"form field {name!r}")
    except PipelineError as exc:
        raise Problem("invalid-request", str(exc)) from None
    if not isinstance(value, expected):
        raise Problem("invalid-request", f"form field {name!r} must be a JSON {_kind(expected)}")
    return value


def _check_preset(preset: str) -> None:
    """422 for a preset name the reader does not know."""
    from gbuffer.presets import PRESETS

    if preset != "auto" and preset not in PRESETS:
        raise Problem(
            "invalid-request",
            f"preset {preset!r} is unknown; valid presets: auto, {', '.join(PRESETS)}",
        )


def _check_camera(name: str, value: dict[str, Any] | None) -> None:
    """422 naming ``name`` when ``value`` is not a valid camera JSON object."""
    if value is None:
        return
    from gbuffer.camera import Camera

    try:
        Camera.from_dict(value)
    except Exception as exc:  # any malformed value is the client's mistake
        raise Problem("invalid-request", f"{name}: {exc}") from None


def _kind(expected: type | tuple[type, ...]) -> str:
    types = expected if isinstance(expected, tuple) else (expected,)
    names: dict[type, str] = {dict: "object", list: "array", str: "string"}
    return " or ".join(names.get(t, t.__name__) for t in types)


# -- the gate: request id, auth, content type, body limit, metrics, access log ----------------


class Gate:
    """Pure ASGI middleware in front of the app; refuses before any body byte is parsed."""

    def __init__(self, app: ASGIApp, settings: Settings, metrics: Metrics) -> None:
        self.app = app
        self.settings = settings
        self.metrics = metrics

    def _refuse(self, scope: Scope, headers: dict[str, str]) -> Problem | None:
        path = scope["path"]
        key = self.settings.key
        public = (
            path in PUBLIC_PATHS
            or path.startswith(f"{DOCS_ASSETS}/")
            or (path == "/metrics" and self.settings.metrics_public)
        )
        if key and not public:
            auth = headers.get("authorization", "")
            scheme, _, token = auth.partition(" ")
            if scheme.lower() != "bearer" or not token.strip():
                return Problem(
                    "unauthorized",
                    "this server needs an API key: send 'Authorization: Bearer <DEPICT_API_KEY>'",
                    headers={"WWW-Authenticate": 'Bearer realm="depict"'},
                )
            if not hmac.compare_digest(token.strip().encode(), key.encode()):
                return Problem(
                    "unauthorized",
                    "the API key is wrong (Authorization: Bearer <key>)",
                    headers={"WWW-Authenticate": 'Bearer realm="depict", error="invalid_token"'},
                )
        if scope["method"] == "POST" and path in UPLOAD_PATHS:
            ctype = headers.get("content-type", "")
            if not ctype.lower().startswith("multipart/form-data"):
                return Problem(
                    "unsupported-media-type",
                    f"{path} takes multipart/form-data (curl -F file=@frame.exr), "
                    f"not {ctype or 'a body without Content-Type'}",
                )
        length = headers.get("content-length")
        if length is not None and length.isdigit() and int(length) > self.settings.max_upload_bytes:
            return Problem("limit", self._too_large(int(length)))
        return None

    def _too_large(self, size: int | None) -> str:
        got = f"{size / 2**20:.1f} MiB" if size is not None else "the body"
        return (
            f"request body of {got} is over DEPICT_MAX_UPLOAD_MB="
            f"{self.settings.max_upload_mb:g} MiB; send a smaller file"
        )

    def _too_slow(self) -> str:
        return (
            f"the request was not received within DEPICT_UPLOAD_TIMEOUT_S="
            f"{self.settings.upload_timeout_s:g} s; the connection is closed"
        )

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope["headers"]}
        rid = headers.get("x-request-id", "")
        if not _REQUEST_ID_RE.match(rid):
            rid = uuid.uuid4().hex
        token = REQUEST_ID.set(rid)
        scope.setdefault("state", {})["request_id"] = rid
        start = time.perf_counter()
        status = 500
        counts = {"in": 0, "out": 0}
        limit = self.settings.max_upload_bytes

        status_sent = False

        async def send_wrapper(message: Message) -> None:
            nonlocal status, status_sent
            if message["type"] == "http.response.start":
                status = message["status"]
                status_sent = True
                message.setdefault("headers", [])
                message["headers"] = [
                    *message["headers"],
                    (b"x-request-id", rid.encode()),
                ]
            elif message["type"] == "http.response.body":
                counts["out"] += len(message.get("body", b""))
            await send(message)

        body_deadline = start + self.settings.upload_timeout_s
        body_done = False

        async def receive_wrapper() -> Message:
            nonlocal body_done
            if body_done:
                return await receive()
            with anyio.move_on_after(body_deadline - time.perf_counter()) as waited:
                message = await receive()
            if waited.cancelled_caught:  # a stalled or trickling upload: answer, then close
                raise HTTPException(408, self._too_slow(), headers={"Connection": "close"})
            if message["type"] == "http.request":
                counts["in"] += len(message.get("body", b""))
                if counts["in"] > limit:
                    raise HTTPException(413, self._too_large(None))
                body_done = not message.get("more_body", False)
            return message

        self.metrics.in_flight.inc()
        try:
            problem = self._refuse(scope, headers)
            if problem is not None:
                if problem.kind == "limit":  # drain a little so the client reads the answer
                    with anyio.move_on_after(2.0):
                        drained = 0
                        while drained < 32 * 2**20:
                            message = await receive()
                            drained += len(message.get("body", b""))
                            if not message.get("more_body"):
                                break
                response = problem.response(scope["path"], rid)
                await response(scope, receive, send_wrapper)
            else:
                try:
                    await self.app(scope, receive_wrapper, send_wrapper)
                except Exception as exc:  # a bug: 500 problem with the request id, logged
                    log.error("unhandled error on %s", scope["path"], exc_info=exc)
                    if status_sent:
                        raise
                    response = Problem(
                        "internal",
                        "internal error; the server log has the details (see request_id)",
                    ).response(scope["path"], rid)
                    await response(scope, receive, send_wrapper)
        finally:
            self.metrics.in_flight.dec()
            label = _route_label(scope)
            elapsed = time.perf_counter() - start
            self.metrics.requests.labels(label, scope["method"], str(status)).inc()
            self.metrics.latency.labels(label, scope["method"]).observe(elapsed)
            self.metrics.bytes_in.labels(label).inc(counts["in"])
            self.metrics.bytes_out.labels(label).inc(counts["out"])
            client = scope.get("client")
            log.info(
                "request",
                extra={
                    "method": scope["method"],
                    "path": scope["path"],
                    "route": label,
                    "status": status,
                    "duration_ms": round(elapsed * 1e3, 2),
                    "bytes_in": counts["in"],
                    "bytes_out": counts["out"],
                    "client": f"{client[0]}:{client[1]}" if client else None,
                },
            )
            REQUEST_ID.reset(token)


def _route_label(scope: Scope) -> str:
    """The route template of a request (``other`` for unknown paths): a bounded label set."""
    route = scope.get("route")
    if getattr(route, "path", None):
        return str(route.path)  # type: ignore[union-attr]
    app = scope.get("app")
    for candidate in getattr(app, "routes", ()):
        if getattr(candidate, "path", None) == scope["path"]:
            return str(scope["path"])
    return "other"


# -- the app -----------------------------------------------------------------------------------


def _workdir(root: Path) -> Path:
    return Path(tempfile.mkdtemp(prefix="job-", dir=root))


def _cleanup(path: Path) -> None:
    shutil.rmtree(path, ignore_errors=True)


async def _save_upload(upload: UploadFile, target: Path) -> int:
    """Copy an upload to ``target`` (off the event loop); its size in bytes."""

    def copy() -> int:
        upload.file.seek(0)
        with open(target, "wb") as out:
            shutil.copyfileobj(upload.file, out, 1 << 20)
            return out.tell()

    return await anyio.to_thread.run_sync(copy)


async def _check_exr(path: Path, limits: dict[str, int]) -> None:
    """400 when the file is not an EXR or is truncated, 413 when its header is over the limits
    (pixels, decoded bytes, channels): header and offset tables only, no pixel decoded, no
    worker used."""

    def check() -> None:
        from gbuffer.exr import read_layout
        from gbuffer.limits import Limits

        with open(path, "rb") as f:
            magic = f.read(4)
        if magic != EXR_MAGIC:
            what = "an empty file" if not magic else f"a file starting with {magic.hex(' ')}"
            raise Problem("bad-file", f"{path} is not an OpenEXR file ({what}); send an .exr")
        Limits(**limits).check(read_layout(path), str(path))

    await anyio.to_thread.run_sync(check)


async def checked_pipeline(text: str | None) -> str | None:
    """The ``pipeline`` form field validated off the event loop (a large one takes a while, and
    other requests must not wait for it): its JSON, or None when absent (422 when invalid)."""
    if not text:
        return None
    from service import pipeline

    def check() -> str:
        return pipeline.checked(text).model_dump_json()

    return await anyio.to_thread.run_sync(check)


async def _read_fields(
    preset: str,
    camera: str | None,
    map: str | None = None,
    normal_space: str | None = None,
) -> dict[str, Any]:
    """The form fields saying how to read the frame, checked off the event loop (422 naming
    the bad one)."""
    return await anyio.to_thread.run_sync(_check_read_fields, preset, camera, map, normal_space)


def _check_read_fields(
    preset: str, camera: str | None, map: str | None, normal_space: str | None
) -> dict[str, Any]:
    _check_preset(preset)
    camera_value = _json_field("camera", camera, dict)
    _check_camera("camera", camera_value)
    mapping = _json_field("map", map, dict) or {}
    if not all(isinstance(v, str) for v in mapping.values()):
        raise Problem("invalid-request", "form field 'map' must map buffer names to strings")
    return {
        "preset": preset,
        "camera": camera_value,
        "mapping": mapping,
        "normal_space": normal_space,
    }


def mesh_suffix(upload: UploadFile) -> str:
    """The mesh format of an upload from its file name, or a 415 listing the known ones."""
    suffix = Path(upload.filename or "").suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise Problem(
            "unsupported-media-type",
            f"mesh file name {upload.filename!r} has no known mesh suffix; "
            f"send one of {', '.join(MESH_SUFFIXES)}",
        )
    return suffix


async def _receive_frame(
    upload: UploadFile, src: Path, fields: dict[str, Any], limits: dict[str, int]
) -> dict[str, Any]:
    """Save and check the uploaded EXR (header only); the job's read options."""
    await _save_upload(upload, src)
    await _check_exr(src, limits)
    camera = fields["camera"]
    path = None if camera is None else jobs.dump_json(camera, src.parent / "camera.json")
    return {**fields, "camera": path}


@contextlib.contextmanager
def _scrubbed(work: Path, names: dict[Path, str]) -> Iterator[None]:
    """Errors name the client's file names, never the server's temporary paths."""
    try:
        yield
    except Exception as exc:
        problem = from_exception(exc)
        if problem.kind == "internal":
            raise
        detail = problem.detail
        for path, name in names.items():
            detail = detail.replace(str(path), name)
        detail = detail.replace(f"{work}/", "").replace(str(work), "")
        for flag, field in HTTP_WORDS:
            detail = detail.replace(flag, field)
        raise Problem(
            problem.kind, detail, headers=problem.headers, status=problem.status, **problem.extra
        ) from None


def _problem_handler(request: Request, exc: Exception) -> Response:
    problem = from_exception(exc)
    if problem.kind == "internal":
        log.error("unhandled error on %s", request.url.path, exc_info=exc)
    return problem.response(request.url.path, REQUEST_ID.get())


def _http_handler(request: Request, exc: Exception) -> Response:
    assert isinstance(exc, HTTPException)
    detail = exc.detail if isinstance(exc.detail, str) else json.dumps(exc.detail)
    if exc.status_code == 404:
        detail = f"no route {request.method} {request.url.path}; see /openapi.json"
    elif exc.status_code == 405:
        detail = f"{request.url.path} does not accept {request.method}; see /openapi.json"
    elif exc.status_code == 400 and "exceeded maximum size" in detail:  # the multipart parser
        detail = "a form field is over 1 MiB (the limit of a field that is not a file)"
        return Problem("limit", detail).response(request.url.path, REQUEST_ID.get())
    problem = Problem(
        kind_for_status(exc.status_code),
        detail,
        status=exc.status_code,
        headers=dict(exc.headers or {}),
    )
    return problem.response(request.url.path, REQUEST_ID.get())


def _validation_handler(request: Request, exc: Exception) -> Response:
    assert isinstance(exc, RequestValidationError)
    parts = []
    for err in exc.errors():
        loc = ".".join(str(p) for p in err.get("loc", ()) if p not in ("body", "query"))
        parts.append(f"{loc or 'request'}: {err.get('msg', 'invalid')}")
    problem = Problem("invalid-request", "; ".join(parts) or "invalid request")
    return problem.response(request.url.path, REQUEST_ID.get())


def create_app(settings: Settings | None = None) -> FastAPI:
    """The FastAPI app. Its worker pool starts and stops with the app's lifespan."""
    settings = settings or Settings()
    metrics = Metrics()
    state: dict[str, Any] = {}

    @contextlib.asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        root = Path(tempfile.mkdtemp(prefix="depict-"))
        pool = jobs.JobPool(
            settings.workers, settings.queue, settings.timeout_s, metrics, settings.log_level
        )
        state.update(pool=pool, root=root)
        pool.start()  # the workers warm up in the background; /readyz says when one is ready
        try:
            yield
        finally:
            await pool.shutdown()
            shutil.rmtree(root, ignore_errors=True)

    app = FastAPIOffline(  # /docs (Swagger UI) and /redoc with packaged assets, no CDN
        static_url=DOCS_ASSETS,
        title="Depict",
        version=API_VERSION,
        summary="Shape depiction on EXR G-buffers: enhance, render, score.",
        description=(
            "Errors are application/problem+json (RFC 9457). When the server has "
            "DEPICT_API_KEY set, every route but /healthz and /readyz needs "
            "`Authorization: Bearer <key>` (/metrics too, unless DEPICT_METRICS_PUBLIC=true)."
        ),
        lifespan=lifespan,
    )
    app.state.settings = settings
    app.state.metrics = metrics
    app.add_exception_handler(Problem, _problem_handler)
    app.add_exception_handler(FrameError, _problem_handler)
    app.add_exception_handler(PipelineError, _problem_handler)
    app.add_exception_handler(HTTPException, _http_handler)
    app.add_exception_handler(RequestValidationError, _validation_handler)
    app.add_exception_handler(Exception, _problem_handler)
    app.add_middleware(Gate, settings=settings, metrics=metrics)

    def pool() -> jobs.JobPool:
        if "pool" not in state:
            raise Problem("unavailable", "the server is starting or stopping; retry shortly")
        return state["pool"]

    def new_work() -> Path:
        if "root" not in state:
            raise Problem("unavailable", "the server is starting or stopping; retry shortly")
        return _workdir(state["root"])

    async def run_job(kind: str, fn: Callable[..., dict[str, Any]], *args: Any) -> dict[str, Any]:
        return await pool().submit(kind, fn, *args)

    common = (400, 401, 408, 413, 415, 422, 429, 503, 504)

    # -- enhance -------------------------------------------------------------------------------

    @app.post(
        "/v1/enhance",
        tags=["frames"],
        summary="Apply a pipeline of operators to an EXR frame",
        response_class=Response,
        responses={
            200: {
                "description": "the enhanced EXR (everything else in the file preserved), or a "
                "PNG preview with ?preview=png",
                "content": {
                    EXR_MEDIA_TYPE: {"schema": {"type": "string", "format": "binary"}},
                    "image/png": {"schema": {"type": "string", "format": "binary"}},
                },
            },
            **openapi_responses(*common),
        },
    )
    async def enhance(
        file: Annotated[UploadFile, File(description="the EXR frame (G-buffer)")],
        pipeline: Annotated[
            str | None,
            Form(
                description='pipeline JSON: {"steps": [{"op": NAME, "params": {...}}]} '
                "(schema: components/schemas/Pipeline); default: radiance_scaling"
            ),
        ] = None,
        preset: Annotated[
            str,
            Form(description=preset_help()),
        ] = "auto",
        camera: Annotated[str | None, Form(description="camera JSON, overrides the file's")] = None,
        map: Annotated[
            str | None,
            Form(description='JSON object buffer -> channels, e.g. {"normal": "MyLayer.N"}'),
        ] = None,
        normal_space: Annotated[
            Literal["world", "camera"] | None, Form(description="override the normals' space")
        ] = None,
        debug_layers: Annotated[bool, Form(description="also write intermediate layers")] = False,
        output_layer: Annotated[
            str | None,
            Form(
                description="write the result to NAME.R/G/B/A, e.g. ViewLayer.Depict (default: "
                "the view layer's Depict pass for Blender files, else R,G,B,A)",
                pattern=LAYER_PATTERN,
                max_length=200,
            ),
        ] = None,
        preview: Annotated[
            Literal["png"] | None, Query(description="png: answer a tone-mapped PNG preview")
        ] = None,
        exposure: Annotated[
            float, Query(ge=-20.0, le=20.0, description="preview exposure, stops")
        ] = 0.0,
    ) -> Response:
        from service import pipeline as pipelines

        spec_json = await checked_pipeline(pipeline) or pipelines.DEFAULT_PIPELINE.model_dump_json()
        fields = await _read_fields(preset, camera, map, normal_space)
        work = new_work()
        src = work / "in.exr"
        try:
            with _scrubbed(work, {src: file.filename or "upload.exr"}):
                read = await _receive_frame(file, src, fields, settings.limits)
                write = {
                    "input_name": Path(file.filename or "upload.exr").name,
                    "debug_layers": debug_layers,
                    "output_layer": output_layer,
                    "preview": preview == "png",
                    "exposure": exposure,
                }
                out = work / ("out.png" if preview == "png" else "out.exr")
                await run_job(
                    "enhance",
                    jobs.enhance_job,
                    str(src),
                    str(out),
                    spec_json,
                    read,
                    write,
                    settings.limits,
                )
        except BaseException:
            _cleanup(work)
            raise
        stem = Path(file.filename or "frame").stem or "frame"
        suffix = ".png" if preview == "png" else ".exr"
        return FileResponse(
            out,
            media_type="image/png" if preview == "png" else EXR_MEDIA_TYPE,
            filename=f"{stem}_depict{suffix}",
            background=BackgroundTask(_cleanup, work),
        )

    # -- render --------------------------------------------------------------------------------

    @app.post(
        "/v1/render",
        tags=["frames"],
        summary="Render a mesh to a canonical G-buffer EXR",
        response_class=Response,
        responses={
            200: {
                "description": "canonical G-buffer EXR (beauty, normals, depth, lobes, AO)",
                "content": {EXR_MEDIA_TYPE: {"schema": {"type": "string", "format": "binary"}}},
            },
            **openapi_responses(*common),
        },
    )
    async def render(
        mesh: Annotated[UploadFile, File(description="the mesh: OBJ, PLY, STL, GLB or GLTF")],
        scene: Annotated[
            str,
            Form(
                description="scene JSON (components/schemas/Scene): width, height, camera, "
                "azimuth, elevation, lights"
            ),
        ] = "{}",
    ) -> Response:
        suffix = mesh_suffix(mesh)
        try:
            spec = Scene.model_validate_json(scene or "{}")
        except ValidationError as exc:
            first = exc.errors()[0]
            loc = ".".join(str(p) for p in first["loc"]) or "scene"
            raise Problem("invalid-request", f"scene.{loc}: {first['msg']}") from None
        if spec.camera is not None:
            _check_camera("scene.camera", spec.camera)
        pixels = spec.width * spec.height
        if pixels > settings.max_pixels:
            raise Problem(
                "limit",
                f"render of {spec.width}x{spec.height} = {pixels} pixels is over "
                f"DEPICT_MAX_PIXELS={settings.max_pixels}; ask for a smaller size",
            )
        work = new_work()
        src = work / f"mesh{suffix}"
        try:
            with _scrubbed(work, {src: mesh.filename or "mesh"}):
                await _save_upload(mesh, src)
                out = work / "render.exr"
                await run_job(
                    "render",
                    jobs.render_job,
                    str(src),
                    str(out),
                    spec.model_dump(mode="json"),
                )
        except BaseException:
            _cleanup(work)
            raise
        stem = Path(mesh.filename or "mesh").stem or "mesh"
        return FileResponse(
            out,
            media_type=EXR_MEDIA_TYPE,
            filename=f"{stem}.exr",
            background=BackgroundTask(_cleanup, work),
        )

    # -- discovery, health, metrics ------------------------------------------------------------

    @app.get(
        "/v1/operators",
        tags=["operators"],
        summary="Every operator with the JSON schema of its parameters",
        response_model=list[OperatorInfo],
        responses=openapi_responses(401),
    )
    async def list_operators() -> list[dict[str, Any]]:
        from service.registry import operators

        return [op.schema() for op in operators().values()]

    @app.get(
        "/healthz",
        tags=["health"],
        summary="Alive and able to work (503: restart the service)",
        response_model=Health,
        responses=openapi_responses(503),
    )
    async def healthz() -> dict[str, str]:
        healthy, why = pool().pool.health()
        if not healthy:
            raise Problem("unavailable", f"{why}; restart the service")
        return {"status": "ok", "version": version()}

    @app.get(
        "/readyz",
        tags=["health"],
        summary="Ready to take work: worker pool up, OSMesa context created",
        response_model=Ready,
        responses=openapi_responses(503),
    )
    async def readyz() -> Any:
        info = pool().ready()
        if not info.get("osmesa"):
            raise Problem("unavailable", str(info.get("detail", "not ready")))
        return {
            "status": "ready",
            "osmesa": True,
            "workers": settings.workers,
            "queue": settings.queue,
        }

    @app.get(
        "/metrics",
        tags=["health"],
        summary="Prometheus metrics",
        response_class=Response,
        responses={
            200: {"description": "text exposition format", "content": {"text/plain": {}}},
            **openapi_responses(401),
        },
    )
    async def get_metrics() -> Response:
        return Response(metrics.render(), media_type=metrics.content_type)

    from service import api_analysis

    api_analysis.install(app, new_work, run_job, common)
    app.openapi = lambda: _openapi(app)  # type: ignore[method-assign]
    return app


# -- OpenAPI -----------------------------------------------------------------------------------


def pipeline_schemas() -> dict[str, Any]:
    """Components: ``Pipeline`` (one ``oneOf`` branch per registered operator) and its params."""
    from service.registry import operators

    ops = list(operators().values())
    models: list[tuple[type[BaseModel], Literal["validation"]]] = [
        (op.params, "validation") for op in ops
    ]
    refs, defs = models_json_schema(models, ref_template="#/components/schemas/{model}")
    components: dict[str, Any] = dict(defs.get("$defs", {}))
    branches = []
    for op in ops:
        branches.append(
            {
                "type": "object",
                "title": op.name,
                "description": op.summary,
                "properties": {
                    "op": {"const": op.name},
                    "params": refs[(op.params, "validation")],
                },
                "required": ["op"],
                "additionalProperties": False,
            }
        )
    step: dict[str, Any] = {"oneOf": branches} if branches else {"type": "object"}
    components["Pipeline"] = {
        "title": "Pipeline",
        "type": "object",
        "description": "operator steps applied in order (the `pipeline` form field, as JSON)",
        "properties": {"steps": {"type": "array", "minItems": 1, "items": step}},
        "required": ["steps"],
        "additionalProperties": False,
    }
    return components


def _openapi(app: FastAPI) -> dict[str, Any]:
    if app.openapi_schema:
        return app.openapi_schema
    schema = get_openapi(
        title=app.title,
        version=app.version,
        summary=app.summary,
        description=app.description,
        routes=app.routes,
    )
    components = schema.setdefault("components", {})
    schemas = components.setdefault("schemas", {})
    schemas["Problem"] = PROBLEM_SCHEMA
    schemas["Scene"] = Scene.model_json_schema()
    from service.api_analysis import CompareOptions

    schemas["CompareOptions"] = CompareOptions.model_json_schema()
    schemas.update(pipeline_schemas())
    components["securitySchemes"] = {
        "bearer": {
            "type": "http",
            "scheme": "bearer",
            "description": "DEPICT_API_KEY, when the server sets one",
        }
    }
    for path, item in schema.get("paths", {}).items():
        if path in PUBLIC_PATHS:
            continue
        for operation in item.values():
            operation["security"] = [{"bearer": []}, {}]
    app.openapi_schema = schema
    return schema


# -- serve -------------------------------------------------------------------------------------


def slow_client_guard(timeout_s: float) -> type:
    """uvicorn's h11 protocol, closing a connection whose request headers have not all arrived
    ``timeout_s`` after it opened or after its previous answer (the gate times the body)."""
    from uvicorn.protocols.http.h11_impl import H11Protocol

    class SlowClientGuard(H11Protocol):
        _guard: Any = None

        def connection_made(self, transport: Any) -> None:
            super().connection_made(transport)
            self._arm()

        def on_response_complete(self) -> None:
            super().on_response_complete()
            self._arm()

        def connection_lost(self, exc: Exception | None) -> None:
            if self._guard is not None:
                self._guard.cancel()
            super().connection_lost(exc)

        def _arm(self) -> None:
            if self._guard is not None:
                self._guard.cancel()
            self._guard = self.loop.call_later(timeout_s, self._headers_overdue)

        def _headers_overdue(self) -> None:
            waiting = self.cycle is None or self.cycle.response_complete
            if waiting and not self.transport.is_closing():
                log.info("closed a connection whose request did not arrive in time")
                self.transport.close()

    return SlowClientGuard


def serve(settings: Settings | None = None) -> None:
    """Run the service with uvicorn (``depict serve``): JSON logs, one event loop."""
    import uvicorn

    settings = settings or Settings()
    configure_logging(settings.log_level)
    log.info(
        "starting",
        extra={"path": f"http://{settings.host}:{settings.port}"},
    )
    uvicorn.run(
        create_app(settings),
        host=settings.host,
        port=settings.port,
        http=slow_client_guard(settings.upload_timeout_s),
        log_config=None,
        access_log=False,
        timeout_graceful_shutdown=10,
    )
