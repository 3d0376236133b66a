"""The visible surface at full resolution (:class:`_Surface`) and the first level of its pyramid
(:class:`_Level`), formed in one pass over strips of rows."""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from ops import color
from ops.opencv import written
from ops.parallel import STRIP_PIXELS, run_strips, strip_rows
from ops.pyramid.reduce import halve
from ops.unsharp._common import _MIN_LEVEL_SIDE, Array
from ops.unsharp._reduce import (
    cell_average,
    cell_coverage,
    cell_planes,
    masked_rows,
    masked_vectors,
)

_cv: Any = cv2  # OpenCV's stubs reject scalar operands (cv2.max(a, 0.0))


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
        written(v, out, r)
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
        return _box(y0, y1, x0, x1, valid.shape)

    lo, hi = min(f[0] for f in found), max(f[1] for f in found)
    return valid, (lo, hi), union(rects[0]), union(rects[1])


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
    """The bounding box of the surface (None: nothing visible), as :func:`_box` makes it."""
    x, y, w, h = _cv.boundingRect(valid)
    if w == 0 or h == 0:
        return None
    return _box(y, y + h, x, x + w, valid.shape)


def _box(y0: int, y1: int, x0: int, x1: int, shape: tuple[int, ...]) -> tuple[slice, slice]:
    """Rows y0:y1 and columns x0:x1 of an image of ``shape``, widened to 2 where they are 1 and
    the image allows: OpenCV's Python binding takes an array of one element for a scalar, so
    the crop of a single pixel (the one pixel of a surface) would fail its arithmetic. Widening
    a box only adds pixels off the surface, which keep their input."""
    if y1 - y0 < 2 <= shape[0]:
        y0 = min(y0, shape[0] - 2)
        y1 = y0 + 2
    if x1 - x0 < 2 <= shape[1]:
        x0 = min(x0, shape[1] - 2)
        x1 = x0 + 2
    return slice(y0, y1), slice(x0, x1)


