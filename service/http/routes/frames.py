"""``POST /v1/enhance`` (a pipeline on an EXR frame) and ``POST /v1/render`` (a mesh to a
canonical G-buffer EXR): the upload is saved and checked here, the pixels are handled on a
worker (:func:`service.worker.enhance_job`, :func:`service.worker.render_job`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Depends, File, Form, Query, UploadFile
from pydantic import ConfigDict, Field, ValidationError
from starlette.responses import FileResponse, Response

from gbuffer.io import DEFAULT_LAYOUT
from gbuffer.presets import preset_help
from service import pipeline as pipelines
from service.enhance import WriteRequest
from service.headers import WARNING, warning_value
from service.http import forms, worker
from service.http.deps import Server, Work
from service.http.uploads import EXR_MEDIA_TYPE, mesh_suffix, receive_exr, save, scrubbed
from service.numbers import NumbersModel
from service.output import LAYER_PATTERN
from service.problems import openapi_responses
from service.scene import RenderRequest

router = APIRouter(tags=["frames"], dependencies=[Depends(forms.known_fields)])

#: The error statuses of the routes that take an upload and run a job.
COMMON = (400, 401, 408, 413, 415, 422, 429, 503, 504)


def binary(description: str, *media_types: str) -> dict[int | str, dict[str, Any]]:
    """``responses=`` of a route answering a file (its warnings in headers), with the problems
    of :data:`COMMON`."""
    schema = {"schema": {"type": "string", "format": "binary"}}
    warning = {
        "description": "one per warning about the file, as `depict` prints them (NaN pixels "
        "read as holes, triangles left out, ...); percent-encoded but for printable ASCII",
        "schema": {"type": "string"},
    }
    return {
        200: {
            "description": description,
            "content": {t: schema for t in media_types},
            "headers": {WARNING: warning},
        },
        **openapi_responses(*COMMON),
    }


class Scene(NumbersModel):
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


@router.post(
    "/v1/enhance",
    summary="Apply a pipeline of operators to an EXR frame",
    response_class=Response,
    responses=binary(
        "the enhanced EXR (everything else in the file preserved), or a PNG preview with "
        "?preview=png",
        EXR_MEDIA_TYPE,
        "image/png",
    ),
)
async def enhance(
    file: Annotated[UploadFile, File(description="the EXR frame (G-buffer)")],
    server: Server,
    work: Work,
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
    colorspace: forms.ColorspaceField = None,
    view_layer: forms.ViewLayerField = None,
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
    layout: Annotated[
        Literal["same", "part", "sidecar"],
        Form(
            description="where new layers go: same (the input's part), part (an added part of "
            "a multi-part file; the input's parts copied as they are), sidecar (an EXR with "
            "only the new layers)"
        ),
    ] = DEFAULT_LAYOUT,
    preview: Annotated[
        Literal["png"] | None, Query(description="png: answer a tone-mapped PNG preview")
    ] = None,
    exposure: Annotated[
        float,
        Query(ge=-20.0, le=20.0, allow_inf_nan=False, description="preview exposure, stops"),
    ] = 0.0,
    display: forms.DisplayQuery = None,
    view: forms.ViewQuery = None,
) -> Response:
    steps = await forms.pipeline_field(pipeline) or pipelines.DEFAULT
    fields = await forms.read_fields(preset, camera, map, normal_space, colorspace, view_layer)
    shown = forms.preview_view(display, view)
    name = file.filename or "upload.exr"
    src = work.path / "in.exr"
    out = work.path / ("out.png" if preview == "png" else "out.exr")
    with scrubbed(work.path, {src: name}):
        await receive_exr(file, src, server.settings.limits)
        write = WriteRequest(
            debug_layers=debug_layers,
            output_layer=output_layer,
            preview=preview == "png",
            exposure=exposure,
            input_name=Path(name).name,
            view=shown,
            layout=layout,
        )
        read = fields.request(server.settings.limits)
        done = await server.run(
            "enhance", worker.enhance_job, str(src), str(out), steps, read, write
        )
    stem = Path(file.filename or "frame").stem or "frame"
    suffix = ".png" if preview == "png" else ".exr"
    media_type = "image/png" if preview == "png" else EXR_MEDIA_TYPE
    return _with_warnings(
        FileResponse(out, media_type=media_type, filename=f"{stem}_depict{suffix}"), done
    )


def _with_warnings(answer: Response, done: dict[str, Any]) -> Response:
    """``answer`` with one :data:`~service.headers.WARNING` header per warning of the job (the
    reader's first, as the command line prints them)."""
    for text in [*done.get("read_warnings", []), *done.get("warnings", [])]:
        answer.headers.append(WARNING, warning_value(str(text)))
    return answer


@router.post(
    "/v1/render",
    summary="Render a mesh to a canonical G-buffer EXR",
    response_class=Response,
    responses=binary("canonical G-buffer EXR (beauty, normals, depth, lobes, AO)", EXR_MEDIA_TYPE),
)
async def render(
    mesh: Annotated[UploadFile, File(description="the mesh: OBJ, PLY, STL, GLB or GLTF")],
    server: Server,
    work: Work,
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
        request = _render_request(Scene.model_validate_json(scene or "{}"))
    except ValidationError as exc:
        raise forms.invalid(exc, "scene") from None
    server.settings.limits.check_render(request.width, request.height, "render")
    src = work.path / f"mesh{suffix}"
    out = work.path / "render.exr"
    with scrubbed(work.path, {src: mesh.filename or "mesh"}):
        await save(mesh, src)
        done = await server.run("render", worker.render_job, str(src), str(out), request)
    stem = Path(mesh.filename or "mesh").stem or "mesh"
    return _with_warnings(
        FileResponse(out, media_type=EXR_MEDIA_TYPE, filename=f"{stem}.exr"), done
    )


def _render_request(scene: Scene) -> RenderRequest:
    return RenderRequest(
        width=scene.width,
        height=scene.height,
        camera=forms.camera("scene.camera", scene.camera),
        azimuth=scene.azimuth,
        elevation=scene.elevation,
        lights=tuple(scene.lights),
    )
