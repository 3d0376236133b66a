"""The web viewer's routes: frames kept on the server for a session (``/v1/frames``), pictures of
their layers, previews and the full-resolution result; and the page itself at ``/ui/``.

* ``POST /v1/frames``: multipart ``file`` (EXR) + ``preset``, ``camera``, ``map``,
  ``normal_space``, ``colorspace``, ``view_layer`` -> ``{"id", "name", "info", "expires_s"}``;
  ``POST /v1/frames/example``: the bundled example (a render of ``examples/spot.obj``);
* ``GET /v1/frames/{id}``: what ``inspect`` found; ``DELETE /v1/frames/{id}``: forget it now;
* ``GET /v1/frames/{id}/layers/{layer}.png?height=``: a layer as a picture;
* ``POST /v1/frames/{id}/preview``: JSON ``{"pipeline", "height", "exposure", "score_map"}``
  -> the result (and its score map when asked for) as base64 PNGs, the congruence scores before
  and after;
* ``GET /v1/frames/{id}/enhanced.exr?pipeline=``: the full-resolution EXR, the bytes
  ``depict enhance`` writes.

A preview waits for the frame's running one; when a newer preview of the frame comes meanwhile,
or its client went away, it is dropped (409 ``superseded``) before reaching a worker.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Iterator
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Annotated, Any

import anyio
from fastapi import APIRouter, Depends, File, Query, Request, UploadFile
from fastapi import Path as PathParam
from fastapi.staticfiles import StaticFiles
from pydantic import BaseModel, ConfigDict, Field
from starlette.responses import FileResponse, RedirectResponse, Response

import service
from gbuffer.presets import PRESETS
from service import pipeline as pipelines
from service.enhance import ReadRequest, WriteRequest
from service.http import forms, worker
from service.http.deps import Server, Work
from service.http.routes.analysis import CameraField, MapField, NormalSpace, Preset
from service.http.routes.frames import COMMON, binary
from service.http.uploads import EXR_MEDIA_TYPE, receive_exr, scrubbed
from service.numbers import NumbersModel
from service.problems import Problem, openapi_responses
from service.scene import RenderRequest
from service.viewer import work as jobs
from service.viewer.store import ID_PATTERN, FrameStore, StoredFrame

router = APIRouter(tags=["viewer"], dependencies=[Depends(forms.known_fields)])

STATIC = Path(__file__).resolve().parent / "static"
#: The example frame: Keenan Crane's cow, rendered by Depict's renderer when asked for.
EXAMPLE_MESH = Path(service.__file__).resolve().parent.parent / "examples" / "spot.obj"
EXAMPLE_SIZE = (960, 720)

FrameId = Annotated[str, PathParam(pattern=ID_PATTERN.strip("^$"), description="frame id")]
Height = Annotated[int, Query(ge=16, le=4320, description="picture height, pixels")]
#: The height of the previews the page will ask for first: their copy of the frame is made as
#: it is inspected, from the same decode.
PreviewHeight = Annotated[
    int, Query(ge=16, le=4320, description="height of the first previews, pixels")
]


class FrameInfo(BaseModel):
    id: str = Field(description="the frame id, for the routes under /v1/frames/{id}")
    name: str = Field(description="the uploaded file's name")
    info: dict[str, Any] = Field(description="what `depict inspect --json` says, and `layers`")
    expires_s: float = Field(description="seconds the frame is kept after its last use")


class PreviewRequest(NumbersModel):
    model_config = ConfigDict(extra="forbid")
    pipeline: dict[str, Any] | list[Any] = Field(
        default_factory=lambda: {"steps": [{"op": "radiance_scaling"}]},
        description='pipeline JSON: {"steps": [{"op": NAME, "params": {...}}]}',
    )
    height: int = Field(
        540,
        ge=16,
        le=4320,
        description="preview height asked for: the frame's height divided by the nearest whole "
        "number (never above the frame's)",
    )
    exposure: float = Field(0.0, ge=-20.0, le=20.0, description="preview exposure, stops")
    score_map: bool = Field(False, description="also answer the result's per-pixel score map")


class Preview(BaseModel):
    image: str = Field(description="the result, base64 PNG")
    size: list[int] = Field(description="(width, height) of the preview")
    op_s: list[tuple[str, float]] = Field(description="seconds of each step")
    warnings: list[str] = Field(
        description="what the steps say besides their result (a mask that selects no pixel)"
    )
    score: dict[str, float] | None = Field(
        description="congruence score of the input and the result (on the input's scale); "
        "null without depth"
    )
    score_map: str | None = Field(
        description="the result's per-pixel score, base64 PNG (when asked for)"
    )
    pipeline: dict[str, Any] = Field(description="the pipeline as run")
    job_s: float = Field(description="seconds on the worker")


def store(server: Server) -> FrameStore:
    return server.frame_store()


def _naming(frame: StoredFrame) -> AbstractContextManager[None]:
    """Errors of a job on a kept frame name its upload, not the server's copy of it."""
    return scrubbed(frame.folder, {frame.source: frame.name})