@dataclass(frozen=True)
class _Guide:
    """How the depth guide I is made from the depth (see :func:`_surface`)."""

    iz_scale: float  # I = iz_scale · ln z (perspective) or iz_scale · z (orthographic)
    lps_from: tuple[float, float]  # ln(pixel_size) = a · I + b where it is not measured
    focal: float | None  # perspective focal length in pixels (None: orthographic)
    measure_lps: bool  # pixel_size is not z / focal: measure ln(pixel_size)

    @staticmethod
    def of(
        depth: Array,
        pixel_size: Array,
        valid: Array,
        ps_range: tuple[float, float],
        depth_sigma: float,
    ) -> _Guide:
        """The guide of a surface, from every 7th row and column of its pixels (all of them
        where those hold none)."""
        sub_v = valid[::7, ::7].view(bool)
        sub_z = depth[::7, ::7][sub_v]
        sub_ps = pixel_size[::7, ::7][sub_v]
        if sub_z.size == 0:
            vb = valid.view(bool)
            sub_z, sub_ps = depth[vb], pixel_size[vb]
        ps_min, ps_max = ps_range
        if ps_max <= 1.001 * ps_min:  # orthographic: constant footprint
            p0 = float(np.median(sub_ps))
            return _Guide(1.0 / (p0 * depth_sigma), (0.0, math.log(p0)), None, False)
        # perspective: footprint ∝ depth (also the fallback for anything else)
        ratio = sub_z / sub_ps
        f = float(np.median(ratio))
        # not pixel_size = z / f: measure
        measure = float(ratio.max()) > 1.001 * float(ratio.min())
        return _Guide(f / depth_sigma, (depth_sigma / f, -math.log(f)), f, measure)

    def rows(self, depth: Array, valid: Array, out: Array) -> None:
        """I of rows of ``depth`` into ``out`` (0 off the surface, ``valid`` 0)."""
        if self.focal is None:  # 0 off the surface
            masked_rows(depth, valid, 0.0, out)
        else:  # ln 1 = 0 off the surface
            masked_rows(depth, valid, 1.0, out)
            written(_cv.log(out, dst=out), out, slice(None))
        # × iz_scale: OpenCV multiplies by a scalar in double precision (and rounds once), 5x
        # slower than NumPy's float32 product, which is the same number when the factor is a
        # float32 (as f = median(z / pixel_size) is when depth_sigma is 1)
        factor32 = np.float32(self.iz_scale)
        if float(factor32) == self.iz_scale:
            np.multiply(out, factor32, out=out)
        else:
            written(_cv.multiply(out, self.iz_scale, dst=out), out, slice(None))


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
    others: tuple[Array, ...] = (),
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
    averages of the signal, of its square if ``squares`` or else of the ``others`` (signals at
    full resolution, smoothed alike), of I and of the normals, normalised by
    the cell's coverage, and the guide's slopes (``_guide_gradient``); ``_finish_first_level``
    does the rest. Level 1 is None where the image is too small for a level.
    """
    ps_min, ps_max = ps_range  # of pixel_size where valid (from _valid)
    h, w = valid.shape
    guide = _Guide.of(depth, pixel_size, valid, ps_range, depth_sigma)
    iz = np.empty((h, w), np.float32)
    lps = np.empty((h, w), np.float32) if guide.measure_lps else None
    sig = np.empty((h, w), np.float32)
    first = min(h, w) // 2 >= _MIN_LEVEL_SIDE
    hc, wc = (h + 1) // 2, (w + 1) // 2
    nsig = 2 if squares else 1 + len(others)

    def cells() -> Array:
        return np.empty((hc, wc), np.float32)

    cov, iz1 = cells(), cells()
    sig1 = [cells() for _ in range(nsig)]
    lps1 = cells() if guide.measure_lps else None
    nrm1 = None if normal is None else [cells() for _ in range(3)]
    surf = _Surface(
        valid,
        iz,
        lps,
        guide.lps_from,
        normal,
        float(ps_min),
        float(ps_max),
        guide.focal,
        depth_sigma,
        centre,
    )
    step = max(2, (STRIP_PIXELS // max(w, 1)) & ~1)  # even: strips hold whole cells

    def strip(r: slice) -> None:
        r0 = r.start
        v = valid[r]
        iz_r = iz[r]
        guide.rows(depth[r], v, iz_r)
        if lps is not None:
            masked_rows(pixel_size[r], v, 1.0, lps[r])
            written(_cv.log(lps[r], dst=lps[r]), lps, r)
        s_r = sig[r]
        signal(r, s_r)
        if not first:
            return
        # level 1: 2×2 averages (0 off the surface) normalised by the cell's coverage, compiled
        # (ops.unsharp._reduce; the numbers of OpenCV's area halving)
        c = slice(r0 // 2, (r.stop + 1) // 2)
        inv = np.empty((c.stop - c.start, wc), np.float32)
        cell_coverage(v, cov[c], inv)
        cell_average(s_r, v, inv, sig1[0][c])
        if squares:
            cell_average(s_r, v, inv, sig1[1][c], square=True)
        for i, other in enumerate(others, 1):
            cell_average(other[r], v, inv, sig1[i][c])
        cell_average(iz_r, None, inv, iz1[c])
        if lps is not None and lps1 is not None:
            cell_average(lps[r], None, inv, lps1[c])
        if normal is not None and nrm1 is not None:
            # normals off the surface may be anything (0, NaN, a sky's): 0 there, so a partial
            # cell's sum renormalised by its coverage is its surface's (NaN on the surface: 0)
            n3 = halve(masked_vectors(normal[r], v))
            _cv.patchNaNs(n3, 0.0)
            cell_planes(n3, inv, [n[c] for n in nrm1])

    color.row_strips(h, w, strip, step)
    if not first:
        return surf, sig, None
    if lps1 is None:
        a, b = guide.lps_from
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
    The same float32 operations as _plane_slope, in OpenCV where that is faster, on strips of
    rows on every core."""
    nx, ny, nz = nrm
    gx, gy = np.empty(cov.shape, np.float32), np.empty(cov.shape, np.float32)
    scale = np.float32(1.0 / surf.depth_sigma)

    def rows(a: int, b: int) -> None:
        r = slice(a, b)
        if uv is not None:
            den = _cv.subtract(nz[r], _cv.multiply(nx[r], uv[0][r]))
            _cv.subtract(den, _cv.multiply(ny[r], uv[1][r]), dst=den)
        else:
            den = nz[r].copy()
        np.maximum(den, np.float32(0.02), out=den)
        x, y = gx[r], gy[r]
        with np.errstate(invalid="ignore"):
            np.divide(np.multiply(nx[r], scale, out=x), den, out=x)
            np.divide(np.multiply(ny[r], -scale, out=y), den, out=y)
        bad = ~(np.isfinite(x) & np.isfinite(y)) | (cov[r] <= 0.0)
        x[bad] = 0.0
        y[bad] = 0.0

    run_strips(cov.shape[0], rows, strip_rows(cov.shape[1]))
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
