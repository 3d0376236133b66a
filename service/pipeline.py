"""Pipelines: JSON lists of operator steps, validated against the registry, run on a frame.

A pipeline is ``{"steps": [{"op": "radiance_scaling", "params": {...}}, ...]}`` - the same spec
for the CLI (``--pipeline PIPE.json`` or ``--op NAME --set k=v``), the HTTP API and batch runs.

Python API::

    import gbuffer, service.pipeline
    frame = gbuffer.read("shot.exr", preset="auto")
    out = service.pipeline.run(frame, [{"op": "radiance_scaling", "params": {"gamma": 2}}])
    gbuffer.write(out, "shot_rs.exr")
"""

from __future__ import annotations

import json
import re
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from gbuffer import holes
from gbuffer.atomic import read_text
from gbuffer.errors import FrameError
from gbuffer.frame import NORMAL_COMPONENT_MAX, Frame, normals_in_range
from service.output import finish as finish  # pipeline.finish: the result placed for writing
from service.registry import Context, Operator, Params, PipelineError, get

#: Most steps in a pipeline.
MAX_STEPS = 64
#: Deepest nesting of JSON arrays and objects in a pipeline (or any JSON field of a request).
MAX_DEPTH = 20
#: Largest pipeline, in characters of JSON.
MAX_CHARS = 1 << 20

_JSON_STRING = re.compile(r'"(?:[^"\\]|\\.)*"')


def json_depth(text: str) -> int:
    """How deeply arrays and objects nest in JSON ``text`` (counted without parsing it, so
    a document nested 100000 deep costs no recursion)."""
    code = np.frombuffer(_JSON_STRING.sub("", text).encode("utf-8", "replace"), np.uint8)
    steps = (code == ord("[")).astype(np.int32) + (code == ord("{"))
    steps -= (code == ord("]")).astype(np.int32) + (code == ord("}"))
    return int(np.cumsum(steps).max(initial=0))


def value_depth(value: Any, limit: int = MAX_DEPTH) -> int:
    """How deeply lists and dicts nest in ``value`` (walked without recursion, up to
    ``limit + 1``)."""
    deepest = 0
    todo = [(value, 1)]
    while todo:
        item, depth = todo.pop()
        if isinstance(item, dict | list | tuple):
            deepest = max(deepest, depth)
            if depth > limit:
                break
            children = item.values() if isinstance(item, dict) else item
            todo.extend((child, depth + 1) for child in children)
    return deepest


def loads(text: str, what: str, max_chars: int = MAX_CHARS) -> Any:
    """JSON ``text`` parsed, with its size and nesting bounded; PipelineError naming ``what``."""
    if len(text) > max_chars:
        raise PipelineError(f"{what} is {len(text)} characters long; at most {max_chars}")
    depth = json_depth(text)
    if depth > MAX_DEPTH:
        raise PipelineError(f"{what} nests {depth} levels deep; at most {MAX_DEPTH}")
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise PipelineError(f"{what} is not valid JSON: {exc}") from None
    except ValueError:  # Python's limit on the digits of an integer it converts
        raise PipelineError(f"{what} holds a number with more digits than can be read") from None


class Step(BaseModel):
    """One step: an operator name and its parameters."""

    model_config = ConfigDict(extra="forbid")
    op: str = Field(description="operator name (see GET /v1/operators or `depict ops`)")
    params: dict[str, Any] = Field(default_factory=dict, description="operator parameters")


class PipelineSpec(BaseModel):
    """A pipeline: steps applied in order."""

    model_config = ConfigDict(extra="forbid")
    steps: list[Step] = Field(min_length=1, max_length=MAX_STEPS)


DEFAULT_PIPELINE = PipelineSpec(steps=[Step(op="radiance_scaling")])


def parse(spec: PipelineSpec | dict[str, Any] | Sequence[Any] | str) -> PipelineSpec:
    """A pipeline from a model, a dict, a list of steps or JSON text; PipelineError if invalid."""
    if isinstance(spec, PipelineSpec):
        return spec
    if isinstance(spec, str):
        data = loads(spec, "pipeline")
    else:
        data = spec
        depth = value_depth(data)
        if depth > MAX_DEPTH:
            raise PipelineError(f"pipeline nests more than {MAX_DEPTH} levels deep")
    if isinstance(data, list):
        data = {"steps": data}
    try:
        return PipelineSpec.model_validate(data)
    except ValidationError as exc:
        first = exc.errors()[0]
        loc = ".".join(str(p) for p in first["loc"])
        raise PipelineError(
            f"pipeline {loc}: {first['msg']}; expected "
            '{"steps": [{"op": NAME, "params": {...}}, ...]}'
        ) from None