@contextlib.contextmanager
def _on_kept(server: Server, frame: StoredFrame) -> Iterator[None]:
    """A job on a kept frame's folder: its errors name the upload (:func:`_naming`), and what
    it leaves there is accounted for (:meth:`FrameStore.job`)."""
    with store(server).job(frame), _naming(frame):
        yield


def _answer(frame: StoredFrame, server: Server) -> dict[str, Any]:
    return {
        "id": frame.id,
        "name": frame.name,
        "info": frame.info,
        "expires_s": server.settings.viewer_ttl_s,
    }


async def _keep(server: Server, frame: StoredFrame, height: int) -> dict[str, Any]:
    """Inspect the received frame on a worker (and make its copy at the preview ``height``),
    then keep it."""
    with _naming(frame):
        out = await server.run("inspect", jobs.inspect_job, str(frame.source), frame.read, height)
    frame.info = out["info"]
    frame.info["file"] = frame.name
    store(server).admit(frame)
    return _answer(frame, server)


@router.get(
    "/v1/presets",
    summary="The renderer presets a frame can be read with (besides auto)",
    responses=openapi_responses(401),
)
async def presets() -> list[str]:
    return list(PRESETS)


@router.post(
    "/v1/frames",
    summary="Keep an EXR frame on the server for the viewer (previews, layers, result)",
    response_model=FrameInfo,
    responses=openapi_responses(*COMMON),
)
async def upload(
    file: Annotated[UploadFile, File(description="the EXR frame (G-buffer)")],
    server: Server,
    preset: Preset = "auto",
    camera: CameraField = None,
    map: MapField = None,
    normal_space: NormalSpace = None,
    colorspace: forms.ColorspaceField = None,
    view_layer: forms.ViewLayerField = None,
    height: PreviewHeight = 540,
) -> dict[str, Any]:
    fields = await forms.read_fields(preset, camera, map, normal_space, colorspace, view_layer)
    limits = server.settings.limits
    name = Path(file.filename or "frame.exr").name or "frame.exr"
    with store(server).new_folder() as (frame_id, folder):
        frame = StoredFrame(frame_id, folder, name, fields.request(limits), 0)
        with _naming(frame):
            await receive_exr(file, frame.source, limits)
        return await _keep(server, frame, height)


@router.post(
    "/v1/frames/example",
    summary="Keep the bundled example frame (a render of a cow) for the viewer",
    response_model=FrameInfo,
    responses=openapi_responses(401, 404, 413, 422, 429, 503, 504),
)
async def example(server: Server, height: PreviewHeight = 540) -> dict[str, Any]:
    if not EXAMPLE_MESH.is_file():
        raise Problem("not-found", "this installation has no example mesh (examples/spot.obj)")
    width, rows = EXAMPLE_SIZE
    if width * rows > server.settings.max_pixels:
        raise Problem(
            "limit",
            f"the example is {width}x{rows} pixels, over "
            f"DEPICT_MAX_PIXELS={server.settings.max_pixels}",
        )
    scene = RenderRequest(width=width, height=rows, camera=None, azimuth=30.0, elevation=20.0)
    read = ReadRequest(limits=server.settings.limits)
    with store(server).new_folder() as (frame_id, folder):
        frame = StoredFrame(frame_id, folder, "spot.exr", read, 0)
        await server.run("render", worker.render_job, str(EXAMPLE_MESH), str(frame.source), scene)
        return await _keep(server, frame, height)


@router.get(
    "/v1/frames/{frame_id}",
    summary="What the viewer knows of a kept frame",
    response_model=FrameInfo,
    responses=openapi_responses(401, 404, 422),
)
async def frame_info(frame_id: FrameId, server: Server) -> dict[str, Any]:
    return _answer(store(server).get(frame_id), server)


