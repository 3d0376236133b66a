"""Congruence between shading flow and shape flow (Mestres et al., EG 2021, §7, Eq. 2).

Local Light Alignment measures how well a shading depicts shape by comparing, per pixel, the
*shading flow* (structure tensor of the image luminance gradients) with the *shape flow*
(structure tensor of the depth gradients), following Vergne et al. 2016 [VBBF16] and the structure
tensor of Bigün 1987 [Big87]. Each flow gives a dominant eigenvector ``v`` (the direction in which
patterns are most compressed, i.e. the local gradient direction) and a strength ``e``, the mean
of the two eigenvalues. The score is Eq. 2 of the paper::

    s = Σ_i e_shape(i) (1 − ⌊e_shape(i) − e_shading(i)⌋) |v_shape(i) · v_shading(i)|
        ───────────────────────────────────────────────────────────────────────────────
                                   Σ_i e_shape(i)

where ⌊x⌋ clamps x to [0, 1]. The paper writes the shape terms with subscript ``c`` and the
shading terms with ``s``; the weights are the *shape* strengths ("a weight proportional to the
magnitude of the shape flow"), and the clamp keeps exaggeration (e_shading > e_shape) from
lowering the score.

Implementation choices (the paper does not fix them):

- Shading = Rec.709 luminance of linear RGB (``cv2.transform``).
- Shape = the **normals** when they are given: the structure tensor of the gradients of the
  camera-space normal (summed over its three components), i.e. how fast and in which direction
  the surface turns in the image. The paper computes the shape flow "using depth gradients" and
  expects that "curved surfaces will thus have much more impact on the final score than flat
  ones, for which the directions become undefined". Depth gradients give that only for planes
  facing the camera: a receding floor has a strong, well-defined depth gradient everywhere, and
  on path-traced frames with a ground plane it carried most of the weight (80 % of Σ e_shape on
  a Cycles still life), so the score mostly measured the floor's cast shadows and noise, which
  no shape enhancement should touch. The normal's gradient is 0 on every plane, whatever its
  slant, and on a curved surface points across the feature like the depth gradient does; it is
  dimensionless, like the log depth. Without normals the shape is the **log** depth, so the
  flow does not depend on the scene's units or its distance to the camera (∇log d = ∇d / d).
- Gradients at ``gradient_scale`` (a Gaussian σ relative to the image height), integration at
  ``integration_scale`` (idem). For speed the image is area-downsampled by an integer factor so
  that each σ is 1–4 px at its level; the score is evaluated at the integration level, where the
  integrated tensor is smooth, and the full-resolution maps are upsampled from it on first access.
- Background and depth discontinuities do not count: gradients are only taken where the whole 3×3
  Sobel stencil is covered and the log depth does not jump by more than ``depth_jump`` between
  neighbours; the tensors are integrated by normalised convolution over those pixels, so the
  silhouette neither produces shape flow nor bleeds background into the shading flow.
- Strengths are made comparable by dividing each by its ``percentile``-th percentile over the
  covered pixels and clipping to [0, 1]. With normals both are taken where there is shape: the
  shape's over the pixels whose shape strength is above 1e-4 of the largest (not the planes,
  where it is 0), the shading's over those whose normalised shape strength is above 0.1, so the
  shading strength of a floor's cast shadows does not set the scale the objects' shading is
  measured on. This makes the score invariant to scaling the image
  brightness (the tensor scales by k², and so does the percentile) and to the depth units.
  To compare several renderings of one frame (LLA §7), the shading strength can instead be
  divided by a reference's (``shading_norm``): then only the shape's scale is per image, and a
  rendering with more shading contrast than the reference keeps it, as the clamp of Eq. 2
  intends ("prevents the score from dropping in case of exaggeration"); with per-image
  normalisation that clamp could never act on a rendering that is only more contrasted.
  A strength below ~1e-5 of the signal's own scale (float rounding noise on a constant image or
  a fronto-parallel plane) counts as no flow: its direction is undefined and gives a dot of 0.

Speed (none of it changes the result beyond float rounding): the full-resolution pass and the
gradient level run on strips of rows (with a halo covering the filters) on parallel threads,
so the intermediates stay in the CPU cache (OpenCV's filters are single-threaded); after the
first pass only the bounding box of the covered pixels, grown by more than the filters' reach,
is processed, since everything is exactly 0 further away; OpenCV works on one channel at a time
(its area resize and blur are several times faster on single channels).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

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
from ops.parallel import run_strips

__all__ = ["CongruenceResult", "congruence"]

F32 = NDArray[np.float32]

#: Rec. 709 / sRGB luminance weights of linear RGB.
_LUMA = np.array([REC709_Y], dtype=np.float32)  # (1, 3) for cv2.transform

# Relative floor under which a tensor is treated as zero (float32 rounding noise).
_REL_FLOOR = 1e-10
# With normals: the pixels whose shape strength exceeds this fraction of the largest set the
# shape's scale, and those whose normalised shape strength exceeds _SHAPE_COUNTED the shading's.
_REL_CURVED = 1e-4
_SHAPE_COUNTED = 0.1


@dataclass
class CongruenceResult:
    """Result of :func:`congruence`.

    ``score`` is computed eagerly; the per-pixel maps are upsampled to the input resolution on
    first access (and cached), so a sweep that only needs scores does not pay for them. All maps
    are 0 outside the scored pixels (background, silhouette borders, depth discontinuities).

    Attributes
    ----------
    score : float
        Eq. 2, in [0, 1]; 0 when there is no shape flow at all.
    score_map : (H, W) float32
        Per-pixel score (1 − ⌊e_shape − e_shading⌋) |v_shape · v_shading| in [0, 1].
    shading_flow, shape_flow : (H, W, 2) float32
        Dominant eigenvectors (x right, y up: camera convention), unit length, sign arbitrary
        (an orientation); (0, 0) where the flow is undefined.
    shading_strength, shape_strength : (H, W) float32
        Normalised mean eigenvalues in [0, 1].
    weight : (H, W) float32
        Fraction of each pixel that is scored (1 inside, 0 on background).
    analysis_shape : (h, w)
        Resolution at which the score was evaluated.
    shading_norm : float
        The shading strength that was mapped to 1 (the ``shading_norm`` argument, or this
        image's percentile): pass it to score other renderings of the same frame on this scale.
    """

    score: float
    analysis_shape: tuple[int, int]
    shading_norm: float
    _out_shape: tuple[int, int] = field(repr=False)
    _low: dict[str, F32] = field(repr=False)

    def _up(self, arr: F32) -> F32:
        h, w = self._out_shape
        if arr.shape[:2] == (h, w):
            return arr
        return np.asarray(cv2.resize(arr, (w, h), interpolation=cv2.INTER_LINEAR), np.float32)

    @functools.cached_property
    def _maps(self) -> dict[str, F32]:
        low = self._low
        weight = self._up(low["weight"])
        insidef = (weight > 0.5).astype(np.float32)
        out: dict[str, F32] = {
            "weight": np.asarray(cv2.threshold(weight, 1e-3, 0, cv2.THRESH_TOZERO)[1], np.float32)
        }
        for name in ("score", "e_shading", "e_shape"):
            out[name] = np.asarray(cv2.multiply(self._up(low[name]), insidef), np.float32)
        for name in ("shading", "shape"):
            c = self._up(low[f"cos2_{name}"])
            s = self._up(low[f"sin2_{name}"])
            out[f"{name}_flow"] = _half_angle(c, s, insidef)
        return out

    @property
    def score_map(self) -> F32:
        return self._maps["score"]

    @property
    def shading_flow(self) -> F32:
        return self._maps["shading_flow"]

    @property
    def shape_flow(self) -> F32:
        return self._maps["shape_flow"]

    @property
    def shading_strength(self) -> F32:
        return self._maps["e_shading"]

    @property
    def shape_strength(self) -> F32:
        return self._maps["e_shape"]

    @property
    def weight(self) -> F32:
        return self._maps["weight"]


def _f32(x: object) -> F32:
    """An OpenCV result as a float32 array (no copy)."""
    return np.asarray(x, np.float32)


def _half_angle(c: F32, s: F32, insidef: F32) -> F32:
    """Unit (cos θ, sin θ) from a doubled-angle vector ∝ (cos 2θ, sin 2θ); 0 where undefined."""
    mag, ang = cv2.cartToPolar(c, s)
    okf = cv2.multiply((mag > 1e-6).astype(np.float32), insidef)
    vx, vy = cv2.polarToCart(okf, ang * np.float32(0.5))
    return np.asarray(cv2.merge([vx, vy]), np.float32)


# Strip heights, in rows of the level a pass writes: the full-resolution pass (gradient-level
# rows) and the gradient pass (gradient-level rows, rounded to a multiple of the integration
# factor). Strips keep each pass's working set in the CPU cache and run on parallel threads.
_ROWS_COVER = 48
_ROWS_GRAD = 136

_ONES3 = np.ones((3, 3), np.uint8)


def _covered_level(
    img: F32,
    dep: F32,
    mask: NDArray[np.generic] | None,
    f: int,
    size: tuple[int, int],
    normal: F32 | None = None,
) -> list[F32]:
    """Covered luminance, covered depth and coverage (then, with ``normal``, the covered n_x,
    n_y, n_z), area-downsampled by ``f`` to ``size``.

    Coverage is finite positive depth (and mask > 0.5); the other planes are 0 where it is 0
    (a NaN depth stays NaN). When ``f`` divides the image this runs on strips of rows (an
    integer area resize only mixes rows of one strip, so the result is the same as one pass).
    """
    h, w = dep.shape
    ws, hs = size
    strips = f == 1 or (w == ws * f and h == hs * f)
    n_out = 3 if normal is None else 6
    out = [np.empty((hs, ws), np.float32) for _ in range(n_out)]
    msk = None if mask is None else np.asarray(mask)

    def strip(a: int, b: int) -> None:
        r0, r1 = (a * f, b * f) if strips else (0, h)
        if f == 1:
            planes = [o[a:b] for o in out]
        else:
            planes = [np.empty((r1 - r0, w), np.float32) for _ in range(n_out)]
        lum, depc, covf = planes[:3]
        cv2.threshold(dep[r0:r1], 1e30, 0, cv2.THRESH_TOZERO_INV, dst=depc)  # +inf -> 0
        cv2.threshold(depc, 0, 1, cv2.THRESH_BINARY, dst=covf)  # > 0 -> 1
        if msk is not None:
            cv2.multiply(covf, (msk[r0:r1] > 0.5).astype(np.float32), dst=covf)
        cv2.multiply(depc, covf, dst=depc)
        if img.ndim == 3:
            cv2.transform(img[r0:r1], _LUMA, dst=lum)
            cv2.multiply(lum, covf, dst=lum)
        else:
            cv2.multiply(img[r0:r1], covf, dst=lum)
        if normal is not None:
            for c, dst in enumerate(planes[3:]):
                cv2.multiply(np.ascontiguousarray(normal[r0:r1, :, c]), covf, dst=dst)
                cv2.patchNaNs(dst, 0.0)  # uncovered normals may be NaN (NaN * 0 = NaN)
        if f > 1:
            rows = slice(a, b) if strips else slice(0, hs)
            for src, o in zip(planes, out, strict=True):
                cv2.resize(src, (ws, o[rows].shape[0]), dst=o[rows], interpolation=cv2.INTER_AREA)

    run_strips(hs, strip, _ROWS_COVER if strips else hs)
    return out


def _tensor_products(
    planes: list[F32], sigma: float, jump: float, f: int, size: tuple[int, int]
) -> list[F32]:
    """Gradient-level pass over the planes of :func:`_covered_level` (luminance, depth,
    coverage and, when given, n_x, n_y, n_z): blur them by ``sigma``, normalise by the
    coverage, take Sobel gradients of the luminance and of the shape signal (the log depth, or
    each normal component) where the whole stencil is covered and the log depth steps by at most
    ``jump``, and return the structure-tensor products [lxx, lxy, lyy, sxx, sxy, syy, valid]
    area-downsampled by ``f`` to ``size`` (the shape products summed over the normal's
    components).

    Runs on strips of rows with a halo covering the blur and the 3×3 stencils when ``f``
    divides the level, which gives the same result as one pass over the whole level.
    """
    cov = planes[2]
    h, w = cov.shape
    ws, hs = size
    strips = f == 1 or (w == ws * f and h == hs * f)
    halo = int(4.0 * sigma) + 4  # > Gaussian radius (≈ 4σ) + the Sobel / erosion row
    out = [np.empty((hs, ws), np.float32) for _ in range(7)]

    def sobel(x: F32, rows: slice) -> tuple[F32, F32]:
        return (
            _f32(cv2.Sobel(x, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)[rows]),
            _f32(cv2.Sobel(x, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)[rows]),
        )

    def strip(a: int, b: int) -> None:
        lo, hi = max(0, a - halo), min(h, b + halo)
        chans = [x[lo:hi] for x in planes]
        if sigma >= 0.3:
            chans = [_f32(cv2.GaussianBlur(x, (0, 0), sigma)) for x in chans]
        lum1, dep1, c1 = chans[:3]
        # 1 / coverage; where the coverage is <= 1e-6 this is 1e6 instead of 0, which only
        # changes values no kept gradient reads (those need coverage > 0.999) and keeps them
        # finite
        inv = cv2.divide(1.0, np.maximum(c1, np.float32(1e-6)))
        logd1 = _f32(cv2.log(np.maximum(cv2.multiply(dep1, inv), np.float32(1e-30))))
        # Sobel derivatives per level pixel (x right, rows down), kept where the whole stencil
        # is covered and the log depth does not jump; computed on the strip, used on [a, b)
        rows = slice(a - lo, b - lo)
        lx, ly = sobel(_f32(cv2.multiply(lum1, inv)), rows)
        dx, dy = sobel(logd1, rows)
        full = cv2.erode(cv2.threshold(c1, 0.999, 1, cv2.THRESH_BINARY)[1], _ONES3)[rows]
        steep = cv2.max(np.abs(dx), np.abs(dy))
        vf = cv2.multiply(cv2.threshold(steep, jump, 1, cv2.THRESH_BINARY_INV)[1], full)
        shape = [(dx, dy)]
        if len(chans) > 3:  # the normal's components
            shape = [sobel(_f32(cv2.multiply(n, inv)), rows) for n in chans[3:]]
        lx, ly = _f32(cv2.multiply(lx, vf)), _f32(cv2.multiply(ly, vf))
        sxx, sxy, syy = (np.zeros_like(vf) for _ in range(3))
        for sx, sy in shape:
            gx, gy = cv2.multiply(sx, vf), cv2.multiply(sy, vf)
            cv2.accumulateSquare(gx, sxx)
            cv2.accumulateProduct(gx, gy, sxy)
            cv2.accumulateSquare(gy, syy)
        # xy products in image (row-down) convention; the sign is flipped to y-up later
        prods = (lx * lx, lx * ly, ly * ly, sxx, sxy, syy, vf)
        orows = slice(a // f, b // f) if strips else slice(0, hs)
        for p, o in zip(prods, out, strict=True):
            if f > 1:
                cv2.resize(p, (ws, o[orows].shape[0]), dst=o[orows], interpolation=cv2.INTER_AREA)
            else:
                o[orows] = p

    run_strips(h, strip, max(1, _ROWS_GRAD // f) * f if strips else h)
    return out


#: The analysis-level maps a :class:`CongruenceResult` upsamples on demand.
_LOW_MAPS = (
    "score",
    "e_shading",
    "e_shape",
    "weight",
    "cos2_shading",
    "sin2_shading",
    "cos2_shape",
    "sin2_shape",
)


def _reach(sigma: float) -> int:
    """An upper bound of the radius of OpenCV's float Gaussian kernel for ``sigma`` (its size
    is round(8σ + 1) | 1)."""
    return int(4.0 * sigma) + 1


def _window(
    cov: F32, f: int, size: tuple[int, int], margin: int
) -> tuple[tuple[int, int, int, int], tuple[int, int, int, int]] | None:
    """Rows and columns (y0, y1, x0, x1) of the level ``cov`` that hold its covered pixels plus
    ``margin``, aligned to the factor ``f`` of the next level, and the same window at the next
    level (of ``size``); the whole level when ``f`` does not divide it; None when nothing is
    covered.

    The first column is a multiple of 16 at both levels and the window extends 16 columns
    further on the right, so that OpenCV's vectorised filters process every column that is
    not 0 with the same lanes as on the whole level (a bit-identical result).
    """
    h, w = cov.shape
    ws, hs = size
    bx, by, bw, bh = cv2.boundingRect((cov > 0).view(np.uint8))
    if bw == 0 or bh == 0:
        return None
    if f > 1 and (w != ws * f or h != hs * f):
        return (0, h, 0, w), (0, hs, 0, ws)
    y0 = max(0, by - margin) // f
    x0 = max(0, bx - margin) // (16 * f) * 16
    y1 = min(hs, -(-(by + bh + margin) // f))
    x1 = min(ws, -(-(bx + bw + margin) // f) + 16)
    return (y0 * f, y1 * f, x0 * f, x1 * f), (y0, y1, x0, x1)


def _percentile(vals: F32, q: float) -> float:
    """``np.percentile(vals, q)`` (linear method), bit for bit, with one partial sort of ``vals``
    in place (numpy's partitions at four ranks and copies the array first)."""
    if type(q) not in (int, float):  # numpy scalars interpolate in their own precision
        return float(np.percentile(vals, q))
    n = vals.size
    virtual = (n - 1) * (q / 100.0)
    k = min(int(np.floor(virtual)), n - 1)
    gamma = virtual - k
    vals.partition(k)
    a = vals[k]
    b = vals[k + 1 :].min() if k + 1 < n else a
    d = b - a
    return float(b - d * (1.0 - gamma) if gamma >= 0.5 else a + d * gamma)


def _flow(
    txx: F32,
    txy: F32,
    tyy: F32,
    invw: F32,
    inside: NDArray[np.bool_],
    outside: NDArray[np.bool_],
    ref: float,
    q: float,
    norm: float | None = None,
    counted: NDArray[np.bool_] | None = None,
) -> tuple[F32, F32, F32, NDArray[np.bool_], float]:
    """Normalised strength, doubled-angle direction (cos 2θ, sin 2θ), definedness and the
    strength mapped to 1 (``norm``, else the ``q``-th percentile over the ``counted`` pixels,
    by default the ``inside`` ones) of one integrated structure tensor (row-down xy products; y
    flipped to up here)."""
    jxx = np.multiply(txx, invw)
    jyy = np.multiply(tyy, invw)
    e = np.add(jxx, jyy)
    e *= 0.5  # mean eigenvalue (≥ 0: the tensor is a positive blur of squares)
    a = np.subtract(jxx, jyy, out=jxx)
    b = np.asarray(cv2.multiply(txy, invw, scale=-2.0))  # 2 jxy, y up
    floor = _REL_FLOOR * ref * ref
    mag = np.asarray(cv2.magnitude(a, b))
    defined = mag > e * np.float32(1e-6)
    defined &= e > floor
    defined &= inside
    if norm is None:
        vals = e[inside if counted is None else counted]
        p = _percentile(vals, q) if vals.size else 0.0
    else:
        p = float(norm)
    p = max(p, floor)
    if p > 0:
        en = np.multiply(e, np.float32(1.0 / p), out=e)
        np.minimum(en, np.float32(1.0), out=en)
    else:
        en = np.multiply(e, 0, out=e)
    en[outside] = 0.0
    inv_mag = np.divide(1.0, mag, out=np.zeros_like(mag), where=defined)
    return en, np.multiply(a, inv_mag, out=a), np.multiply(b, inv_mag, out=b), defined, p


def _brightness(lum: F32, cov: F32) -> float:
    """The scale of the image's brightness for the noise floor: the 99.9th percentile of the
    covered pixels' |luminance| (the maximum would let one firefly or sun glint, thousands of
    times brighter than the rest, push every real gradient under the floor)."""
    full = cov > 0.5
    if not full.any():
        lmin, lmax = cv2.minMaxLoc(lum)[:2]
        return max(abs(lmin), abs(lmax)) / max(float(cv2.minMaxLoc(cov)[1]), 1e-6)
    return float(np.percentile(np.abs(lum[full] / cov[full]), 99.9))


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

    Returns
    -------
    CongruenceResult
        The score and its per-pixel maps.
    """
    img = np.asarray(image)
    dep = np.asarray(depth)
    if dep.ndim != 2:
        raise ValueError(f"depth must be (H, W), got shape {dep.shape}")
    h, w = dep.shape
    if h < 3 or w < 3:
        raise ValueError(f"depth must be at least 3x3, got shape {dep.shape}")
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[..., 0]
    if img.shape[:2] != (h, w) or img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] != 3):
        raise ValueError(
            f"image must be (H, W, 3) or (H, W) matching depth {dep.shape}, got {img.shape}"
        )
    if mask is not None and np.shape(mask) != (h, w):
        raise ValueError(f"mask must be (H, W) = {dep.shape}, got shape {np.shape(mask)}")
    href = h if image_height is None else int(image_height)
    if href <= 0:
        raise ValueError(f"image_height must be a positive number of pixels, got {image_height!r}")
    sg = GRADIENT_SCALE.check(gradient_scale, "gradient_scale") * href
    si = INTEGRATION_SCALE.check(integration_scale, "integration_scale") * href
    PERCENTILE.check(percentile, "percentile")
    DEPTH_JUMP.check(depth_jump, "depth_jump")
    if shading_norm is not None:
        SHADING_NORM.check(shading_norm, "shading_norm")

    img = img.astype(np.float32, copy=False)
    dep = dep.astype(np.float32, copy=False)

    # --- gradient level: area-downsample by f1 so that sigma_g is 1-2 px there; area-average
    # the covered depth, luminance and coverage, blur them, and normalise by the coverage.
    f1 = max(1, min(int(sg), h // 8 or 1, w // 8 or 1))
    size1 = (max(w // f1, 3), max(h // f1, 3)) if f1 > 1 else (w, h)
    nrm = None if normal is None else np.asarray(normal, np.float32)
    if nrm is not None and nrm.shape != (h, w, 3):
        raise ValueError(f"normal must be (H, W, 3) matching depth {dep.shape}, got {nrm.shape}")
    level = _covered_level(img, dep, mask, f1, size1, nrm)
    lum0, dep0, cov0 = level[:3]
    # NaN / inf anywhere propagate through the weighted sums (x * 0 = NaN): check the small
    # copies (a sum accumulated in float64 cannot overflow: it is finite iff every value is)
    if not np.isfinite(cv2.sumElems(lum0)[0] + cv2.sumElems(dep0)[0]):
        if np.isnan(dep).any():
            raise ValueError("depth contains NaN (use +inf for background)")
        raise ValueError("image contains NaN or infinite values")
    lref = _brightness(lum0, cov0)

    # --- integration level: area-downsample the tensor products by f2 so that sigma_i is
    # 2-4 px there.
    w1, h1 = size1
    s1, si1 = sg / f1, si / f1
    f2 = max(1, min(int(si1 / 2.0), h1 // 8 or 1, w1 // 8 or 1))
    size2 = (max(w1 // f2, 3), max(h1 // f2, 3)) if f2 > 1 else (w1, h1)
    s2 = si1 / f2
    low = {k: np.zeros(size2[::-1], np.float32) for k in _LOW_MAPS}
    # Everything below is 0 away from the covered pixels: work on their bounding box, grown by
    # more than the blurs' and stencils' reach (the result is the same as on the whole level)
    win = _window(cov0, f2, size2, max(_reach(s1) + 2, (_reach(s2) + 2) * f2))
    if win is None:  # nothing covered
        return CongruenceResult(0.0, (size2[1], size2[0]), shading_norm or 0.0, (h, w), low)
    (y0, y1, x0, x1), (v0, v1, u0, u1) = win
    crop = [np.ascontiguousarray(c[y0:y1, x0:x1]) for c in level]
    jump = 0.5 * float(depth_jump)
    prods = _tensor_products(crop, s1, jump, f2, (u1 - u0, v1 - v0))
    area = prods[6]  # fraction of each analysis pixel with valid gradients
    tens = list(prods)

    def integrate(a: int, b: int) -> None:
        for i in range(a, b):
            tens[i] = _f32(cv2.GaussianBlur(prods[i], (0, 0), s2))

    run_strips(len(tens), integrate, 1)
    wsum = tens[6]
    invw = np.divide(1.0, wsum, out=np.zeros_like(wsum), where=wsum > 1e-4)

    inside = area > 0.5
    outside = ~inside
    # signal scales for the noise floors: lref (brightness) above; log depth and unit normals
    # are dimensionless
    dref = 1.0

    # with normals, the scales are measured where there is shape: planes (0) do not set the
    # shape's, nor a floor's cast shadows the shading's; the log depth's flow is strong on
    # floors too, so it counts every pixel
    curved = None
    if nrm is not None:
        e_shape = np.multiply(np.add(tens[3], tens[5]), invw)
        curved = inside & (e_shape > _REL_CURVED * float(e_shape.max(initial=0.0)))
        curved = curved if curved.any() else None
    ec, cb, sb, dc, _ = _flow(
        tens[3], tens[4], tens[5], invw, inside, outside, dref, percentile, None, curved
    )
    counted = None if curved is None else inside & (ec > _SHAPE_COUNTED)
    counted = counted if counted is not None and counted.any() else None
    es, ca, sa, ds, norm_s = _flow(
        tens[0], tens[1], tens[2], invw, inside, outside, lref, percentile, shading_norm, counted
    )
    cosd = ca * cb
    cosd += sa * sb  # cos of the doubled-angle difference
    cosd += 1.0
    cosd *= 0.5
    dot = np.sqrt(np.clip(cosd, 0.0, 1.0, out=cosd), out=cosd)
    ds &= dc
    dot[~ds] = 0.0
    smap = np.subtract(ec, es)
    np.clip(smap, 0.0, 1.0, out=smap)
    np.subtract(1.0, smap, out=smap)
    smap *= dot
    smap[outside] = 0.0
    wgt = ec * area
    den = float(wgt.sum(dtype=np.float64))
    wgt *= smap
    score = float(wgt.sum(dtype=np.float64) / den) if den > 0 else 0.0

    maps = (smap, es, ec, np.where(inside, area, np.float32(0)), ca, sa, cb, sb)
    for name, m in zip(_LOW_MAPS, maps, strict=True):
        low[name][v0:v1, u0:u1] = m
    return CongruenceResult(
        score=float(np.clip(score, 0.0, 1.0)),
        analysis_shape=(size2[1], size2[0]),
        shading_norm=norm_s,
        _out_shape=(h, w),
        _low=low,
    )
