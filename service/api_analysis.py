"""The analysis routes of the HTTP service: ``POST /v1/score``, ``POST /v1/compare`` and
``POST /v1/relief/pick``. Each runs the job function the CLI runs locally
(:mod:`service.jobs`) and answers its JSON, so ``depict score|compare|relief-pick --server``
prints what the local command prints."""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Annotated, Any, Literal

from fastapi import FastAPI, File, Form, UploadFile
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from service import jobs
from service.api import (
    _cleanup,
    _json_field,
    _read_fields,
    _receive_frame,
    _save_upload,
    _scrubbed,
    checked_pipeline,
    mesh_suffix,
)
from service.problems import Problem, openapi_responses
from service.settings import Settings

RunJob = Callable[..., Awaitable[dict[str, Any]]]

Preset = Annotated[str, Form(description="renderer preset (as for /v1/enhance)")]
CameraField = Annotated[str | None, Form(description="camera JSON, overrides the file's")]
MapField = Annotated[
    str | None, Form(description='JSON object buffer -> channels, e.g. {"normal": "MyLayer.N"}')
]
NormalSpace = Annotated[
    Literal["world", "camera"] | None, Form(description="override the normals' space")
]


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


class CompareOptions(BaseModel):
    """The ``options`` form field of ``POST /v1/compare`` (JSON); unknown keys are refused."""

    model_config = ConfigDict(extra="forbid")
    methods: list[str] | None = Field(None, max_length=16, description="methods to compare")
    directions: int | list[int] = Field(
        21, description="the first N directions of the sweep (1-21), or their numbers"
    )
    params: dict[str, dict[str, Any]] | None = Field(
        None, description='per-section overrides, e.g. {"light_alignment": {"gamma": 2}}'
    )
    albedo: Literal["white", "frame"] = "white"
    label: str = Field("", max_length=200)
    shading_norm: Literal["reference", "per_image"] | float = "reference"
    width: int = Field(512, ge=1, le=16384, description="mesh render width")
    height: int = Field(512, ge=1, le=16384, description="mesh render height")
    azimuth: float = Field(30.0, ge=-360, le=360, description="mesh framing azimuth, degrees")
    elevation: float = Field(20.0, ge=-90, le=90, description="mesh framing elevation, degrees")


def compare_options(text: str) -> dict[str, Any]:
    """The ``options`` field checked (422 naming the bad key), as :func:`service.jobs.compare_job`
    takes it."""
    value = _json_field("options", text, dict) or {}
    try:
        opts = CompareOptions.model_validate(value)
    except ValidationError as exc:
        first = exc.errors()[0]
        loc = ".".join(str(p) for p in first["loc"]) or "options"
        raise Problem("invalid-request", f"options.{loc}: {first['msg']}") from None
    return opts.model_dump(exclude_unset=True)


class Pick(BaseModel):
    """The answer of ``POST /v1/relief/pick`` (the JSON of ``depict relief-pick --json``)."""

    x: int
    y: int
    s: list[float] = Field(description="the descriptor S = (S1, S2) under the pixel")
    uv: list[float] = Field(description="its ARM texture coordinates (u right, v up)")
    region: str = Field(description="plane, cap, convex, saddle, concave or cup")
    r: float = Field(description="the relief value of the default ARM there")
    curvedness_norm: float | None


