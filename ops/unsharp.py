"""Unsharp masking that follows surfaces (3D unsharp masking) and its image-space baselines.

Three operators, all on CIELAB lightness with the chroma scaled so that saturation is kept:

* :func:`unsharp_masking` - 3D Unsharp Masking (Ritschel, Smith, Ihrke, Grosch, Myszkowski,
  Seidel, SIGGRAPH 2008, ``papers/3d-unsharp-masking.txt`` §4-5, Eq. 1), adapted to image space:
  the smooth signal S_σ is computed along the visible surfaces with a domain transform whose
  arc length is the surface's own (depth steps count as distance), its width given in scene
  units and converted per pixel, so it neither mixes an object with what lies behind it nor
  shrinks with distance.
* :func:`depth_unsharp_masking` - the depth-buffer baseline of Luft, Colditz and Deussen
  (SIGGRAPH 2006): ΔD = G∗D − D on normalised depth, darkening where ΔD < 0.
* :func:`plain_unsharp_mask` - a plain 2-D unsharp mask of L*, for comparisons.

:func:`surface_blur` exposes the surface-following smoothing itself.

Colour handling (paper §4): with φ the centred CIELAB cube-root coordinates
(:func:`ops.color.rgb_to_lab_phi`, L* = 116 φ_y, a* = 500 (φ_x − φ_y), b* = 200 (φ_y − φ_z)),
the enhanced colour is (U(L*), k a*, k b*) with k = U(L*)/L*, i.e. φ' = k φ: the hue angle
atan2(b*, a*) and the saturation √(a*² + b*²)/L* are unchanged. U is clamped at 0 (no negative
lightness); k = U / max(L*, 1e-3) (black stays black). Only L* is ever formed on the way in
(:func:`ops.color.lightness`); on the way out :func:`ops.color.scale_lab` applies φ' = k φ strip
by strip, with k (and the gain, Eq. 1) formed for each strip of rows while it is in cache: L*_σ
and √(1 + Var) are upsampled to the strip there, in the strip's columns that hold some surface
(the others are returned as they are, not converted).

The surface pyramid (``_surface_pyramid``), in short: level k holds cells of 2^k pixels that
each keep the front-most surface of their block (depth steps are told from steep surfaces by
extrapolating each cell's plane, from its normal); each level is smoothed by a domain transform
guided by the depth (so its distances are the surface's own); levels are combined coarse to
fine, each pixel mixing the two levels around its σ_px = σ / pixel_size, with an upsampling that
only interpolates between cells of the pixel's own surface. Only the bounding box of the
surface is processed, and a level only where some pixel needs it. The full-resolution fields
(depth guide, L*, the averages that make level 1) are formed in one pass over strips of rows.
The domain transforms (OpenCV, without the GIL) run on a thread of their own, each as soon as
its level is made, while the next levels are made and the upsamplings' re-weighted pixels are
found (NumPy, which holds the GIL): the two kinds of work share the cores instead of taking
turns.
"""

from __future__ import annotations

import functools
import math
import os
import threading
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor, wait
from dataclasses import dataclass
from typing import Any, Literal

import cv2
import numpy as np

from ops import color
from ops.checks import POSITIVE, RELATIVE_SIGMA, UNSHARP_AMOUNT, UNSHARP_SIGMA
from ops.masked import masked_gaussian
from ops.parallel import STRIP_PIXELS

_cv: Any = cv2  # OpenCV's stubs reject scalar operands (cv2.max(a, 0.0))

__all__ = [
    "depth_unsharp_masking",
    "plain_unsharp_mask",
    "surface_blur",
    "unsharp_masking",
]

# Each level of the surface pyramid is filtered by a domain transform of this σ, in that level's
# own pixels (level k is 2^k times coarser than the image).
_SIGMA_C = 2.0
# Depth-guide step (in level pixels, beyond what the surface's own slope explains) above which
# two cells are not on the same surface: the pyramid's reduction and upsampling never mix them.
_JUMP = 4.0
# Depth slope (|ΔI| per pixel, = tan of the surface tilt) below which the domain transform
# treats a surface as flat (see _smooth_level).
_KNEE = 1.0
# The domain transform (normalised convolution, 3 iterations, σ_H = σ_c (1 + KNEE)) never
# crosses a single step longer than its first box radius r1 = 3 σ_H · 2² / √(4³ − 1) ≈ 6.05;
# the depth guide is scaled so that a step of _JUMP level pixels already costs more than that
# (1 + 1.3 · 4 = 6.2), so what the reduction and upsampling keep apart the smoothing does too.
_DT_DEPTH_GAIN = 1.3
_DT_MODE = cv2.ximgproc.DTF_NC
# Guide value of empty cells: a wall this many level pixels above the largest depth guide value.
# Finite (OpenCV's domain transform accumulates arc length in float32: 1e8 steps give NaN).
_WALL = 1.0e3
_MIN_LEVEL_SIDE = 4
# Cells added around the region a level is needed in (the domain transform's reach plus the
# upsampling taps).
_BOX_MARGIN = 8
# Measured σ of level k (smoothing + area reduction + bilinear upsampling) is _LEVEL_SIGMA · 2^k
# image pixels (2.218 · 2^k for k = 1…5 on a plane, x and y alike).
_LEVEL_SIGMA = 2.218
_LN2 = math.log(2.0)
_L_EPS = 1.0e-3  # L* below which k = U/L is not formed (black)
_ONE = np.float32(1.0)

Array = np.ndarray


# ---------------------------------------------------------------------------------------------
# validation helpers


def _rgb(name: str, a: Array) -> Array:
    arr = np.asarray(a)
    if arr.ndim != 3 or arr.shape[2] != 3:
        raise ValueError(f"{name} must have shape (H, W, 3), got {arr.shape}")
    return np.ascontiguousarray(arr, dtype=np.float32)


def _plane(name: str, a: Array | float, shape: tuple[int, int]) -> Array:
    arr = np.asarray(a, dtype=np.float32)
    if arr.ndim == 0:
        return np.full(shape, float(arr), dtype=np.float32)
    if arr.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    return np.ascontiguousarray(arr)


# ---------------------------------------------------------------------------------------------
# colour: lightness in, lightness out


def _lightness(beauty: Array, white: float, out: Array | None = None) -> Array:
    """L* (H, W) of linear RGB relative to ``white`` (a*, b* are never formed)."""
    return color.lightness(beauty, white, out)


def _with_lightness(
    beauty: Array,
    lum: Array,
    new_lum: Array,
    white: float,
    keep: Array | None,
    out: Array | None = None,
) -> Array:
    """Linear RGB with L* replaced by ``new_lum`` and (a*, b*) scaled by k = new/old (§4).

    U is clamped at 0; k = U / max(L*, 1e-3) (below L* = 1e-3, black, the scaling saturates).
    ``new_lum`` is consumed. Pixels where ``keep`` (uint8, non-zero) get ``beauty`` back bit
    for bit. ``out``: where to write (an (H, W, 3) view), else a new array.
    """
    _cv.max(new_lum, 0.0, dst=new_lum)
    k = _cv.divide(new_lum, _cv.max(lum, _L_EPS), dst=new_lum)
    return color.scale_lab(beauty, k, white, keep=keep, out=out)


# ---------------------------------------------------------------------------------------------
# Gaussian blur of any width at bounded cost


