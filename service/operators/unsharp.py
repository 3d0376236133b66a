"""``unsharp_masking`` (3D Unsharp Masking, Ritschel et al., SIGGRAPH 2008, §4-5) and
``depth_unsharp_masking`` (Luft, Colditz, Deussen, SIGGRAPH 2006) on a frame.

``unsharp_masking`` enhances one signal — the beauty, one lobe, or the shadows — along the
surfaces (:func:`ops.unsharp.unsharp_masking`): the smooth signal is taken over the visible
surfaces with σ in scene units, converted per pixel with the depth and the focal length, so the
enhancement keeps its width on the surface whatever its distance. With ``sigma: "auto"`` the
width is ``sigma_fraction`` of the image height at the median depth of the surface, and a frame
without a camera works too: a 40° vertical field of view is then assumed to turn depth steps into
surface lengths (the smoothing's depth term depends on it; pass the camera for exact results).

Signals:

``beauty``
    the beauty (default).
``ambient`` / ``diffuse`` / ``specular`` / ``transmission``
    one renderer lobe; the beauty gets the lobe's change, everything else is untouched.
``shadows``
    the shadow term T = Y(beauty) / Y(unlit) (``unlit``: a layer of the file holding the same
    render without shadows, e.g. a shadow-free light AOV), T enhanced, the beauty multiplied by
    U(T)/T: only shadow edges gain contrast, shading and textures do not.
"""

from __future__ import annotations

from typing import Annotated, Any, ClassVar, Literal

import numpy as np
from pydantic import Field, model_validator

from gbuffer.frame import Frame
from ops import checks, color
from ops import curvature as curv_ops
from ops.color import luminance
from ops.unsharp import depth_unsharp_masking, surface_blur, unsharp_masking
from service.errors import PipelineError
from service.masks import plane
from service.operators.base import Context, Params, register
from service.operators.common import (
    Auto,
    WhiteLevel,
    kept_lighting_gain,
    pixel_sizes,
    relative_pixel_sizes,
    relative_scene_sigma,
    statistic,
)
from service.operators.curvature import CurvatureParams, frame_curvature, scale_px

Signal = Literal["beauty", "ambient", "diffuse", "specular", "transmission", "shadows"]


#: §4 as printed: every pixel's own lightness, enhanced everywhere (``preset: "paper"``).
PAPER = {"relief_only": False, "fine_scale": 0.0, "keep_lighting": False}


class UnsharpParams(Params):
    """3D unsharp masking (Ritschel et al. 2008, §4-5)."""

    PRESETS: ClassVar[dict[str, dict[str, Any]]] = {
        "default": {},
        "paper": {"relief_only": False, "fine_scale": 0.0},
    }

    preset: Literal["default", "paper"] = Field(
        "default",
        description="default: contrast added where the surface has relief, from the signal "
        "above `fine_scale` (noise and flat surfaces kept as rendered); paper: §4 as printed, "
        "every pixel's own lightness, everywhere; parameters given with it override it",
    )
    amount: float = Field(
        1.0, **checks.UNSHARP_AMOUNT.bounds, description="λ (users preferred 1.7-2, §6)"
    )
    sigma: Annotated[float, Field(**checks.POSITIVE.bounds)] | Auto = Field(
        "auto",
        description="σ of the smooth signal in scene units (> 0), or auto: `sigma_fraction` of "
        "the image height at the surface's median depth",
    )
    sigma_fraction: float = Field(
        0.04, **checks.RELATIVE_SIGMA.bounds, description="auto σ, relative to the image height"
    )
    adaptive: bool = Field(True, description="λ_adapt = λ √(1 + Var(S)) (Eq. 1)")
    variance_sigma: float | None = Field(
        None,
        **checks.POSITIVE.bounds,
        description="neighbourhood of Var(S), scene units (default σ/4)",
    )
    gain_map: str | None = Field(
        None,
        description="per-pixel gain (any sign): a layer of the file (e.g. `gain` or `gain.X`) or, "
        "on the command line, an image file (PNG: 0..1, EXR: any value)",
    )
    signal: Signal = Field("beauty", description="what is enhanced (see the operator's docs)")
    unlit: str | None = Field(
        None, description="signal 'shadows': layer of the file with the render without shadows"
    )
    white: WhiteLevel = Field(
        "auto", description="linear white level of CIELAB (auto: 99th percentile; pin it)"
    )
    depth_sigma: float = Field(
        1.0,
        **checks.UNSHARP_SIGMA.bounds,
        description="depth gap (in σ) above which surfaces do not mix",
    )
    normal_sigma: float | None = Field(
        1.0,
        **checks.UNSHARP_SIGMA.bounds,
        description="normal change counted as one σ (null: no crease term)",
    )
    fine_scale: float = Field(
        0.002,
        **checks.FINE_SCALE.bounds,
        description="σ of the lightness the contrast is taken from, relative to the image height "
        "(at least a pixel): Monte-Carlo noise finer than it is not amplified (0: each pixel's "
        "own, as the paper)",
    )
    keep_lighting: bool = Field(
        True,
        description="divide the result by its low-frequency gain along the surfaces at 4σ, so "
        "the lightness curve of CIELAB does not brighten a region on the whole (false: as is)",
    )
    relief_only: bool = Field(
        True,
        description="gain × the surface's relief, tanh(0.03·(|κ1|+|κ2|)) of the normals' "
        "curvature averaged over σ/2: flat surfaces (floors, walls) keep their shadows, texture "
        "and noise as rendered and no halo follows a shadow across them (needs normals)",
    )

    @model_validator(mode="after")
    def _check(self) -> UnsharpParams:
        if self.signal == "shadows" and not self.unlit:
            raise ValueError("signal 'shadows' needs `unlit`: the layer rendered without shadows")
        return self