@router.delete(
    "/v1/frames/{frame_id}",
    summary="Forget a kept frame now",
    status_code=204,
    response_class=Response,
    responses=openapi_responses(401, 404, 422),
)
async def forget(frame_id: FrameId, server: Server) -> Response:
    store(server).remove(frame_id)
    return Response(status_code=204)


@router.get(
    "/v1/frames/{frame_id}/layers/{layer}.png",
    summary="A layer of a kept frame as a picture (buffers, or score_map)",
    response_class=Response,
    responses=binary("the layer, tone-mapped (gbuffer.preview)", "image/png"),
)
async def layer_png(
    frame_id: FrameId,
    layer: Annotated[str, PathParam(pattern=r"^[A-Za-z0-9_.]{1,64}$", description="layer")],
    server: Server,
    work: Work,
    height: Height = 540,
) -> Response:
    frame = store(server).get(frame_id)
    if layer not in frame.info.get("layers", []):
        have = ", ".join(frame.info.get("layers", []))
        raise Problem("not-found", f"the frame has no layer {layer!r}; layers: {have}")
    out = work.path / "layer.png"
    factor = jobs.shrink_factor(frame.info["size"], height)
    with _on_kept(server, frame):
        await server.run(
            "layer", jobs.layer_job, str(frame.folder), factor, layer, frame.read, str(out)
        )
    return FileResponse(out, media_type="image/png")


async def _latest(request: Request, frame: StoredFrame) -> asyncio.Lock:
    """Wait for the frame's running preview; 409 when a newer one came meanwhile or the client
    went away. Returns the lock, held."""
    frame.latest_preview += 1
    ticket = frame.latest_preview
    lock = frame.previewing
    await lock.acquire()
    if ticket != frame.latest_preview or await request.is_disconnected():
        lock.release()
        raise Problem(
            "superseded", "a newer preview of this frame was asked for; this one is dropped"
        )
    return lock


@router.post(
    "/v1/frames/{frame_id}/preview",
    summary="A pipeline on a kept frame, at the preview height, with its congruence score",
    response_model=Preview,
    responses=openapi_responses(400, 401, 404, 409, 422, 429, 503, 504),
)
async def preview(
    frame_id: FrameId, body: PreviewRequest, request: Request, server: Server
) -> dict[str, Any]:
    frame = store(server).get(frame_id)
    steps = await anyio.to_thread.run_sync(pipelines.compile, body.pipeline)
    factor = jobs.shrink_factor(frame.info["size"], body.height)
    lock = await _latest(request, frame)
    try:
        args = (str(frame.folder), factor, steps, frame.read, body.exposure, body.score_map)
        with _on_kept(server, frame):
            return await server.run("preview", jobs.preview_job, *args)
    finally:
        lock.release()


@router.get(
    "/v1/frames/{frame_id}/enhanced.exr",
    summary="The full-resolution result of a pipeline on a kept frame (as `depict enhance`)",
    response_class=Response,
    responses=binary("the enhanced EXR", EXR_MEDIA_TYPE),
)
async def enhanced(
    frame_id: FrameId,
    server: Server,
    work: Work,
    pipeline: Annotated[
        str | None, Query(description="pipeline JSON (default: radiance_scaling)", max_length=4096)
    ] = None,
) -> Response:
    frame = store(server).get(frame_id)
    steps = await forms.pipeline_field(pipeline) or pipelines.DEFAULT
    out = work.path / "out.exr"
    write = WriteRequest(input_name=frame.name)
    with _on_kept(server, frame):
        await server.run(
            "enhance", worker.enhance_job, str(frame.source), str(out), steps, frame.read, write
        )
    stem = Path(frame.name).stem or "frame"
    return FileResponse(out, media_type=EXR_MEDIA_TYPE, filename=f"{stem}_depict.exr")


async def ui_root() -> RedirectResponse:
    return RedirectResponse("/ui/")


def mount_static(app: Any) -> None:
    """Serve the viewer's page and its scripts at ``/ui/`` (public: the API calls carry the key;
    a query string, which the page's address may carry, is not checked there)."""
    app.add_api_route("/ui", ui_root, methods=["GET"], include_in_schema=False)
    app.mount("/ui", StaticFiles(directory=STATIC, html=True), name="ui")
