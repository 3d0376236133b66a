"""``apparent_relief``: the Apparent Relief descriptor, an Apparent Relief Map lookup and a
shading style (Vergne et al., NPAR 2008, §2-3, Figs. 1-2) on a frame.

The ARM is one of the shipped maps (:data:`ops.relief.SHIPPED_ARMS`), a layer of the file, or
(on the command line) an image file; ``depict arm`` writes the template to paint one on.
Styles: ``cel`` (r itself, Fig. 1c-d), ``counter`` (counter shading thresholded at
``threshold``, Fig. 2b), ``xtoon`` (X-Toon texture indexed by (n·ℓ, r), Fig. 2a), ``mask`` (r
blends the current beauty with the result of the ``effect`` step, e.g. exaggerated shading
only on the selected features, Fig. 2c) and ``descriptor`` (the Fig. 1a colour code).

Writes the beauty and the layers ``relief.X`` (r), ``relief.S.X/Y`` (the descriptor S); with
``--debug-layers`` also ``relief.color.R/G/B`` (the colour code).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Annotated, Any, Literal

import cv2
import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from gbuffer.errors import FrameError
from gbuffer.frame import Frame
from ops import checks
from ops import relief as rl
from ops.parallel import run_strips
from ops.shading import lambert, light_vectors, parse_light
from service.errors import PipelineError
from service.masks import layer_plane
from service.operators.base import Context, get, register
from service.operators.common import Auto, LightText, channels, user_image
from service.operators.curvature import CurvatureParams, frame_curvature

Style = Literal["cel", "counter", "xtoon", "mask", "descriptor"]


class EffectStep(BaseModel):
    """A pipeline step run on a copy of the frame, for ``style: mask``."""

    model_config = ConfigDict(extra="forbid")

    op: str = Field(description="operator name (e.g. exaggerated_shading, radiance_scaling)")
    params: dict[str, Any] = Field(default_factory=dict, description="its parameters")


class ReliefParams(CurvatureParams):
    """Apparent Relief (Vergne et al. 2008): descriptor, ARM lookup, style."""

    scale: float = Field(
        rl.DEFAULT_SCALE,
        **checks.CURVATURE_SCALE.bounds,
        description="curvature scale relative to the image height: the level of detail",
    )
    arm: str = Field(
        "convex_black_concave_white",
        description=f"Apparent Relief Map: a shipped one ({', '.join(rl.SHIPPED_ARMS)}), a "
        "layer of the file, or (command line) an image file",
    )
    curvedness_norm: Annotated[float, Field(**checks.CURVEDNESS_NORM.bounds)] | Auto = Field(
        "auto",
        description="curvedness mapped to |S| = 1, per image height (auto: the `percentile` of "
        "the surface; pin it for sequences)",
    )
    percentile: float = Field(
        rl.DEFAULT_PERCENTILE, **checks.PERCENTILE.bounds, description="of auto"
    )
    style: Style = Field("cel", description="cel, counter, xtoon, mask or descriptor")
    light: LightText = Field(
        "-0.4,0.6,0.7", description="counter / xtoon: the light giving n·ℓ (camera space)"
    )
    threshold: float = Field(0.5, **checks.FRACTION.bounds, description="counter shading threshold")
    toon: str | None = Field(
        None, description="xtoon: a 2-D toon texture image (default: a warm 3-tone ramp)"
    )
    effect: EffectStep | None = Field(
        None, description='mask: the step whose result r selects, e.g. {"op": "radiance_scaling"}'
    )

    @field_validator("light")
    @classmethod
    def _light(cls, value: str) -> str:
        parse_light(value)
        return value

    @model_validator(mode="after")
    def _check(self) -> ReliefParams:
        if self.style == "mask" and self.effect is None:
            raise ValueError(
                'style \'mask\' needs `effect`: a step such as {"op": "radiance_scaling"}'
            )
        return self


@functools.cache
def _shipped_arm(name: str) -> np.ndarray:
    """A shipped ARM, decoded once (read-only)."""
    img = cv2.imread(str(rl.shipped_arm_path(name)), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise FrameError(f"the shipped ARM {name!r} cannot be read")
    arm = rl.arm_from_image(img)
    arm.setflags(write=False)
    return arm


def load_arm(frame: Frame, name: str, ctx: Context) -> np.ndarray:
    """An ARM by name: shipped, a layer of the frame's file, or an image file (where allowed)."""
    if name in rl.SHIPPED_ARMS:
        return _shipped_arm(name)
    if frame.layer(name):
        return rl.arm_from_image(layer_plane(frame, name, "arm"))
    return rl.arm_from_image(user_image(ctx, name, "arm", srgb=False, grey=True))


