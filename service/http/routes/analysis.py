"""The analysis routes: ``POST /v1/score``, ``POST /v1/compare`` and ``POST /v1/relief/pick``.
Each runs the job function the CLI runs locally (:mod:`service.jobs`) on a worker and answers its
JSON, so ``depict score|compare|relief-pick --server`` prints what the local command prints."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Depends, File, Form, UploadFile
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from service import jobs
from service.enhance import ReadRequest
from service.http import forms
from service.http.deps import Server, Work
from service.http.routes.frames import COMMON
from service.http.uploads import mesh_suffix, receive_exr, save, scrubbed
from service.numbers import NumbersModel
from service.problems import openapi_responses
from service.registry import get

router = APIRouter(tags=["analysis"], dependencies=[Depends(forms.known_fields)])

Preset = Annotated[str, Form(description="renderer preset (as for /v1/enhance)")]
CameraField = Annotated[str | None, Form(description="camera JSON, overrides the file's")]
MapField = Annotated[
    str | None, Form(description='JSON object buffer -> channels, e.g. {"normal": "MyLayer.N"}')
]
NormalSpace = Annotated[
    Literal["world", "camera"] | None, Form(description="override the normals' space")
]
#: What :func:`run_on_upload` submits, given the saved upload and its read request:
#: ``(kind, job function, *arguments)``.
JobCall = Callable[[Path, ReadRequest | None], tuple[Any, ...]]


class Score(BaseModel):
    """The answer of ``POST /v1/score`` (the JSON of ``depict score --json``)."""

    score: float = Field(description="congruence score (LLA Eq. 2) in [0, 1]")
    shading_norm: float = Field(
        description="the shading strength mapped to 1: pass it as `shading_norm` to score "
        "another rendering of this frame (a result) on this one's scale"
    )
    analysis_shape: list[int] = Field(description="(h, w) at which the score was evaluated")
    image_shape: list[int] = Field(description="(h, w) of the frame")
    params: dict[str, float | str] = Field(description="the congruence parameters used")
    warnings: list[str] = Field(
        default_factory=list,
        description="what to know about the number: e.g. that no pixel was scored (no covered "
        "pixel, or every pixel's radiance NaN or Inf), when the score is 0 for that reason",
    )


class Comparison(BaseModel):
    """The answer of ``POST /v1/compare`` (the JSON of ``depict compare --json``)."""

    label: str
    image_shape: list[int]
    albedo: str
    methods: list[str]
    directions: list[dict[str, Any]] = Field(description="index, vector, theta_deg, phi_deg")
    scores: dict[str, list[float]] = Field(description="method -> score per direction")
    means: dict[str, float]
    claim: dict[str, Any] = Field(description="the paper's claim checked for Light Alignment")
    params: dict[str, Any]
    shading_norm: dict[str, Any] = Field(
        description="scale of the shading strengths: mode (reference, per_image, pinned), value"
    )
    seconds: dict[str, float]
    sheet_png: str | None = Field(None, description="the contact sheet, base64 PNG (sheet=true)")
    warnings: list[str] = Field(
        default_factory=list, description="what the scores do not say (nothing covered)"
    )


class CompareOptions(NumbersModel):
    """The ``options`` form field of ``POST /v1/compare`` (JSON); unknown keys are refused."""

    model_config = ConfigDict(extra="forbid")
    methods: list[str] | None = Field(  # ([] ran every method, as leaving it out does)
        None, min_length=1, max_length=16, description="methods to compare (default: all)"
    )
    directions: int | list[int] = Field(
        21, description="the first N directions of the sweep (1-21), or their numbers"
    )
    params: dict[str, dict[str, Any]] | None = Field(
        None, description='per-section overrides, e.g. {"light_alignment": {"gamma": 2}}'
    )
    albedo: Literal["white", "frame"] = "white"
    label: str = Field("", max_length=200)
    shading_norm: Literal["reference", "per_image"] | float = "reference"
    width: int = Field(512, ge=3, le=16384, description="mesh render width")
    height: int = Field(512, ge=3, le=16384, description="mesh render height")
    azimuth: float = Field(30.0, ge=-360, le=360, description="mesh framing azimuth, degrees")
    elevation: float = Field(20.0, ge=-90, le=90, description="mesh framing elevation, degrees")


class Pick(BaseModel):
    """The answer of ``POST /v1/relief/pick`` (the JSON of ``depict relief-pick --json``)."""

    x: int
    y: int
    s: list[float] = Field(description="the descriptor S = (S1, S2) under the pixel")
    uv: list[float] = Field(description="its ARM texture coordinates (u right, v up)")
    region: str = Field(description="plane, cap, convex, saddle, concave or cup")
    r: float = Field(description="the relief value of the default ARM there")
    curvedness_norm: float | None


async def run_on_upload(
    server: Server, work: Work, file: UploadFile, fields: forms.ReadFields | None, call: JobCall
) -> dict[str, Any]:
    """Receive the upload (an EXR read with ``fields``, or a mesh when ``fields`` is None) into
    the workspace and run ``call(src, read)`` on a worker."""
    src_name = "in.exr" if fields is not None else f"mesh{mesh_suffix(file)}"
    src = work.path / src_name
    limits = server.settings.limits
    with scrubbed(work.path, {src: file.filename or src_name}):
        read = None
        if fields is None:
            await save(file, src)
        else:
            await receive_exr(file, src, limits)
            read = fields.request(limits)
        kind, fn, *args = call(src, read)
        return await server.run(kind, fn, *args)


@router.post(
    "/v1/score",
    summary="Congruence score of a frame's beauty (Local Light Alignment, Eq. 2)",
    response_model=Score,
    responses=openapi_responses(*COMMON),
)
async def score(
    file: Annotated[UploadFile, File(description="the EXR frame (beauty + depth)")],
    server: Server,
    work: Work,
    pipeline: Annotated[
        str | None,
        Form(description="pipeline JSON to apply before scoring (default: score as is)"),
    ] = None,
    preset: Preset = "auto",
    camera: CameraField = None,
    map: MapField = None,
    normal_space: NormalSpace = None,
    colorspace: forms.ColorspaceField = None,
    view_layer: forms.ViewLayerField = None,
    gradient_scale: Annotated[
        float | None,
        Form(
            allow_inf_nan=False,
            gt=0,
            le=0.1,
            description="gradient sigma, relative to the image height",
        ),
    ] = None,
    integration_scale: Annotated[
        float | None,
        Form(
            allow_inf_nan=False,
            gt=0,
            le=0.25,
            description="integration sigma, relative to the image height",
        ),
    ] = None,
    percentile: Annotated[
        float | None,
        Form(allow_inf_nan=False, gt=0, le=100, description="strength normalisation percentile"),
    ] = None,
    depth_jump: Annotated[
        float | None,
        Form(allow_inf_nan=False, gt=0, le=100, description="largest log-depth step of a surface"),
    ] = None,
    shading_norm: Annotated[
        float | None, Form(allow_inf_nan=False, gt=0, description="pinned shading strength scale")
    ] = None,
    shape: Annotated[
        Literal["normals", "depth"] | None,
        Form(description="shape flow from the normals' gradients (default) or the log depth's"),
    ] = None,
) -> dict[str, Any]:
    steps = await forms.pipeline_field(pipeline)
    given = {
        "gradient_scale": gradient_scale,
        "integration_scale": integration_scale,
        "percentile": percentile,
        "depth_jump": depth_jump,
        "shading_norm": shading_norm,
        "shape": shape,
    }
    options = {k: v for k, v in given.items() if v is not None}
    fields = await forms.read_fields(preset, camera, map, normal_space, colorspace, view_layer)
    out = await run_on_upload(
        server,
        work,
        file,
        fields,
        lambda src, read: ("score", jobs.score_job, str(src), steps, read, options),
    )
    keys = ("score", "shading_norm", "analysis_shape", "image_shape", "params", "warnings")
    return {k: out[k] for k in keys}


@router.post(
    "/v1/compare",
    summary="Score every depiction method under the fixed light sweep (LLA §7)",
    response_model=Comparison,
    responses=openapi_responses(*COMMON),
)
async def compare(
    file: Annotated[UploadFile, File(description="an EXR frame (normals, depth) or a mesh")],
    server: Server,
    work: Work,
    kind: Annotated[
        Literal["exr", "mesh"], Form(description="what `file` is: exr or mesh")
    ] = "exr",
    options: Annotated[
        str,
        Form(
            description="JSON (components/schemas/CompareOptions): methods, directions, "
            "params, albedo, label, shading_norm; for a mesh width, height, azimuth, "
            "elevation"
        ),
    ] = "{}",
    sheet: Annotated[bool, Form(description="also answer the contact sheet")] = False,
    preset: Preset = "auto",
    camera: CameraField = None,
) -> dict[str, Any]:
    try:
        opts = CompareOptions.model_validate(forms.json_field("options", options, dict) or {})
    except ValidationError as exc:
        raise forms.invalid(exc, "options") from None
    fields = await forms.read_fields(preset, camera) if kind == "exr" else None
    limits = server.settings.limits
    return await run_on_upload(
        server,
        work,
        file,
        fields,
        lambda src, read: (
            "compare",
            jobs.compare_job,
            str(src),
            read,
            opts.model_dump(exclude_unset=True),
            sheet,
            limits,
        ),
    )


@router.post(
    "/v1/relief/pick",
    summary="The Apparent Relief descriptor under a pixel, to paint an ARM around it",
    response_model=Pick,
    responses=openapi_responses(*COMMON),
)
async def relief_pick(
    file: Annotated[UploadFile, File(description="the EXR frame (normals, depth)")],
    server: Server,
    work: Work,
    x: Annotated[int, Form(ge=0, description="column, from the left")],
    y: Annotated[int, Form(ge=0, description="row, from the top")],
    params: Annotated[
        str, Form(description="apparent_relief parameters JSON (scale, curvedness_norm)")
    ] = "{}",
    preset: Preset = "auto",
    camera: CameraField = None,
) -> dict[str, Any]:
    values = forms.json_field("params", params, dict) or {}
    get("apparent_relief").parse(values)  # 422 for a bad parameter
    fields = await forms.read_fields(preset, camera)
    return await run_on_upload(
        server,
        work,
        file,
        fields,
        lambda src, read: ("pick", jobs.pick_job, str(src), read, x, y, values),
    )
