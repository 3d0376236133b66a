"""The operator registry: one entry per operator, from which the CLI, HTTP schema and docs follow.

An entry names the operator, its pydantic parameter model (ranges, defaults, units and
descriptions live there), the frame buffers it needs, the layers it writes, and the function that
applies it to a frame (:class:`service.operators.base.Operator`). Adding an operator means one
function in ``ops/`` and one :func:`register` call in a module of :mod:`service.operators`;
importing this module registers the built-in ones.
"""

from __future__ import annotations

from typing import Any

import service.operators  # noqa: F401  (registers the built-in operators)
from service.errors import PipelineError
from service.operators.base import (
    REGISTRY,
    Apply,
    Context,
    Operator,
    Params,
    describe_validation,
    get,
    register,
)

__all__ = [
    "REGISTRY",
    "Apply",
    "Context",
    "Operator",
    "Params",
    "PipelineError",
    "describe_validation",
    "get",
    "operators",
    "register",
    "runnable",
]


def operators() -> dict[str, Operator]:
    """Every registered operator, by name, in registration order."""
    return REGISTRY


def _tells_pixel_sizes(camera: dict[str, Any] | None) -> bool:
    """Whether an inspected camera (:meth:`gbuffer.camera.Camera.to_dict`) has its intrinsics."""
    if camera is None:
        return False
    orthographic = camera.get("projection") == "orthographic"
    return camera.get("ortho_height" if orthographic else "fov_y_deg") is not None


def runnable(info: dict[str, Any]) -> dict[str, Any]:
    """Which operators can run on the inspected frame, and what the others lack."""
    have = set(info["buffers"])
    if "position" in have:
        have.add("depth")
    blocked = {}
    for op in operators().values():
        lacks = [b for b in op.needs if b not in have]
        if op.needs_camera and not _tells_pixel_sizes(info["camera"]):
            lacks.append("camera" if info["camera"] is None else "the camera's intrinsics")
        if lacks:
            blocked[op.name] = lacks
    return {"runnable": [n for n in operators() if n not in blocked], "not_runnable": blocked}