def _lit(frame: Frame, p: ReliefParams) -> dict[str, np.ndarray]:
    """What the counter / X-Toon styles need for n·ℓ: the normals and the light vector of a
    directional light (n·ℓ is then computed in the style's own pass), else the per-pixel
    Lambert term towards a point light."""
    light = parse_light(p.light)
    normal = frame.need("normal", f"style {p.style!r}")
    if light.kind == "directional":
        return {"normal": normal, "light": np.asarray(light.vector, np.float32)}
    return {"ndotl": lambert(normal, light_vectors(light, frame.positions()))}


Block = tuple[slice, slice]
_FULL: Block = (slice(None), slice(None))
_COMPOSE_ROWS = 135  # rows per strip of the composite (8 strips at 1080p)
_CROP_MAX = 0.6  # shade only the covered box when it is at most this fraction of the frame


def _covered_box(covered: np.ndarray) -> Block:
    """The bounding box (rows, columns) of the True pixels of ``covered`` (empty if none)."""
    rows = np.flatnonzero(covered.any(axis=1))
    cols = np.flatnonzero(covered.any(axis=0))
    if rows.size == 0:
        return slice(0, 0), slice(0, 0)
    return slice(int(rows[0]), int(rows[-1]) + 1), slice(int(cols[0]), int(cols[-1]) + 1)


def _over(src: np.ndarray, base: np.ndarray, covered: np.ndarray, dst: np.ndarray) -> None:
    """``dst = np.where(covered, rgb(src), base)`` for an (h, w) grey ``src``, or in place
    (``dst`` is ``src``) for an (h, w, 3) one, in row strips on both cores: cv2.cvtColor and
    cv2.copyTo, which write into array views in place (np.where with a broadcast condition is
    ~10x slower)."""
    grey = src.ndim == 2

    def strip(r0: int, r1: int) -> None:
        if grey:
            cv2.cvtColor(src[r0:r1], cv2.COLOR_GRAY2RGB, dst=dst[r0:r1])
        uncovered = np.logical_not(covered[r0:r1]).view(np.uint8)
        cv2.copyTo(base[r0:r1], uncovered, dst[r0:r1])

    run_strips(dst.shape[0], strip, _COMPOSE_ROWS)


def _beauty(shade: Callable[[Block], np.ndarray], frame: Frame, crop: bool) -> np.ndarray:
    """The beauty the operator writes: ``shade(block)``, the style on a block of the frame as RGB
    (grey repeated, alpha dropped), where the frame is covered (``mask > 0``), and the frame's
    own beauty elsewhere: ``np.where(mask > 0, rgb(shade(all)), beauty)``. With ``crop`` (an
    expensive style), only the covered pixels' bounding box is shaded when it is at most
    _CROP_MAX of the frame (the rest is the beauty anyway): the same result, pixel for pixel."""
    base = frame.buffers.get("beauty")
    if base is None:
        styled = _rgb(shade(_FULL))
        return np.asarray(cv2.cvtColor(styled, cv2.COLOR_GRAY2RGB)) if styled.ndim == 2 else styled
    h, w = frame.shape
    covered = frame.covered()
    if base.shape != (h, w, 3) or base.dtype != np.float32:
        styled = _rgb(shade(_FULL))
        img = np.repeat(styled[..., None], 3, axis=2) if styled.ndim == 2 else styled
        return np.where(covered[..., None], img, base)
    rows, cols = _covered_box(covered) if crop else (slice(0, h), slice(0, w))
    if (rows.stop - rows.start) * (cols.stop - cols.start) > _CROP_MAX * h * w:
        rows, cols = slice(0, h), slice(0, w)
    if rows.stop - rows.start == h and cols.stop - cols.start == w:
        styled = _rgb(shade(_FULL))
        out = np.empty((h, w, 3), np.float32) if styled.ndim == 2 else styled
        _over(styled, base, covered, out)
        return out
    out = np.empty((h, w, 3), np.float32)
    styled = _rgb(shade((rows, cols))) if rows.stop > rows.start else np.empty((0, 0, 3))
    if styled.ndim == 2:
        styled = np.asarray(cv2.cvtColor(styled, cv2.COLOR_GRAY2RGB))
    covered_u8 = covered.view(np.uint8)

    def strip(r0: int, r1: int) -> None:  # the beauty, then the style on the covered box
        np.copyto(out[r0:r1], base[r0:r1])
        a, b = max(r0, rows.start), min(r1, rows.stop)
        if a < b:
            box = slice(a - rows.start, b - rows.start)
            cv2.copyTo(styled[box], covered_u8[a:b, cols], out[a:b, cols])

    run_strips(h, strip, _COMPOSE_ROWS)
    return out


