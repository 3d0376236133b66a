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

- Shading = Rec.709 luminance of linear RGB (``cv2.transform``). Shape = **log** depth, so the
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
  covered pixels and clipping to [0, 1]. This makes the score invariant to scaling the image
  brightness (the tensor scales by k², and so does the percentile) and to the depth units.
  A strength below ~1e-5 of the signal's own scale (float rounding noise on a constant image or
  a fronto-parallel plane) counts as no flow: its direction is undefined and gives a dot of 0.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]

#: Rec. 709 / sRGB luminance weights of linear RGB.
REC709 = np.array([[0.2126, 0.7152, 0.0722]], dtype=np.float32)

# Relative floor under which a tensor is treated as zero (float32 rounding noise).
_REL_FLOOR = 1e-10


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
    """

    score: float
    analysis_shape: tuple[int, int]
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


def _half_angle(c: F32, s: F32, insidef: F32) -> F32:
    """Unit (cos θ, sin θ) from a doubled-angle vector ∝ (cos 2θ, sin 2θ); 0 where undefined."""
    mag, ang = cv2.cartToPolar(c, s)
    okf = cv2.multiply((mag > 1e-6).astype(np.float32), insidef)
    vx, vy = cv2.polarToCart(okf, ang * np.float32(0.5))
    return np.asarray(cv2.merge([vx, vy]), np.float32)


def _check_scale(name: str, value: float, hi: float) -> float:
    v = float(value)
    if not np.isfinite(v) or not (0.0 < v <= hi):
        raise ValueError(f"{name} must be in (0, {hi:g}] (relative to image height), got {value!r}")
    return v


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
) -> CongruenceResult:
    """Congruence score between shading and shape flows (Mestres et al. 2021, §7, Eq. 2).

    ``s = Σ e_shape (1 − ⌊e_shape − e_shading⌋) |v_shape·v_shading| / Σ e_shape`` over the
    covered pixels, with (v, e) the dominant eigenvector and mean eigenvalue of the structure
    tensor ``G_σi * (∇f ∇fᵀ)`` of f = luminance (shading) and f = log depth (shape), the gradient
    taken at σ_g. See the module docstring for the normalisation of e.

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
    sg = _check_scale("gradient_scale", gradient_scale, 0.1) * href
    si = _check_scale("integration_scale", integration_scale, 0.25) * href
    if not (0.0 < float(percentile) <= 100.0):
        raise ValueError(f"percentile must be in (0, 100], got {percentile!r}")
    if not (np.isfinite(depth_jump) and depth_jump > 0):
        raise ValueError(f"depth_jump must be > 0, got {depth_jump!r}")

    img = img.astype(np.float32, copy=False)
    dep = dep.astype(np.float32, copy=False)
    lum = cv2.transform(img, REC709) if img.ndim == 3 else img

    # coverage: finite positive depth (and mask); depc = depth there, 0 elsewhere (a NaN depth
    # stays NaN and is reported below)
    depc = cv2.threshold(dep, 1e30, 0, cv2.THRESH_TOZERO_INV)[1]  # +inf -> 0
    covf = cv2.threshold(depc, 0, 1, cv2.THRESH_BINARY)[1]  # > 0 -> 1
    if mask is not None:
        covf = cv2.multiply(covf, (np.asarray(mask) > 0.5).astype(np.float32))
    depc = cv2.multiply(depc, covf)
    lumc = cv2.multiply(lum, covf)

    # --- gradient level: area-downsample by f1 so that sigma_g is 1-2 px there; area-average
    # the covered depth, luminance and coverage, blur them, and normalise by the coverage.
    f1 = max(1, min(int(sg), h // 8 or 1, w // 8 or 1))
    chans = [lumc, depc, covf]
    if f1 > 1:
        size1 = (max(w // f1, 3), max(h // f1, 3))
        chans = [cv2.resize(c, size1, interpolation=cv2.INTER_AREA) for c in chans]
    # NaN / inf anywhere propagate through the weighted sums (x * 0 = NaN): check the small copy
    if not (cv2.checkRange(chans[0])[0] and cv2.checkRange(chans[1])[0]):
        if np.isnan(dep).any():
            raise ValueError("depth contains NaN (use +inf for background)")
        raise ValueError("image contains NaN or infinite values")
    lmin, lmax = cv2.minMaxLoc(chans[0])[:2]
    lref = max(abs(lmin), abs(lmax)) / max(float(np.max(chans[2])), 1e-6)
    s1 = sg / f1
    if s1 >= 0.3:
        chans = [cv2.GaussianBlur(c, (0, 0), s1) for c in chans]
    c1 = chans[2]
    inv = np.divide(1.0, c1, out=np.zeros_like(c1), where=c1 > 1e-6)
    lum1 = cv2.multiply(chans[0], inv)
    logd1 = cv2.log(np.maximum(cv2.multiply(chans[1], inv), np.float32(1e-30)))

    # Sobel derivatives per level pixel (x right, rows down); gradients are kept where the whole
    # stencil is covered and the log depth does not jump.
    lx = cv2.Sobel(lum1, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
    ly = cv2.Sobel(lum1, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
    dx = cv2.Sobel(logd1, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
    dy = cv2.Sobel(logd1, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
    full = np.asarray(cv2.erode((c1 > 0.999).view(np.uint8), np.ones((3, 3), np.uint8))) > 0
    jump = 0.5 * float(depth_jump)
    vf = (full & (np.asarray(cv2.max(np.abs(dx), np.abs(dy))) <= jump)).astype(np.float32)
    lx, ly, dx, dy = (cv2.multiply(g, vf) for g in (lx, ly, dx, dy))
    # xy products in image (row-down) convention; the sign is flipped to y-up below.
    tens = cv2.merge(
        [
            cv2.multiply(lx, lx),
            cv2.multiply(lx, ly),
            cv2.multiply(ly, ly),
            cv2.multiply(dx, dx),
            cv2.multiply(dx, dy),
            cv2.multiply(dy, dy),
            vf,
        ]
    )

    # --- integration level: area-downsample by f2 so that sigma_i is 2-4 px there.
    h1, w1 = tens.shape[:2]
    si1 = si / f1
    f2 = max(1, min(int(si1 / 2.0), h1 // 8 or 1, w1 // 8 or 1))
    if f2 > 1:
        tens = cv2.resize(tens, (max(w1 // f2, 3), max(h1 // f2, 3)), interpolation=cv2.INTER_AREA)
    area = tens[..., 6].copy()  # fraction of each analysis pixel with valid gradients
    tens = cv2.GaussianBlur(tens, (0, 0), si1 / f2)
    wsum = tens[..., 6]
    invw = np.divide(1.0, wsum, out=np.zeros_like(wsum), where=wsum > 1e-4)

    inside = area > 0.5
    # signal scales for the noise floors: lref (brightness) above, log depth is dimensionless
    dref = 1.0

    flows = {}
    for name, k, ref in (("shading", 0, lref), ("shape", 3, dref)):
        jxx = tens[..., k] * invw
        jxy = tens[..., k + 1] * -invw  # y up
        jyy = tens[..., k + 2] * invw
        e = 0.5 * (jxx + jyy)
        a = jxx - jyy
        b = 2.0 * jxy
        floor = _REL_FLOOR * ref * ref
        defined = inside & (e > floor)
        mag = cv2.magnitude(a, b)
        defined &= mag > 1e-6 * e
        vals = e[inside]
        p = float(np.percentile(vals, percentile)) if vals.size else 0.0
        p = max(p, floor)
        en = np.clip(e * np.float32(1.0 / p), 0.0, 1.0).astype(np.float32) if p > 0 else e * 0
        en[~inside] = 0.0
        inv_mag = np.divide(1.0, mag, out=np.zeros_like(mag), where=defined)
        flows[name] = (en, a * inv_mag, b * inv_mag, defined)

    es, ca, sa, ds = flows["shading"]
    ec, cb, sb, dc = flows["shape"]
    cosd = ca * cb + sa * sb  # cos of the doubled-angle difference
    dot = np.sqrt(np.clip(0.5 * (1.0 + cosd), 0.0, 1.0))
    dot[~(ds & dc)] = 0.0
    smap = (1.0 - np.clip(ec - es, 0.0, 1.0)) * dot
    smap[~inside] = 0.0
    wgt = ec * area
    den = float(wgt.sum(dtype=np.float64))
    score = float((wgt * smap).sum(dtype=np.float64) / den) if den > 0 else 0.0

    weight = np.where(inside, area, 0).astype(np.float32)
    low: dict[str, F32] = {
        "score": smap.astype(np.float32),
        "e_shading": es,
        "e_shape": ec,
        "weight": weight,
        "cos2_shading": ca.astype(np.float32),
        "sin2_shading": sa.astype(np.float32),
        "cos2_shape": cb.astype(np.float32),
        "sin2_shape": sb.astype(np.float32),
    }
    return CongruenceResult(
        score=float(np.clip(score, 0.0, 1.0)),
        analysis_shape=(int(smap.shape[0]), int(smap.shape[1])),
        _out_shape=(h, w),
        _low=low,
    )
