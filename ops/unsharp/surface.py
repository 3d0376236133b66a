"""3D unsharp masking (Ritschel et al., SIGGRAPH 2008, §4-5, Eq. 1) in image space, and the
surface-following smoothing it is built on (:func:`surface_blur`).

The maths, per pixel, on CIELAB lightness (:func:`unsharp_lightness` writes it as the paper
does)::

    U(L*) = L* + λ_adapt (L*_f − L*_σ),   λ_adapt = λ · g · α · √(1 + Var(S))

:func:`unsharp_masking` evaluates it strip by strip on the smoothed levels of the surface
pyramid (:mod:`ops.unsharp._pyramid`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import cv2
import numpy as np
from numpy.typing import ArrayLike

from ops import color
from ops.checks import POSITIVE, UNSHARP_AMOUNT, UNSHARP_SIGMA
from ops.colorspace import LINEAR_REC709, ColorSpace
from ops.opencv import written
from ops.parallel import run_strips, strip_rows
from ops.pyramid.masked import masked_gaussian
from ops.unsharp._common import (
    _L_EPS,
    _LEVEL_SIGMA,
    _ONE,
    Array,
    _clip_new_negatives,
    _mask,
    _normals,
    _plane,
    _rgb,
)
from ops.unsharp._levels import _sub_resize
from ops.unsharp._pyramid import _fade, _surface_pyramid
from ops.unsharp._surface import _box, _outside, _Surface, _surface, _valid
from ops.unsharp._upsample import _Upsampler

_cv: Any = cv2  # OpenCV's stubs reject scalar operands (cv2.max(a, 0.0))

__all__ = [
    "SurfaceBlurRows",
    "surface_blur",
    "surface_blur_rows",
    "surface_blurs",
    "unsharp_lightness",
    "unsharp_masking",
]


def surface_blur(
    signal: Array,
    depth: Array,
    normal: Array | None,
    mask: Array,
    *,
    sigma_scene: float,
    pixel_size: Array | float,
    depth_sigma: float = 1.0,
    normal_sigma: float | None = 1.0,
) -> Array:
    """Gaussian-like smoothing of ``signal`` along the visible surfaces, σ in scene units.

    The image-space stand-in for the smoothing over the mesh of 3D Unsharp Masking (Ritschel
    et al. 2008, §5):

    * distances are the surface's arc length: a domain transform (Gastal & Oliveira 2011,
      normalised convolution, 3 iterations) guided by I with |ΔI| = |Δz| / pixel_size
      (``_surface``), so a depth step counts as (1.3 ×) its own length: an object does not mix
      with what lies behind it when the gap in depth exceeds about 3 σ · ``depth_sigma``
      (closer layers are smoothed together, as if touching); surfaces tilted less than 45° are
      treated as flat, steeper ones are foreshortened (see ``_smooth_level``); with
      ``normal_sigma`` a change of the normal's (n_x, n_y) (L1) of ``normal_sigma`` counts as
      one σ, which damps smoothing across creases;
    * the width σ_px = sigma_scene / pixel_size is per pixel: levels k = 1, 2, … (cells of 2^k
      pixels, each keeping the front-most surface of its block) smooth by s_k ≈ 2.2 · 2^k
      pixels, and each pixel mixes the two levels around its σ_px so that the mix has the
      second moment σ_px² (below s_1 ≈ 4.4 pixels: the signal itself and level 1), so a
      gradient keeps its width on the surface at any distance (paper Fig. 4 "P");
    * levels are upsampled edge-aware: a pixel takes cells of its own surface only.

    Pixels off the surface (mask 0, non-finite or non-positive depth or pixel_size) never
    contribute; their output is their input. σ_px is capped at the coarsest level (about a
    quarter of the image's smaller side).

    Parameters
    ----------
    signal : (H, W) float32
    depth : (H, W) float32, planar depth, > 0 (background +inf or masked)
    normal : (H, W, 3) float32 camera-space unit normals, or None (no crease term)
    mask : (H, W) bool or coverage (> 0 is surface)
    sigma_scene : float
        σ of the smoothing, scene units (> 0).
    pixel_size : (H, W) float32 or float
        Scene units per pixel at each pixel (depth / focal_px perspective, constant ortho).
    depth_sigma : float
        Divides the depth term (> 0): 1 counts a depth step as about its own length (layers
        more than ≈ 3 σ apart in depth are kept apart); smaller values separate closer layers
        (0.25: ≈ 0.75 σ) and shorten the smoothing on steep surfaces.
    normal_sigma : float or None
        Change of the normal's (n_x, n_y) (L1 norm, 0…2) that counts as one σ of distance
        (> 0); None disables the term. Normals are also what tells a steep surface from a depth
        step; without ``normal`` steep surfaces are treated as steps (slower, less smoothing
        there).

    Returns
    -------
    (H, W) float32
    """
    (out,) = surface_blurs(
        [signal],
        depth,
        normal,
        mask,
        sigma_scene=sigma_scene,
        pixel_size=pixel_size,
        depth_sigma=depth_sigma,
        normal_sigma=normal_sigma,
    )
    return out


def surface_blurs(
    signals: Sequence[Array],
    depth: Array,
    normal: Array | None,
    mask: Array,
    *,
    sigma_scene: float,
    pixel_size: Array | float,
    depth_sigma: float = 1.0,
    normal_sigma: float | None = 1.0,
) -> list[Array]:
    """:func:`surface_blur` of each of ``signals`` ((H, W) each, at least one), the surface's
    pyramid built once for all of them."""
    rows = surface_blur_rows(
        signals,
        depth,
        normal,
        mask,
        sigma_scene=sigma_scene,
        pixel_size=pixel_size,
        depth_sigma=depth_sigma,
        normal_sigma=normal_sigma,
    )
    outs = [np.empty(rows.shape, np.float32) for _ in signals]

    def strip(r0: int, r1: int) -> None:
        for out, got in zip(outs, rows(r0, r1), strict=True):
            out[r0:r1] = got

    run_strips(rows.shape[0], strip, strip_rows(rows.shape[1]))
    return outs


def surface_blur_rows(
    signals: Sequence[Array],
    depth: Array,
    normal: Array | None,
    mask: Array,
    *,
    sigma_scene: float,
    pixel_size: Array | float,
    depth_sigma: float = 1.0,
    normal_sigma: float | None = 1.0,
) -> SurfaceBlurRows:
    """:func:`surface_blurs`, given by strips of rows: the pyramid is built here, and each call
    of the result upsamples and finishes only the rows asked for (safe from several threads at
    once), so a caller uses the smoothed rows while they are in cache."""
    sigs = [np.ascontiguousarray(s, dtype=np.float32) for s in signals]
    for sig in sigs:
        if sig.ndim != 2 or sig.shape != sigs[0].shape:
            raise ValueError(f"signal must have shape (H, W) (all alike), got {sig.shape}")
    shape = (int(sigs[0].shape[0]), int(sigs[0].shape[1]))
    sigma = POSITIVE.check(sigma_scene, "sigma_scene")
    ds = UNSHARP_SIGMA.check(depth_sigma, "depth_sigma")
    ns = None if normal_sigma is None else UNSHARP_SIGMA.check(normal_sigma, "normal_sigma")
    depth_a = _plane("depth", depth, shape)
    ps = _plane("pixel_size", pixel_size, shape)
    nrm = None if normal is None else _normals(normal, shape)
    valid, ps_range, box, _ = _valid(depth_a, ps, _mask(mask, shape))
    if box is None:
        return SurfaceBlurRows(sigs)
    ys, xs = box
    centre = (0.5 * shape[1] - xs.start, 0.5 * shape[0] - ys.start)
    first_box = sigs[0][box]
    surf, sub, first = _surface(
        depth_a[box],
        ps[box],
        valid[box],
        None if nrm is None else nrm[box],
        ds,
        centre,
        ps_range,
        lambda r, out: np.copyto(out, first_box[r]),
        False,
        tuple(sig[box] for sig in sigs[1:]),
    )
    subs = [sub, *(np.ascontiguousarray(sig[box]) for sig in sigs[1:])]
    res = _surface_pyramid(surf, subs, first, sigma, None, ns)
    if res is None:
        return SurfaceBlurRows(sigs)
    # 0/1: pixels of the box off the surface keep the signal
    smooth = _BoxRows(box, res[0], subs, _fade(sigma, surf, ps[box]), _cv.subtract(1, surf.valid))
    return SurfaceBlurRows(sigs, smooth)


@dataclass(frozen=True)
class _BoxRows:
    """The smoothed signals in the bounding box of the surface, by strips of its rows."""

    box: tuple[slice, slice]  # the box in the image
    up: _Upsampler  # the pyramid's smoothed signals, upsampled to the box
    subs: list[Array]  # the signals in the box
    fade: tuple[tuple[slice, slice], Array] | None  # see _fade
    off: Array  # uint8 1 where a pixel of the box is off the surface

    def rows(self, sigs: list[Array], r0: int, r1: int) -> list[Array]:
        """Rows r0 … r1 − 1 of the image: the signals ``sigs`` with the box's columns smoothed
        where the rows meet the box (the smoothed rows themselves where the box holds them
        whole)."""
        ys, xs = self.box
        a, b = max(r0, ys.start), min(r1, ys.stop)
        if a >= b:
            return [sig[r0:r1].copy() for sig in sigs]
        outs = []
        for sig, full in zip(sigs, self._smoothed(sigs, a, b), strict=True):
            if (a, b, xs.start, xs.stop) == (r0, r1, 0, sig.shape[1]):
                outs.append(full)
                continue
            out = np.empty((r1 - r0, sig.shape[1]), np.float32)
            out[: a - r0], out[b - r0 :] = sig[r0:a], sig[b:r1]
            mid = out[a - r0 : b - r0]
            mid[:, : xs.start], mid[:, xs.stop :] = sig[a:b, : xs.start], sig[a:b, xs.stop :]
            mid[:, xs] = full
            outs.append(out)
        return outs

    def _smoothed(self, sigs: list[Array], a: int, b: int) -> list[Array]:
        """Image rows a … b − 1 (inside the box) of the box's columns: each signal smoothed on
        the surface, faded to itself where σ_px < s_1, itself off the surface."""
        xs = self.box[1]
        rb = slice(a - self.box[0].start, b - self.box[0].start)
        fulls = self.up.rows(rb)
        for sig, full, sub_i in zip(sigs, fulls, self.subs, strict=True):
            if self.fade is not None:  # (1 − a0) sub + a0 full, where a0 < 1
                (fy, fx), a0 = self.fade
                f0, f1 = max(rb.start, fy.start), min(rb.stop, fy.stop)
                if f0 < f1:
                    at = (slice(f0 - rb.start, f1 - rb.start), fx)
                    fs, ss, a0_r = full[at], sub_i[f0:f1, fx], a0[f0 - fy.start : f1 - fy.start]
                    diff = _cv.multiply(_cv.subtract(fs, ss), a0_r)
                    written(_cv.scaleAdd(diff, 1.0, ss, dst=fs), full, at)
            # (cv2.copyTo: many times faster than np.copyto's where=)
            written(_cv.copyTo(sig[a:b, xs], self.off[rb], dst=full), full, slice(None))
        return fulls


class SurfaceBlurRows:
    """What :func:`surface_blur_rows` returns: called with rows (r0, r1), the (r1 − r0, W)
    rows of each smoothed signal (new arrays)."""

    def __init__(self, sigs: list[Array], box: _BoxRows | None = None):
        self.shape: tuple[int, int] = sigs[0].shape
        self._sigs = sigs
        self._box = box

    def __call__(self, r0: int, r1: int) -> list[Array]:
        if self._box is None:
            return [sig[r0:r1].copy() for sig in self._sigs]
        return self._box.rows(self._sigs, r0, r1)


# ---------------------------------------------------------------------------------------------
# operators


def _finite_plane(name: str, a: Array | float, shape: tuple[int, int]) -> Array:
    arr = _plane(name, a, shape)
    if not _cv.checkRange(arr)[0]:
        raise ValueError(f"{name} must be finite everywhere")
    return arr


def _shifted(box: tuple[slice, slice], y0: int, x0: int) -> tuple[slice, slice]:
    """``box`` in a grid whose origin is at (y0, x0)."""
    ys, xs = box
    return slice(ys.start - y0, ys.stop - y0), slice(xs.start - x0, xs.stop - x0)


def _adapt(res: tuple[_Upsampler, tuple[int, Array] | None] | None) -> tuple[Array, int] | None:
    """√(1 + Var(L*/100)) on its level, and that level's factor (None: not adaptive)."""
    if res is None or res[1] is None:
        return None
    kv, v = res[1]
    return _cv.sqrt(_cv.addWeighted(v, 1e-4, v, 0.0, 1.0)), 2**kv


@dataclass
class _LightnessRows:
    """The k of :func:`unsharp_masking` for ``color.scale_lab``, strip by strip.

    Per strip of rows r: k = max(U, 0) / max(L*, 1e-3) with U = L* + λ_adapt (L* − L*_σ) (§4,
    Eq. 1, as :func:`unsharp_lightness`), and where λ_adapt = 0 (kept bit for bit), in the
    columns that hold some surface (the others are kept whole). L*_σ and √(1 + Var) are
    upsampled here, strip by strip.
    """

    surf: _Surface
    lum: Array  # L*
    fine: Array  # L*_f
    up: _Upsampler | None  # L*_σ (None: too small for any level, nothing to smooth)
    lam: float  # λ
    cov: Array | None  # α (None: a bool mask)
    gain: Array | None  # g
    fade: tuple[slice, slice] | None  # where σ_px < s_1: U fades to L* (see _fade)
    ps: Array  # pixel sizes
    c_fade: float
    adapt: tuple[Array, int] | None  # √(1 + Var) on its level, and its factor

    def __call__(self, r: slice) -> color.KRows:
        x, _, n, _ = _cv.boundingRect(self.surf.valid[r])
        if n == 0:
            return np.empty((r.stop - r.start, 0), np.float32), None, slice(x, x)
        # (a window one column wide is two: OpenCV takes an array of one column and up to four
        # rows for a scalar; the other column is off the surface or on it, and kept or
        # sharpened alike, to rounding)
        c = _box(r.start, r.stop, x, x + n, self.surf.valid.shape)[1]
        rc = (r, c)
        valid_r = self.surf.valid[rc]
        # λ g α: 0 off the surface
        if self.cov is None:
            lam_r = np.multiply(valid_r, np.float32(self.lam), dtype=np.float32)
        else:
            lam_r = _cv.min(_cv.max(self.cov[rc], 0.0), 1.0)
            _cv.multiply(lam_r, valid_r, dst=lam_r, scale=self.lam, dtype=_cv.CV_32F)
        if self.gain is not None:
            _cv.multiply(lam_r, self.gain[rc], dst=lam_r)
        if self.fade is not None:
            self._fade(lam_r, r, c)
        keep_r = _cv.compare(lam_r, 0.0, _cv.CMP_EQ)
        if self.adapt is not None:  # √(1 + Var)
            lam_r = _cv.multiply(lam_r, _sub_resize(self.adapt[0], self.adapt[1], r, c), dst=lam_r)
        lum_r = self.lum[rc]
        # L*_σ (a view: written in)
        new = lum_r.copy() if self.up is None else self.up.rows(r, c)[0]
        new = _cv.subtract(self.fine[rc], new, dst=new)
        new = _cv.multiply(lam_r, new, dst=new)
        new = _cv.add(lum_r, new, dst=new)
        new = _cv.max(new, 0.0, dst=new)
        return _cv.divide(new, _cv.max(lum_r, _L_EPS), dst=new), keep_r, c

    def _fade(self, lam_r: Array, r: slice, c: slice) -> None:
        """λ_r ×= a0 where the fade box meets the window (rows r, columns c): L − ((1 − a0) L +
        a0 S) = a0 (L − S), a0 = min(σ_px²/s_1², 1) (elsewhere on the surface a0 = 1)."""
        assert self.fade is not None
        fy, fx = self.fade
        y0, y1 = max(r.start, fy.start), min(r.stop, fy.stop)
        x0, x1 = max(c.start, fx.start), min(c.stop, fx.stop)
        if not (y0 < y1 and x0 < x1):
            return
        fb = (slice(y0 - r.start, y1 - r.start), slice(x0 - c.start, x1 - c.start))
        part, ps = lam_r[fb], self.ps[y0:y1, x0:x1]
        if min(ps.shape) == 1 and ps.size <= 4:  # (OpenCV would take it for a scalar)
            a0 = np.float32(self.c_fade) / np.maximum(ps, np.float32(1e-30))
            np.multiply(part, np.minimum(a0 * a0, np.float32(1.0)), out=part)
            return
        a0 = _cv.divide(self.c_fade, _cv.max(ps, 1e-30))
        _cv.multiply(a0, a0, dst=a0)
        written(_cv.multiply(part, _cv.min(a0, 1.0, dst=a0), dst=part), lam_r, fb)


def unsharp_lightness(
    lightness: ArrayLike,
    smooth: ArrayLike,
    amount: float,
    *,
    variance: ArrayLike | None = None,
    gain: ArrayLike = 1.0,
    fine: ArrayLike | None = None,
) -> Array:
    """3D unsharp masking of a lightness, as Ritschel et al. (2008) write it (§4, Eq. 1)::

        U(L) = L + λ_adapt (L_f − L_σ),   λ_adapt = λ · g · √(1 + Var(S)),   S = L / 100

    ``smooth`` is L_σ (the lightness smoothed along the surfaces, :func:`surface_blur`),
    ``fine`` L_f (default: L itself), ``variance`` Var(S) (None: λ_adapt = λ · g, the
    non-adaptive form), ``gain`` g (per pixel, any sign). U is clamped at 0. The reference for
    :func:`unsharp_masking`, which evaluates the same per strip on the pyramid's levels.

    >>> float(unsharp_lightness(50.0, 40.0, 2.0))
    70.0
    >>> round(float(unsharp_lightness(50.0, 40.0, 2.0, variance=0.44)), 4)  # λ √1.44 = 2.4
    74.0
    >>> float(unsharp_lightness(10.0, 40.0, 2.0))  # clamped at 0
    0.0
    """
    lum = np.asarray(lightness, np.float32)
    lum_f = lum if fine is None else np.asarray(fine, np.float32)
    lam = np.float32(UNSHARP_AMOUNT.check(amount, "amount")) * np.asarray(gain, np.float32)
    if variance is not None:
        lam = lam * np.sqrt(_ONE + np.asarray(variance, np.float32))
    return np.maximum(lum + lam * (lum_f - np.asarray(smooth, np.float32)), np.float32(0.0))


def unsharp_masking(
    beauty: Array,
    depth: Array,
    normal: Array | None,
    mask: Array,
    *,
    amount: float = 1.0,
    sigma_scene: float,
    pixel_size: Array | float,
    adaptive: bool = True,
    variance_sigma: float | None = None,
    gain_map: Array | None = None,
    white: float | Literal["auto"] = "auto",
    depth_sigma: float = 1.0,
    normal_sigma: float | None = 1.0,
    fine_px: float = 0.0,
    space: ColorSpace = LINEAR_REC709,
) -> Array:
    """3D unsharp masking of a rendered image along its surfaces (Ritschel et al. 2008).

    U(L*) = L* + λ_adapt (L*_f − L*_σ)               (§4: U(S) = S + λ C(S), C(S) = S − S_σ)
    λ_adapt = λ · g · α · √(1 + Var(S))                (Eq. 1)
    (L*, a*, b*) → (U, k a*, k b*),  k = U / L*        (§4: hue angle and saturation kept)

    * L*_f is L* itself (``fine_px`` = 0, the paper) or L* averaged over the surface's pixels
      with a Gaussian of ``fine_px`` pixels (:func:`ops.pyramid.masked_gaussian`): the contrast
      added is then that of the structure between the two scales, and the pixel-scale
      Monte-Carlo noise of a path-traced frame passes through as it is instead of being
      multiplied by 1 + λ.
    * L*_σ is L* smoothed along the surfaces with σ = ``sigma_scene`` scene units
      (:func:`surface_blur`: depth- and normal-aware, σ converted per pixel through
      ``pixel_size``) - the image-space version of the paper's smoothing over the mesh (§5).
    * Var(S): the paper takes the variance of the reflected light over a vertex's 1-ring. Here
      S = L*/100 (lightness on the [0, 1] scale of the paper's radiance), and Var(S) = E[S²] −
      E[S]² under the same surface-following smoothing with the smaller
      σ = ``variance_sigma`` (default sigma_scene / 4, at least ≈ 8 pixels: it is computed on
      the pyramid levels from 2 up and interpolated bilinearly to the image). √(1 + Var) lies in
      [1, √1.25]: it raises the gain by up to ≈ 12 % where texture masks halos.
    * g = ``gain_map`` (per pixel, any sign: negative values de-emphasise, paper Fig. 10) and
      α = clip(mask, 0, 1) (partial coverage gets partial enhancement).
    * L* is relative to the white level ``white``; HDR values above it are fine (L* > 100).
      U is clamped at 0.

    Background pixels (mask 0, non-finite depth) and pixels whose effective gain is 0 are
    returned bit for bit; the background never contributes to the smoothing of the surface.

    Parameters
    ----------
    beauty : (H, W, 3) float32 linear RGB
    depth : (H, W) float32 planar depth, > 0 on the surface
    normal : (H, W, 3) float32 camera-space unit normals, or None
    mask : (H, W) bool or coverage
    amount : float
        λ, in [-10, 10] (the paper's study used 0…3; users preferred ≈ 1.7-2).
    sigma_scene : float
        σ of the smooth signal, scene units (> 0).
    pixel_size : (H, W) float32 or float
        Scene units per pixel at each pixel (depth / focal_px perspective, constant ortho).
    adaptive : bool
        Use λ_adapt (Eq. 1); False: λ_adapt = λ · g · α.
    variance_sigma : float or None
        Neighbourhood of Var(S), scene units (> 0); None: sigma_scene / 4.
    gain_map : (H, W) float32 or None
        Per-pixel multiplier of λ (finite).
    white : "auto" or float
        Linear white level for CIELAB; "auto": 99th percentile of luminance over the surface
        (:func:`ops.color.auto_white`); pin a number for sequences.
    depth_sigma, normal_sigma : see :func:`surface_blur`.
    fine_px : float
        σ of L*_f in pixels (≥ 0; 0: L* itself).
    space : ColorSpace
        The frame's working space (:mod:`ops.colorspace`): CIELAB through its XYZ and white,
        the automatic white level from its luminance.

    Returns
    -------
    (H, W, 3) float32 linear RGB, never negative.
    """
    img = _rgb("beauty", beauty)
    shape = (int(img.shape[0]), int(img.shape[1]))
    lam = UNSHARP_AMOUNT.check(amount, "amount")
    sigma = POSITIVE.check(sigma_scene, "sigma_scene")
    vsig = (
        sigma / 4.0 if variance_sigma is None else POSITIVE.check(variance_sigma, "variance_sigma")
    )
    ds = UNSHARP_SIGMA.check(depth_sigma, "depth_sigma")
    ns = None if normal_sigma is None else UNSHARP_SIGMA.check(normal_sigma, "normal_sigma")
    depth_a = _plane("depth", depth, shape)
    ps = _plane("pixel_size", pixel_size, shape)
    mask_a = _mask(mask, shape)
    nrm = None if normal is None else _normals(normal, shape)
    gain = None if gain_map is None else _finite_plane("gain_map", gain_map, shape)

    # σ_px < s_1 (pixel size above c_fade): U fades to L* itself (see _fade); the box of those
    # pixels is found with the others
    c_fade = sigma / (2.0 * _LEVEL_SIGMA)
    valid, ps_range, box, fade_box = _valid(depth_a, ps, mask_a, c_fade * (1.0 - 1e-5))
    if box is None:
        return img.copy()
    wl = color.resolve_white(white, img, valid.view(bool), space.weights)
    # everything below works on the bounding box of the surface (the rest is returned as is)
    ys, xs = box
    sub_shape = (ys.stop - ys.start, xs.stop - xs.start)
    centre = (0.5 * shape[1] - xs.start, 0.5 * shape[0] - ys.start)
    ps = ps[box]
    img_box = img[box]
    light = color.lightness_rows(wl, space.matrix)
    surf, lum, first = _surface(
        depth_a[box],
        ps,
        valid[box],
        None if nrm is None else nrm[box],
        ds,
        centre,
        ps_range,
        lambda r, out: light(img_box[r], out),
        adaptive,
    )
    res = _surface_pyramid(surf, [lum], first, sigma, vsig if adaptive else None, ns)
    cov_a = None if mask_a.dtype == np.bool_ else mask_a[box]
    gain_a = None if gain is None else gain[box]
    # the box where U fades to L*, in the bounding box of the surface
    fade_box = None if res is None or fade_box is None else _shifted(fade_box, ys.start, xs.start)
    up = None if res is None else res[0]  # None: too small for any level, nothing to smooth
    fine = (
        lum
        if fine_px <= 0.0
        else masked_gaussian(lum, surf.valid, POSITIVE.check(fine_px, "fine_px"))
    )

    k_rows = _LightnessRows(
        surf, lum, fine, up, lam, cov_a, gain_a, fade_box, ps, c_fade, _adapt(res)
    )
    if sub_shape == shape:
        out = color.scale_lab(img_box, k_rows, wl, rgb_to_xyz=space.matrix)
    else:
        out = _outside(img, box)
        color.scale_lab(img_box, k_rows, wl, out=out[box], rgb_to_xyz=space.matrix)
    return _clip_new_negatives(out, img)