def _pixel_sizes(frame: Frame, p: UnsharpParams) -> np.ndarray:
    if p.sigma != "auto":
        return pixel_sizes(frame, "unsharp_masking with sigma in scene units")
    return relative_pixel_sizes(frame, "unsharp_masking")


def _relief(
    frame: Frame, p: UnsharpParams, sigma: float, pixel_size: np.ndarray, ctx: Context
) -> np.ndarray | None:
    """tanh(s·(|κ1| + |κ2|)) · weight of the normals' curvature at the default scale (RS §4,
    the default gain s), smoothed along the surfaces over σ / 2 (scene units): it reaches as far
    as the contrast it lets in, without crossing onto another surface; None without normals."""
    if not p.relief_only or "normal" not in frame.buffers:
        return None
    curv = frame_curvature(frame, CurvatureParams(), ctx)
    trace = np.abs(curv.k1) + np.abs(curv.k2)
    relief = (np.tanh(np.float32(curv_ops.DEFAULT_GAIN) * trace) * curv.weight).astype(np.float32)
    normal = frame.buffers["normal"]
    return surface_blur(
        relief,
        frame.buffers["depth"],
        normal,
        frame.mask,
        sigma_scene=0.5 * sigma,
        pixel_size=pixel_size,
    )


def _gain_map(frame: Frame, p: UnsharpParams, ctx: Context) -> np.ndarray | None:
    if p.gain_map is None:
        return None
    gain = plane(frame, p.gain_map, "gain_map", ctx.files)  # a layer, unless a file exists
    if not np.isfinite(gain).all():  # (said before it is multiplied by anything)
        raise PipelineError(f"unsharp_masking: gain_map {p.gain_map!r} must be finite everywhere")
    return gain