def install(
    app: FastAPI, new_work: Callable[[], Path], run_job: RunJob, common: tuple[int, ...]
) -> None:
    """Add the analysis routes to ``app``."""
    settings: Settings = app.state.settings

    async def upload_job(
        kind: str,
        file: UploadFile,
        fields: dict[str, Any] | None,
        fn: Callable[..., dict[str, Any]],
        args: Callable[[Path, dict[str, Any] | None], tuple[Any, ...]],
    ) -> dict[str, Any]:
        """Receive the upload — an EXR read with ``fields``, or a mesh when ``fields`` is None —,
        run ``fn(*args(src, read))`` on a worker, clean up."""
        src_name = "in.exr" if fields is not None else f"mesh{mesh_suffix(file)}"
        work = new_work()
        src = work / src_name
        try:
            with _scrubbed(work, {src: file.filename or src_name}):
                if fields is None:
                    await _save_upload(file, src)
                    read = None
                else:
                    read = await _receive_frame(file, src, fields, settings.limits)
                return await run_job(kind, fn, *args(src, read))
        finally:
            _cleanup(work)

    @app.post(
        "/v1/score",
        tags=["analysis"],
        summary="Congruence score of a frame's beauty (Local Light Alignment, Eq. 2)",
        response_model=Score,
        responses=openapi_responses(*common),
    )
    async def score(
        file: Annotated[UploadFile, File(description="the EXR frame (beauty + depth)")],
        pipeline: Annotated[
            str | None,
            Form(description="pipeline JSON to apply before scoring (default: score as is)"),
        ] = None,
        preset: Preset = "auto",
        camera: CameraField = None,
        map: MapField = None,
        normal_space: NormalSpace = None,
        gradient_scale: Annotated[
            float | None,
            Form(gt=0, le=0.1, description="gradient sigma, relative to the image height"),
        ] = None,
        integration_scale: Annotated[
            float | None,
            Form(gt=0, le=0.25, description="integration sigma, relative to the image height"),
        ] = None,
        percentile: Annotated[
            float | None, Form(gt=0, le=100, description="strength normalisation percentile")
        ] = None,
        depth_jump: Annotated[
            float | None, Form(gt=0, le=100, description="largest log-depth step of a surface")
        ] = None,
        shading_norm: Annotated[
            float | None, Form(gt=0, description="pinned shading strength scale")
        ] = None,
        shape: Annotated[
            Literal["normals", "depth"] | None,
            Form(description="shape flow from the normals' gradients (default) or the log depth's"),
        ] = None,
    ) -> dict[str, Any]:
        spec_json = await checked_pipeline(pipeline)
        given = {
            "gradient_scale": gradient_scale,
            "integration_scale": integration_scale,
            "percentile": percentile,
            "depth_jump": depth_jump,
            "shading_norm": shading_norm,
            "shape": shape,
        }
        options = {k: v for k, v in given.items() if v is not None}
        out = await upload_job(
            "score",
            file,
            await _read_fields(preset, camera, map, normal_space),
            jobs.score_job,
            lambda src, read: (str(src), spec_json, read, options, settings.limits),
        )
        keys = ("score", "shading_norm", "analysis_shape", "image_shape", "params")
        return {k: out[k] for k in keys}

    @app.post(
        "/v1/compare",
        tags=["analysis"],
        summary="Score every depiction method under the fixed light sweep (LLA §7)",
        response_model=Comparison,
        responses=openapi_responses(*common),
    )
    async def compare(
        file: Annotated[UploadFile, File(description="an EXR frame (normals, depth) or a mesh")],
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
        opts = compare_options(options)
        return await upload_job(
            "compare",
            file,
            await _read_fields(preset, camera) if kind == "exr" else None,
            jobs.compare_job,
            lambda src, read: (str(src), read, opts, sheet, settings.limits),
        )

    @app.post(
        "/v1/relief/pick",
        tags=["analysis"],
        summary="The Apparent Relief descriptor under a pixel, to paint an ARM around it",
        response_model=Pick,
        responses=openapi_responses(*common),
    )
    async def relief_pick(
        file: Annotated[UploadFile, File(description="the EXR frame (normals, depth)")],
        x: Annotated[int, Form(ge=0, description="column, from the left")],
        y: Annotated[int, Form(ge=0, description="row, from the top")],
        params: Annotated[
            str, Form(description="apparent_relief parameters JSON (scale, curvedness_norm)")
        ] = "{}",
        preset: Preset = "auto",
        camera: CameraField = None,
    ) -> dict[str, Any]:
        values = _json_field("params", params, dict) or {}
        from service.registry import get

        get("apparent_relief").parse(values)  # 422 for a bad parameter
        return await upload_job(
            "pick",
            file,
            await _read_fields(preset, camera),
            jobs.pick_job,
            lambda src, read: (str(src), read, x, y, values, settings.limits),
        )
