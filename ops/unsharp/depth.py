"""Image-space baselines of 3D unsharp masking: the depth-buffer unsharp mask of Luft, Colditz and
Deussen (SIGGRAPH 2006) and a plain 2-D unsharp mask of L*, for comparisons."""

from __future__ import annotations

from typing import Any, Literal

import cv2
import numpy as np

from ops import color
from ops.checks import POSITIVE, RELATIVE_SIGMA, UNSHARP_AMOUNT
from ops.colorspace import LINEAR_REC709, ColorSpace
from ops.pyramid.reduce import gaussian_blur
from ops.unsharp._common import Array, _lightness, _mask, _plane, _rgb, _with_lightness
from ops.unsharp._surface import _crop, _outside

_cv: Any = cv2  # OpenCV's stubs reject scalar operands (cv2.max(a, 0.0))

__all__ = ["depth_unsharp_masking", "plain_unsharp_mask"]


# ---------------------------------------------------------------------------------------------
def plain_unsharp_mask(
    beauty: Array,
    sigma: float,
    amount: float,
    *,
    white: float | Literal["auto"] = "auto",
    image_height: int | None = None,
    space: ColorSpace = LINEAR_REC709,
) -> Array:
    """Plain 2-D unsharp masking of CIELAB lightness, for comparisons.

    U(L*) = L* + λ (L* − G_σ ∗ L*), (a*, b*) scaled by U/L* (as :func:`unsharp_masking`, but the
    Gaussian G_σ blurs the picture, across objects and depth: the baseline of Ritschel et al.
    2008 Fig. 4, top row).

    Parameters
    ----------
    beauty : (H, W, 3) float32 linear RGB
    sigma : float
        Gaussian σ relative to the image height (0 < σ ≤ 1).
    amount : float
        λ in [-10, 10].
    white : "auto" or float
        White level ("auto": 99th percentile of luminance over the whole image).
    image_height : int or None
        Height the relative σ refers to (default: this image's height; pass the full frame's
        height when processing a crop).
    space : the working space (as :func:`ops.unsharp.unsharp_masking`).
    """
    img = _rgb("beauty", beauty)
    s = RELATIVE_SIGMA.check(sigma, "sigma")
    lam = UNSHARP_AMOUNT.check(amount, "amount")
    hh = img.shape[0] if image_height is None else int(POSITIVE.check(image_height, "image_height"))
    wl = color.resolve_white(white, img, None, space.weights)
    lum = _lightness(img, wl, space)
    smooth = gaussian_blur(lum, s * hh)
    new_lum = _cv.scaleAdd(_cv.subtract(lum, smooth), lam, lum)
    return _with_lightness(img, lum, new_lum, wl, None, space)


#: Normalised depth D of the background in :func:`depth_unsharp_masking` (surfaces span [0, 1]).
BACKGROUND_DEPTH = 2.0


def depth_unsharp_masking(
    beauty: Array,
    depth: Array,
    mask: Array,
    *,
    amount: float = 1.0,
    sigma: float = 0.02,
    image_height: int | None = None,
    mode: Literal["darken", "both"] = "darken",
    white: float | Literal["auto"] = "auto",
    space: ColorSpace = LINEAR_REC709,
) -> Array:
    """Unsharp masking of the depth buffer (Luft, Colditz, Deussen, SIGGRAPH 2006).

    ΔD = G_σ ∗ D − D on normalised depth D; ``mode="darken"`` (the paper's and MegaMol's
    default, ``col + λ·min(ΔD, 0)``): L*' = L* + 100 λ min(ΔD, 0); ``"both"`` also brightens
    where ΔD > 0: L*' = L* + 100 λ ΔD. The offset is applied to CIELAB lightness (L*/100 plays
    the part of MegaMol's display colour) and (a*, b*) are scaled by L*'/L*, so hue and
    saturation are kept, as in :func:`unsharp_masking`.

    Normalisation: D = (z − z_near) / (z_far − z_near) with z_near, z_far the smallest and
    largest depth over the surface (mask > 0, finite depth); background pixels take
    D = :data:`BACKGROUND_DEPTH` = 2, one depth range behind the farthest surface (in a depth
    buffer the far plane lies well beyond the objects): the blur of a surface bordering the
    background is then pulled back, never forward, so the far edge of a floor or the far side of
    an object is not darkened as if something stood in front of it. Background pixels
    themselves are returned unchanged (their colour may be premultiplied zero).

    Parameters
    ----------
    beauty : (H, W, 3) float32 linear RGB
    depth : (H, W) float32 planar depth
    mask : (H, W) coverage (> 0 is surface)
    amount : float
        λ in [-10, 10] (Luft et al. use about 0.5…5 on [0, 1] colours).
    sigma : float
        Gaussian σ relative to the image height, (0, 1].
    image_height : int or None
        Height σ refers to (default this image's).
    mode : "darken" or "both"
    white : "auto" or float
    space : the working space (as :func:`ops.unsharp.unsharp_masking`).
    """
    img = _rgb("beauty", beauty)
    shape = (int(img.shape[0]), int(img.shape[1]))
    lam = UNSHARP_AMOUNT.check(amount, "amount")
    s = RELATIVE_SIGMA.check(sigma, "sigma")
    if mode not in ("darken", "both"):
        raise ValueError(f"mode={mode!r} must be 'darken' or 'both'")
    hh = img.shape[0] if image_height is None else int(POSITIVE.check(image_height, "image_height"))
    depth_a = _plane("depth", depth, shape)
    mask_a = _mask(mask, shape)
    valid = _cv.inRange(depth_a, 1e-30, 3.0e38)
    if mask_a.dtype == np.bool_:
        _cv.bitwise_and(valid, mask_a.view(np.uint8), dst=valid)
    else:
        _cv.bitwise_and(valid, _cv.compare(mask_a, 0.0, _cv.CMP_GT), dst=valid)
    z_near, z_far, _, _ = _cv.minMaxLoc(depth_a, mask=valid)
    if not _cv.countNonZero(valid):
        return img.copy()
    span = z_far - z_near
    # D = (z − z_near) / (z_far − z_near) on the surface, BACKGROUND_DEPTH elsewhere
    far = z_far + (BACKGROUND_DEPTH - 1.0) * span
    dn = _cv.copyTo(depth_a, valid, np.full(shape, far, np.float32))
    if span > 0.0:
        _cv.addWeighted(dn, 1.0 / span, dn, 0.0, -z_near / span, dst=dn)
    else:
        dn = np.where(valid > 0, np.float32(0.0), np.float32(BACKGROUND_DEPTH))
    delta = _cv.subtract(gaussian_blur(dn, s * hh), dn)
    if mode == "darken":
        _cv.min(delta, 0.0, dst=delta)
    wl = color.resolve_white(white, img, valid.view(bool), space.weights)
    # colour work on the bounding box of the surface only (the rest is returned as is)
    box = _crop(valid)
    assert box is not None
    ys, xs = box
    lum = _lightness(img[box], wl, space)
    new_lum = _cv.scaleAdd(delta[box], 100.0 * lam, lum)
    keep = _cv.compare(valid[box], 0, _cv.CMP_EQ)
    if (ys.stop - ys.start, xs.stop - xs.start) == shape:
        return _with_lightness(img, lum, new_lum, wl, keep, space)
    out = _outside(img, box)
    _with_lightness(img[box], lum, new_lum, wl, keep, space, out=out[box])
    return out
