"""``curvature``: view-centred curvature (Radiance Scaling §4), and its parameters, which every
curvature-driven operator shares."""

from __future__ import annotations

import numpy as np
from pydantic import Field

from gbuffer.frame import MASK_SOURCES, Frame
from ops import checks
from ops import curvature as curv_ops
from service.operators.base import Context, Params, register

#: Smallest derivative / averaging scale, pixels.
MIN_SCALE_PX = 1.0


class CurvatureParams(Params):
    """View-centred curvature (RS §4), shared by every operator that needs it."""

    scale: float = Field(
        curv_ops.DEFAULT_SCALE,
        **checks.CURVATURE_SCALE.bounds,
        description="derivative scale, relative to the image height (Gaussian σ, at least a pixel)",
    )
    gain: float = Field(
        curv_ops.DEFAULT_GAIN,
        **checks.CURVATURE_GAIN.bounds,
        description="curvature gain s in κ = tanh(s·(κ1+κ2)), curvature per image height",
    )
    foreshortening: float = Field(
        curv_ops.DEFAULT_FORESHORTENING,
        **checks.FRACTION.bounds,
        description="foreshortening f in g = −(n_x, n_y)/n_z^f (0: none, 1: full)",
    )
    depth_jump: float = Field(
        curv_ops.DEFAULT_DEPTH_JUMP,
        **checks.CURVATURE_DEPTH_JUMP.bounds,
        description="relative depth jump treated as a discontinuity (no curvature across it)",
    )


def scale_px(frame: Frame, scale: float) -> float:
    """A scale relative to the image height in pixels, at least :data:`MIN_SCALE_PX` (below a
    pixel a derivative or an average only sees pixel noise)."""
    return max(scale * frame.image_height, MIN_SCALE_PX)


def frame_curvature(frame: Frame, p: CurvatureParams, ctx: Context) -> curv_ops.Curvature:
    """The view-centred curvature of a frame at the parameters' scale (at least a pixel); the
    run's memo keeps it for the next run on the same normals, depth and mask
    (:attr:`Context.memo`), and each run reads a view of it of its own
    (:meth:`ops.curvature.Curvature.view`)."""
    normal = frame.need("normal", "for curvature")
    depth = frame.need("depth", "for curvature")
    scale = min(scale_px(frame, p.scale) / frame.image_height, 0.1)
    params = (scale, p.foreshortening, frame.image_height, p.depth_jump)
    return ctx.memo.get(
        "curvature",
        (normal, depth, *mask_sources(frame)),
        params,
        lambda: curv_ops.principal_curvatures(
            normal,
            depth,
            frame.mask,
            scale=scale,
            foreshortening=p.foreshortening,
            image_height=frame.image_height,
            depth_jump=p.depth_jump,
        ),
    ).view()


def mask_sources(frame: Frame) -> tuple[np.ndarray | None, ...]:
    """The buffers :attr:`gbuffer.frame.Frame.mask` is made of (for :attr:`Context.memo`)."""
    return tuple(frame.buffers.get(name) for name in MASK_SOURCES)


@register(
    "curvature",
    summary="view-centred curvature (RS §4): mapped mean curvature, principal curvatures "
    "and direction",
    params=CurvatureParams,
    needs=("normal", "depth"),
    writes=("curvature.H", "curvature.k1", "curvature.k2", "curvature.dir.X", "curvature.dir.Y"),
)
def apply_curvature(frame: Frame, p: CurvatureParams, ctx: Context) -> None:
    curvature = frame_curvature(frame, p, ctx)
    frame.set_layer("curvature", curv_ops.mean_curvature_layers(curvature, p.gain))
