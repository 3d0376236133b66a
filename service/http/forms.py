"""Form fields into typed requests, checked off the event loop (a large field takes a while to
parse, and other requests must not wait for it); a 422 problem naming the bad field.

* ``pipeline`` -> a compiled :class:`service.pipeline.Pipeline` (parsed and validated once);
* ``preset``, ``camera``, ``map``, ``normal_space`` -> :class:`ReadFields`, then, once the
  upload is checked, a :class:`service.enhance.ReadRequest` carrying a :class:`gbuffer.Camera`;
* JSON fields with a model (``scene``, ``options``): :func:`invalid` names the bad key.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any

import anyio
from fastapi import Form, Query, Request
from pydantic import ValidationError
from starlette.datastructures import FormData

from gbuffer.camera import Camera
from gbuffer.colorspace import View
from gbuffer.colorspace import named as named_colorspace
from gbuffer.errors import OptionError
from gbuffer.limits import Limits
from gbuffer.presets import PRESETS, ReadOptions
from service import pipeline
from service.enhance import ReadRequest
from service.errors import PipelineError
from service.problems import Problem


def json_field(name: str, text: str | None, expected: type | tuple[type, ...]) -> Any:
    """A form field holding JSON (size and nesting bounded), or a 422 problem naming it."""
    if text is None or text == "":
        return None
    try:
        value = pipeline.loads(text, f"form field {name!r}")
    except PipelineError as exc:
        raise Problem("invalid-request", str(exc)) from None
    if not isinstance(value, expected):
        raise Problem("invalid-request", f"form field {name!r} must be a JSON {_kind(expected)}")
    return value


def _kind(expected: type | tuple[type, ...]) -> str:
    types = expected if isinstance(expected, tuple) else (expected,)
    names: dict[type, str] = {dict: "object", list: "array", str: "string"}
    return " or ".join(names.get(t, t.__name__) for t in types)


def invalid(exc: ValidationError, name: str) -> Problem:
    """The 422 problem of JSON field ``name`` that its model refused: the first bad key
    (``name.key: what is wrong``)."""
    first = exc.errors()[0]
    loc = ".".join(str(p) for p in first["loc"]) or name
    return Problem("invalid-request", f"{name}.{loc}: {first['msg']}")


def camera(name: str, value: dict[str, Any] | None) -> Camera | None:
    """The camera of a JSON object, or a 422 naming ``name``."""
    if value is None:
        return None
    try:
        return Camera.from_dict(value)
    except Exception as exc:  # any malformed value is the client's mistake
        raise Problem("invalid-request", f"{name}: {exc}") from None


async def pipeline_field(text: str | None) -> pipeline.Pipeline | None:
    """The ``pipeline`` field compiled (422 when invalid), or None when absent."""
    if not text:
        return None
    return await anyio.to_thread.run_sync(pipeline.compile, text)


@dataclass(frozen=True)
class ReadFields:
    """The form fields saying how to read the uploaded frame, checked."""

    preset: str
    camera: Camera | None
    mapping: dict[str, str]
    normal_space: str | None
    colorspace: str | None = None
    view_layer: str | None = None

    def request(self, limits: Limits) -> ReadRequest:
        """The read request (the mapping's buffer names checked here, after the upload)."""
        options = ReadOptions(
            mapping=dict[str, str | list[str]](self.mapping),
            normal_space=self.normal_space,
            layer=self.view_layer,
            colorspace=self.colorspace,
        )
        return ReadRequest(self.preset, self.camera, options, limits)


def _read_fields(
    preset: str,
    camera_text: str | None,
    map_text: str | None,
    normal_space: str | None,
    colorspace: str | None,
    view_layer: str | None,
) -> ReadFields:
    if preset != "auto" and preset not in PRESETS:
        raise Problem(
            "invalid-request",
            f"preset {preset!r} is unknown; valid presets: auto, {', '.join(PRESETS)}",
        )
    cam = camera("camera", json_field("camera", camera_text, dict))
    mapping = json_field("map", map_text, dict) or {}
    if not all(isinstance(v, str) for v in mapping.values()):
        raise Problem("invalid-request", "form field 'map' must map buffer names to strings")
    if colorspace:
        try:
            named_colorspace(colorspace)
        except OptionError as exc:
            raise Problem("invalid-request", f"colorspace: {exc}") from None
    return ReadFields(preset, cam, mapping, normal_space, colorspace or None, view_layer or None)


async def read_fields(
    preset: str,
    camera_text: str | None,
    map_text: str | None = None,
    normal_space: str | None = None,
    colorspace: str | None = None,
    view_layer: str | None = None,
) -> ReadFields:
    """The read fields checked off the event loop (422 naming the bad one)."""
    return await anyio.to_thread.run_sync(
        _read_fields, preset, camera_text, map_text, normal_space, colorspace, view_layer
    )


#: The ``view_layer`` form field: which view layer of a render with several is read.
ViewLayerField = Annotated[
    str | None,
    Form(
        max_length=200,
        description="the view layer whose passes are read, of a render with several (Blender's; "
        "default: the one with the most passes)",
    ),
]


#: The ``colorspace`` form field: the working space of the radiance.
ColorspaceField = Annotated[
    str | None,
    Form(
        max_length=200,
        description="working space of the radiance, a linear colour space of the OpenColorIO "
        "config (e.g. ACEScg, lin_rec709); default: the file's chromaticities, else the "
        "preset's, else linear Rec.709",
    ),
]
#: The ``display`` and ``view`` query parameters of a PNG preview.
DisplayQuery = Annotated[
    str | None,
    Query(max_length=200, description="preview display of the OCIO config (default: its own)"),
]
ViewQuery = Annotated[
    str | None,
    Query(
        max_length=200,
        description="preview view of that display (default: its own, ACES 2.0 SDR for the "
        "built-in config); raw: exposure and a hard clip",
    ),
]


def preview_view(display: str | None, view: str | None) -> View:
    """The display and view of a preview, checked (422 naming the bad one)."""
    chosen = View(display or None, view or None)
    if not chosen.raw:
        try:
            chosen.resolved()
        except OptionError as exc:
            raise Problem("invalid-request", str(exc)) from None
    return chosen


def _declared(dependant: Any) -> tuple[set[str], set[str]]:
    """The form fields and query parameters a route (and its dependencies) declares."""
    form = {str(f.alias) for f in dependant.body_params}
    query = {str(f.alias) for f in dependant.query_params}
    for sub in dependant.dependencies:
        sub_form, sub_query = _declared(sub)
        form |= sub_form
        query |= sub_query
    return form, query


async def known_fields(request: Request) -> None:
    """A 422 problem naming a form field or query parameter the route does not take: a
    misspelt ``pipline`` ran the default pipeline, a misspelt ``mask`` scored the whole frame,
    each answered 200. (FastAPI has parsed the form already: ``request.form()`` is its.)"""
    dependant = getattr(request.scope.get("route"), "dependant", None)
    if dependant is None:
        return
    form, query = _declared(dependant)
    sent = await request.form() if form else FormData()
    for kind, given, known in (
        ("form field", sent, form),
        ("query parameter", request.query_params, query),
    ):
        unknown = sorted(set(given) - known)
        if unknown:
            takes = ", ".join(sorted(known)) or "none"
            raise Problem(
                "invalid-request",
                f"unknown {kind}{'s' * (len(unknown) > 1)} {', '.join(map(repr, unknown))}; "
                f"{request.url.path} takes: {takes}",
            )
        names = [name for name, _ in given.multi_items()]
        twice = sorted({name for name in names if names.count(name) > 1})
        if twice:  # (the last one was taken, the others dropped without a word)
            raise Problem(
                "invalid-request",
                f"{kind}{'s' * (len(twice) > 1)} {', '.join(map(repr, twice))} given more than "
                "once; give each once",
            )