def _blur(img: Array, sigma_px: float) -> Array:
    """Gaussian blur of ``img`` with σ = ``sigma_px`` (replicated border), float32.

    Wide blurs go through a pyramid: the image is area-downsampled by 2^m so that σ is at least
    2 pixels there, blurred with the remaining σ' = √(σ² − σ_box²) / 2^m, and upsampled
    bilinearly (the result is band-limited, so the interpolation error is far below the
    enhancement). Cost stays ≈ a few copies at any σ.
    """
    if sigma_px <= 0.0:
        return img.copy()
    h, w = img.shape[:2]
    m = 0
    while sigma_px / 2 ** (m + 1) >= 2.0 and min(h, w) // 2 ** (m + 1) >= 8:
        m += 1
    if m == 0:
        return _cv.GaussianBlur(img, (0, 0), sigma_px, borderType=_cv.BORDER_REPLICATE)
    f = 2**m
    hs, ws = -(-h // f), -(-w // f)
    pad = img
    if hs * f != h or ws * f != w:
        pad = _cv.copyMakeBorder(img, 0, hs * f - h, 0, ws * f - w, _cv.BORDER_REPLICATE)
    small = _cv.resize(pad, (ws, hs), interpolation=_cv.INTER_AREA)
    # the box of the area average has variance (f² − 1)/12 image pixels², the bilinear
    # upsampling about f²/6 more; take both out of the Gaussian applied at the small scale
    rest = max(sigma_px**2 - (f * f - 1) / 12.0 - f * f / 6.0, (0.5 * f) ** 2)
    small = _cv.GaussianBlur(small, (0, 0), math.sqrt(rest) / f, borderType=_cv.BORDER_REPLICATE)
    big = _cv.resize(small, (ws * f, hs * f), interpolation=_cv.INTER_LINEAR)
    return big if big.shape[:2] == (h, w) else np.ascontiguousarray(big[:h, :w])


# ---------------------------------------------------------------------------------------------
# the surface pyramid


@dataclass
class _Surface:
    """What the smoothing needs to know about the visible surface, at full resolution."""

    valid: Array  # uint8 0/1: pixel on the surface
    iz: Array  # depth guide, image-pixel units, 0 off the surface (see _surface)
    lps: Array | None  # ln(pixel_size), 0 off the surface; None: derived from iz (lps_from)
    lps_from: tuple[float, float]  # ln(pixel_size) = a · iz + b where ``lps`` is None
    normal: Array | None  # (H, W, 3) as given (sanitised at level 1); None: not given
    ps_min: float
    ps_max: float
    focal: float | None  # perspective focal length in pixels (None: orthographic)
    depth_sigma: float
    centre: tuple[float, float]  # optical centre (column, row) in this (cropped) grid


def _valid(
    depth: Array, pixel_size: Array, mask: Array, far: float | None = None
) -> tuple[Array, tuple[float, float], tuple[slice, slice] | None, tuple[slice, slice] | None]:
    """uint8 0/1: mask > 0 and finite, positive depth and pixel size; the (min, max) of the
    pixel size there ((0, 0) where there is none); the bounding box of those pixels, and that
    of those with a pixel size above ``far`` (None: none, or ``far`` None). Only the bounding
    box of the mask is tested, in strips of rows over the shared pool (each strip's depth and
    pixel size read once)."""
    if mask.dtype == np.bool_:
        vm = mask.view(np.uint8)  # 0/1
    else:
        vm = _cv.compare(mask, 0.0, _cv.CMP_GT)
        _cv.min(vm, 1, dst=vm)
    valid = np.zeros(vm.shape, np.uint8)
    mb = _crop(vm)
    if mb is None:
        return valid, (0.0, 0.0), None, None
    d, ps, m, out = depth[mb], pixel_size[mb], vm[mb], valid[mb]
    found: list[tuple[float, float]] = []  # per strip: the pixel size's range
    rects: list[list[tuple[int, int, int, int]]] = [[], []]  # per strip: valid, far boxes

    def strip(r: slice) -> None:
        v = _cv.bitwise_and(_cv.inRange(d[r], 1e-30, 3.0e38), _cv.inRange(ps[r], 1e-30, 3.0e38))
        v = _cv.bitwise_and(v, m[r], dst=out[r])  # (0/1: the mask is)
        _write(v, out, r)
        x, y, w, h = _cv.boundingRect(v)
        if not (w and h):
            return
        a, b, _, _ = _cv.minMaxLoc(ps[r], mask=v)
        found.append((a, b))  # (list.append is atomic)
        rects[0].append((x, r.start + y, x + w, r.start + y + h))
        if far is not None and b > far:
            fv = _cv.bitwise_and(_cv.compare(ps[r], far, _cv.CMP_GT), v)
            x, y, w, h = _cv.boundingRect(fv)
            if w and h:
                rects[1].append((x, r.start + y, x + w, r.start + y + h))

    color.row_strips(d.shape[0], d.shape[1], strip)
    if not found:
        return valid, (0.0, 0.0), None, None
    ys, xs = mb

    def union(rs: list[tuple[int, int, int, int]]) -> tuple[slice, slice] | None:
        if not rs:
            return None
        x0, y0 = min(q[0] for q in rs) + xs.start, min(q[1] for q in rs) + ys.start
        x1, y1 = max(q[2] for q in rs) + xs.start, max(q[3] for q in rs) + ys.start
        return slice(y0, y1), slice(x0, x1)

    lo, hi = min(f[0] for f in found), max(f[1] for f in found)
    return valid, (lo, hi), union(rects[0]), union(rects[1])


def _write(res: Array, dst: Array, box: tuple[slice, slice] | slice) -> None:
    """Make sure ``dst[box]`` holds ``res`` (the result of a cv2 call given ``dst=dst[box]``:
    OpenCV writes through views of rows with a stride, but allocates anew for others)."""
    if not np.shares_memory(res, dst):
        dst[box] = res


def _outside(img: Array, box: tuple[slice, slice]) -> Array:
    """A new array holding ``img`` outside ``box`` (the inside is left for the caller)."""
    ys, xs = box
    out = np.empty_like(img)
    out[: ys.start] = img[: ys.start]
    out[ys.stop :] = img[ys.stop :]
    out[ys, : xs.start] = img[ys, : xs.start]
    out[ys, xs.stop :] = img[ys, xs.stop :]
    return out


def _crop(valid: Array) -> tuple[slice, slice] | None:
    """The bounding box of the surface (None: nothing visible)."""
    x, y, w, h = _cv.boundingRect(valid)
    if w == 0 or h == 0:
        return None
    return slice(y, y + h), slice(x, x + w)


def _surface(
    depth: Array,
    pixel_size: Array,
    valid: Array,
    normal: Array | None,
    depth_sigma: float,
    centre: tuple[float, float],
    ps_range: tuple[float, float],
    signal: Callable[[slice, Array], object],
    squares: bool,
) -> tuple[_Surface, Array, _Level | None]:
    """Depth guide and footprint of the visible surface (``valid``: uint8 0/1, not all 0).

    The depth guide I is built so that |ΔI| between neighbouring pixels is the depth step over
    the pixel footprint, |Δz| / pixel_size: perspective (pixel_size = z / f, detected from the
    ratio z / pixel_size) gives I = f ln z, orthographic (constant pixel_size) I = z / pixel_size;
    anything else is treated as perspective with f = median(z / pixel_size). A domain transform
    with σ_s/σ_r = 1 on I measures 1 + |Δz|/pixel_size per pixel step: the (L1) arc length of the
    surface in units of the pixel footprint, a depth gap counting as its own length - the
    image-space stand-in for distances over the mesh (``_smooth_level`` scales it by
    _DT_DEPTH_GAIN and flattens slopes below _KNEE). ``depth_sigma`` divides I. ``centre``:
    the optical centre (column, row) in this grid (the image centre, shifted by any crop).
    ``ps_range``: (min, max) of ``pixel_size`` where ``valid``.

    In the same pass over strips of rows (each strip's fields are formed and averaged while in
    cache), returns the signal at full resolution (``signal(rows, out)`` writes those rows of
    it into ``out``, e.g. L* of the beauty's rows) and level 1 of the pyramid: 2×2 area
    averages of the signal, of its square if ``squares``, of I and of the normals, normalised by
    the cell's coverage, and the guide's slopes (``_guide_gradient``); ``_finish_first_level``
    does the rest. Level 1 is None where the image is too small for a level.
    """
    sub_v = valid[::7, ::7].view(bool)
    sub_z = depth[::7, ::7][sub_v]
    sub_ps = pixel_size[::7, ::7][sub_v]
    if sub_z.size == 0:
        vb = valid.view(bool)
        sub_z, sub_ps = depth[vb], pixel_size[vb]
    ps_min, ps_max = ps_range  # of pixel_size where valid (from _valid)
    h, w = valid.shape
    ratio = sub_z / sub_ps
    measure_lps = False
    focal: float | None = None
    if ps_max <= 1.001 * ps_min:  # orthographic: constant footprint
        p0 = float(np.median(sub_ps))
        iz_scale = 1.0 / (p0 * depth_sigma)
        lps_from = (0.0, math.log(p0))
    else:  # perspective: footprint ∝ depth (also the fallback for anything else)
        f = float(np.median(ratio))
        focal = f
        iz_scale = f / depth_sigma
        lps_from = (depth_sigma / f, -math.log(f))
        # not pixel_size = z / f: measure
        measure_lps = float(ratio.max()) > 1.001 * float(ratio.min())
    # I = iz_scale · (z or ln z): OpenCV multiplies by a scalar in double precision (and
    # rounds once), 5x slower than NumPy's float32 product, which is the same number when the
    # factor is a float32 (as f = median(z / pixel_size) is when depth_sigma is 1)
    exact32 = float(np.float32(iz_scale)) == iz_scale
    iz_scale32 = np.float32(iz_scale)

    def scale_iz(a: Array) -> None:
        if exact32:
            np.multiply(a, iz_scale32, out=a)
        else:
            _write(_cv.multiply(a, iz_scale, dst=a), a, slice(None))

    iz = np.empty((h, w), np.float32)
    lps = np.empty((h, w), np.float32) if measure_lps else None
    sig = np.empty((h, w), np.float32)
    first = min(h, w) // 2 >= _MIN_LEVEL_SIDE
    hc, wc = (h + 1) // 2, (w + 1) // 2
    nsig = 2 if squares else 1

    def cells() -> Array:
        return np.empty((hc, wc), np.float32)

    cov, iz1 = cells(), cells()
    sig1 = [cells() for _ in range(nsig)]
    lps1 = cells() if measure_lps else None
    nrm1 = None if normal is None else [cells() for _ in range(3)]
    surf = _Surface(
        valid,
        iz,
        lps,
        lps_from,
        normal,
        float(ps_min),
        float(ps_max),
        focal,
        depth_sigma,
        centre,
    )
    step = max(2, (STRIP_PIXELS // max(w, 1)) & ~1)  # even: strips hold whole cells

    def strip(r: slice) -> None:
        r0 = r.start
        v = valid[r]
        w_r = np.empty((r.stop - r0, w), np.float32)  # the weight: 1 on the surface, 0 elsewhere
        iz_r = iz[r]
        if focal is None:
            iz_r.fill(0.0)  # 0 off the surface
            _write(_cv.copyTo(depth[r], v, iz_r), iz, r)
        else:  # ln 1 = 0 off the surface
            w_r.fill(1.0)
            _write(_cv.log(_cv.copyTo(depth[r], v, w_r), dst=iz_r), iz, r)
        scale_iz(iz_r)
        if lps is not None:
            w_r.fill(1.0)
            _write(_cv.log(_cv.copyTo(pixel_size[r], v, w_r), dst=lps[r]), lps, r)
        s_r = sig[r]
        signal(r, s_r)
        if not first:
            return
        np.copyto(w_r, v, casting="unsafe")
        c = slice(r0 // 2, (r.stop + 1) // 2)
        cv_c = cov[c]
        _write(_area_half(w_r), cov, c)
        inv = np.divide(_ONE, _cv.max(cv_c, 1e-12))  # fields are 0 in empty cells: stay 0
        sw = _cv.copyTo(s_r, v)  # 0 off the surface
        _write(_cv.multiply(_area_half(sw), inv, dst=sig1[0][c]), sig1[0], c)
        if squares:
            _write(_cv.multiply(_area_half(_cv.multiply(sw, sw)), inv, dst=sig1[1][c]), sig1[1], c)
        _write(_cv.multiply(_area_half(iz_r), inv, dst=iz1[c]), iz1, c)
        if lps is not None and lps1 is not None:
            _write(_cv.multiply(_area_half(lps[r]), inv, dst=lps1[c]), lps1, c)
        if normal is not None and nrm1 is not None:
            # normals off the surface may be anything (0, NaN): average them in and zero the
            # NaN; a partial cell's sum is renormalised by its coverage
            n3 = _area_half(normal[r])
            _cv.patchNaNs(n3, 0.0)
            for i, ch in enumerate(_cv.split(n3)):
                _write(_cv.multiply(ch, inv, dst=nrm1[i][c]), nrm1[i], c)

    color.row_strips(h, w, strip, step)
    if not first:
        return surf, sig, None
    if lps1 is None:
        a, b = lps_from
        lps1 = _cv.addWeighted(iz1, a, iz1, 0.0, b)
    lv = _Level(1, cov, sig1, iz1, lps1, nrm1)
    # the guide's slopes at the cells, after the pass (element-wise: fewer, larger calls)
    lv.grad = _guide_gradient(lv, surf)
    return surf, sig, lv


@dataclass
class _Level:
    """One level of the surface pyramid, ``2**k`` image pixels per cell."""

    k: int
    cov: Array  # fraction of the cell's pixels kept (0: empty cell)
    sig: list[Array]  # signal channels, normalised (0 in empty cells)
    iz: Array  # depth guide in image-pixel units
    lps: Array  # ln(pixel_size)
    nrm: list[Array] | None  # normal x, y, z (averaged, not renormalised)
    grad: tuple[Array, Array] | None = None  # ∂I/∂column, ∂I/∂row from the normals
    flags: tuple[float, Array] | None = None  # (thr, _block_flags(self, thr)) once known
    _valid: Array | None = None

    @property
    def valid(self) -> Array:
        """bool: the cell holds some surface."""
        if self._valid is None:
            self._valid = self.cov > 0.0
        return self._valid

    @property
    def valid_u8(self) -> Array:
        return self.valid.view(np.uint8)


def _area_half(a: Array) -> Array:
    """2×2 area average (pads odd sizes with zeros: coverage-weighted fields stay exact).

    Multi-channel arrays go through INTER_LINEAR, which at a scale of exactly 1/2 samples the
    midpoint of each 2×2 block with weights ½, ½: the same average, 3× faster than OpenCV's
    INTER_AREA on three channels (one channel: INTER_AREA is the faster).
    """
    h, w = a.shape[:2]
    if h % 2 or w % 2:
        a = _cv.copyMakeBorder(a, 0, h % 2, 0, w % 2, _cv.BORDER_CONSTANT, value=0.0)
    interp = _cv.INTER_AREA if a.ndim == 2 else _cv.INTER_LINEAR
    return _cv.resize(a, (a.shape[1] // 2, a.shape[0] // 2), interpolation=interp)


def _finish_first_level(lv: _Level, surf: _Surface, sig: Array) -> None:
    """Level 1 as ``_surface`` averaged it (with the guide's slopes), the cells on a step
    holding the front-most surface only (``sig``: the signal at full resolution)."""
    _front_most_cells(lv, surf, sig)


class _Gather:
    """``a[rows, cols]`` of (H, W) or (H, W, C) arrays at fixed points, through the flat index
    where ``a`` is C-contiguous (NumPy's fast path), by (row, column) elsewhere (a view with a
    row stride is read in place, not copied)."""

    def __init__(self, rows: Array, cols: Array, w: int) -> None:
        self.rows, self.cols = rows, cols
        self.flat = rows * w + cols

    def __call__(self, a: Array) -> Array:
        if a.flags.c_contiguous:  # (np.take: 3x faster than indexing for rows of channels)
            return np.take(a.reshape(-1, *a.shape[2:]), self.flat, axis=0)
        return a[self.rows, self.cols]


def _front_most_cells(lv: _Level, surf: _Surface, sig: Array) -> None:
    """Make the level-1 cells that straddle a depth step hold the front-most surface only.

    The area average mixes the 2×2 pixels of a cell whatever they show; where a cell sits on a
    step (it touches a block ``_block_flags`` rejects), its pixels are re-averaged keeping
    those within _JUMP pixels (plus the cell's own slope) of the nearest one, as
    ``_reduce_selective`` does for the coarser levels. A one-pixel-wide object in front of a
    surface then keeps its own cells instead of half-mixing with what lies behind it.
    """
    thr = np.float32(_JUMP * 2)
    fl = _block_flags(lv, thr)
    cand = _cv.dilate(fl, _BLOCK, anchor=(0, 0))[:-1, :-1]  # cell touches a flagged block
    _cv.bitwise_and(cand, lv.valid_u8, dst=cand)
    pts = _cv.findNonZero(cand)
    if pts is None:
        return
    pts = pts.reshape(-1, 2)
    cx, cy = pts[:, 0].astype(np.intp), pts[:, 1].astype(np.intp)
    cell = cy * lv.cov.shape[1] + cx  # flat index of the cell in its level
    hf, wf = surf.iz.shape
    # (4, N): the cell's pixels (top-left, top-right, bottom-left, bottom-right), then cells
    px = (2 * cx)[None, :] + np.array([0, 1, 0, 1], np.intp)[:, None]
    py = (2 * cy)[None, :] + np.array([0, 0, 1, 1], np.intp)[:, None]
    inside = (px < wf) & (py < hf)
    np.minimum(px, wf - 1, out=px)
    np.minimum(py, hf - 1, out=py)
    at = _Gather(py, px, wf)
    ok = inside & at(surf.valid).view(bool)
    iz = at(surf.iz)
    slope = np.float32(0.0)
    if lv.grad is not None:
        slope = (np.abs(lv.grad[0].ravel()[cell]) + np.abs(lv.grad[1].ravel()[cell]))[None, :]
    front = np.where(ok, iz, np.float32(_BIG)).min(axis=0, keepdims=True)
    # weight 1 within _JUMP/2 (+ the cell's slope) of the front, fading to 0 at _JUMP
    half = np.float32(0.5) * thr
    keep = (front + thr + 2.0 * slope - iz) / half
    keep = np.minimum(np.maximum(keep, np.float32(0.0), out=keep), np.float32(1.0), out=keep)
    keep *= ok
    n = _sum_taps(keep).astype(np.float32)
    wk = keep / np.maximum(n, np.float32(1e-6))[None, :]
    np.put(lv.cov, cell, n * np.float32(0.25))
    vals = np.where(ok, at(sig), np.float32(0.0))  # the signal, 0 off the surface
    np.put(lv.sig[0], cell, _sum_taps(wk * vals))
    if len(lv.sig) > 1:  # and its square
        np.put(lv.sig[1], cell, _sum_taps(wk * (vals * vals)))
    iz_c = _sum_taps(wk * iz)
    np.put(lv.iz, cell, iz_c)
    if surf.lps is not None:
        np.put(lv.lps, cell, _sum_taps(wk * at(surf.lps)))
    else:
        a, b = surf.lps_from
        np.put(lv.lps, cell, a * iz_c + b)
    if lv.nrm is not None and surf.normal is not None:
        nv = at(surf.normal)  # (4, N, 3)
        np.copyto(nv, np.float32(0.0), where=np.isnan(nv))  # (normals off the surface: any)
        nv *= wk[:, :, None]
        nc = _sum_taps(nv)  # (N, 3)
        for i in range(3):
            np.put(lv.nrm[i], cell, nc[:, i])
        if lv.grad is not None:  # the re-averaged cells' slopes
            gx, gy = _plane_slope(
                nc[:, 0],
                nc[:, 1],
                nc[:, 2],
                cy.astype(np.float32),
                cx.astype(np.float32),
                1,
                surf,
            )
            bad = ~(np.isfinite(gx) & np.isfinite(gy)) | (n == 0)
            gx[bad] = 0.0
            gy[bad] = 0.0
            np.put(lv.grad[0], cell, gx)
            np.put(lv.grad[1], cell, gy)
    lv._valid = None
    # the blocks' flags after the change: only blocks touching a changed cell can differ (cell
    # validity is kept: each changed cell keeps at least its front-most pixel)
    lv.flags = (float(thr), _update_flags(lv, thr, fl, cand))


def _touching(cells: Array) -> Array:
    """uint8 (h + 1, w + 1): the 2×2 blocks (the bilinear taps, as in ``_block_flags``) that
    hold a cell where ``cells`` (uint8, (h, w)) is non-zero; block (i, j) holds cells
    i−1…i, j−1…j."""
    near = _cv.copyMakeBorder(cells, 1, 0, 1, 0, _cv.BORDER_CONSTANT, value=0)
    return _cv.dilate(near, _BLOCK, anchor=(0, 0), borderType=_cv.BORDER_CONSTANT, borderValue=0)


def _update_flags(lv: _Level, thr: np.float32, fl: Array, changed: Array) -> Array:
    """``_block_flags(lv, thr)`` from ``fl``, the flags before the cells where ``changed``
    (uint8, non-zero) changed their guide or slope (not their validity): the blocks touching
    them are tested again, sparsely, with the same float32 operations."""
    h, w = lv.cov.shape
    pts = _cv.findNonZero(_touching(changed))
    out = fl.copy()
    if pts is None:
        return out
    pts = pts.reshape(-1, 2)
    bi, bj = pts[:, 1].astype(np.int64), pts[:, 0].astype(np.int64)
    # (np.clip is slow on small arrays)
    r0, r1 = np.maximum(bi - 1, 0) * w, np.minimum(bi, h - 1) * w
    c0, c1 = np.maximum(bj - 1, 0), np.minimum(bj, w - 1)
    cells = (r0 + c0, r0 + c1, r1 + c0, r1 + c1)  # tl, tr, bl, br
    cov = lv.cov.ravel()
    bad = (cov[cells[0]] <= 0) | (cov[cells[1]] <= 0) | (cov[cells[2]] <= 0) | (cov[cells[3]] <= 0)
    iz = lv.iz.ravel()
    if lv.grad is None:
        tl, tr, bl, br = (iz[c] for c in cells)
    else:
        hd = np.float32(0.5 * 2**lv.k)  # a power of 2: the products are exact, as in OpenCV
        gx, gy = lv.grad[0].ravel(), lv.grad[1].ravel()
        tl = gy[cells[0]] * hd + (gx[cells[0]] * hd + iz[cells[0]])
        tr = gy[cells[1]] * hd + (gx[cells[1]] * -hd + iz[cells[1]])
        bl = gy[cells[2]] * -hd + (gx[cells[2]] * hd + iz[cells[2]])
        br = gy[cells[3]] * -hd + (gx[cells[3]] * -hd + iz[cells[3]])
    hi = np.maximum(np.maximum(tl, tr), np.maximum(bl, br))
    lo = np.minimum(np.minimum(tl, tr), np.minimum(bl, br))
    step = (hi - lo) > thr
    out[bi, bj] = (bad | step).view(np.uint8)
    return out


def _guide_gradient(lv: _Level, surf: _Surface) -> tuple[Array, Array] | None:
    """Slope of the depth guide predicted by the normals, per image pixel, at a level's cells.

    For a plane n·P = c seen in perspective, I = (f/depth_sigma) ln z has
    ∂I/∂u = n_x / (n_z − n_x u/f − n_y v/f) / depth_sigma (u, v: pixels from the image centre,
    v up; ∂/∂row = −∂/∂v); orthographic: ∂I/∂u = n_x / n_z / depth_sigma. Used to tell a
    slanted surface (however steep) from a step between two surfaces: neighbouring cells are on
    one surface when each predicts the other's guide value. None without normals (then only
    the raw guide difference is used, which treats steep surfaces as steps: safe, slower).
    """
    if lv.nrm is None:
        return None
    h, w = lv.cov.shape
    uv = None if surf.focal is None else _view_grid(h, w, lv.k, surf.centre, surf.focal)
    return _cell_slopes(lv.nrm, lv.cov, uv, surf)


def _cell_slopes(
    nrm: list[Array], cov: Array, uv: tuple[Array, Array] | None, surf: _Surface
) -> tuple[Array, Array]:
    """_plane_slope on (part of) a level: normals ``nrm``, coverage ``cov``, ``uv`` the
    ``_view_grid`` of those cells (None: orthographic); 0 in empty cells and where not finite.
    The same float32 operations as _plane_slope, in OpenCV where that is faster."""
    nx, ny, nz = nrm
    if uv is not None:
        den = _cv.subtract(nz, _cv.multiply(nx, uv[0]))
        _cv.subtract(den, _cv.multiply(ny, uv[1]), dst=den)
    else:
        den = nz.copy()
    np.maximum(den, np.float32(0.02), out=den)
    scale = np.float32(1.0 / surf.depth_sigma)
    with np.errstate(invalid="ignore"):
        gx = np.multiply(nx, scale)
        np.divide(gx, den, out=gx)
        gy = np.multiply(ny, -scale)
        np.divide(gy, den, out=gy)
    bad = ~(np.isfinite(gx) & np.isfinite(gy)) | (cov <= 0.0)
    gx[bad] = 0.0
    gy[bad] = 0.0
    return gx, gy


@functools.lru_cache(maxsize=32)
def _view_grid(
    h: int, w: int, k: int, centre: tuple[float, float], focal: float
) -> tuple[Array, Array]:
    """(u/f, v/f) at the cell centres of a level-k grid of (h, w) cells (as in _plane_slope):
    u = (column + ½) 2^k − c_x, v = c_y − (row + ½) 2^k. Read-only, cached per grid."""
    d = np.float32(2**k)
    cx, cy = centre
    inv_f = np.float32(1.0 / focal)
    cols = np.arange(w, dtype=np.float32)[None, :]
    rows = np.arange(h, dtype=np.float32)[:, None]
    u = np.ascontiguousarray(
        np.broadcast_to(((cols + np.float32(0.5)) * d - np.float32(cx)) * inv_f, (h, w))
    )
    v = np.ascontiguousarray(
        np.broadcast_to((np.float32(cy) - (rows + np.float32(0.5)) * d) * inv_f, (h, w))
    )
    u.flags.writeable = False
    v.flags.writeable = False
    return u, v


def _plane_slope(
    nx: Array, ny: Array, nz: Array, rows: Array, cols: Array, k: int, surf: _Surface
) -> tuple[Array, Array]:
    """(∂I/∂column, ∂I/∂row) for normals at cells (rows, cols) of level k (broadcasting)."""
    den = nz.astype(np.float32, copy=True)
    if surf.focal is not None:
        d = np.float32(2**k)
        cx, cy = surf.centre
        inv_f = np.float32(1.0 / surf.focal)
        den = den - nx * (((cols + np.float32(0.5)) * d - np.float32(cx)) * inv_f)
        den -= ny * ((np.float32(cy) - (rows + np.float32(0.5)) * d) * inv_f)
    np.maximum(den, np.float32(0.02), out=den)
    scale = np.float32(1.0 / surf.depth_sigma)
    with np.errstate(invalid="ignore"):
        return nx * scale / den, ny * -scale / den


def _reduce_selective(lv: _Level, surf: _Surface) -> _Level:
    """Next coarser level, each cell keeping only the front-most surface of its 2×2 block.

    Each sample predicts the depth guide at the block centre along its own plane (normals); the
    samples within _JUMP (at this level's scale) of the nearest prediction are averaged and the
    others (a farther surface) dropped, so a coarse cell does not mix an object with what lies
    behind it, while a steep surface keeps all its samples.
    """
    h, w = lv.cov.shape
    hp, wp = h + h % 2, w + w % 2
    d = float(2**lv.k)
    # each sample's prediction at its block centre, half a cell away along its plane
    if lv.grad is not None:
        sc, sr = _parity(h, w, d)
        p = _cv.add(lv.iz, _cv.multiply(lv.grad[0], sc))
        _cv.add(p, _cv.multiply(lv.grad[1], sr), dst=p)
    else:
        p = lv.iz.copy()
    p[~lv.valid] = _BIG
    if (hp, wp) != (h, w):
        p = _cv.copyMakeBorder(p, 0, hp - h, 0, wp - w, _cv.BORDER_CONSTANT, value=float(_BIG))
    # the nearest prediction of each block (a 2×2 minimum), back on the cells
    near = _cv.erode(p, _BLOCK, anchor=(0, 0), borderType=_cv.BORDER_REPLICATE)[::2, ::2]
    # weight 1 within _JUMP/2 of the front, fading to 0 at _JUMP (no hard switch along a contact)
    half = np.float32(0.5 * _JUMP * 2**lv.k)
    near = near + np.float32(2.0) * half
    keep = _cv.resize(near, (wp, hp), interpolation=_cv.INTER_NEAREST)[:h, :w]
    np.subtract(keep, p[:h, :w], out=keep)
    np.divide(keep, half, out=keep)
    np.minimum(np.maximum(keep, np.float32(0.0), out=keep), np.float32(1.0), out=keep)
    sel = _cv.multiply(lv.cov, keep)
    cov = _area_half(sel)
    inv = np.divide(_ONE, _cv.max(cov, 1e-12))  # empty cells: the sums are 0, stay 0

    def red(field: Array) -> Array:
        return _cv.multiply(_area_half(_cv.multiply(field, sel)), inv)

    iz = red(lv.iz)
    if surf.lps is None:
        a, b = surf.lps_from
        lps = _cv.addWeighted(iz, a, iz, 0.0, b)
    else:
        lps = red(lv.lps)
    out = _Level(
        lv.k + 1,
        cov,
        [red(s) for s in lv.sig],
        iz,
        lps,
        None if lv.nrm is None else [red(n) for n in lv.nrm],
    )
    out.grad = _guide_gradient(out, surf)
    return out


_BLOCK = np.ones((2, 2), np.uint8)


@functools.lru_cache(maxsize=32)
def _parity(h: int, w: int, d: float) -> tuple[Array, Array]:
    """(+d/2, −d/2, +d/2, …) along the columns and along the rows of an (h, w) grid: the
    offset of each cell from the centre of its 2×2 block, in image pixels. Read-only."""
    alt = np.array([0.5 * d, -0.5 * d], np.float32)
    sc = np.ascontiguousarray(np.broadcast_to(np.tile(alt, (w + 1) // 2)[None, :w], (h, w)))
    sr = np.ascontiguousarray(np.broadcast_to(np.tile(alt, (h + 1) // 2)[:h, None], (h, w)))
    sc.flags.writeable = False
    sr.flags.writeable = False
    return sc, sr


@functools.lru_cache(maxsize=16)
def _ramp(h: int, w: int) -> Array:
    """(KNEE/2)(row + column), read-only (cached per level shape)."""
    ramp = np.add.outer(np.arange(h, dtype=np.float32), np.arange(w, dtype=np.float32))
    ramp *= np.float32(0.5 * _KNEE)
    ramp.flags.writeable = False
    return ramp


_SMOOTHER: ThreadPoolExecutor | None = None
_SMOOTHER_LOCK = threading.Lock()


def _smoother() -> ThreadPoolExecutor:
    """The thread the pyramid's domain transforms run on, in the background of the rest of
    its work (one, shared, created on first use; a forked child makes its own)."""
    global _SMOOTHER
    with _SMOOTHER_LOCK:
        if _SMOOTHER is None:
            _SMOOTHER = ThreadPoolExecutor(1, "depict-smooth")
        return _SMOOTHER


def _forget_smoother() -> None:  # in a forked child: the parent's thread is not there
    global _SMOOTHER, _SMOOTHER_LOCK
    _SMOOTHER, _SMOOTHER_LOCK = None, threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_smoother)


def _smooth_level(
    lv: _Level, nsig: int, normal_sigma: float | None, box: tuple[slice, slice] | None = None
) -> list[Array]:
    """Domain-transform smoothing (normalised convolution, σ = 2 cells) of the first ``nsig``
    signal channels of a level, guided by the depth guide (and normals), empty cells walled off.

    The depth guide I enters as the pair I/2 ± (KNEE/2)(x + y): OpenCV's transform adds the L1
    norm of the guide step, and |a + b| + |a − b| = 2 max(|a|, |b|), so each step costs
    1 + max(|ΔI|, KNEE) instead of 1 + |ΔI|. Surfaces tilted less than atan(KNEE) are smoothed
    as if flat (σ is rescaled by 1 + KNEE), steeper ones and depth steps are stretched as before:
    this removes the crease that the L1 arc length |ΔI| has where the depth slope changes sign
    (it showed as lines across the middle of a sphere in L* − L*_σ).
    """
    bx = box if box is not None else (slice(None), slice(None))
    iz, valid = lv.iz[bx], lv.valid[bx]
    h, w = iz.shape
    gz = _cv.multiply(iz, 0.5 * _DT_DEPTH_GAIN / 2**lv.k)  # 0 in empty cells
    _, top, _, _ = _cv.minMaxLoc(gz, mask=valid.view(np.uint8))
    empty = (~valid).astype(np.float32)
    _cv.scaleAdd(empty, top + 0.5 * _WALL, gz, dst=gz)  # walls around the surface
    ramp = _ramp(h, w)
    chans = [_cv.add(gz, ramp), _cv.subtract(gz, ramp)]
    sigma = _SIGMA_C * (1.0 + _KNEE)
    if lv.nrm is not None and normal_sigma is not None:
        s = sigma / normal_sigma
        chans += [_cv.multiply(n[bx], s) for n in lv.nrm[:2]]
    guide = _cv.merge(chans)
    src = _cv.merge([g[bx] for g in lv.sig[:nsig]]) if nsig > 1 else lv.sig[0][bx]
    out = _cv.ximgproc.dtFilter(
        guide,
        src,
        sigmaSpatial=sigma,
        sigmaColor=sigma,
        mode=_DT_MODE,
        numIters=3,
    )
    # (empty cells hold whatever: nothing reads them - flagged blocks skip them)
    return [np.ascontiguousarray(out[:, :, i]) for i in range(nsig)] if nsig > 1 else [out]


_BIG = np.float32(1.0e30)


def _block_flags(lv: _Level, thr: np.float32) -> Array:
    """Per 2×2 block of cells (the bilinear taps), padded: 1 where it is not one surface.

    Entry (i, j) covers cells (i−1…i, j−1…j) (clamped at the borders). A block is flagged when
    one of its cells is empty, or when the four cells, each extrapolating the depth guide along
    its own plane (``grad``) to the block's centre, disagree by more than ``thr``: a step
    between surfaces, not a steep surface. uint8 0/1, shape (h + 1, w + 1). Large levels are
    done in strips of block rows over the shared pool (OpenCV's element-wise operations run on
    one thread each).
    """
    h, w = lv.cov.shape
    out = np.empty((h + 1, w + 1), np.uint8)
    rep = _cv.BORDER_REPLICATE
    d = float(2**lv.k)

    def rows(r: slice) -> None:
        # block rows r read cell rows r.start − 1 … r.stop − 1, clamped (replicated)
        c = slice(max(r.start - 1, 0), min(r.stop, h))
        pad = (int(r.start == 0), int(r.stop > h), 1, 1)
        inv = _cv.copyMakeBorder(_cv.compare(lv.cov[c], 0.0, _cv.CMP_LE), *pad, rep)
        bad = _cv.dilate(inv, _BLOCK, anchor=(0, 0), borderType=rep)[:-1, :-1]  # 2×2 maximum
        # the four cells' predictions at the block centre, I + (±½, ±½) 2^k ∇I
        iz = _cv.copyMakeBorder(lv.iz[c], *pad, rep)
        if lv.grad is None:
            tl, tr, bl, br = iz[:-1, :-1], iz[:-1, 1:], iz[1:, :-1], iz[1:, 1:]
        else:
            gx, gy = (_cv.copyMakeBorder(g[c], *pad, rep) for g in lv.grad)
            right, left = _cv.scaleAdd(gx, 0.5 * d, iz), _cv.scaleAdd(gx, -0.5 * d, iz)
            tl = _cv.scaleAdd(gy[:-1, :-1], 0.5 * d, right[:-1, :-1])
            tr = _cv.scaleAdd(gy[:-1, 1:], 0.5 * d, left[:-1, 1:])
            bl = _cv.scaleAdd(gy[1:, :-1], -0.5 * d, right[1:, :-1])
            br = _cv.scaleAdd(gy[1:, 1:], -0.5 * d, left[1:, 1:])
        hi = _cv.max(_cv.max(tl, tr), _cv.max(bl, br))
        lo = _cv.min(_cv.min(tl, tr), _cv.min(bl, br))
        step = _cv.compare(_cv.subtract(hi, lo, dst=hi), float(thr), _cv.CMP_GT)
        _write(_cv.min(_cv.bitwise_or(bad, step, dst=bad), 1, dst=out[r]), out, r)

    if (h + 1) * (w + 1) >= 2 * STRIP_PIXELS:
        color.row_strips(h + 1, w + 1, rows, max(1, STRIP_PIXELS // 2 // (w + 1)))
    else:
        rows(slice(0, h + 1))
    return out


def _sub_resize(a: Array, f: int, rows: slice, cols: slice) -> Array:
    """Rows ``rows``, columns ``cols`` of the bilinear ×``f`` upsampling of ``a`` (as
    ``cv2.resize(a, (w f, h f), INTER_LINEAR)``, bit for bit), resizing only the cells they
    read: bilinear taps are local, and OpenCV's weights depend on the position relative to the
    crop only through f · (first cell), an integer. A view (with a row stride) of a new array."""
    hc, wc = a.shape[:2]
    y0, y1 = max(rows.start // f - 1, 0), min((rows.stop - 1) // f + 2, hc)
    x0, x1 = max(cols.start // f - 1, 0), min((cols.stop - 1) // f + 2, wc)
    size = ((x1 - x0) * f, (y1 - y0) * f)
    sub = _cv.resize(a[y0:y1, x0:x1], size, interpolation=_cv.INTER_LINEAR)
    return sub[rows.start - y0 * f : rows.stop - y0 * f, cols.start - x0 * f : cols.stop - x0 * f]


class _Upsampler:
    """Edge-aware upsampling from level ``lv`` to the grid of ``fine_iz``, read by strips of
    fine rows (:meth:`rows`), so that the caller can use each strip while it is in cache, from
    several threads at once.

    Bilinear, except at the few fine pixels whose four bilinear taps are not all on one surface
    (a tap block spanning a depth step of more than _JUMP level pixels, or holding an empty
    cell) or whose own depth guide departs from the interpolated one: there the taps are
    re-weighted by surface compatibility (|ΔI| < _JUMP level pixels, cell not empty), widening
    to a 4×4 tent where none of the four is compatible, and falling back to ``fallback`` (the
    pixel's own, less smoothed value) where no nearby cell lies on its surface. Nothing from
    another surface is interpolated in. ``fine_valid`` is uint8 0/1.

    Construction finds the re-weighted pixels and their taps and weights (``_FixupTaps``): that
    depends on the levels' geometry only, not on the channels, so it can run while the channels
    are being smoothed. :meth:`bind` then gives the channels (level ``lv``) and computes the
    re-weighted values, in one vectorised pass each (many small NumPy calls: in threads they
    would only contend for the GIL); :meth:`rows` interpolates its rows and writes them in.
    """

    def __init__(
        self,
        lv: _Level,
        fine_iz: Array,
        fine_valid: Array,
        fine_k: int,
        fallback: list[Array],
    ) -> None:
        hc, wc = lv.cov.shape
        hf, wf = self.shape = fine_iz.shape[:2]
        f = self.f = 2 ** (lv.k - fine_k)  # fine pixels per coarse cell, per axis
        self.fallback = fallback
        self.coarse: list[Array] = []
        self.in_order = False  # idx ascending
        thr = np.float32(_JUMP * 2**lv.k)
        blocks = (
            lv.flags[1] if lv.flags is not None and lv.flags[0] == thr else _block_flags(lv, thr)
        )
        # flat fine indices of the re-weighted pixels (ascending where ``fine_k`` is 0)
        self.idx: Array | None = None
        self.taps: _FixupTaps | None = None  # their taps and weights (in the order of idx)
        self.vals: list[Array] = []  # their values, per channel (once bound)
        if f == 2:
            # the fine pixels of the flagged blocks that hold some surface (block (i, j) holds
            # cells i−1…i, j−1…j and fine pixels 2i−1…2i, 2j−1…2j), found on the coarse grid
            some = _touching(lv.valid_u8)
            bp = _cv.findNonZero(_cv.bitwise_and(blocks, some, dst=some))
            if bp is None:
                return
            bp = bp.reshape(-1, 2).astype(np.int64)
            xx = (2 * bp[:, 0] - 1)[:, None] + np.array([0, 1, 0, 1])[None, :]
            yy = (2 * bp[:, 1] - 1)[:, None] + np.array([0, 0, 1, 1])[None, :]
            ok = (xx >= 0) & (xx < wf) & (yy >= 0) & (yy < hf)
            xx, yy = xx[ok], yy[ok]
            idx = yy * wf + xx
            on = _Gather(yy, xx, wf)(fine_valid).view(bool)
            xx, yy, idx = xx[on], yy[on], idx[on]
        else:
            half = f // 2
            flag = _cv.resize(blocks, ((wc + 1) * f, (hc + 1) * f), interpolation=_cv.INTER_NEAREST)
            need = _cv.bitwise_and(flag[half : half + hf, half : half + wf], fine_valid)
            # a fine pixel whose own guide departs from the interpolated one: a small object
            # inside a cell (at f = 2 any such cell already differs from its neighbours)
            izn = _cv.resize(lv.iz, (wc * f, hc * f), interpolation=_cv.INTER_LINEAR)[:hf, :wf]
            far = _cv.compare(_cv.absdiff(fine_iz, izn), float(thr), _cv.CMP_GT)
            _cv.bitwise_and(far, fine_valid, dst=far)
            _cv.bitwise_or(need, far, dst=need)
            pts = _cv.findNonZero(need)
            if pts is None:
                return
            pts = pts.reshape(-1, 2)
            xx, yy = pts[:, 0], pts[:, 1]
            idx = yy.astype(np.int64) * wf + xx
        if idx.size == 0:
            return
        self.in_order = fine_k == 0
        if self.in_order:  # read by strips of rows (:meth:`rows`): sorted
            order = np.argsort(idx, kind="stable")
            idx, xx, yy = idx[order], xx[order], yy[order]
        self.idx = idx
        self.taps = _FixupTaps(xx, yy, f, lv, fine_iz.ravel()[idx], thr)

    def bind(self, coarse: list[Array]) -> _Upsampler:
        """Give the channels to upsample (level ``lv``, one per ``fallback``); returns self."""
        self.coarse = coarse
        self.vals = []
        if self.taps is not None and self.idx is not None:
            for arr, fb in zip(coarse, self.fallback, strict=True):
                col = self.taps.apply(arr)
                if self.taps.none is not None:
                    col[self.taps.none] = fb.ravel()[self.idx[self.taps.none]]
                self.vals.append(col)
        return self

    def rows(self, r: slice, cols: slice | None = None) -> list[Array]:
        """The upsampled channels at fine rows ``r`` (new arrays), columns ``cols`` (None: all;
        else they must hold every surface pixel of the rows)."""
        hf, wf = self.shape
        c = slice(0, wf) if cols is None else cols
        ups = [_sub_resize(a, self.f, r, c) for a in self.coarse]
        if self.idx is not None and r.start == 0 and r.stop == hf and cols is None:
            ups = [np.ascontiguousarray(u) for u in ups]
            for u, v in zip(ups, self.vals, strict=True):
                u.ravel()[self.idx] = v
        elif self.idx is not None:
            assert self.in_order, "strips of rows are read from the image's upsampling only"
            i0, i1 = np.searchsorted(self.idx, (r.start * wf, r.stop * wf))
            if i1 > i0:  # (re-weighted pixels are on the surface: in the columns)
                at_r, at_c = np.divmod(self.idx[i0:i1], wf)
                at_r -= r.start
                at_c -= c.start
                for u, v in zip(ups, self.vals, strict=True):
                    u[at_r, at_c] = v[i0:i1]
        return ups

    def full(self) -> list[Array]:
        """All rows at once."""
        return self.rows(slice(0, self.shape[0]))


class _FixupTaps:
    """Surface-compatible interpolation at fine pixels (xx, yy) of level ``lv``'s cells: the
    taps and weights, to be applied to any channel of that level (:meth:`apply`); ``none``: the
    points where no compatible tap is found (None: there are none).

    Taps: the 2×2 bilinear ones, then (where none of those is compatible) a 4×4 tent of radius 2
    cells. A tap is compatible when its plane (``lv.grad``), extrapolated to the pixel, meets the
    pixel's depth guide ``iz_p`` within ``thr``; weight tent × (1 − (miss/thr)²), normalised.
    All in float32 (the offsets from the taps are multiples of 1/(2f), exact).
    """

    def __init__(
        self, xx: Array, yy: Array, f: int, lv: _Level, iz_p: Array, thr: np.float32
    ) -> None:
        hc, wc = lv.cov.shape
        valid_c = lv.valid.ravel()
        izc = lv.iz.ravel()
        d = np.float32(2**lv.k)
        grad = None if lv.grad is None else (lv.grad[0].ravel(), lv.grad[1].ravel())
        inv_f = np.float32(1.0 / f)
        u = (xx.astype(np.float32) + np.float32(0.5)) * inv_f - np.float32(0.5)
        v = (yy.astype(np.float32) + np.float32(0.5)) * inv_f - np.float32(0.5)
        x0 = np.floor(u).astype(np.intp)
        y0 = np.floor(v).astype(np.intp)
        inv_thr = np.float32(1.0 / thr)
        self.n = xx.size
        # per pass: (points it gives, (taps, points) flat cell indices, normalised weights)
        self.passes: list[tuple[Array | slice, Array, Array]] = []
        todo: Array | None = None  # None: all
        zero, one = np.float32(0.0), np.float32(1.0)
        # arrays are (taps, points): each tap's values are contiguous, sums over taps add rows
        for radius, offs in ((1.0, (0, 1)), (2.0, (-1, 0, 1, 2))):
            if todo is None:
                ut, vt, it, xt, yt = u, v, iz_p, x0, y0
            else:
                ut, vt, it, xt, yt = u[todo], v[todo], iz_p[todo], x0[todo], y0[todo]
            npt = ut.size
            m = len(offs)
            o = np.array(offs, np.intp)[:, None]
            cx = xt[None, :] + o  # (m, N)
            cy = yt[None, :] + o
            dx = ut[None, :] - cx.astype(np.float32)
            dy = vt[None, :] - cy.astype(np.float32)
            if radius == 1.0:  # |dx| < 1 at the two taps: the tent 1 − |dx| is positive
                tx = one - np.abs(dx)
                ty = one - np.abs(dy)
            else:
                inv_r = np.float32(1.0 / radius)
                tx = np.maximum(zero, one - np.abs(dx) * inv_r)
                ty = np.maximum(zero, one - np.abs(dy) * inv_r)
            tx[(cx < 0) | (cx >= wc)] = 0.0
            ty[(cy < 0) | (cy >= hc)] = 0.0
            # (m, m, N): rows of taps, columns of taps (np.clip is slow on small arrays)
            rowi = np.minimum(np.maximum(cy, 0), hc - 1)
            rowi *= wc
            coli = np.minimum(np.maximum(cx, 0), wc - 1)
            flat = rowi[:, None, :] + coli[None, :, :]
            pred = izc[flat]
            if grad is not None:  # the tap's plane extrapolated to the pixel
                ddx, ddy = dx * d, dy * d  # (exact: d is a power of 2)
                pred += grad[0][flat] * ddx[None, :, :] + grad[1][flat] * ddy[:, None, :]
            # weight 1 − (miss / thr)², miss = |pred − I| (the sign goes with the square)
            pred -= it[None, None, :]
            pred *= inv_thr
            np.square(pred, out=pred)
            wts = np.subtract(one, pred, out=pred)
            np.maximum(wts, zero, out=wts)
            wts *= ty[:, None, :] * tx[None, :, :]
            wts *= valid_c[flat]
            wts = wts.reshape(m * m, npt)
            flat = flat.reshape(m * m, npt)
            sw = _sum_taps(wts)
            found = sw > 1e-4
            nfound = int(np.count_nonzero(found))
            if nfound:
                rows: Array | slice
                if todo is None:  # all points (those not found get another pass, or none)
                    rows = slice(None)
                    with np.errstate(divide="ignore", invalid="ignore"):
                        wts /= sw[None, :]
                else:
                    if nfound < npt:
                        wts, flat, sw = wts[:, found], flat[:, found], sw[found]
                    wts /= sw[None, :]
                    rows = todo if nfound == npt else todo[found]
                self.passes.append((rows, flat, wts))
            todo = (
                None
                if nfound == npt
                else (np.flatnonzero(~found) if todo is None else todo[~found])
            )
            if todo is None:
                break
        self.none = todo  # (None: every point has a compatible tap)

    def apply(self, arr: Array) -> Array:
        """The interpolated values of ``arr`` (a channel of the level) at the points (garbage
        where no compatible tap is found: see ``none``)."""
        out = np.full(self.n, np.nan, dtype=np.float32)
        a = arr.ravel()
        for rows, flat, wts in self.passes:
            out[rows] = _sum_taps(wts * np.take(a, flat))
        return out


def _sum_taps(a: Array) -> Array:
    """Sum of a (taps, points) array over its taps, in the order NumPy sums a (points, taps)
    row (sequential below 8 terms, 8 partial sums and a pairwise tree from 8 to 128)."""
    t = a.shape[0]
    if t < 8:
        res = a[0].copy()
        for i in range(1, t):
            res += a[i]
        return res
    r = a[:8].copy()
    i = 8
    while i + 8 <= t:
        r += a[i : i + 8]
        i += 8
    res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    for j in range(i, t):
        res += a[j]
    return res


def _alpha(lv: _Level, sigma: float, bx: tuple[slice, slice]) -> Array:
    """Weight of the coarser level k + 1 against level k at a level's cells.

    a = clip((σ_px² / s_k² − 1) / 3, 0, 1) with s_k = _LEVEL_SIGMA · 2^k and s_{k+1} = 2 s_k:
    the mix (1 − a) G_{s_k} + a G_{s_k+1} then has the second moment σ_px² exactly.
    """
    lps = lv.lps[bx]
    q = _cv.addWeighted(lps, -2.0, lps, 0.0, 2.0 * (math.log(sigma / _LEVEL_SIGMA) - lv.k * _LN2))
    q = _cv.exp(q)
    a = _cv.addWeighted(q, 1.0 / 3.0, q, 0.0, -1.0 / 3.0, dst=q)
    return np.minimum(np.maximum(a, np.float32(0.0), out=a), np.float32(1.0), out=a)


def _level_span(sigma: float, surf: _Surface, kmax: int) -> tuple[int, int]:
    """Levels [k_lo, k_hi] a chain of σ (scene units) needs: s_k ≤ σ_px < s_{k+1} uses k, k + 1."""
    lo = math.log2(sigma / surf.ps_max / _LEVEL_SIGMA)
    hi = math.log2(sigma / surf.ps_min / _LEVEL_SIGMA)
    k_lo = int(min(max(math.floor(lo), 1), kmax))
    k_hi = int(min(max(math.floor(hi) + 1, k_lo), kmax))
    return k_lo, k_hi


def _surface_pyramid(
    surf: _Surface,
    lum: Array,
    first: _Level | None,
    sigma: float,
    var_sigma: float | None,
    normal_sigma: float | None,
) -> tuple[_Upsampler, tuple[int, Array] | None] | None:
    """Surface-following smoothing of ``lum`` (σ = ``sigma``) and, optionally, its local
    variance (σ = ``var_sigma``).

    Levels k = 1, 2, … (cells of 2^k pixels, front-most surface per cell) are each smoothed by a
    domain transform of σ = 2 cells; with the reduction and the upsampling a level smooths by
    s_k = 2.218 · 2^k image pixels (measured). Coarse to fine, per chain:
    R_K = S_K; R_k = S_k + a_k (up(R_{k+1}) − S_k), a_k = clip((σ_px²/s_k² − 1)/3, 0, 1),
    σ_px = σ / pixel_size: each pixel ends up with the mix of the two levels around its σ_px
    whose second moment is σ_px² (σ_px is clamped to the levels that exist: at most about a
    quarter of the image's smaller side).

    ``first``: level 1 as ``_surface`` made it (from ``lum``, with its square when
    ``var_sigma`` is given; None: too small), finished here and then reduced.

    Returns the smoothed ``lum`` at full resolution, as the upsampler of its finest level
    (:meth:`_Upsampler.rows` gives it by strips of rows; the fade from ``lum`` itself for
    σ_px < s_1 ≈ 4.4 is the caller's, see ``_fade``) and, for the variance chain, (k, Var) at
    its finest level k (Var of L*, E[L²] − E[L]², upsampled bilinearly by the caller);
    None if the image is too small for one level.
    """
    h, wd = lum.shape
    kmax = 0
    while min(h, wd) // 2 ** (kmax + 1) >= _MIN_LEVEL_SIDE:
        kmax += 1
    if kmax == 0:
        return None
    m_lo, m_hi = _level_span(sigma, surf, kmax)
    v_lo, v_hi = (kmax + 1, 0)
    if var_sigma is not None:
        v_lo, v_hi = _level_span(var_sigma, surf, kmax)
        # the variance is a gain modulator: it starts at level 2 (σ ≈ 8 pixels), whose cells
        # already hold the 4×4-pixel means of L and L², so no half-resolution filtering for it
        v_lo = min(max(v_lo, 2), kmax)
        v_hi = max(v_hi, v_lo)
    k_lo, k_hi = min(m_lo, v_lo), max(m_hi, v_hi)

    assert first is not None and len(first.sig) == (1 if var_sigma is None else 2)
    # per level, coarse to fine: the chains it is in, whether they run on from the level above,
    # and the box to smooth: a level below the top of its chains only matters where
    # σ_px < s_{k+1} (elsewhere the coarser level takes over, a_k = 1)
    plan: dict[int, tuple[bool, bool, bool, bool, tuple[slice, slice] | None]] = {}
    # the domain transforms (most of the time here, in OpenCV, without the GIL) run on a
    # thread of their own, each as soon as its level is made, while this one makes the next
    # levels and then finds the upsamplings' re-weighted pixels and taps
    smoothed: dict[int, Future[list[Array]]] = {}

    def schedule(lv: _Level) -> None:
        k = lv.k
        in_m, in_v = m_lo <= k <= m_hi, v_lo <= k <= v_hi
        run_m, run_v = in_m and k < m_hi, in_v and k < v_hi
        box = None
        if (not in_m or run_m) and (not in_v or run_v):  # no chain starts here
            used = [sg for sg, on in ((sigma, in_m), (var_sigma, in_v)) if on and sg is not None]
            box = _need_box(lv, used)
        plan[k] = (in_m, in_v, run_m, run_v, box)
        if box is None or (box[0].stop > box[0].start and box[1].stop > box[1].start):
            smoothed[k] = _smoother().submit(_smooth_level, lv, 2 if in_v else 1, normal_sigma, box)

    levels: dict[int, _Level] = {}
    lv = first
    try:
        _finish_first_level(lv, surf, lum)
        while True:
            if lv.k >= k_lo:
                levels[lv.k] = lv
                schedule(lv)
            if lv.k >= k_hi:
                break
            lv = _reduce_selective(lv, surf)
        ups_of: dict[int, _Upsampler] = {}
        for k, (_, _, run_m, run_v, _) in plan.items():
            if run_m or run_v:
                lv = levels[k]
                fallback = (lv.sig[:1] if run_m else []) + (lv.sig[:2] if run_v else [])
                ups_of[k] = _Upsampler(levels[k + 1], lv.iz, lv.valid_u8, k, fallback)
        full = _Upsampler(levels[m_lo], surf.iz, surf.valid, 0, [lum])
    except BaseException:
        for fut in smoothed.values():
            fut.cancel()
        wait(list(smoothed.values()))
        raise

    main: list[Array] | None = None
    var: list[Array] | None = None
    for k in range(k_hi, k_lo - 1, -1):
        in_m, in_v, run_m, run_v, box = plan[k]
        lv = levels[k]
        # upsample the running chains from level k + 1 in one go (shared taps)
        chans = (main if run_m and main is not None else []) + (
            var if run_v and var is not None else []
        )
        ups = ups_of[k].bind(chans).full() if chans else []
        up_m, up_v = (ups[:1], ups[1:]) if run_m else ([], ups)
        if k not in smoothed:
            # nothing needs this level: the coarser level carries on
            main = up_m if run_m else main
            var = up_v if run_v else var
            continue
        sm = smoothed[k].result()
        if in_m:
            main = _blend(up_m, sm[:1], lv, sigma, box) if run_m else [sm[0]]
        if in_v:
            assert var_sigma is not None
            var = _blend(up_v, sm[:2], lv, var_sigma, box) if run_v else [sm[0].copy(), sm[1]]
    assert main is not None
    full.bind(main)
    var_out = None
    if var is not None:
        v = _cv.subtract(var[1], _cv.multiply(var[0], var[0]))
        _cv.max(v, 0.0, dst=v)
        v[~levels[v_lo].valid] = 0.0
        var_out = (v_lo, v)
    return full, var_out


def _need_box(lv: _Level, sigmas: list[float]) -> tuple[slice, slice] | None:
    """Bounding box (plus a margin of _BOX_MARGIN cells) of the surface cells of a level where
    some chain of σ in ``sigmas`` has σ_px < s_{k+1}, i.e. still mixes in this level."""
    s_next = _LEVEL_SIGMA * 2 ** (lv.k + 1)
    need = np.zeros(lv.cov.shape, np.uint8)
    for sg in sigmas:
        # σ / pixel_size < s_next  ⇔  ln(pixel_size) > ln(σ / s_next)
        _cv.bitwise_or(
            need, _cv.compare(lv.lps, math.log(sg / s_next) - 0.05, _cv.CMP_GT), dst=need
        )
    _cv.bitwise_and(need, lv.valid_u8 * np.uint8(255), dst=need)
    x, y, w, h = _cv.boundingRect(need)
    if w == 0 or h == 0:
        return (slice(0, 0), slice(0, 0))
    hh, ww = lv.cov.shape
    m = _BOX_MARGIN
    y0, y1, x0, x1 = max(y - m, 0), min(y + h + m, hh), max(x - m, 0), min(x + w + m, ww)
    if (y0, y1, x0, x1) == (0, hh, 0, ww):
        return None
    return slice(y0, y1), slice(x0, x1)


def _blend(
    up: list[Array],
    smooth: list[Array],
    lv: _Level,
    sigma: float,
    box: tuple[slice, slice] | None,
) -> list[Array]:
    """R_k = up + (1 − a_k)(S_k − up) inside ``box`` (S_k given there), up elsewhere."""
    bx = box if box is not None else (slice(None), slice(None))
    a = _alpha(lv, sigma, bx)
    for u, sm in zip(up, smooth, strict=True):
        ub = u[bx]
        # ub = sm + a (ub − sm)
        _cv.scaleAdd(_cv.multiply(_cv.subtract(ub, sm), a), 1.0, sm, dst=ub)
    return up


def _fade(
    sigma: float, surf: _Surface, pixel_size: Array
) -> tuple[tuple[slice, slice], Array] | None:
    """Weight of level 1 against the signal itself where σ_px < s_1: min(σ_px² / s_1², 1)
    (the mix then has the second moment σ_px²), as (box, weight in the box): outside the
    bounding box of the surface pixels with σ_px < s_1 the weight is exactly 1. None where it
    is 1 everywhere."""
    s1 = 2.0 * _LEVEL_SIGMA
    c = sigma / s1  # pixel size at which σ_px = s_1
    if c / surf.ps_max >= 1.0:
        return None
    # (the margin keeps pixels whose weight rounds to just below 1 inside the box)
    far = _cv.compare(pixel_size, c * (1.0 - 1e-5), _cv.CMP_GT)
    box = _crop(_cv.bitwise_and(far, surf.valid, dst=far))
    if box is None:
        return None
    a0 = _cv.divide(c, _cv.max(pixel_size[box], 1e-30))
    _cv.multiply(a0, a0, dst=a0)
    return box, _cv.min(a0, 1.0, dst=a0)


def _normals(normal: Array, shape: tuple[int, int]) -> Array:
    n = np.asarray(normal, dtype=np.float32)
    if n.shape != (*shape, 3):
        raise ValueError(f"normal must have shape {(*shape, 3)}, got {n.shape}")
    return np.ascontiguousarray(n)


def _mask(mask: Array | bool, shape: tuple[int, int]) -> Array:
    m = np.asarray(mask)
    if m.ndim == 0:
        m = np.full(shape, m)
    if m.shape != shape:
        raise ValueError(f"mask must have shape {shape}, got {m.shape}")
    if m.dtype == np.bool_:
        return np.ascontiguousarray(m)
    return np.ascontiguousarray(m, dtype=np.float32)


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
    sig = np.asarray(signal, dtype=np.float32)
    if sig.ndim != 2:
        raise ValueError(f"signal must have shape (H, W), got {sig.shape}")
    shape = (int(sig.shape[0]), int(sig.shape[1]))
    sig = np.ascontiguousarray(sig)
    sigma = POSITIVE.check(sigma_scene, "sigma_scene")
    ds = UNSHARP_SIGMA.check(depth_sigma, "depth_sigma")
    ns = None if normal_sigma is None else UNSHARP_SIGMA.check(normal_sigma, "normal_sigma")
    depth_a = _plane("depth", depth, shape)
    ps = _plane("pixel_size", pixel_size, shape)
    nrm = None if normal is None else _normals(normal, shape)
    valid, ps_range, box, _ = _valid(depth_a, ps, _mask(mask, shape))
    out = sig.copy()
    if box is None:
        return out
    ys, xs = box
    centre = (0.5 * shape[1] - xs.start, 0.5 * shape[0] - ys.start)
    sig_box = sig[box]
    surf, sub, first = _surface(
        depth_a[box],
        ps[box],
        valid[box],
        None if nrm is None else nrm[box],
        ds,
        centre,
        ps_range,
        lambda r, out: np.copyto(out, sig_box[r]),
        False,
    )
    res = _surface_pyramid(surf, sub, first, sigma, None, ns)
    if res is None:
        return out
    full = res[0].full()[0]
    fade = _fade(sigma, surf, ps[box])
    if fade is not None:  # (1 − a0) sub + a0 full, in the box where a0 < 1
        fb, a0 = fade
        fs, ss = full[fb], sub[fb]
        _write(_cv.scaleAdd(_cv.multiply(_cv.subtract(fs, ss), a0), 1.0, ss, dst=fs), full, fb)
    np.copyto(out[box], full, where=surf.valid.view(bool))
    return out


# ---------------------------------------------------------------------------------------------
# operators


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
) -> Array:
    """3D unsharp masking of a rendered image along its surfaces (Ritschel et al. 2008).

    U(L*) = L* + λ_adapt (L*_f − L*_σ)               (§4: U(S) = S + λ C(S), C(S) = S − S_σ)
    λ_adapt = λ · g · α · √(1 + Var(S))                (Eq. 1)
    (L*, a*, b*) → (U, k a*, k b*),  k = U / L*        (§4: hue angle and saturation kept)

    * L*_f is L* itself (``fine_px`` = 0, the paper) or L* averaged over the surface's pixels
      with a Gaussian of ``fine_px`` pixels (:func:`ops.masked.masked_gaussian`): the contrast
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
    gain = None if gain_map is None else _plane("gain_map", gain_map, shape)
    if gain is not None and not _cv.checkRange(gain)[0]:
        raise ValueError("gain_map must be finite everywhere")

    # σ_px < s_1 (pixel size above c_fade): U fades to L* itself (see _fade); the box of those
    # pixels is found with the others
    c_fade = sigma / (2.0 * _LEVEL_SIGMA)
    valid, ps_range, box, fade_box = _valid(depth_a, ps, mask_a, c_fade * (1.0 - 1e-5))
    if box is None:
        return img.copy()
    wl = color.resolve_white(white, img, valid.view(bool))
    # everything below works on the bounding box of the surface (the rest is returned as is)
    ys, xs = box
    sub_shape = (ys.stop - ys.start, xs.stop - xs.start)
    centre = (0.5 * shape[1] - xs.start, 0.5 * shape[0] - ys.start)
    ps = ps[box]
    img_box = img[box]
    light = color.lightness_rows(wl)
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
    res = _surface_pyramid(surf, lum, first, sigma, vsig if adaptive else None, ns)
    cov_a = None if mask_a.dtype == np.bool_ else mask_a[box]
    gain_a = None if gain is None else gain[box]
    if res is None or fade_box is None:
        fade_box = None
    else:  # in the bounding box of the surface
        fy, fx = fade_box
        fade_box = (
            slice(fy.start - ys.start, fy.stop - ys.start),
            slice(fx.start - xs.start, fx.stop - xs.start),
        )
    adapt = None
    if res is not None and res[1] is not None:
        kv, v = res[1]
        a = _cv.sqrt(_cv.addWeighted(v, 1e-4, v, 0.0, 1.0))  # √(1 + Var(L*/100))
        adapt = (a, 2**kv)
    up = None if res is None else res[0]  # None: too small for any level, nothing to smooth
    lam32 = np.float32(lam)
    fine = (
        lum
        if fine_px <= 0.0
        else masked_gaussian(lum, surf.valid, POSITIVE.check(fine_px, "fine_px"))
    )

    def k_rows(r: slice) -> color.KRows:
        """k = max(U, 0) / max(L*, 1e-3) with U = L* + λ_adapt (L* − L*_σ) (§4, Eq. 1), and
        where λ_adapt = 0 (kept bit for bit), for the rows r, in the columns that hold some
        surface (the others are kept whole). L*_σ and √(1 + Var) are upsampled here, strip by
        strip."""
        x, _, n, _ = _cv.boundingRect(surf.valid[r])
        c = slice(x, x + n)
        if n == 0:
            return np.empty((r.stop - r.start, 0), np.float32), None, c
        rc = (r, c)
        valid_r = surf.valid[rc]
        # λ g α: 0 off the surface
        if cov_a is None:
            lam_r = np.multiply(valid_r, lam32, dtype=np.float32)
        else:
            lam_r = _cv.min(_cv.max(cov_a[rc], 0.0), 1.0)
            _cv.multiply(lam_r, valid_r, dst=lam_r, scale=lam, dtype=_cv.CV_32F)
        if gain_a is not None:
            _cv.multiply(lam_r, gain_a[rc], dst=lam_r)
        if fade_box is not None:  # L − ((1 − a0) L + a0 S) = a0 (L − S), a0 = min(σ_px²/s_1², 1)
            fy, fx = fade_box
            y0, y1 = max(r.start, fy.start), min(r.stop, fy.stop)
            x0, x1 = max(c.start, fx.start), min(c.stop, fx.stop)
            if y0 < y1 and x0 < x1:  # (elsewhere on the surface a0 = 1)
                fb = (slice(y0 - r.start, y1 - r.start), slice(x0 - c.start, x1 - c.start))
                a0 = _cv.divide(c_fade, _cv.max(ps[y0:y1, x0:x1], 1e-30))
                _cv.multiply(a0, a0, dst=a0)
                part = lam_r[fb]
                _write(_cv.multiply(part, _cv.min(a0, 1.0, dst=a0), dst=part), lam_r, fb)
        keep_r = _cv.compare(lam_r, 0.0, _cv.CMP_EQ)
        if adapt is not None:  # √(1 + Var)
            lam_r = _cv.multiply(lam_r, _sub_resize(adapt[0], adapt[1], r, c), dst=lam_r)
        lum_r = lum[rc]
        new = lum_r.copy() if up is None else up.rows(r, c)[0]  # L*_σ (a view: written in)
        new = _cv.subtract(fine[rc], new, dst=new)
        new = _cv.multiply(lam_r, new, dst=new)
        new = _cv.add(lum_r, new, dst=new)
        new = _cv.max(new, 0.0, dst=new)
        return _cv.divide(new, _cv.max(lum_r, _L_EPS), dst=new), keep_r, c

    if sub_shape == shape:
        out = color.scale_lab(img_box, k_rows, wl)
    else:
        out = _outside(img, box)
        color.scale_lab(img_box, k_rows, wl, out=out[box])
    # saturated colours can leave the RGB cube below 0 when their lightness drops: clip the
    # changed values (the pixels kept bit for bit are left as they came)
    np.maximum(out, np.float32(0.0), out=out, where=(out < 0) & (out != img))
    return out


def plain_unsharp_mask(
    beauty: Array,
    sigma: float,
    amount: float,
    *,
    white: float | Literal["auto"] = "auto",
    image_height: int | None = None,
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
    """
    img = _rgb("beauty", beauty)
    s = RELATIVE_SIGMA.check(sigma, "sigma")
    lam = UNSHARP_AMOUNT.check(amount, "amount")
    hh = img.shape[0] if image_height is None else int(POSITIVE.check(image_height, "image_height"))
    wl = color.resolve_white(white, img, None)
    lum = _lightness(img, wl)
    smooth = _blur(lum, s * hh)
    new_lum = _cv.scaleAdd(_cv.subtract(lum, smooth), lam, lum)
    return _with_lightness(img, lum, new_lum, wl, None)


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
    delta = _cv.subtract(_blur(dn, s * hh), dn)
    if mode == "darken":
        _cv.min(delta, 0.0, dst=delta)
    wl = color.resolve_white(white, img, valid.view(bool))
    # colour work on the bounding box of the surface only (the rest is returned as is)
    box = _crop(valid)
    assert box is not None
    ys, xs = box
    lum = _lightness(img[box], wl)
    new_lum = _cv.scaleAdd(delta[box], 100.0 * lam, lum)
    keep = _cv.compare(valid[box], 0, _cv.CMP_EQ)
    if (ys.stop - ys.start, xs.stop - xs.start) == shape:
        return _with_lightness(img, lum, new_lum, wl, keep)
    out = _outside(img, box)
    _with_lightness(img[box], lum, new_lum, wl, keep, out=out[box])
    return out