@register(
    "unsharp_masking",
    summary="3D Unsharp Masking (Ritschel et al. 2008): Cornsweet contrast in CIELAB lightness "
    "along the surfaces, σ in scene units, adaptive gain, gain maps",
    params=UnsharpParams,
    needs=("beauty", "depth"),
    writes=("beauty",),
)
def apply_unsharp_masking(frame: Frame, p: UnsharpParams, ctx: Context) -> None:
    beauty = frame.buffers["beauty"]
    depth = frame.buffers["depth"]
    mask = frame.mask
    pixel_size = _pixel_sizes(frame, p)
    covered = (mask > 0) & np.isfinite(pixel_size)
    space = frame.colorspace
    sigma = statistic(
        ctx,
        "unsharp_masking.sigma",
        p.sigma,
        lambda: relative_scene_sigma(frame, pixel_size, p.sigma_fraction),
    )
    if p.signal == "shadows":
        unlit = frame.layer(p.unlit or "")
        if not all(c in unlit for c in "RGB"):
            raise PipelineError(f"unsharp_masking: no RGB layer {p.unlit!r} (unlit) in the file")
        unlit_y = luminance(np.dstack([unlit["R"], unlit["G"], unlit["B"]]), weights=space.weights)
        term = luminance(beauty, weights=space.weights) / np.maximum(unlit_y, np.float32(1e-6))
        term = np.clip(term, 0.0, 1.0)
        signal = np.repeat(term[..., None], 3, axis=2).astype(np.float32, copy=False)
        white: float | Auto = 1.0
    else:
        lobe = None if p.signal == "beauty" else p.signal
        signal = frame.need(lobe, "the signal of unsharp_masking") if lobe else beauty
        white = statistic(
            ctx,
            f"unsharp_masking.white.{p.signal}",
            p.white,
            lambda: color.auto_white(signal, ctx.counted(covered), weights=space.weights),
        )
    gain = _gain_map(frame, p, ctx)
    relief = _relief(frame, p, sigma, pixel_size, ctx)
    if relief is not None:
        gain = relief if gain is None else gain * relief
    out = unsharp_masking(
        signal,
        depth,
        frame.buffers.get("normal"),
        mask,
        amount=p.amount,
        sigma_scene=sigma,
        pixel_size=pixel_size,
        adaptive=p.adaptive,
        variance_sigma=p.variance_sigma,
        gain_map=gain,
        white=white,
        depth_sigma=p.depth_sigma,
        normal_sigma=p.normal_sigma,
        fine_px=scale_px(frame, p.fine_scale) if p.fine_scale > 0 else 0.0,
        space=space,
    )
    if p.keep_lighting and p.signal != "shadows":
        typical = float(np.median(pixel_size[covered])) if covered.any() else 1.0
        scale = 4.0 * sigma / max(typical, 1e-30) / frame.image_height
        kept = kept_lighting_gain(frame, signal, out, scale, "unsharp_masking")
        if relief is not None:  # as far as the contrast was let in: 1 on flat surfaces
            kept = 1.0 + np.clip(relief, 0.0, 1.0) * (kept - 1.0)
        out = np.asarray(out * kept[..., None], np.float32)
    if p.signal == "shadows":
        factor = out[..., :1] / np.maximum(signal[..., :1], np.float32(1e-6))
        frame.buffers["beauty"] = np.where(signal > 0, beauty * factor, beauty).astype(
            np.float32, copy=False
        )
    elif p.signal == "beauty":
        frame.buffers["beauty"] = out
    else:
        frame.buffers["beauty"] = (beauty + (out - signal)).astype(np.float32, copy=False)
        frame.buffers[p.signal] = out


class DepthUnsharpParams(Params):
    """Unsharp masking of the depth buffer (Luft et al. 2006)."""

    amount: float = Field(1.0, **checks.UNSHARP_AMOUNT.bounds, description="λ, on normalised depth")
    sigma: float = Field(
        0.02, **checks.RELATIVE_SIGMA.bounds, description="Gaussian σ relative to the image height"
    )
    mode: Literal["darken", "both"] = Field(
        "darken", description="darken: L + λ·min(ΔD, 0) (MegaMol's default); both: L + λ·ΔD"
    )
    white: WhiteLevel = Field("auto", description="linear white level of CIELAB")


@register(
    "depth_unsharp_masking",
    summary="unsharp masking of the depth buffer (Luft et al. 2006): darken behind "
    "silhouettes and in creases by λ·ΔD, ΔD = G∗D − D",
    params=DepthUnsharpParams,
    needs=("beauty", "depth"),
    writes=("beauty",),
)
def apply_depth_unsharp_masking(frame: Frame, p: DepthUnsharpParams, ctx: Context) -> None:
    beauty = frame.buffers["beauty"]
    mask = frame.mask
    space = frame.colorspace
    white = statistic(
        ctx,
        "depth_unsharp_masking.white",
        p.white,
        lambda: color.auto_white(beauty, mask > 0, weights=space.weights),
    )
    frame.buffers["beauty"] = depth_unsharp_masking(
        beauty,
        frame.buffers["depth"],
        mask,
        amount=p.amount,
        sigma=p.sigma,
        image_height=frame.image_height,
        mode=p.mode,
        white=white,
        space=space,
    )
