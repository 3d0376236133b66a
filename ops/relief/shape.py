"""The Apparent Relief descriptor S = D · L (§2): its readable form (:func:`relief_vector`), the
fused one on a curvature (:func:`descriptor`), the shape index, the regions and Fig. 1a's colour
code."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Literal

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from ops.checks import CURVEDNESS_NORM, PERCENTILE
from ops.curvature import Curvature
from ops.numerics import magnitude
from ops.parallel import run_strips, strip_rows
from ops.relief._common import (
    _PERCENTILE_SAMPLES,
    _SQRT1_2,
    AUTO_NORM_FLOOR,
    DEFAULT_PERCENTILE,
    F32,
    PLANE_RADIUS,
    REGION_COLORS,
    Descriptor,
    _check_s,
)
from ops.relief._kernels import _descriptor_rows

__all__ = [
    "classify",
    "curvedness",
    "descriptor",
    "descriptor_colors",
    "relief_vector",
    "shape_index",
]

# -- the descriptor --------------------------------------------------------------------------------


def curvedness(curv: Curvature) -> F32:
    """Koenderink's curvedness ``L = sqrt((κ1² + κ2²) / 2) · weight`` (Apparent Relief §2).

    Per unit image height, (H, W) float32, 0 where the curvature weight is 0 (background, depth
    discontinuities). This is the unnormalised length of the descriptor S.
    """
    mag = magnitude(curv.k1, curv.k2)
    return np.asarray(cv2.multiply(mag, curv.weight, scale=_SQRT1_2), np.float32)


def _auto_norm(k1: np.ndarray, k2: np.ndarray, weight: np.ndarray, percentile: float) -> float:
    """The ``percentile`` of the curvedness ``|K| · weight / √2`` over covered pixels (weight >
    0.5), on a regular subsample of at most ~_PERCENTILE_SAMPLES pixels (|K| computed there
    only), floored at AUTO_NORM_FLOOR."""
    step = max(1, math.ceil(math.sqrt(k1.size / _PERCENTILE_SAMPLES)))
    sub_w = weight[::step, ::step]
    mag = magnitude(k1[::step, ::step], k2[::step, ::step])
    sel = (mag * sub_w)[sub_w > 0.5] * np.float32(_SQRT1_2)
    if sel.size == 0 or np.isnan(sel).any():
        return AUTO_NORM_FLOOR
    value = _percentile(sel, percentile)
    return max(value, AUTO_NORM_FLOOR) if math.isfinite(value) else AUTO_NORM_FLOOR


def _percentile(a: np.ndarray, percentile: float) -> float:
    """``float(np.percentile(a, percentile))`` of a 1-D float32 array without NaN, bit for bit
    (NumPy's default "linear" method: a partition and the same float32 lerp), without NumPy's
    generic quantile machinery (~0.15 ms a call, more than the partition itself)."""
    pos = (a.size - 1) * float(np.true_divide(percentile, 100))
    lo = math.floor(pos)
    hi = min(lo + 1, a.size - 1)
    part = np.partition(a, (lo, hi))
    below, above, t = part[lo], part[hi], pos - lo
    diff = above - below
    return float(above - diff * (1 - t)) if t >= 0.5 else float(below + diff * t)


def _grid_descriptor(
    curv: Curvature,
    curvedness_norm: float | str,
    percentile: float,
    texture: tuple[int, int] | None = None,
) -> tuple[F32, F32, float, Callable[[np.ndarray], np.ndarray] | None, F32 | None, F32 | None]:
    """(S1, S2) on the curvature's working grid, the L_norm used, the bilinear upsampling from
    that grid to full resolution (None when the curvature is at full resolution) and, for a
    ``texture`` of (h, w) texels, the texel coordinates (x, y) of S there (else None, None); one
    pass of :func:`_descriptor_rows` in row strips on both cores."""
    p = PERCENTILE.check(percentile, "percentile")
    if isinstance(curvedness_norm, str):
        if curvedness_norm != "auto":
            raise ValueError(
                f"curvedness_norm={curvedness_norm!r} must be 'auto' or a number in "
                f"{CURVEDNESS_NORM}"
            )
    else:
        norm = CURVEDNESS_NORM.check(curvedness_norm, "curvedness_norm")
    coarse = curv._coarse_for("k1", "k2", "weight")
    if coarse is not None:
        k1, k2, wgt = coarse.k1, coarse.k2, coarse.weight
    else:
        k1, k2, wgt = curv.k1, curv.k2, curv.weight
    k1 = np.ascontiguousarray(k1, dtype=np.float32)
    k2 = np.ascontiguousarray(k2, dtype=np.float32)
    wgt = np.ascontiguousarray(wgt, dtype=np.float32)
    if isinstance(curvedness_norm, str):
        norm = _auto_norm(k1, k2, wgt, p)
    c = np.float32(_SQRT1_2 / norm)
    hgt, wid = k1.shape
    s1 = np.empty((hgt, wid), np.float32)
    s2 = np.empty((hgt, wid), np.float32)
    if texture is None:
        ax = ay = np.float32(0.0)
        mx = my = np.empty((0, wid), np.float32)
    else:
        ax, ay = np.float32(0.5 * (texture[1] - 1)), np.float32(0.5 * (texture[0] - 1))
        mx = np.empty((hgt, wid), np.float32)
        my = np.empty((hgt, wid), np.float32)

    def strip(r0: int, r1: int) -> None:
        m = slice(r0, r1) if texture is not None else slice(0, 0)
        _descriptor_rows(
            k1[r0:r1], k2[r0:r1], wgt[r0:r1], c, ax, ay, s1[r0:r1], s2[r0:r1], mx[m], my[m]
        )

    run_strips(hgt, strip, strip_rows(wid))
    up = None if coarse is None else coarse.upsample
    if texture is None:
        return s1, s2, norm, up, None, None
    return s1, s2, norm, up, mx, my


def relief_vector(k1: ArrayLike, k2: ArrayLike, norm: float, weight: ArrayLike = 1.0) -> F32:
    """The descriptor S = D · L of Apparent Relief (§2), as the paper writes it::

        K = (κ1, κ2),   D = K / |K|  (0 where |K| = 0),
        L = min(sqrt((κ1² + κ2²) / 2) · weight / L_norm, 1),   S = D · L

    ``norm`` is L_norm; the result has the broadcast shape of the inputs plus a last axis
    (S1, S2), float32. :func:`descriptor` computes the same per strip in one compiled pass.

    >>> relief_vector(3.0, 0.0, 1.0).tolist()  # a ridge beyond L_norm: S on the rim, θ = 0
    [1.0, 0.0]
    >>> relief_vector(0.3, -0.4, 1.0).astype(float).round(4).tolist()  # |K| = 0.5: L = 0.5/√2
    [0.2121, -0.2828]
    >>> relief_vector(0.0, 0.0, 1.0).tolist()  # a plane
    [0.0, 0.0]
    """
    a, b, w = np.broadcast_arrays(
        np.asarray(k1, np.float32), np.asarray(k2, np.float32), np.asarray(weight, np.float32)
    )
    length = np.hypot(a, b)
    big_l = np.minimum(length * w * np.float32(_SQRT1_2 / norm), np.float32(1.0))
    d_scale = np.divide(big_l, length, out=np.zeros_like(length), where=length > 0)
    return np.stack([a * d_scale, b * d_scale], axis=-1).astype(np.float32)


def descriptor(
    curv: Curvature,
    *,
    curvedness_norm: float | Literal["auto"] = "auto",
    percentile: float = DEFAULT_PERCENTILE,
) -> Descriptor:
    """Apparent Relief descriptor ``S = D · L`` (Apparent Relief §2, Fig. 1a-b).

    ::

        D = (κ1, κ2) / |(κ1, κ2)|   (0 where |(κ1, κ2)| = 0)
        L = min(sqrt((κ1² + κ2²) / 2) · weight / L_norm, 1)
        S = D · L = (κ1, κ2) · min(weight / (√2 · L_norm), 1 / |(κ1, κ2)|)

    Parameters
    ----------
    curv : Curvature
        View-centred principal curvatures (:func:`ops.curvature.principal_curvatures`; its
        ``scale``, relative to the image height, sets the level of detail).
    curvedness_norm : "auto" or float
        L_norm, the curvedness (per unit image height) that reaches the rim of the descriptor
        domain, in (0, 1e6]; ``"auto"``: the ``percentile`` of the covered pixels' (weight > 0.5)
        curvedness, at least :data:`AUTO_NORM_FLOOR`. Pin it (the returned ``norm``) so a
        sequence does not flicker.
    percentile : float
        In (0, 100], used by ``"auto"``.

    Returns
    -------
    Descriptor
        ``s``: (H, W, 2) float32 (S1, S2) with |S| <= 1, S1 >= S2, 0 on background;
        ``norm``: the L_norm used.

    Notes
    -----
    When the curvature was computed on a coarser working grid, S is computed there and
    interpolated bilinearly (S is linear in κ below the rim, so this matches interpolating κ).
    """
    s1, s2, norm, up, _, _ = _grid_descriptor(curv, curvedness_norm, percentile)
    if up is not None:
        s1, s2 = up(s1), up(s2)
    return Descriptor(np.asarray(cv2.merge([s1, s2]), np.float32), norm)


def _polar(s: F32) -> tuple[F32, F32]:
    """(|S| clipped to 1, t) with t in [0, 180] degrees the *folded* shape angle: 0 cap, 45 convex,
    90 saddle, 135 concave, 180 cup; the unreached half (S2 > S1) is mirrored onto the other."""
    s1, s2 = cv2.split(np.ascontiguousarray(s, dtype=np.float32))
    rho = np.minimum(magnitude(s1, s2), np.float32(1.0))
    phase = np.asarray(cv2.phase(s1, s2, angleInDegrees=True), np.float32)  # [0, 360)
    phase += np.float32(135.0)
    np.subtract(phase, np.float32(360.0), out=phase, where=phase >= 360.0)
    phase -= np.float32(180.0)
    t = np.abs(phase)
    return np.asarray(rho, np.float32), np.asarray(t, np.float32)


def shape_index(s: NDArray[np.generic]) -> F32:
    """Koenderink's shape index of the descriptor, ``2θ/π + 1/2`` with θ = atan2(S2, S1):
    1 on caps, 0.5 convex, 0 saddles, -0.5 concave, -1 cups (0 where S = 0). (H, W) float32."""
    arr = _check_s(s)
    rho, t = _polar(arr)
    si = cv2.addWeighted(t, -1.0 / 90.0, t, 0.0, 1.0)
    si[rho <= 0.0] = 0.0
    return np.asarray(si, np.float32)


def classify(s: NDArray[np.generic]) -> NDArray[np.int8]:
    """Region index (into :data:`REGIONS`) of each descriptor: 0 plane (|S| < PLANE_RADIUS),
    then cap, convex, saddle, concave, cup, each ±22.5° around its angle (Fig. 1a); S2 > S1 is
    classified as its mirror image (S2, S1)."""
    arr = _check_s(s)
    rho, t = _polar(arr)
    sector = np.minimum(np.floor((t + 22.5) / 45.0), 4.0).astype(np.int8) + 1
    return np.where(rho < PLANE_RADIUS, np.int8(0), sector).astype(np.int8)


# -- colour code (Fig. 1a) ------------------------------------------------------------------------


def _hue_lut() -> F32:
    """(1, 181, 3) RGB of the folded angle t = 0..180 degrees: cap, convex, saddle, concave, cup
    colours at 0, 45, 90, 135, 180, linearly interpolated."""
    names = ("cap", "convex", "saddle", "concave", "cup")
    anchors = np.array([0.0, 45.0, 90.0, 135.0, 180.0])
    cols = np.array([REGION_COLORS[n] for n in names])
    t = np.arange(181.0)
    lut = np.stack([np.interp(t, anchors, cols[:, c]) for c in range(3)], axis=-1)
    return lut.reshape(1, 181, 3).astype(np.float32)


_LUT = _hue_lut()


def descriptor_colors(s: NDArray[np.generic]) -> F32:
    """Fig. 1a colour code of the descriptor: white on planes, blending with |S| towards yellow
    (caps), green (convex), blue (saddles), red (concave), pink (cups) interpolated by angle.

    ``colour = white + |S| · (hue(θ) − white)``. Returns (H, W, 3) float32 RGB in [0, 1].
    """
    arr = _check_s(s)
    rho, t = _polar(arr)
    hue = cv2.remap(_LUT, t, np.zeros_like(t), cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    hue = np.asarray(hue, np.float32).reshape(*t.shape, 3) - np.float32(1.0)
    hue *= rho[..., None]
    hue += np.float32(1.0)
    return np.asarray(np.clip(hue, 0.0, 1.0, out=hue), np.float32)
