"""``exaggerated_shading`` (Rusinkiewicz, Burns, DeCarlo, SIGGRAPH 2006) and ``light_warping``
(an image-space approximation of Vergne et al., SIGGRAPH 2009): the baselines of the Local Light
Alignment comparison (LLA §7), usable as operators. Each shades the G-buffer with one light and
writes the beauty (× the frame's albedo, or a constant)."""

from __future__ import annotations

from typing import Annotated

import numpy as np
from pydantic import Field, field_validator

from gbuffer.frame import Frame
from ops import checks
from ops.baselines import ES_SCALES, exaggerated_shading, light_warping
from ops.curvature import isotropic
from ops.shading import parse_light
from service.operators.base import Context, Params, register
from service.operators.common import LightText, frame_albedo, surface_normals
from service.operators.curvature import CurvatureParams, frame_curvature


class OneLightParams(Params):
    """One directional light and the albedo of a baseline shading."""

    light: LightText = Field(
        "-0.4,0.6,0.7", description="directional light, camera space (towards it)"
    )
    albedo: float | None = Field(
        None, **checks.WEIGHT.bounds, description="constant albedo (default: the frame's, else 0.8)"
    )

    @field_validator("light")
    @classmethod
    def _light(cls, value: str) -> str:
        if parse_light(value).kind != "directional":
            raise ValueError("the light must be directional (X,Y,Z)")
        return value

    def direction(self) -> np.ndarray:
        return np.asarray(parse_light(self.light).vector, np.float32)


def _shade(frame: Frame, p: OneLightParams, shading: np.ndarray) -> None:
    albedo = frame_albedo(frame, p.albedo)
    img = (np.asarray(shading, np.float32)[..., None] * albedo).astype(np.float32, copy=False)
    old = frame.buffers.get("beauty")
    frame.buffers["beauty"] = (
        img if old is None else np.where((frame.mask > 0)[..., None], img, old)
    )


class ExaggeratedParams(OneLightParams):
    """Exaggerated Shading (RBD06)."""

    scales: list[Annotated[float, Field(**checks.ES_SCALE.bounds)]] = Field(
        default_factory=lambda: list(ES_SCALES),
        min_length=1,
        max_length=12,
        description="smoothing σ of each scale, relative to the image height",
    )
    contrast: float = Field(
        8.0, **checks.CONTRAST.bounds, description="exaggeration a of clamp(a n·ℓ)"
    )
    weight_exponent: float = Field(
        -0.5, **checks.WEIGHT_EXPONENT.bounds, description="k_i ∝ σ_i^exponent"
    )
    ambient: float = Field(
        0.5, **checks.FRACTION.bounds, description="ambient of the half-Lambertian"
    )


@register(
    "exaggerated_shading",
    summary="Exaggerated Shading (Rusinkiewicz et al. 2006): multi-scale clamped half-Lambertian "
    "with the light made grazing at each scale",
    params=ExaggeratedParams,
    needs=("normal", "depth"),
    writes=("beauty",),
)
def apply_exaggerated_shading(frame: Frame, p: ExaggeratedParams, ctx: Context) -> None:
    shading = exaggerated_shading(
        surface_normals(frame, "exaggerated_shading"),
        frame.buffers["depth"],
        frame.mask,
        p.direction(),
        scales=p.scales,
        contrast=p.contrast,
        weight_exponent=p.weight_exponent,
        ambient=p.ambient,
        image_height=frame.image_height,
    )
    _shade(frame, p, shading)


class WarpingParams(OneLightParams, CurvatureParams):
    """Light Warping approximation for a directional light."""

    strength: float = Field(
        1.0, **checks.WEIGHT.bounds, description="how far curvature warps the light"
    )


@register(
    "light_warping",
    summary="Light Warping (Vergne et al. 2009), directional-light approximation: the light "
    "rotated towards / away from the view by view-centred curvature, Lambert shading",
    params=WarpingParams,
    needs=("normal", "depth"),
    writes=("beauty",),
)
def apply_light_warping(frame: Frame, p: WarpingParams, ctx: Context) -> None:
    shading = light_warping(
        surface_normals(frame, "light_warping"),
        frame.buffers["depth"],
        frame.mask,
        p.direction(),
        strength=p.strength,
        curvature=isotropic(frame_curvature(frame, p, ctx), p.gain),
        view=frame.view_vectors(),
        image_height=frame.image_height,
    )
    _shade(frame, p, shading)
