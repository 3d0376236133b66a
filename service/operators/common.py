"""Parameter pieces and frame helpers shared by several operators."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Annotated, Any, Literal

import cv2
import numpy as np
from pydantic import BeforeValidator, Field, field_validator

from gbuffer.frame import NORMAL_COMPONENT_MAX, Frame, normal_faults
from ops import checks
from ops.color import luminance
from ops.lighting import luminance_gain
from ops.numerics import finite_quotient
from ops.radiance_scaling import covered_percentile
from ops.shading import LIGHT_SYNTAX, Light, parse_light
from service.errors import PipelineError
from service.images import load_image
from service.operators.base import Context, Params

#: α of Radiance Scaling's Eq. 2.
Alpha = Annotated[float, Field(**checks.ALPHA.bounds)]
#: γ of Radiance Scaling's Eq. 2.
Gamma = Annotated[float, Field(**checks.GAMMA.bounds)]
#: ``"auto"`` (measured on the frame, pinnable for a sequence) or a number.
Auto = Literal["auto"]
#: A linear white level, or ``auto`` (measured on the frame, pinned along a sequence).
WhiteLevel = Annotated[float, Field(**checks.WHITE.bounds)] | Auto

#: A key light from the upper left and a dim fill from the right (camera space).
DEFAULT_LIGHTS = ["-0.4,0.6,0.7", "0.6,0.2,0.5*0.35"]


class LightsParams(Params):
    """Explicit lights for operators that shade the G-buffer themselves."""

    lights: list[str] = Field(
        default_factory=lambda: list(DEFAULT_LIGHTS),
        min_length=1,
        max_length=16,
        description=f"lights in camera space, {LIGHT_SYNTAX}: 'X,Y,Z' is a directional light "
        "(towards it), 'point:X,Y,Z' a point light",
    )

    @field_validator("lights", mode="before")
    @classmethod
    def _one_light(cls, value: Any) -> Any:
        """One light given as its text, or as what ``--set lights=X,Y,Z`` makes of it (its
        comma-separated pieces, numbers or not): a list of that one light. Pieces that are
        lights each stay several lights."""
        if isinstance(value, str):
            return [value]
        joined = joined_light(value)
        if joined is None:
            return value
        if not all(isinstance(v, str) for v in value):  # (numbers: pieces of one light)
            return [joined]
        if not all(_is_light(p) for p in value) and _is_light(joined):
            return [joined]
        return value

    @field_validator("lights")
    @classmethod
    def _lights(cls, value: list[str]) -> list[str]:
        for text in value:
            parse_light(text)  # raises ValueError naming what is wrong
        return value

    def parsed_lights(self) -> list[Light]:
        return [parse_light(text) for text in self.lights]


def joined_light(value: Any) -> str | None:
    """The text of a light that ``--set NAME=X,Y,Z`` split into its comma-separated pieces
    (numbers or text), joined again; None unless ``value`` is a non-empty list of such pieces."""
    if not isinstance(value, list) or not value:
        return None
    if not all(isinstance(v, int | float | str) and not isinstance(v, bool) for v in value):
        return None
    return ",".join(str(v) for v in value)


def _one_light_text(value: Any) -> Any:
    """A light given as its text, or as what ``--set light=X,Y,Z`` makes of it (its
    comma-separated pieces, numbers or not: ``-1,1,1`` was refused as 'not a valid string'),
    joined back into its text."""
    joined = joined_light(value)
    return value if joined is None else joined


#: A parameter holding one light's text (:func:`ops.shading.parse_light`), also given as a list
#: of its pieces (``--set light=-1,1,1``, ``"light": [-1, 1, 1]`` over HTTP).
LightText = Annotated[str, BeforeValidator(_one_light_text)]


def _is_light(text: str) -> bool:
    try:
        parse_light(text)
    except ValueError:
        return False
    return True


def statistic(ctx: Context, key: str, value: float | str, compute: Callable[[], float]) -> float:
    """``value`` when it is a number, else the pinned or measured statistic ``key``."""
    if value != "auto":
        return float(value)
    return ctx.statistic(key, compute)


def user_image(ctx: Context, path: str, what: str, **kwargs: Any) -> np.ndarray:
    """An image file named by a parameter, where this run may read files (not over HTTP);
    ``kwargs``: those of :func:`service.images.load_image` (``space``: the frame's)."""
    if not ctx.files:
        raise PipelineError(
            f"{what}: image files cannot be named here ({path!r}); use a layer of the uploaded "
            "file or a built-in name"
        )
    return load_image(path, **kwargs)


def surface_normals(frame: Frame, why: str) -> np.ndarray:
    """The frame's normals, with what is no normal off the surface (NaN, Inf, a component past
    ±2: a frame built in Python may hold anything there; files are read with 0) made 0: a
    :class:`PipelineError` counts the covered pixels whose normal is NaN or Inf (a file's are
    refused as it is read; ``pipeline.run`` refuses those past ±2)."""
    normal = frame.need("normal", why)
    if not any(normal_faults(normal)):
        return normal
    bad = ~(np.abs(normal) <= NORMAL_COMPONENT_MAX).all(axis=2)  # (NaN: not <=)
    covered = int(np.count_nonzero(bad & frame.covered()))
    if covered:
        raise PipelineError(
            f"{why}: the normal is NaN or Inf at {covered} covered pixel{'s' * (covered != 1)} "
            "(give those pixels coverage 0, or a finite normal)"
        )
    return np.where(bad[..., None], np.float32(0.0), normal).astype(np.float32)


def frame_albedo(frame: Frame, albedo: float | None) -> np.ndarray:
    """The frame's albedo buffer, or a constant grey (``albedo``, or 0.8 without one)."""
    if albedo is None and "albedo" in frame.buffers:
        return frame.buffers["albedo"]
    return np.full(3, 0.8 if albedo is None else albedo, np.float32)


def pixel_sizes(frame: Frame, why: str) -> np.ndarray:
    """Scene units per pixel at each pixel (depth / focal length, or the orthographic size)."""
    camera = frame.need_camera(why)
    depth = frame.need("depth", why)
    if camera.projection == "orthographic":
        return camera.pixel_size_at(depth, frame.image_height)
    return finite_quotient(depth, camera.focal_px(frame.image_height))


#: Vertical field of view assumed for sizes relative to the image height when a frame has no
#: camera (they only need pixel sizes up to a common factor).
NOMINAL_FOV_Y_DEG = 40.0


def relative_pixel_sizes(frame: Frame, why: str) -> np.ndarray:
    """:func:`pixel_sizes` with the frame's camera (one with a field of view), else with a
    perspective camera of :data:`NOMINAL_FOV_Y_DEG`: enough for smoothing whose size is relative
    to the image height (its size in scene units is taken at the covered pixels' median pixel
    size)."""
    if frame.camera is not None and frame.camera.has_intrinsics:
        return pixel_sizes(frame, why)
    depth = frame.need("depth", why)
    focal = 0.5 * frame.image_height / math.tan(math.radians(NOMINAL_FOV_Y_DEG) / 2.0)
    return finite_quotient(depth, focal)


#: Relative luminance change from which an operator's change is corrected in full by
#: :func:`kept_lighting_gain` (smaller changes are corrected in proportion).
KEPT_CHANGE = 0.05


def kept_lighting_gain(
    frame: Frame, before: np.ndarray, after: np.ndarray, scale: float, why: str
) -> np.ndarray:
    """:func:`ops.lighting.luminance_gain` of an operator's change on ``frame``: the factor per
    pixel that gives ``after`` the low-frequency luminance of ``before`` along the surfaces, at
    ``scale`` (relative to the image height); each of them RGB (H, W, 3) or already a luminance
    (H, W). The correction is weighed by how much the operator changed each pixel,
    ``min(1, |ΔY| / (KEPT_CHANGE · Y))``: what it left alone stays bit for bit, and the
    correction fades out continuously where the change does (a cut-off would draw a line where
    the curvature ends, e.g. beside a CAD part's creases)."""
    pixel_size = relative_pixel_sizes(frame, why)
    y0, y1 = (x if x.ndim == 2 else luminance(x, frame.colorspace.weights) for x in (before, after))
    return luminance_gain(
        y0,
        y1,
        frame.need("depth", why),
        frame.buffers.get("normal"),
        frame.mask,
        sigma_scene=relative_scene_sigma(frame, pixel_size, scale),
        pixel_size=pixel_size,
        full_change=KEPT_CHANGE,  # (weighed_gain, in the same pass)
    )


def relative_scene_sigma(frame: Frame, pixel_size: np.ndarray, fraction: float) -> float:
    """``fraction`` of the image height in scene units at the covered pixels' median pixel size
    (its finite values; 1.0 when nothing is covered)."""
    median = covered_percentile(pixel_size, frame.mask > 0, 50.0)
    return 1.0 if math.isnan(median) else fraction * frame.image_height * median


def channels(field: np.ndarray, names: str = "XYZ", *, copy: bool = True) -> dict[str, np.ndarray]:
    """An (H, W, C) field as output channels ``{"X": ..., "Y": ..., "Z": ...}``: new planes, or
    with ``copy=False`` views of a float32 ``field`` nothing changes afterwards (the EXR
    writer makes each plane contiguous as it encodes it, so a layer nobody writes costs
    nothing)."""
    field = np.asarray(field, np.float32)
    if not copy:
        return {n: field[..., i] for i, n in enumerate(names)}
    planes = cv2.split(np.ascontiguousarray(field))
    return {n: np.asarray(planes[i]) for i, n in enumerate(names)}


def holds_light(frame: Frame, lobe: str) -> bool:
    """Whether the frame has ``lobe`` with light in it: a value other than 0 (NaN counts) in the
    lobe or in its light. One early-exit pass over each."""
    for name in (lobe, f"{lobe}.light"):
        buffer = frame.buffers.get(name)
        if buffer is not None:
            plane = np.ascontiguousarray(buffer, np.float32)
            if cv2.hasNonZero(plane.reshape(plane.shape[0], -1)):
                return True
    return False