def _rgb(styled: np.ndarray) -> np.ndarray:
    """A style's result as (h, w) grey or (h, w, 3) float32 (alpha dropped)."""
    if styled.ndim == 3 and (styled.shape[2] != 3 or styled.dtype != np.float32):
        return np.ascontiguousarray(styled[..., :3], np.float32)
    return styled


def _effect(frame: Frame, step: EffectStep, ctx: Context) -> np.ndarray:
    op = get(step.op)
    if op.name == "apparent_relief":
        raise PipelineError("apparent_relief: the mask effect cannot be apparent_relief itself")
    copy = frame.copy()
    for buffer in op.needs:
        copy.need(buffer, f"needed by {op.name} (the mask effect)")
    op.run(copy, op.parse(step.params), ctx)
    return copy.need("beauty", f"the result of {op.name}")


def _mask_layers(
    frame: Frame, p: ReliefParams, ctx: Context
) -> tuple[np.ndarray, np.ndarray] | tuple[None, None]:
    """For style ``mask``: the beauty and the effect it is blended with; else (None, None)."""
    if p.style != "mask":
        return None, None
    assert p.effect is not None
    before = frame.need("beauty", "style 'mask' blends the beauty with the effect")
    return before, _effect(frame, p.effect, ctx)


def _curvedness_norm(p: ReliefParams, ctx: Context, key: str) -> float | Literal["auto"]:
    """The norm given, else the one pinned for a sequence, else ``"auto"`` (measured here)."""
    if p.curvedness_norm != "auto":
        return p.curvedness_norm
    return ctx.pinned.get(key, "auto")


@register(
    "apparent_relief",
    summary="Apparent Relief (Vergne et al. 2008): curvature descriptor S, Apparent Relief Map "
    "lookup r, and cel / counter / X-Toon / mask styles",
    params=ReliefParams,
    needs=("normal", "depth"),
    writes=("beauty", "relief.X", "relief.S.X/Y", "relief.color.R/G/B (debug)"),
)
def apply_apparent_relief(frame: Frame, p: ReliefParams, ctx: Context) -> None:
    """Apparent Relief (§2, Figs. 1-2): S and r = ARM(S) fused on the curvature's working grid
    (:func:`ops.relief.relief`; S also interpolated to full resolution for the ``relief.S``
    layers), then the style over the covered pixels."""
    curv = frame_curvature(frame, p, ctx)
    key = "apparent_relief.curvedness_norm"
    norm = _curvedness_norm(p, ctx, key)
    arm = load_arm(frame, p.arm, ctx)
    rel = rl.relief(curv, arm, curvedness_norm=norm, percentile=p.percentile, with_descriptor=True)
    if norm == "auto":
        ctx.measured[key] = rel.norm
    assert rel.s1 is not None and rel.s2 is not None
    r = rel.r if rel.r.ndim == 2 else np.ascontiguousarray(rel.r[..., 0])
    colors: np.ndarray | None = None
    debug: dict[str, np.ndarray] = {}
    if ctx.debug_layers:
        colors = rl.descriptor_colors(cv2.merge([rel.s1, rel.s2]))
        debug = channels(colors, "RGB")  # copies: the descriptor style may reuse colors
    lit = _lit(frame, p) if p.style in ("counter", "xtoon") else {}
    toon = user_image(ctx, p.toon, "toon", srgb=False) if p.toon and p.style == "xtoon" else None
    before, effect = _mask_layers(frame, p, ctx)
    lo, hi = cv2.minMaxLoc(r)[:2] if p.style == "cel" else (0.0, 1.0)

    def shade(block: Block) -> np.ndarray:
        """The style on a block of the frame (a fresh array, but for cel's r itself)."""
        rb = r[block]
        on = {k: v[block] if v.ndim > 1 else v for k, v in lit.items()}
        if p.style == "cel":  # I = r (rl.cel: r clipped, a copy; _beauty copies anyway)
            return rb if 0.0 <= lo and hi <= 1.0 else rl.cel(rb)
        if p.style == "counter":
            return rl.counter_shading(rb, threshold=p.threshold, **on)
        if p.style == "xtoon":
            return rl.xtoon(rb, toon=toon, **on)
        if p.style == "descriptor":
            if colors is not None:
                return colors[block]
            assert rel.s1 is not None and rel.s2 is not None
            return rl.descriptor_colors(cv2.merge([rel.s1[block], rel.s2[block]]))
        assert before is not None and effect is not None
        return rl.masked(rb, before[block], effect[block])

    frame.buffers["beauty"] = _beauty(shade, frame, crop=p.style in ("xtoon", "descriptor"))
    frame.set_layer("relief", {"X": r})
    frame.set_layer("relief.S", {"X": rel.s1, "Y": rel.s2})
    if debug:
        frame.set_layer("relief.color", debug)
