"""The congruence of shading flow and shape flow, LLA Eq. 2 (see :mod:`ops.congruence`)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from ops.checks import (
    DEPTH_JUMP,
    GRADIENT_SCALE,
    INTEGRATION_SCALE,
    PERCENTILE,
    SHADING_NORM,
)
from ops.color import REC709_Y
from ops.congruence._common import _REL_CURVED, _SHAPE_COUNTED, F32
from ops.congruence._flow import (
    _LOW_MAPS,
    _brightness,
    _covered_level,
    _f32,
    _flow,
    _reach,
    _shading_products,
    _shape_products,
    _window,
)
from ops.congruence.result import CongruenceResult
from ops.parallel import run_strips

__all__ = ["ShapeFlow", "congruence", "shape_flow"]


def _checked(
    depth: NDArray[np.floating],
    mask: NDArray[np.generic] | None,
    image_height: int | None,
    image: NDArray[np.floating] | None = None,
) -> tuple[np.ndarray, int, np.ndarray | None]:
    """The depth (H, W) checked, then the image (H, W) or (H, W, 3) when given, the mask's
    shape and the image height."""
    dep = np.asarray(depth)
    if dep.ndim != 2:
        raise ValueError(f"depth must be (H, W), got shape {dep.shape}")
    h, w = dep.shape
    if h < 3 or w < 3:
        raise ValueError(f"depth must be at least 3x3, got shape {dep.shape}")
    img = None if image is None else np.asarray(image)
    if img is not None and img.ndim == 3 and img.shape[2] == 1:
        img = img[..., 0]
    if img is not None and (
        img.shape[:2] != (h, w) or img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] != 3)
    ):
        raise ValueError(
            f"image must be (H, W, 3) or (H, W) matching depth {dep.shape}, got {img.shape}"
        )
    if mask is not None and np.shape(mask) != (h, w):
        raise ValueError(f"mask must be (H, W) = {dep.shape}, got shape {np.shape(mask)}")
    href = h if image_height is None else int(image_height)
    if href <= 0:
        raise ValueError(f"image_height must be a positive number of pixels, got {image_height!r}")
    return dep, href, img


def _checked_params(
    href: int, gradient_scale: float, integration_scale: float, percentile: float, jump: float
) -> tuple[float, float]:
    """The parameters checked; σ_g and σ_i in pixels."""
    sg = GRADIENT_SCALE.check(gradient_scale, "gradient_scale") * href
    si = INTEGRATION_SCALE.check(integration_scale, "integration_scale") * href
    PERCENTILE.check(percentile, "percentile")
    DEPTH_JUMP.check(jump, "depth_jump")
    return sg, si


def _eq2(
    e_shape: F32,
    e_shading: F32,
    shading_dir: tuple[F32, F32],
    shape_dir: tuple[F32, F32],
    defined: np.ndarray,
    area: F32,
    outside: np.ndarray,
) -> tuple[F32, float]:
    """Eq. 2 on the analysis level: the per-pixel score (1 − ⌊e_shape − e_shading⌋) |v·v'| and
    the score Σ e_shape·area·map / Σ e_shape·area. The directions are (cos 2φ, sin 2φ), so
    |v·v'| = √((1 + cos 2(φ − φ'))/2); it is 0 where either is undefined (not ``defined``)."""
    (ca, sa), (cb, sb) = shading_dir, shape_dir
    cosd = ca * cb
    cosd += sa * sb  # cos of the doubled-angle difference
    cosd += 1.0
    cosd *= 0.5
    dot = np.sqrt(np.clip(cosd, 0.0, 1.0, out=cosd), out=cosd)
    dot[~defined] = 0.0
    smap = np.subtract(e_shape, e_shading)
    np.clip(smap, 0.0, 1.0, out=smap)
    np.subtract(1.0, smap, out=smap)
    smap *= dot
    smap[outside] = 0.0
    wgt = e_shape * area
    den = float(wgt.sum(dtype=np.float64))
    wgt *= smap
    score = float(wgt.sum(dtype=np.float64) / den) if den > 0 else 0.0
    return smap, score


def _integrated(prods: list[np.ndarray], sigma: float) -> list[np.ndarray]:
    """The tensor products blurred by the integration Gaussian (one per task on the shared
    pool)."""
    tens = list(prods)

    def integrate(a: int, b: int) -> None:
        for i in range(a, b):
            tens[i] = _f32(cv2.GaussianBlur(prods[i], (0, 0), sigma))

    run_strips(len(tens), integrate, 1)
    return tens


@dataclass(frozen=True, eq=False)
class ShapeFlow:
    """The shape's side of Eq. 2 for one frame (its depth, mask and normals) at one set of
    congruence parameters (:func:`shape_flow`): everything :func:`congruence` computes that does
    not depend on the image, to score several images of the frame (renderings, a preview's
    results) without computing it again. Not to be written into: every image's score reads the
    same arrays."""

    key: tuple[object, ...]  # the depth's shape, the image height and the parameters
    depth: np.ndarray  # (H, W) float32, as checked
    mask: NDArray[np.generic] | None
    normal: np.ndarray | None  # (H, W, 3) float32
    f1: int  # gradient level: factor, size (w, h) and σ_g there
    size1: tuple[int, int]
    s1: float
    f2: int  # integration level: factor, size (w, h) and σ_i there
    size2: tuple[int, int]
    s2: float
    cov0: np.ndarray  # coverage at the gradient level
    # None when nothing is covered; else the window at both levels, and at the gradient level
    # (its crop) 1 / the blurred coverage and the valid gradients; at the integration level
    # (window) the valid area, 1 / its weight, the scored pixels, the shape's normalised
    # strength and doubled-angle direction, where it is defined, and where the shading's scale
    # is measured
    win: tuple[tuple[int, int, int, int], tuple[int, int, int, int]] | None = None
    inv: np.ndarray | None = None
    valid: np.ndarray | None = None
    area: np.ndarray | None = None
    invw: np.ndarray | None = None
    inside: np.ndarray | None = None
    strength: np.ndarray | None = None
    direction: tuple[np.ndarray, np.ndarray] | None = None
    defined: np.ndarray | None = None
    counted: np.ndarray | None = None


def _shape_key(
    shape: tuple[int, ...], href: int, params: tuple[float, float, float, float], normals: bool
) -> tuple[object, ...]:
    return (tuple(shape), href, *params, normals)


def shape_flow(
    depth: NDArray[np.floating],
    mask: NDArray[np.generic] | None = None,
    *,
    gradient_scale: float = 0.002,
    integration_scale: float = 0.01,
    image_height: int | None = None,
    percentile: float = 95.0,
    depth_jump: float = 0.05,
    normal: NDArray[np.floating] | None = None,
) -> ShapeFlow:
    """The shape flow of a frame for :func:`congruence` (its ``flow``): the parameters are
    those of :func:`congruence`, which computes the same thing itself when given none."""
    dep, href, _ = _checked(depth, mask, image_height)
    h, w = dep.shape
    sg, si = _checked_params(href, gradient_scale, integration_scale, percentile, depth_jump)
    dep = dep.astype(np.float32, copy=False)
    params = (gradient_scale, integration_scale, percentile, depth_jump)
    key = _shape_key(dep.shape, href, params, normal is not None)

    # --- gradient level: area-downsample by f1 so that sigma_g is 1-2 px there; area-average
    # the covered depth, coverage and normals (the image's luminance: in congruence()).
    f1 = max(1, min(int(sg), h // 8 or 1, w // 8 or 1))
    size1 = (max(w // f1, 3), max(h // f1, 3)) if f1 > 1 else (w, h)
    nrm = None if normal is None else np.asarray(normal, np.float32)
    if nrm is not None and nrm.shape != (h, w, 3):
        raise ValueError(f"normal must be (H, W, 3) matching depth {dep.shape}, got {nrm.shape}")
    level = _covered_level(None, dep, mask, f1, size1, nrm)
    dep0, cov0 = level[:2]
    # NaN / inf anywhere propagate through the weighted sums (x * 0 = NaN): check the small
    # copy (a sum accumulated in float64 cannot overflow: it is finite iff every value is)
    if not np.isfinite(cv2.sumElems(dep0)[0]):
        if np.isnan(dep).any():
            raise ValueError("depth contains NaN (use +inf for background)")
        raise ValueError("depth contains -inf: depth is positive, +inf on background")

    # --- integration level: area-downsample the tensor products by f2 so that sigma_i is
    # 2-4 px there.
    w1, h1 = size1
    s1, si1 = sg / f1, si / f1
    f2 = max(1, min(int(si1 / 2.0), h1 // 8 or 1, w1 // 8 or 1))
    size2 = (max(w1 // f2, 3), max(h1 // f2, 3)) if f2 > 1 else (w1, h1)
    s2 = si1 / f2
    flow = ShapeFlow(key, dep, mask, nrm, f1, size1, s1, f2, size2, s2, cov0)
    # Everything below is 0 away from the covered pixels: work on their bounding box, grown by
    # more than the blurs' and stencils' reach (the result is the same as on the whole level)
    win = _window(cov0, f2, size2, max(_reach(s1) + 2, (_reach(s2) + 2) * f2))
    if win is None:  # nothing covered
        return flow
    (y0, y1, x0, x1), (v0, v1, u0, u1) = win
    crop = [np.ascontiguousarray(c[y0:y1, x0:x1]) for c in level]
    prods, inv, valid = _shape_products(crop, s1, 0.5 * float(depth_jump), f2, (u1 - u0, v1 - v0))
    *tens, wsum = _integrated(prods, s2)
    area = prods[3]  # fraction of each analysis pixel with valid gradients
    invw = np.divide(1.0, wsum, out=np.zeros_like(wsum), where=wsum > 1e-4)
    inside = area > 0.5
    # with normals, the scale is measured where there is shape: planes (0) do not set it; the
    # log depth's flow is strong on floors too, so it counts every pixel
    curved = None
    if nrm is not None:
        e_shape = np.multiply(np.add(tens[0], tens[2]), invw)
        curved = inside & (e_shape > _REL_CURVED * float(e_shape.max(initial=0.0)))
        curved = curved if curved.any() else None
    # (signal scale for the noise floor: log depth and unit normals are dimensionless)
    sxx, sxy, syy = tens
    ec, cb, sb, dc, _ = _flow(sxx, sxy, syy, invw, inside, ~inside, 1.0, percentile, None, curved)
    counted = None if curved is None else inside & (ec > _SHAPE_COUNTED)
    counted = counted if counted is not None and counted.any() else None
    return dataclasses.replace(
        flow,
        win=win,
        inv=inv,
        valid=valid,
        area=area,
        invw=invw,
        inside=inside,
        strength=ec,
        direction=(cb, sb),
        defined=dc,
        counted=counted,
    )


def congruence(
    image: NDArray[np.floating],
    depth: NDArray[np.floating],
    mask: NDArray[np.generic] | None = None,
    *,
    gradient_scale: float = 0.002,
    integration_scale: float = 0.01,
    image_height: int | None = None,
    percentile: float = 95.0,
    depth_jump: float = 0.05,
    shading_norm: float | None = None,
    normal: NDArray[np.floating] | None = None,
    weights: tuple[float, float, float] = REC709_Y,
    flow: ShapeFlow | None = None,
) -> CongruenceResult:
    """Congruence score between shading and shape flows (Mestres et al. 2021, §7, Eq. 2).

    ``s = Σ e_shape (1 − ⌊e_shape − e_shading⌋) |v_shape·v_shading| / Σ e_shape`` over the
    covered pixels, with (v, e) the dominant eigenvector and mean eigenvalue of the structure
    tensor ``G_σi * (∇f ∇fᵀ)`` of f = luminance (shading) and, for the shape, the normal's
    components summed (``normal`` given: a curvature flow) or f = log depth; the gradient taken
    at σ_g. See the module docstring for the shape flow and the normalisation of e.

    Parameters
    ----------
    image : (H, W, 3) or (H, W) float
        Linear RGB (or luminance) rendering to score.
    depth : (H, W) float
        Planar depth, positive; +inf (or <= 0) on background.
    mask : (H, W), optional
        Coverage; pixels with mask <= 0.5 are background.
    gradient_scale : float
        σ of the gradient (derivative-of-Gaussian) scale, relative to the image height, (0, 0.1].
    integration_scale : float
        σ of the Gaussian integrating the tensor, relative to the image height, (0, 0.25].
    image_height : int, optional
        Height the relative scales refer to (defaults to H; pass the full frame's height when
        scoring a crop).
    percentile : float
        Percentile (over covered pixels) each strength is divided by before clipping to [0, 1],
        in (0, 100].
    depth_jump : float
        Largest change of log depth between neighbouring pixels (of the gradient level) still
        treated as a continuous surface, > 0; above it the pixels are not scored.
    shading_norm : float, optional
        The shading strength mapped to 1, instead of this image's own ``percentile``: pass the
        :attr:`CongruenceResult.shading_norm` of a reference rendering of the same frame (same
        parameters) to put several renderings on one scale, so that a shading with more contrast
        than the reference is not normalised back down (the clamp of Eq. 2 then does what the
        paper says: exaggeration, e_shading > e_shape, does not lower the score).
    normal : (H, W, 3) float, optional
        Camera-space unit normals: the shape flow is then the structure tensor of the normal's
        gradients, which is 0 on planes (see the module docstring); without them, of the log
        depth's gradients.
    weights : 3 floats
        Luminance weights of the image's working space (:attr:`ops.colorspace.ColorSpace.
        weights`; default Rec. 709): the shading is its luminance.
    flow : ShapeFlow, optional
        :func:`shape_flow` of this ``depth``, ``mask`` and ``normal`` with these parameters
        (checked): the shape's side of Eq. 2 computed once for every image of the frame; the
        same result as without it, bit for bit.

    Returns
    -------
    CongruenceResult
        The score and its per-pixel maps.
    """
    dep, href, img = _checked(depth, mask, image_height, image)
    assert img is not None
    _checked_params(href, gradient_scale, integration_scale, percentile, depth_jump)
    if shading_norm is not None:
        SHADING_NORM.check(shading_norm, "shading_norm")
    if flow is None:
        flow = shape_flow(
            dep,
            mask,
            gradient_scale=gradient_scale,
            integration_scale=integration_scale,
            image_height=image_height,
            percentile=percentile,
            depth_jump=depth_jump,
            normal=normal,
        )
    else:
        params = (gradient_scale, integration_scale, percentile, depth_jump)
        _check_flow(flow, dep, mask, normal, href, params)
    img = img.astype(np.float32, copy=False)
    h, w = flow.depth.shape
    lw = np.asarray(weights, np.float32).reshape(1, 3)
    (lum0,) = _covered_level(img, flow.depth, flow.mask, flow.f1, flow.size1, None, lw, False)
    if not np.isfinite(cv2.sumElems(lum0)[0]):
        raise ValueError("image contains NaN or infinite values")
    lref = _brightness(lum0, flow.cov0)
    size2 = flow.size2
    low = {k: np.zeros(size2[::-1], np.float32) for k in _LOW_MAPS}
    if flow.win is None:  # nothing covered
        return CongruenceResult(0.0, (size2[1], size2[0]), shading_norm or 0.0, (h, w), low)
    assert flow.inv is not None and flow.valid is not None and flow.area is not None
    assert flow.invw is not None and flow.inside is not None and flow.strength is not None
    assert flow.direction is not None and flow.defined is not None
    (y0, y1, x0, x1), (v0, v1, u0, u1) = flow.win
    lum = np.ascontiguousarray(lum0[y0:y1, x0:x1])
    prods = _shading_products(lum, flow.inv, flow.valid, flow.s1, flow.f2, (u1 - u0, v1 - v0))
    tens = _integrated(prods, flow.s2)
    inside, outside = flow.inside, ~flow.inside
    lxx, lxy, lyy = tens
    es, ca, sa, ds, norm_s = _flow(
        lxx, lxy, lyy, flow.invw, inside, outside, lref, percentile, shading_norm, flow.counted
    )
    ec, (cb, sb) = flow.strength, flow.direction
    smap, score = _eq2(ec, es, (ca, sa), (cb, sb), ds & flow.defined, flow.area, outside)

    maps = (smap, es, ec, np.where(inside, flow.area, np.float32(0)), ca, sa, cb, sb)
    for name, m in zip(_LOW_MAPS, maps, strict=True):
        low[name][v0:v1, u0:u1] = m
    return CongruenceResult(
        score=float(np.clip(score, 0.0, 1.0)),
        analysis_shape=(size2[1], size2[0]),
        shading_norm=norm_s,
        _out_shape=(h, w),
        _low=low,
    )


def _check_flow(
    flow: ShapeFlow,
    depth: np.ndarray,
    mask: NDArray[np.generic] | None,
    normal: NDArray[np.floating] | None,
    href: int,
    params: tuple[float, float, float, float],
) -> None:
    """A :class:`ShapeFlow` given to :func:`congruence` is that of its depth, mask and normals
    (the same arrays, else the same values) and parameters."""
    key = _shape_key(depth.shape, href, params, normal is not None)
    same = (
        flow.key == key
        and _same_values(depth, flow.depth)
        and _same_values(mask, flow.mask)
        and _same_values(normal, flow.normal)
    )
    if not same:
        raise ValueError(
            "flow: a shape flow made for another frame or other parameters; make it with "
            "shape_flow() of the same depth, mask, normal and congruence parameters"
        )


def _same_values(given: NDArray[np.generic] | None, kept: NDArray[np.generic] | None) -> bool:
    """``given`` is ``kept``, or holds the same values (NaN as NaN), or both are None."""
    if given is None or kept is None:
        return given is kept
    if given is kept:
        return True
    a, b = np.asarray(given), np.asarray(kept)
    floats = a.dtype.kind == "f" and b.dtype.kind == "f"
    return a.shape == b.shape and bool(np.array_equal(a, b, equal_nan=floats))
