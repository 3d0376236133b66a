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

from typing import Any, Literal

import cv2
import numpy as np
from pydantic import Field, field_validator, model_validator

from gbuffer.frame import Frame
from ops import relief as rl
from ops.shading import lambert, light_vectors, parse_light
from service.operators.common import Auto, channels, layer_plane, user_image
from service.operators.curvature import CurvatureParams, frame_curvature
from service.registry import Context, Params, PipelineError, get, register

Style = Literal["cel", "counter", "xtoon", "mask", "descriptor"]


class EffectStep(Params):
    """A pipeline step run on a copy of the frame, for ``style: mask``."""

    op: str = Field(description="operator name (e.g. exaggerated_shading, radiance_scaling)")
    params: dict[str, Any] = Field(default_factory=dict, description="its parameters")


class ReliefParams(CurvatureParams):
    """Apparent Relief (Vergne et al. 2008): descriptor, ARM lookup, style."""

    scale: float = Field(
        rl.DEFAULT_SCALE,
        gt=0.0,
        le=0.1,
        description="curvature scale relative to the image height: the level of detail",
    )
    arm: str = Field(
        "convex_black_concave_white",
        description=f"Apparent Relief Map: a shipped one ({', '.join(rl.SHIPPED_ARMS)}), a "
        "layer of the file, or (command line) an image file",
    )
    curvedness_norm: float | Auto = Field(
        "auto",
        description="curvedness mapped to |S| = 1, per image height (auto: the `percentile` of "
        "the surface; pin it for sequences)",
    )
    percentile: float = Field(rl.DEFAULT_PERCENTILE, gt=0.0, le=100.0, description="of auto")
    style: Style = Field("cel", description="cel, counter, xtoon, mask or descriptor")
    light: str = Field(
        "-0.4,0.6,0.7", description="counter / xtoon: the light giving n·ℓ (camera space)"
    )
    threshold: float = Field(0.5, ge=0.0, le=1.0, description="counter shading threshold")
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
        if isinstance(self.curvedness_norm, float) and not 0.0 < self.curvedness_norm <= 1e6:
            raise ValueError("curvedness_norm must be in (0, 1e6] or 'auto'")
        return self


def load_arm(frame: Frame, name: str, ctx: Context) -> np.ndarray:
    """An ARM by name: shipped, a layer of the frame's file, or an image file (where allowed)."""
    if name in rl.SHIPPED_ARMS:
        return rl.arm_from_image(cv2.imread(str(rl.shipped_arm_path(name)), cv2.IMREAD_UNCHANGED))
    if frame.layer(name):
        return rl.arm_from_image(layer_plane(frame, name, "arm"))
    return rl.arm_from_image(user_image(ctx, name, "arm", srgb=False, grey=True))


def _ndotl(frame: Frame, p: ReliefParams) -> np.ndarray:
    light = parse_light(p.light)
    normal = frame.need("normal", f"style {p.style!r}")
    direction = (
        np.asarray(light.vector, np.float32)
        if light.kind == "directional"
        else light_vectors(light, frame.positions())
    )
    return lambert(normal, direction)


def _effect(frame: Frame, step: EffectStep, ctx: Context) -> np.ndarray:
    op = get(step.op)
    if op.name == "apparent_relief":
        raise PipelineError("apparent_relief: the mask effect cannot be apparent_relief itself")
    copy = frame.copy()
    for buffer in op.needs:
        copy.need(buffer, f"needed by {op.name} (the mask effect)")
    op.apply(copy, op.parse(step.params), ctx)
    return copy.need("beauty", f"the result of {op.name}")


@register(
    "apparent_relief",
    summary="Apparent Relief (Vergne et al. 2008): curvature descriptor S, Apparent Relief Map "
    "lookup r, and cel / counter / X-Toon / mask styles",
    params=ReliefParams,
    needs=("normal", "depth"),
    writes=("beauty", "relief.X", "relief.S.X/Y", "relief.color.R/G/B (debug)"),
)
def apply_apparent_relief(frame: Frame, p: ReliefParams, ctx: Context) -> None:
    curv = frame_curvature(frame, p)
    key = "apparent_relief.curvedness_norm"
    norm = p.curvedness_norm if p.curvedness_norm != "auto" else ctx.pinned.get(key, "auto")
    desc = rl.descriptor(curv, curvedness_norm=norm, percentile=p.percentile)
    if norm == "auto":
        ctx.measured[key] = desc.norm
    arm = load_arm(frame, p.arm, ctx)
    r = rl.arm_lookup(desc.s, arm)
    if r.ndim == 3:
        r = np.ascontiguousarray(r[..., 0])
    covered = (frame.mask > 0)[..., None]
    base = frame.buffers.get("beauty")
    if p.style == "cel":
        styled = rl.cel(r)
    elif p.style == "counter":
        styled = rl.counter_shading(r, _ndotl(frame, p), p.threshold)
    elif p.style == "xtoon":
        toon = user_image(ctx, p.toon, "toon", srgb=False) if p.toon else None
        styled = rl.xtoon(r, _ndotl(frame, p), toon)
    elif p.style == "descriptor":
        styled = rl.descriptor_colors(desc.s)
    else:
        assert p.effect is not None
        before = frame.need("beauty", "style 'mask' blends the beauty with the effect")
        styled = rl.masked(r, before, _effect(frame, p.effect, ctx))
    img = styled if styled.ndim == 3 else np.repeat(styled[..., None], 3, axis=2)
    img = np.ascontiguousarray(img[..., :3], np.float32)
    frame.buffers["beauty"] = img if base is None else np.where(covered, img, base)
    frame.set_layer("relief", {"X": r})
    frame.set_layer("relief.S", {"X": desc.s[..., 0], "Y": desc.s[..., 1]})
    if ctx.debug_layers:
        colors = rl.descriptor_colors(desc.s)
        frame.set_layer("relief.color", channels(colors, "RGB"))