def load(path: str | Path) -> PipelineSpec:
    """Read a pipeline JSON file."""
    try:
        text = read_text(path)
    except OSError as exc:
        raise PipelineError(f"cannot read pipeline {path}: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise PipelineError(f"cannot read pipeline {path}: it is not UTF-8 text") from None
    return parse(text)


@dataclass(frozen=True)
class CompiledStep:
    """A step compiled: its operator resolved and its parameters validated."""

    op: Operator
    params: Params


@dataclass(frozen=True)
class Pipeline:
    """A pipeline parsed and validated once (:func:`compile`): what :func:`run` and
    :func:`service.enhance.enhance` take. ``spec`` is the pipeline as given (what a client
    sends on); a worker process receives the validated parameters as they are (pickled by
    operator name), so nothing is validated twice."""

    spec: PipelineSpec
    steps: tuple[CompiledStep, ...]

    def __reduce__(self) -> tuple[Any, ...]:
        return (_restore, (self.spec, tuple((s.op.name, s.params) for s in self.steps)))


def _restore(spec: PipelineSpec, steps: tuple[tuple[str, Params], ...]) -> Pipeline:
    return Pipeline(spec, tuple(CompiledStep(get(name), params) for name, params in steps))


def compile(spec: Pipeline | PipelineSpec | dict[str, Any] | Sequence[Any] | str) -> Pipeline:
    """Parse ``spec`` (:func:`parse`), resolve its operators and validate every step's
    parameters, before any pixel is read; :class:`PipelineError` naming the bad step."""
    if isinstance(spec, Pipeline):
        return spec
    parsed = parse(spec)
    return Pipeline(
        parsed, tuple(CompiledStep(get(s.op), get(s.op).parse(s.params)) for s in parsed.steps)
    )


DEFAULT = compile(DEFAULT_PIPELINE)


def run_timed(
    frame: Frame, pipeline: Pipeline, context: Context
) -> tuple[Frame, list[tuple[str, float]]]:
    """Apply ``pipeline`` to a copy of ``frame``: the result and the seconds of each step."""
    hgt, wid = frame.shape
    if hgt * wid < 2:
        raise PipelineError(f"the frame is {wid}x{hgt} pixels; the operators need 2 or more")
    out = frame.copy()
    op_s: list[tuple[str, float]] = []
    holes.fill(out)  # pixels of NaN/Inf radiance: uncovered for the operators (gbuffer.holes)
    check_normals(out)
    for step in pipeline.steps:
        t0 = time.perf_counter()
        _apply(out, step, context)
        op_s.append((step.op.name, time.perf_counter() - t0))
    holes.restore(out)  # and given back unchanged
    return out, op_s


def check_normals(frame: Frame) -> None:
    """A :class:`PipelineError` counting the covered pixels whose normal is nowhere near a unit
    vector, a component past ±2 (:data:`gbuffer.frame.NORMAL_COMPONENT_MAX`): normals of 1e20
    made curvature, Light Alignment and Apparent Relief NaN, and unsharp masking blame a gain
    map it was not given. One OpenCV pass where every normal is in range; what lies off the
    surface is not counted, and NaN is left to the operators that read it (they ignore it off
    the surface)."""
    normal = frame.buffers.get("normal")
    if normal is None or normal.size == 0 or normals_in_range(normal):
        return
    peak = np.abs(np.asarray(normal, np.float32)).max(axis=2)
    far = (peak > NORMAL_COMPONENT_MAX) & frame.covered()
    count = int(np.count_nonzero(far))
    if count:
        raise PipelineError(
            f"the normal is not a unit vector at {count} covered pixel{'s' * (count != 1)} "
            f"(components up to {float(peak[far].max()):.3g}): give unit camera-space normals "
            "there, or coverage 0"
        )


def _apply(frame: Frame, step: CompiledStep, context: Context) -> None:
    op = step.op
    for buffer in op.needs:
        frame.need(buffer, f"needed by {op.name}")
    if op.needs_camera:
        frame.need_camera(f"{op.name} needs the camera")
    try:
        op.run(frame, step.params, context)  # apply, restricted to the step's mask
    except FrameError:
        raise
    except ValueError as exc:  # ops/ names a bad value in a ValueError
        said = str(exc)  # (prefixed with the operator's name once)
        named = said if said.startswith(f"{op.name}: ") else f"{op.name}: {said}"
        raise PipelineError(named) from None
    frame.history.append({"op": op.name, "params": step.params.model_dump(mode="json")})


def run(
    frame: Frame,
    spec: Pipeline | PipelineSpec | dict[str, Any] | Sequence[Any] | str,
    *,
    debug_layers: bool = False,
    context: Context | None = None,
) -> Frame:
    """Apply the pipeline to a copy of ``frame`` and return it (``frame`` is not changed).

    The enhanced image is ``out.buffers["beauty"]``; layers the operators wrote are in
    ``out.outputs``. Call :func:`finish` to place the beauty in its result layer for writing.
    """
    out, _ = run_timed(frame, compile(spec), context or Context(debug_layers=debug_layers))
    return out
