"""Depth-guided multi-scale normals (Mestres et al., "Local Light Alignment for Multi-Scale Shape
Depiction", EG 2021, §5 "Implementation details").

The paper builds S versions of the normal field, n_1 (the input, finest) … n_S (coarsest), "by
successive bilateral filtering operations [BCCS12] … The range kernel is applied on depth values
to preserve the silhouettes of the surface … we increased this size by a factor of 1.7 for each
coarser scale"::

    n_1 = n,    n_{i+1} = normalize( Σ_q G_{σ_i}(p − q) G_r(log d_p − log d_q) n_i(q) )

with σ_i = ``base`` · H · ``factor``^(i−1) pixels (``base`` relative to the image height H) and a
range kernel G_r on **log** depth (standard deviation ``depth_sigma``), i.e. on depth relative to
depth, so that the same parameters work at any scene scale and resolution.

Cost does not grow with the kernel size: scale i is filtered on a depth-aware pyramid, at the
level where σ_i is at most 1.5 pixels (a joint bilateral filter with the circular window of
radius 1 or 2 of ``cv2.ximgproc.jointBilateralFilter`` there, as a compiled kernel), and brought
back to full resolution by edge-aware upsampling:

- downsampling (level k → k+1) averages each 2×2 block over its covered pixels that lie on the
  front-most surface of the block (log depth within ``2·depth_sigma`` of the block's minimum),
  so no low-resolution sample mixes two surfaces across a depth jump;
- upsampling is bilinear (unit-vector fields are 0 on background and renormalised, so next to
  background only covered samples count), except for the pixels whose parent sample is within
  one sample of a depth jump (a log-depth second difference above 2 ``depth_sigma``, or a step
  above 3 ``depth_sigma``) or of a block that lost pixels to another surface: those take the
  bilinear weights times a log-depth range term (joint bilateral upsampling, Kopf et al. 2007),
  or the nearest sample closest in depth when no sample of the footprint is on their surface.

Background pixels (mask false, depth not finite or ≤ 0) never contribute and stay 0.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from ops.checks import FACTOR, LLA_BASE, LLA_DEPTH_SIGMA, SCALES
from ops.jit import kernel
from ops.numerics import exp_neg
from ops.parallel import STRIP_PIXELS, run_strips, strip_rows

F32 = NDArray[np.float32]

#: Spatial σ of the first filter (n_1 → n_2), relative to the image height.
DEFAULT_BASE = 0.005
#: Growth of the spatial σ per scale (the paper's 1.7).
DEFAULT_FACTOR = 1.7
#: Standard deviation of the range kernel on log depth (≈ 3 % relative depth).
DEFAULT_DEPTH_SIGMA = 0.03
#: Default number of scales S (the paper finds 5-7 enough).
DEFAULT_SCALES = 6

# A scale is filtered at the coarsest level where its σ is at most this many pixels.
_MAX_LEVEL_SIGMA = 1.5
# Block members further than this many depth_sigma behind the block's front are left out.
_DOWN_EXCLUDE = 2.0
# A log-depth step between covered neighbouring samples larger than this many depth_sigma is
# treated as a discontinuity by the upsampling even without a second difference.
_STEP = 3.0
# Rows per strip for the strip-parallel helpers.
STRIP_ROWS = 32


def normalize_field(v: np.ndarray, mask: np.ndarray | None = None) -> F32:
    """Unit vectors along the last axis of ``v`` (..., 3); zero vectors stay 0. ``mask``: an
    (H, W) float 0/1 coverage the result is multiplied by."""
    v = np.asarray(v, np.float32)
    if v.ndim == 3 and v.shape[2] == 3 and v.shape[0] * v.shape[1] >= 4096:
        # planes (cv2.split / merge): the same arithmetic without strided or broadcast passes
        x, y, z = cv2.split(v)
        n2 = x * x
        n2 += y * y
        n2 += z * z
        inv = np.zeros_like(n2)
        np.divide(1.0, np.sqrt(n2), out=inv, where=n2 > 1e-20)
        if mask is not None:
            inv *= mask  # 0/1: (v inv) m = v (inv m)
        for plane in (x, y, z):
            plane *= inv
        return np.asarray(cv2.merge([x, y, z]), np.float32)
    n2 = v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1] + v[..., 2] * v[..., 2]
    inv = np.zeros_like(n2)
    np.divide(1.0, np.sqrt(n2), out=inv, where=n2 > 1e-20)
    out = np.asarray(v * inv[..., None], np.float32)
    if mask is not None:
        out *= mask[..., None]
    return out


@kernel
def _gather_unit(idx, w, planes, out):  # type: ignore[no-untyped-def]
    """out[n, c] = Σ_t w[t, n] planes[c][idx[t, n]] (the weighted samples of
    :meth:`DepthPyramid.up_sparse`), then each group of 3 channels renormalised as by
    :func:`normalize_field` (0 where |v|² ≤ 1e-20)."""
    n_ch = out.shape[1]
    for n in range(out.shape[0]):
        for c in range(n_ch):
            plane = planes[c]
            acc = np.float32(0.0)
            for t in range(idx.shape[0]):
                acc += w[t, n] * plane[idx[t, n]]
            out[n, c] = acc
        for c0 in range(0, n_ch - 2, 3):
            x, y, z = out[n, c0], out[n, c0 + 1], out[n, c0 + 2]
            n2 = x * x + y * y + z * z
            inv = np.float32(1.0) / np.sqrt(n2) if n2 > np.float32(1e-20) else np.float32(0.0)
            out[n, c0], out[n, c0 + 1], out[n, c0 + 2] = x * inv, y * inv, z * inv


#: Log depth of background pixels at level 0 is at least this (a finite sentinel, so that
#: products with zero weights stay 0).
BACKGROUND = np.float32(1e30)


_F0 = np.float32(0.0)
_F1 = np.float32(1.0)
_QUARTER = np.float32(0.25)
_INF = np.float32(np.inf)


@kernel
def _block_row(la, lb, thr, front, ka, kb, cover, low, m_low, lost):  # type: ignore[no-untyped-def]
    """One row of 2×2 blocks of :meth:`DepthPyramid._down_geometry` from two rows ``la``,
    ``lb`` of log depth with :data:`BACKGROUND` on background (covered iff below it): the keep
    flags ``ka``, ``kb`` (covered and within ``thr`` of the block's front, i.e. minimum, log
    depth), the kept fraction ``cover``, the kept log-depth mean ``low`` (0 when nothing is
    kept), ``m_low`` = cover > 0 and ``lost`` (a covered member was left out). ``front``: a
    scratch row. One short loop per output: LLVM vectorises a loop only with few runtime alias
    checks, i.e. few arrays written."""
    wh = cover.shape[0]
    for j in range(wh):
        front[j] = min(min(la[2 * j], la[2 * j + 1]), min(lb[2 * j], lb[2 * j + 1]))
    for lr, kr in ((la, ka), (lb, kb)):
        for j in range(wh):
            f = front[j]
            l0, l1 = lr[2 * j], lr[2 * j + 1]
            kr[2 * j] = np.float32((l0 < BACKGROUND) & (l0 - f <= thr))
            kr[2 * j + 1] = np.float32((l1 < BACKGROUND) & (l1 - f <= thr))
    for j in range(wh):
        cover[j] = (ka[2 * j] + ka[2 * j + 1] + kb[2 * j] + kb[2 * j + 1]) * _QUARTER
    for j in range(wh):
        s = la[2 * j] * ka[2 * j] + la[2 * j + 1] * ka[2 * j + 1]
        s += lb[2 * j] * kb[2 * j] + lb[2 * j + 1] * kb[2 * j + 1]
        # covered blocks have cover ≥ 1/4: max(cover, 1/4) leaves them exact, empty ones 0
        low[j] = s * _QUARTER / max(cover[j], _QUARTER)
    for j in range(wh):
        m_low[j] = np.float32(cover[j] > _F0)
    for j in range(wh):
        n_cov = np.float32(la[2 * j] < BACKGROUND) + np.float32(la[2 * j + 1] < BACKGROUND)
        n_cov += np.float32(lb[2 * j] < BACKGROUND) + np.float32(lb[2 * j + 1] < BACKGROUND)
        lost[j] = n_cov > cover[j] * np.float32(4.0)


@kernel
def _build01_rows(depth, mask8, thr, logd0, mask0, keep0, cover, logd1, mask1, excl1):  # type: ignore[no-untyped-def]
    """Levels 0 and 1 of :class:`DepthPyramid` on rows of an even-sized level 0.

    ``depth``: (2 n, W) planar depth; ``mask8``: (2 n, W) uint8 coverage, or (0, W) for none;
    ``logd0``: on input the log of the clamped depth, on output the level-0 log depth with
    :data:`BACKGROUND` on background (depth not finite or ≤ 0, or mask 0); ``mask0``, ``keep0``
    (2 n, W); ``cover``, ``logd1``, ``mask1``, ``excl1`` (n, W / 2): the blocks of
    :func:`_block_row` (``excl1``: a covered pixel was left out).
    """
    wd = depth.shape[1]
    ones = np.ones(wd, np.uint8)
    use_mask = mask8.shape[0] > 0
    front = np.empty(cover.shape[1], np.float32)
    for r in range(depth.shape[0]):
        d, lg = depth[r], logd0[r]
        m = mask8[r] if use_mask else ones
        for x in range(wd):
            dx = d[x]
            valid = (dx > _F0) & (dx < _INF) & (m[x] != 0)
            lg[x] = lg[x] if valid else BACKGROUND
        v_r = mask0[r]
        for x in range(wd):
            v_r[x] = np.float32(lg[x] < BACKGROUND)
    for i in range(cover.shape[0]):
        _block_row(
            logd0[2 * i], logd0[2 * i + 1], thr, front, keep0[2 * i], keep0[2 * i + 1],
            cover[i], logd1[i], mask1[i], excl1[i],
        )  # fmt: skip


@kernel
def _down_geometry_rows(logd, m, excl, thr, keep, cover, logd_low, m_low, excl_low):  # type: ignore[no-untyped-def]
    """Level k → k+1 of :class:`DepthPyramid` (k ≥ 1) on rows of an even-sized (padded)
    level: ``logd``, ``m`` (covered where > 0), ``excl`` (samples excluded below, bool)
    (2 n, w); outputs ``keep`` (2 n, w) and ``cover``, ``logd_low``, ``m_low``, ``excl_low``
    (n, w / 2) as in :func:`_build01_rows` (``excl_low`` also where a member was excluded)."""
    wd = logd.shape[1]
    wh = cover.shape[1]
    far = np.empty((2, wd), np.float32)
    front = np.empty(wh, np.float32)
    for i in range(cover.shape[0]):
        for r in range(2):
            lr, mr, fr = logd[2 * i + r], m[2 * i + r], far[r]
            for x in range(wd):
                fr[x] = lr[x] if mr[x] > _F0 else BACKGROUND
        e_r = excl_low[i]
        _block_row(
            far[0], far[1], thr, front, keep[2 * i], keep[2 * i + 1],
            cover[i], logd_low[i], m_low[i], e_r,
        )  # fmt: skip
        ea, eb = excl[2 * i], excl[2 * i + 1]
        for j in range(wh):
            e_r[j] = e_r[j] | ea[2 * j] | ea[2 * j + 1] | eb[2 * j] | eb[2 * j + 1]


@kernel
def _down_unit_rows(v, keep, out):  # type: ignore[no-untyped-def]
    """``out`` (n, w / 2, 3) = the 2×2 block sums / 4 of ``v`` (2 n, w, 3) weighted by ``keep``
    (2 n, w) (:meth:`DepthPyramid._down_unit`): the keep-weighted sum of each row pair in a
    row buffer, then the sums of column pairs (two short loops that LLVM vectorises)."""
    wh = out.shape[1]
    wd = 2 * wh
    acc = np.empty(3 * wd, np.float32)
    for i in range(out.shape[0]):
        ra, rb = v[2 * i].reshape(3 * wd), v[2 * i + 1].reshape(3 * wd)
        ka, kb = keep[2 * i], keep[2 * i + 1]
        for x in range(wd):
            a, b = ka[x], kb[x]
            p = 3 * x
            acc[p] = a * ra[p] + b * rb[p]
            acc[p + 1] = a * ra[p + 1] + b * rb[p + 1]
            acc[p + 2] = a * ra[p + 2] + b * rb[p + 2]
        o = out[i].reshape(3 * wh)
        for j in range(wh):
            p, q = 6 * j, 3 * j
            o[q] = (acc[p] + acc[p + 3]) * _QUARTER
            o[q + 1] = (acc[p + 1] + acc[p + 4]) * _QUARTER
            o[q + 2] = (acc[p + 2] + acc[p + 5]) * _QUARTER


#: The taps (dy, dx) of the circular 5×5 window (radius 2) of :func:`_jbf_rows`, row by row;
#: a radius-1 window is its 5-tap cross, the other taps getting a spatial weight of 0.
_JBF_TAPS = (
    (-2, 0),
    (-1, -1), (-1, 0), (-1, 1),
    (0, -2), (0, -1), (0, 0), (0, 1), (0, 2),
    (1, -1), (1, 0), (1, 1),
    (2, 0),
)  # fmt: skip
#: Columns per chunk of :func:`_jbf_rows` (its local buffers have this compile-time row length).
_JBF_CHUNK = 128
_JBF_RS = _JBF_CHUNK + 4


@kernel
def _jb_tap(gc, g, x, y, z, j, sw, c, ax, ay, az):  # type: ignore[no-untyped-def]
    """(ax, ay, az) plus tap j of guide row ``g`` and planes ``x``, ``y``, ``z``: spatial
    weight ``sw`` times the range weight e^{−c (g[j] − gc)²}."""
    d = g[j] - gc
    wt = sw * exp_neg(d * d * c)
    return ax + wt * x[j], ay + wt * y[j], az + wt * z[j]


@kernel
def _jb_planes(b, r, dx):  # type: ignore[no-untyped-def]
    """Guide and x, y, z rows of window row ``r`` in the chunk buffer ``b`` of
    :func:`_jbf_rows`, from column 2 + ``dx`` on."""
    o = 4 * r * _JBF_RS + 2 + dx
    return b[o:], b[o + _JBF_RS :], b[o + 2 * _JBF_RS :], b[o + 3 * _JBF_RS :]


@kernel
def _jbf_rows(guide, src, mask, sw, c, out):  # type: ignore[no-untyped-def]
    """Joint bilateral filter of a unit-vector field on rows, window of radius ≤ 2
    (:func:`_bilateral`), renormalised and times the coverage as by :func:`normalize_field`.

    ``guide``: (n + 4, w + 4) log depth padded by 2 on each side; ``src``: (n + 4, 3 (w + 4))
    the field, padded the same and flattened per row; ``mask``: (n, w) coverage; ``sw``: (13,)
    spatial weights of :data:`_JBF_TAPS`; ``c`` = 1 / (2 σ_r²); ``out``: (n, 3 w).

    Chunks of :data:`_JBF_CHUNK` columns of the 5 window rows are first copied, as guide and
    x, y, z planes, into one local buffer of fixed row length: the 13 taps then read rows of a
    single array at constant distances, which LLVM vectorises without runtime alias checks or
    index-wrap assumptions (with one view per input row it does not).
    """
    wd = mask.shape[1]
    w0, w1, w2, w3, w4, w5, w6, w7, w8, w9, w10, w11, w12 = (
        sw[0], sw[1], sw[2], sw[3], sw[4], sw[5], sw[6],
        sw[7], sw[8], sw[9], sw[10], sw[11], sw[12],
    )  # fmt: skip
    tiny = np.float32(1e-20)
    rs, ch = _JBF_RS, _JBF_CHUNK
    b = np.zeros(21 * rs, np.float32)  # 5 rows × (guide, x, y, z), then the mask
    ob = np.zeros(3 * ch, np.float32)
    ox, oy, oz = ob[:ch], ob[ch : 2 * ch], ob[2 * ch :]
    bm = b[20 * rs :]
    for i in range(mask.shape[0]):
        for j0 in range(0, wd, ch):
            n = min(ch, wd - j0)
            for r in range(5):
                gr = guide[i + r][j0 : j0 + n + 4]
                sr = src[i + r][3 * j0 : 3 * (j0 + n + 4)]
                bg, bx = b[4 * r * rs :], b[(4 * r + 1) * rs :]
                by, bz = b[(4 * r + 2) * rs :], b[(4 * r + 3) * rs :]
                for x in range(n + 4):
                    bg[x] = gr[x]
                for x in range(n + 4):
                    bx[x], by[x], bz[x] = sr[3 * x], sr[3 * x + 1], sr[3 * x + 2]
            mr = mask[i][j0 : j0 + n]
            for x in range(n):
                bm[x] = mr[x]
            g0, x0, y0, z0 = _jb_planes(b, 0, 0)
            g1, x1, y1, z1 = _jb_planes(b, 1, -1)
            g2, x2, y2, z2 = _jb_planes(b, 1, 0)
            g3, x3, y3, z3 = _jb_planes(b, 1, 1)
            g4, x4, y4, z4 = _jb_planes(b, 2, -2)
            g5, x5, y5, z5 = _jb_planes(b, 2, -1)
            g6, x6, y6, z6 = _jb_planes(b, 2, 0)
            g7, x7, y7, z7 = _jb_planes(b, 2, 1)
            g8, x8, y8, z8 = _jb_planes(b, 2, 2)
            g9, x9, y9, z9 = _jb_planes(b, 3, -1)
            g10, x10, y10, z10 = _jb_planes(b, 3, 0)
            g11, x11, y11, z11 = _jb_planes(b, 3, 1)
            g12, x12, y12, z12 = _jb_planes(b, 4, 0)
            for j in range(n):
                gc = g6[j]
                ax, ay, az = w6 * x6[j], w6 * y6[j], w6 * z6[j]
                ax, ay, az = _jb_tap(gc, g0, x0, y0, z0, j, w0, c, ax, ay, az)
                ax, ay, az = _jb_tap(gc, g1, x1, y1, z1, j, w1, c, ax, ay, az)
                ax, ay, az = _jb_tap(gc, g2, x2, y2, z2, j, w2, c, ax, ay, az)
                ax, ay, az = _jb_tap(gc, g3, x3, y3, z3, j, w3, c, ax, ay, az)
                ax, ay, az = _jb_tap(gc, g4, x4, y4, z4, j, w4, c, ax, ay, az)
                ax, ay, az = _jb_tap(gc, g5, x5, y5, z5, j, w5, c, ax, ay, az)
                ax, ay, az = _jb_tap(gc, g7, x7, y7, z7, j, w7, c, ax, ay, az)
                ax, ay, az = _jb_tap(gc, g8, x8, y8, z8, j, w8, c, ax, ay, az)
                ax, ay, az = _jb_tap(gc, g9, x9, y9, z9, j, w9, c, ax, ay, az)
                ax, ay, az = _jb_tap(gc, g10, x10, y10, z10, j, w10, c, ax, ay, az)
                ax, ay, az = _jb_tap(gc, g11, x11, y11, z11, j, w11, c, ax, ay, az)
                ax, ay, az = _jb_tap(gc, g12, x12, y12, z12, j, w12, c, ax, ay, az)
                n2 = ax * ax + ay * ay + az * az
                inv = bm[j] / np.sqrt(n2) if n2 > tiny else _F0
                ox[j], oy[j], oz[j] = ax * inv, ay * inv, az * inv
            o = out[i][3 * j0 : 3 * (j0 + n)]
            for j in range(n):
                o[3 * j], o[3 * j + 1], o[3 * j + 2] = ox[j], oy[j], oz[j]


def _log_depth(depth: F32, mask: np.ndarray | None, out: F32 | None = None) -> F32:
    """Log depth with background (mask 0, depth not finite or ≤ 0) pushed to ≥ BACKGROUND,
    by arithmetic only (masked writes cost ~8 ms at 1080p; cv2.log is slow on +inf, so clamp
    first; fmin maps NaN to 1e30)."""
    clamped = np.fmin(depth, BACKGROUND)  # NaN, +inf -> 1e30
    np.fmax(clamped, np.float32(1e-30), out=clamped)
    logd = cv2.log(clamped)
    invalid = ~((depth > 0) & (depth < np.inf))
    if mask is not None:
        invalid |= ~(mask > 0)
    if out is None:
        return np.asarray(cv2.scaleAdd(invalid.astype(np.float32), float(BACKGROUND), logd))
    cv2.scaleAdd(invalid.astype(np.float32), float(BACKGROUND), logd, out)
    return out


@dataclass
class DepthPyramid:
    """Log depth and coverage at pyramid levels 0 (input) … K, each level half the previous.

    Attributes
    ----------
    depth_sigma : standard deviation of the range kernel on log depth.
    logd : per level (h_k, w_k) log depth; background is ≥ :data:`BACKGROUND` at level 0 and 0
        at coarser levels.
    mask : per level (h_k, w_k) float32 coverage, 1 on surfaces, 0 on background.
    keep : per level k < K, (h_k, w_k) float32 weight of each pixel in the 2×2 block sums that
        make level k+1 (1 for covered pixels on the block's front surface, else 0).
    cover : per level k ≥ 1, (h_k, w_k) fraction of the level-(k−1) block that was kept.
    """

    depth_sigma: float
    logd: list[F32] = field(default_factory=list)
    mask: list[F32] = field(default_factory=list)
    keep: list[F32] = field(default_factory=list)
    cover: list[F32] = field(default_factory=list)
    _keep3: dict[int, F32] = field(default_factory=dict, repr=False)
    _masks: dict[int, np.ndarray] = field(default_factory=dict, repr=False)

    @classmethod
    def build(
        cls, depth: np.ndarray, mask: np.ndarray | None, levels: int, depth_sigma: float
    ) -> DepthPyramid:
        """Pyramid of ``levels + 1`` levels from planar depth and an optional coverage mask.

        Background: mask 0/False, depth not finite (+inf, NaN) or ≤ 0.
        """
        depth = np.asarray(depth, np.float32)
        if depth.ndim != 2:
            raise ValueError(f"depth must be (H, W), got shape {depth.shape}")
        if mask is not None:
            mask = np.asarray(mask)
            if mask.shape != depth.shape:
                raise ValueError(
                    f"mask must have the depth's shape {depth.shape}, got {mask.shape}"
                )
        pyr = cls(depth_sigma=depth_sigma)
        h, w = depth.shape
        if levels >= 1 and h % 2 == 0 and w % 2 == 0:
            pyr._build_01(depth, mask)  # levels 0 and 1 in one pass of row strips
        else:
            logd = _log_depth(depth, mask)
            pyr.logd.append(logd)
            pyr.mask.append(np.asarray(logd < BACKGROUND, np.float32))
        for _ in range(levels - pyr.levels):
            low, m = pyr._down_geometry(pyr.logd[-1], pyr.mask[-1])
            pyr.logd.append(low)
            pyr.mask.append(m)
        return pyr

    def _build_01(self, depth: F32, mask: np.ndarray | None) -> None:
        """Levels 0 and 1 (even-sized level 0), strip by strip on all cores: the same per-pixel
        and per-block arithmetic as :func:`_log_depth` and :meth:`_down_geometry`, in one
        compiled pass (:func:`_build01_rows`) after the log of the clamped depth (cv2.log is
        slow on +inf), with the level-1 samples that lost pixels to another surface
        (:meth:`_excluded`)."""
        h, w = depth.shape
        depth = np.ascontiguousarray(depth)
        logd0 = np.empty((h, w), np.float32)
        mask0 = np.empty((h, w), np.float32)
        keep0 = np.empty((h, w), np.float32)
        cover0 = np.empty((h // 2, w // 2), np.float32)
        logd1 = np.empty((h // 2, w // 2), np.float32)
        mask1 = np.empty((h // 2, w // 2), np.float32)
        excl1 = np.empty((h // 2, w // 2), np.bool_)
        thr = np.float32(_DOWN_EXCLUDE * self.depth_sigma)
        no_mask = np.zeros((0, w), np.uint8)
        mask8 = None
        if mask is not None and mask.dtype == np.bool_:
            mask8 = np.ascontiguousarray(mask).view(np.uint8)

        def strip(b0: int, b1: int) -> None:  # level-1 rows b0:b1, level-0 rows 2 b0:2 b1
            r0, r1 = 2 * b0, 2 * b1
            d = depth[r0:r1]
            far = logd0[r0:r1]
            clamped = cv2.min(d, float(BACKGROUND))  # type: ignore[call-overload]
            cv2.max(clamped, 1e-30, clamped)  # type: ignore[call-overload]
            cv2.log(clamped, far)
            if mask is None:
                m8 = no_mask
            elif mask8 is not None:
                m8 = mask8[r0:r1]
            else:
                m8 = np.asarray(mask[r0:r1] > 0).view(np.uint8)
            _build01_rows(
                d, m8, thr, far, mask0[r0:r1], keep0[r0:r1],
                cover0[b0:b1], logd1[b0:b1], mask1[b0:b1], excl1[b0:b1],
            )  # fmt: skip

        run_strips(h // 2, strip, rows=max(1, strip_rows(w) // 2))
        self.logd += [logd0, logd1]
        self.mask += [mask0, mask1]
        self.keep.append(keep0)
        self.cover.append(cover0)
        self._masks[1001] = excl1

    def _down_geometry(self, logd: F32, m: F32) -> tuple[F32, F32]:
        """Level k + 1 from level k = ``self.levels`` (log depth ``logd``, coverage ``m``):
        the front-surface block means of :func:`_down_geometry_rows` (odd sizes padded with
        background), appending level k's ``keep`` and level k + 1's ``cover`` and excluded
        samples (:meth:`_excluded`). Returns level k + 1's log depth and coverage."""
        k = self.levels
        h, w = logd.shape
        ph, pw = h + (h & 1), w + (w & 1)
        excl = self._excluded(k)
        logd = np.ascontiguousarray(logd, np.float32)
        m = np.ascontiguousarray(m, np.float32)
        if (ph, pw) != (h, w):
            pad = ((0, ph - h), (0, pw - w))
            logd, m, excl = np.pad(logd, pad), np.pad(m, pad), np.pad(excl, pad)
        keep = np.empty((ph, pw), np.float32)
        cover = np.empty((ph // 2, pw // 2), np.float32)
        l_low = np.empty((ph // 2, pw // 2), np.float32)
        m_low = np.empty((ph // 2, pw // 2), np.float32)
        excl_low = np.empty((ph // 2, pw // 2), np.bool_)
        thr = np.float32(_DOWN_EXCLUDE * self.depth_sigma)

        def strip(b0: int, b1: int) -> None:
            r0, r1 = 2 * b0, 2 * b1
            _down_geometry_rows(
                logd[r0:r1], m[r0:r1], excl[r0:r1], thr, keep[r0:r1],
                cover[b0:b1], l_low[b0:b1], m_low[b0:b1], excl_low[b0:b1],
            )  # fmt: skip

        run_strips(ph // 2, strip, rows=max(1, strip_rows(pw) // 2))
        self.keep.append(keep if (ph, pw) == (h, w) else np.ascontiguousarray(keep[:h, :w]))
        self.cover.append(cover)
        self._masks[1000 + k + 1] = excl_low
        return l_low, m_low

    def _weighted(self, v: F32, lvl: int) -> F32:
        keep = self.keep[lvl]
        if v.ndim == 3 and v.shape[2] == 3:
            k3 = self._keep3.get(lvl)
            if k3 is None:
                k3 = self._keep3[lvl] = np.asarray(cv2.merge([keep, keep, keep]), np.float32)
            return np.asarray(cv2.multiply(v, k3), np.float32)
        return np.asarray(v * (keep[..., None] if v.ndim == 3 else keep), np.float32)

    def down(self, values: np.ndarray, k: int, k_to: int, unit: bool = True) -> F32:
        """Front-surface block averages of ``values`` (h_k, w_k[, C]) from level k to k_to.

        Each level-``k_to`` value averages the covered level-k pixels of its block that are on
        the block's front surface (every full-resolution pixel counts once). ``unit``: the values
        are a unit-vector field (C = 3), renormalised instead of divided by the weights.
        """
        v = np.asarray(values, np.float32)
        if k_to <= k:
            return v
        is_unit = unit and v.ndim == 3 and v.shape[2] == 3
        wsum: F32 | None = None
        for lvl in range(k, k_to):
            h, w = self.shape(lvl)
            ph, pw = h + (h & 1), w + (w & 1)
            if is_unit and (ph, pw) == (h, w) and v.flags.c_contiguous:
                v = self._down_unit(v, lvl)
                continue
            vw = self._weighted(v, lvl)
            wk = self.keep[lvl] if wsum is None else self.keep[lvl] * wsum
            if (ph, pw) != (h, w):
                pad = ((0, ph - h), (0, pw - w))
                vw = np.pad(vw, pad + (((0, 0),) if vw.ndim == 3 else ()))
                wk = np.pad(wk, pad)
            v = np.asarray(cv2.resize(vw, (pw // 2, ph // 2), interpolation=cv2.INTER_AREA))
            if not is_unit:
                wsum = np.asarray(cv2.resize(wk, (pw // 2, ph // 2), interpolation=cv2.INTER_AREA))
        if is_unit:
            return normalize_field(v, self.mask[k_to])
        assert wsum is not None
        inv = np.zeros_like(wsum)
        np.divide(1.0, wsum, out=inv, where=wsum > 0)
        return np.asarray(v * (inv[..., None] if v.ndim == 3 else inv), np.float32)

    def _down_unit(self, v: F32, lvl: int) -> F32:
        """Block sums / 4 of a unit-vector field (even-sized level, C-contiguous) weighted by
        ``keep``, strip-parallel (:func:`_down_unit_rows`); blocks without kept pixels are 0."""
        h, w = self.shape(lvl)
        out = np.empty((h // 2, w // 2, 3), np.float32)
        keep = self.keep[lvl]

        def strip(b0: int, b1: int) -> None:
            _down_unit_rows(v[2 * b0 : 2 * b1], keep[2 * b0 : 2 * b1], out[b0:b1])

        run_strips(h // 2, strip, rows=max(1, strip_rows(w) // 2))
        return out

    @property
    def levels(self) -> int:
        return len(self.logd) - 1

    def shape(self, k: int) -> tuple[int, int]:
        return (int(self.logd[k].shape[0]), int(self.logd[k].shape[1]))

    def up(self, values: np.ndarray, k: int, k_to: int = 0) -> F32:
        """Edge-aware upsampling of unit-vector fields (h_k, w_k, 3n), 0 on background, from
        level k to level ``k_to``: bilinear, except near depth jumps and where a block lost
        pixels to another surface, where the joint bilateral weights of :meth:`_jb_weights`
        apply (Kopf et al. 2007; :meth:`up_sparse`); then renormalised, background 0.
        Strip-parallel."""
        vals = np.asarray(values, np.float32)
        if k == k_to:
            return vals
        planes_k = [np.ascontiguousarray(vals[..., c]) for c in range(vals.shape[2])]
        sparse = self.up_sparse(planes_k, k, k_to)
        h_to, w_to = self.shape(k_to)
        out = np.empty((h_to, w_to, len(planes_k)), np.float32)
        m_to = self.mask[k_to]

        def strip(r0: int, r1: int) -> None:
            bufs: dict[str, F32] = {}

            def buf(name: str, shape: tuple[int, ...]) -> F32:
                got = bufs[name] = np.empty(shape, np.float32)
                return got

            planes = self.up_rows(planes_k, k, (r0, r1), buf, sparse, k_to)
            mrows = m_to[r0:r1]
            for c0 in range(0, len(planes) - 2, 3):
                x, y, z = planes[c0 : c0 + 3]
                n2 = x * x + y * y + z * z
                scale = np.zeros_like(n2)
                np.divide(mrows, np.sqrt(n2), out=scale, where=n2 > 1e-20)
                for plane in (x, y, z):
                    plane *= scale
            cv2.merge(planes, out[r0:r1])

        run_strips(h_to, strip, STRIP_ROWS)
        return out

    def _jumps(self, k: int) -> NDArray[np.bool_]:
        """(h_k, w_k): the samples of level k next to a depth jump (cached).

        A sample is next to a depth jump when the second difference of log depth along x or y,
        taken where both neighbours are covered, exceeds 2 ``depth_sigma`` (a slope does not
        produce one), or when the step to a covered 4-neighbour exceeds 3 ``depth_sigma``
        (steeper than most slopes; catches jumps where the other side is background, and
        coarse levels where an object is one or two samples wide). Background samples are not
        jumps: unit-vector fields are 0 there, so bilinear interpolation followed by
        renormalisation averages the covered samples only.
        """
        key = 3000 + k
        got = self._masks.get(key)
        if got is not None:
            return got
        logd, m = self.logd[k], self.mask[k] > 0
        lp = np.pad(logd, 1, mode="edge")
        mp = np.pad(m, 1, mode="constant")
        tau = np.float32(2.0 * self.depth_sigma)
        jump = (np.abs(lp[1:-1, :-2] + lp[1:-1, 2:] - 2.0 * logd) > tau) & mp[1:-1, :-2]
        jump &= mp[1:-1, 2:]
        jy = (np.abs(lp[:-2, 1:-1] + lp[2:, 1:-1] - 2.0 * logd) > tau) & mp[:-2, 1:-1]
        jump |= jy & mp[2:, 1:-1]
        # steps to a covered neighbour larger than a steep slope makes (e.g. at a sample with
        # background on the other side, where there is no second difference)
        step = np.float32(_STEP * self.depth_sigma)
        sx = (np.abs(logd[:, 1:] - logd[:, :-1]) > step) & m[:, 1:] & m[:, :-1]
        jump[:, 1:] |= sx
        jump[:, :-1] |= sx
        sy = (np.abs(logd[1:] - logd[:-1]) > step) & m[1:] & m[:-1]
        jump[1:] |= sy
        jump[:-1] |= sy
        jump &= m
        self._masks[key] = jump
        return jump

    def _excluded(self, k: int) -> NDArray[np.bool_]:
        """(h_k, w_k): samples of level k whose blocks lost a covered level-0 pixel to the
        front-surface selection of some level below (a surface not represented there); made
        with each level by :meth:`_down_geometry` (cached), else from the level below."""
        key = 1000 + k
        got = self._masks.get(key)
        if got is not None:
            return got
        if k == 0:
            out = np.zeros(self.shape(0), np.bool_)
        else:
            below = self._excluded(k - 1).astype(np.float32)
            below += self.mask[k - 1] - self.keep[k - 1]  # covered but not kept
            h, w = below.shape
            ph, pw = h + (h & 1), w + (w & 1)
            if (ph, pw) != (h, w):
                below = np.pad(below, ((0, ph - h), (0, pw - w)))
            out = cv2.resize(below, (pw // 2, ph // 2), interpolation=cv2.INTER_AREA) > 0
        self._masks[key] = out
        return out

    def _dirty(self, k: int) -> NDArray[np.uint8]:
        """(h_k, w_k) uint8: 1 where a pixel whose parent is this sample may have a bilinear
        footprint that is not all on its own surface: within one sample of a depth jump
        (:meth:`_jumps`) or of a sample that lost pixels to another surface."""
        key = 2000 + k
        got = self._masks.get(key)
        if got is not None:
            return got
        unsafe = self._jumps(k) | self._excluded(k)
        out = np.asarray(cv2.dilate(unsafe.astype(np.uint8), np.ones((3, 3), np.uint8)), np.uint8)
        self._masks[key] = out
        return out

    def up_sparse(
        self, planes_k: Sequence[np.ndarray], k: int, k_to: int = 0
    ) -> tuple[NDArray[np.int64], NDArray[np.int64], F32]:
        """The joint bilateral part of :meth:`up_rows` for a whole level: the level-``k_to``
        pixels whose parent sample is within one sample of a depth jump or of a block that lost
        pixels to another surface (:meth:`_dirty`, a sparse set), and their values from the
        level-k ``planes_k`` (unit-vector fields, 3 planes each) by the weights of
        :meth:`_jb_weights` (bilinear where the footprint is on the pixel's own surface), each
        vector renormalised. Returns (ys, xs, values (N, C)), sorted by row."""
        n_ch = len(planes_k)
        h_to, w_to = self.shape(k_to)
        f = 1 << (k - k_to)
        w_k = self.shape(k)[1]
        dirty = np.flatnonzero(self._dirty(k))
        empty = np.zeros(0, np.int64)
        if not dirty.size:
            return empty, empty, np.zeros((0, n_ch), np.float32)
        py, px = np.divmod(dirty, w_k)
        off = np.arange(f)
        ys = (py * f)[:, None, None] + off[None, :, None]
        xs = (px * f)[:, None, None] + off[None, None, :]
        ys, xs = (arr.reshape(-1) for arr in np.broadcast_arrays(ys, xs))
        inside = (ys < h_to) & (xs < w_to)
        ys, xs = ys[inside], xs[inside]
        covered = self.mask[k_to][ys, xs] > 0
        ys, xs = ys[covered], xs[covered]
        order = np.argsort(ys, kind="stable")
        ys, xs = ys[order], xs[order]
        if not ys.size:
            return empty, empty, np.zeros((0, n_ch), np.float32)
        idx, w = self._jb_weights(k, f, ys, xs, self.logd[k_to][ys, xs])
        acc = np.empty((ys.size, n_ch), np.float32)
        flat = tuple(np.ascontiguousarray(plane, np.float32).reshape(-1) for plane in planes_k)
        _gather_unit(idx, np.ascontiguousarray(w, np.float32), flat, acc)
        return ys, xs, acc

    def up_rows(
        self,
        planes_k: Sequence[np.ndarray],
        k: int,
        rows: tuple[int, int],
        buf: Callable[[str, tuple[int, ...]], F32],
        sparse: tuple[np.ndarray, np.ndarray, np.ndarray],
        k_to: int = 0,
        cols: tuple[int, int] | None = None,
    ) -> list[F32]:
        """Rows ``rows`` of level-k unit-vector fields, given as (h_k, w_k) planes (0 on
        background), upsampled to level ``k_to`` edge-aware, as planes in scratch buffers
        ``buf(name, shape)`` (for strip-parallel callers): bilinear, then the pixels of
        ``sparse`` (:meth:`up_sparse`) overwritten. The bilinear results are not renormalised
        (bilinear shortens unit vectors slightly, and to 0 … 1 next to background): callers
        renormalise. ``cols``: only these columns. Returns one (r1 − r0, x1 − x0) plane per
        channel (views into the buffers); :meth:`up_rows_wide` gives the uncropped rows.
        """
        x0, x1 = (0, self.shape(k_to)[1]) if cols is None else cols
        planes, c = self.up_rows_wide(planes_k, k, rows, buf, sparse, k_to, (x0, x1))
        return [plane[:, c : c + x1 - x0] for plane in planes]

    def up_rows_wide(
        self,
        planes_k: Sequence[np.ndarray],
        k: int,
        rows: tuple[int, int],
        buf: Callable[[str, tuple[int, ...]], F32],
        sparse: tuple[np.ndarray, np.ndarray, np.ndarray],
        k_to: int = 0,
        cols: tuple[int, int] | None = None,
    ) -> tuple[list[F32], int]:
        """:meth:`up_rows` with the columns left uncropped: returns C-contiguous planes of
        rows ``rows`` that hold columns ``cols`` from column offset ``c`` on, and ``c``
        (column x0 + j of the window is column c + j of each plane)."""
        r0, r1 = rows
        x0, x1 = (0, self.shape(k_to)[1]) if cols is None else cols
        f = 1 << (k - k_to)
        h_k, w_k = self.shape(k)
        s0 = max(0, math.floor((r0 + 0.5) / f - 0.5))
        s1 = min(h_k, math.floor((r1 - 0.5) / f - 0.5) + 2)
        t0 = max(0, math.floor((x0 + 0.5) / f - 0.5))
        t1 = min(w_k, math.floor((x1 - 0.5) / f - 0.5) + 2)
        size = ((t1 - t0) * f, (s1 - s0) * f)
        a, b = r0 - s0 * f, r1 - s0 * f
        c = x0 - t0 * f
        n_ch, n = len(planes_k), s1 - s0
        planes: list[F32]
        stack: F32 | None = None
        if n_ch > 1 and s0 > 0 and s1 < h_k:
            # the blocks of all planes one above the other, in one resize (a resize call costs
            # ~10 µs more than its pixels): the rows used never reach a block's edge (away from
            # the image's top and bottom, where the resize clamps), so no row mixes two planes
            src = buf(f"upsrc:{k}", (n_ch * n, t1 - t0))
            for ch, plane in enumerate(planes_k):
                src[ch * n : (ch + 1) * n] = plane[s0:s1, t0:t1]
            dst = buf(f"up:{k}", (n_ch * size[1], size[0]))
            cv2.resize(src, (size[0], n_ch * size[1]), dst, interpolation=cv2.INTER_LINEAR)
            stack = dst.reshape(n_ch, size[1], size[0])[:, a:b]
            planes = list(stack)
        else:
            planes = []
            for ch, plane in enumerate(planes_k):
                dst = buf(f"up:{k}:{ch}", (size[1], size[0]))
                cv2.resize(plane[s0:s1, t0:t1], size, dst, interpolation=cv2.INTER_LINEAR)
                planes.append(dst[a:b])
        ys, xs, vals = sparse
        i0, i1 = np.searchsorted(ys, [r0, r1])
        if i1 > i0:
            yy, xx, vv = ys[i0:i1] - r0, xs[i0:i1] - x0, vals[i0:i1]
            inside = (xx >= 0) & (xx < x1 - x0)
            yy, xx, vv = yy[inside], xx[inside] + c, vv[inside]
            if stack is not None:
                stack[:, yy, xx] = vv.T
            else:
                for ch, plane in enumerate(planes):
                    plane[yy, xx] = vv[:, ch]
        return planes, c

    def _jb_weights(
        self, k: int, f: int, ys: np.ndarray, xs: np.ndarray, logd: np.ndarray
    ) -> tuple[NDArray[np.int64], F32]:
        """Joint bilateral upsampling weights (Kopf et al. 2007) of level-k samples for the
        level-(k − log2 f) pixels (ys, xs) of log depth ``logd``: the bilinear (tent) weights of
        the 2×2 footprint times a range term of the log-depth difference Δ over covered
        samples, exp(−max(|Δ| − 2σ, 0)² / 2σ²) with σ = ``depth_sigma``, renormalised — plain
        bilinear where all four are on the pixel's surface. Where none is, the 3×3 nearest
        samples with a Gaussian spatial weight (σ one sample) and a softmax on the depth term,
        so the sample closest in depth wins.
        Returns flat sample indices and weights, (9, N).
        """
        h_k, w_k = self.shape(k)
        sy = (ys.astype(np.float32) + 0.5) / f - 0.5
        sx = (xs.astype(np.float32) + 0.5) / f - 0.5
        cy = np.rint(sy).astype(np.int64)
        cx = np.rint(sx).astype(np.int64)
        offs = np.array([-1, 0, 1], np.int64)
        uy = cy[None, :] + offs[:, None]  # (3, N), unclipped
        ux = cx[None, :] + offs[:, None]
        ny = np.minimum(np.maximum(uy, 0), h_k - 1)
        nx = np.minimum(np.maximum(ux, 0), w_k - 1)
        idx = (ny[:, None, :] * w_k + nx[None, :, :]).reshape(9, -1)
        ddy, ddx = np.abs(uy - sy), np.abs(ux - sx)
        tent = np.maximum(1.0 - ddy, 0.0)[:, None, :] * np.maximum(1.0 - ddx, 0.0)[None, :, :]
        spatial = (ddy[:, None, :] ** 2 + ddx[None, :, :] ** 2).reshape(9, -1)
        # range term flat within 2 depth_sigma (samples of the pixel's own surface keep their
        # bilinear weights, as next to background), Gaussian beyond
        dl = np.abs(self.logd[k].reshape(-1)[idx] - logd)
        dl = np.maximum(dl - np.float32(2.0 * self.depth_sigma), np.float32(0.0))
        inv_r = np.float32(0.5 / (self.depth_sigma * self.depth_sigma))
        range_log = -inv_r * dl * dl
        covered = self.mask[k].reshape(-1)[idx] > 0
        range_log[~covered] = -np.inf
        wts = (tent.reshape(9, -1) * np.exp(range_log)).astype(np.float32)
        total = wts.sum(axis=0)
        far = total < 1e-4
        if np.any(far):
            logw = np.float32(-0.5) * spatial[:, far] + range_log[:, far]
            logw -= logw.max(axis=0, keepdims=True)
            wts[:, far] = np.exp(logw)
            total[far] = wts[:, far].sum(axis=0)
        wts /= total
        return idx, wts


@dataclass
class NormalPyramid:
    """Multi-scale normals n_1 … n_S, each stored at the pyramid level it was filtered at.

    Attributes
    ----------
    geometry : the :class:`DepthPyramid` (log depth and coverage per level).
    normals : n_i (0-based list) at level ``levels[i]``, (h, w, 3) float32, unit, 0 on background.
    levels : pyramid level of each n_i (n_1 at level 0).
    sigmas_px : spatial σ (full-resolution pixels) of each filter n_i → n_{i+1}.
    """

    geometry: DepthPyramid
    normals: list[F32]
    levels: list[int]
    sigmas_px: list[float]
    _planes: dict[int, tuple[F32, F32, F32]] = field(default_factory=dict, repr=False)

    def planes(self, i: int) -> tuple[F32, F32, F32]:
        """n_{i+1} (0-based ``i``) at its level as three (h, w) planes (cached)."""
        got = self._planes.get(i)
        if got is None:
            x, y, z = (np.asarray(c, np.float32) for c in cv2.split(self.normals[i]))
            got = self._planes[i] = (x, y, z)
        return got

    @property
    def scales(self) -> int:
        return len(self.normals)

    @property
    def shape(self) -> tuple[int, int]:
        return self.geometry.shape(0)

    @property
    def mask(self) -> np.ndarray:
        """(H, W) bool coverage."""
        return self.geometry.mask[0] > 0

    def at(self, i: int, k: int, rows: tuple[int, int] | None = None) -> F32:
        """n_{i+1} (0-based ``i``) at pyramid level ``k`` (edge-aware up- or downsampled)."""
        lvl = self.levels[i]
        out = (
            self.geometry.down(self.normals[i], lvl, k)
            if k >= lvl
            else self.geometry.up(self.normals[i], lvl, k)
        )
        return out if rows is None else out[rows[0] : rows[1]]

    def full(self, i: int) -> F32:
        """n_{i+1} (0-based ``i``) at full resolution, unit length, 0 on background."""
        return self.at(i, 0)

    def full_list(self) -> list[F32]:
        """[n_1, …, n_S] at full resolution."""
        return [self.full(i) for i in range(self.scales)]


def scale_sigmas_px(height: int, scales: int, base: float, factor: float) -> list[float]:
    """σ_i = base · H · factor^(i−1), i = 1 … S−1, in pixels (LLA §5: × 1.7 per scale)."""
    return [base * height * factor**i for i in range(scales - 1)]


def _level_for(sigma_px: float, max_level: int) -> int:
    k = 0
    while k < max_level and sigma_px / (1 << k) > _MAX_LEVEL_SIGMA:
        k += 1
    return k


def _validate(
    normal: np.ndarray,
    depth: np.ndarray,
    scales: int,
    base: float,
    factor: float,
    depth_sigma: float,
) -> tuple[F32, F32]:
    normal = np.asarray(normal, np.float32)
    depth = np.asarray(depth, np.float32)
    if normal.ndim != 3 or normal.shape[2] != 3:
        raise ValueError(f"normal must be (H, W, 3), got shape {normal.shape}")
    if depth.shape != normal.shape[:2]:
        raise ValueError(f"depth must be (H, W) = {normal.shape[:2]}, got shape {depth.shape}")
    if isinstance(scales, bool) or not isinstance(scales, int | np.integer) or scales not in SCALES:
        raise ValueError(f"scales must be an integer in {SCALES}, got {scales!r}")
    LLA_BASE.check(base, "base")
    FACTOR.check(factor, "factor")
    LLA_DEPTH_SIGMA.check(depth_sigma, "depth_sigma")
    return normal, depth


def normal_pyramid(
    normal: np.ndarray,
    depth: np.ndarray,
    mask: np.ndarray | None = None,
    *,
    scales: int = DEFAULT_SCALES,
    base: float = DEFAULT_BASE,
    factor: float = DEFAULT_FACTOR,
    depth_sigma: float = DEFAULT_DEPTH_SIGMA,
) -> NormalPyramid:
    """Multi-scale normals by successive depth-guided bilateral filtering (LLA §5).

    n_1 = ``normal``; n_{i+1} = normalize(Σ_q G_{σ_i}(p − q) G_{depth_sigma}(log d_p − log d_q)
    n_i(q)), σ_i = ``base`` · H · ``factor``^(i−1) pixels (Mestres et al. 2021, §5,
    "Implementation details": bilateral filtering with the range kernel on depth, spatial size
    × 1.7 per coarser scale). Each filter runs at the pyramid level where σ_i ≤ 1.5 px.

    Parameters
    ----------
    normal : (H, W, 3) camera-space unit normals (background ignored).
    depth : (H, W) planar depth, +inf (or ≤ 0, NaN) on background.
    mask : optional (H, W) coverage; pixels where it is 0/False are background.
    scales : S, number of normal fields (2 … 12).
    base : σ_1 relative to the image height, in (0, 1].
    factor : growth of σ per scale, in [1, 4].
    depth_sigma : range-kernel σ on log depth (relative depth), in (0, 10].

    Returns
    -------
    NormalPyramid
        ``.full_list()`` gives the (H, W, 3) fields; :func:`ops.light_alignment.align_light`
        uses the pyramid directly to align coarse scales at low resolution.
    """
    normal, depth = _validate(normal, depth, scales, base, factor, depth_sigma)
    h = normal.shape[0]
    sig = scale_sigmas_px(h, int(scales), base, factor)
    max_level = max(0, math.floor(math.log2(max(1, min(normal.shape[:2]) // 4))))
    levels = [0] + [_level_for(s, max_level) for s in sig]
    geo = DepthPyramid.build(depth, mask, max(levels), depth_sigma)
    # n_1 is the input as is: background pixels have zero weight in every block average.
    normals: list[F32] = [normal]
    for i, s in enumerate(sig):
        k = levels[i + 1]
        src = geo.down(normals[i], levels[i], k) if k > levels[i] else normals[i]
        normals.append(_bilateral(src, geo, k, s / (1 << k)))
    return NormalPyramid(geometry=geo, normals=normals, levels=levels, sigmas_px=sig)


def _bilateral(src: F32, geo: DepthPyramid, k: int, sigma: float) -> F32:
    """Joint bilateral filter of a unit-vector field at level k, guided by log depth, then
    renormalised and 0 on background (LLA §5).

    Weights G_σ(p − q) G_r(g_p − g_q) over the circular window of radius
    max(1, round(1.5 σ)) (that of ``cv2.ximgproc.jointBilateralFilter``, borders reflected),
    G_r of standard deviation ``depth_sigma`` on the guide g: log depth, background far behind
    every surface. Radii ≤ 2 (every level the pyramid picks, σ ≤ 1.5) run the compiled
    :func:`_jbf_rows` on row strips, with G_r evaluated to 2e-7 (:func:`ops.numerics.exp_neg`);
    larger ones (levels capped by a small image) ``cv2.ximgproc.jointBilateralFilter``.
    """
    m = geo.mask[k]
    valid = m > 0
    if not np.any(valid):
        return np.zeros_like(src)
    # background: far behind everything (its range weight to surfaces is e^-800)
    logd = geo.logd[k] if k > 0 else np.where(valid, geo.logd[0], np.float32(0.0))
    far = max(float(logd.max()), 0.0) + 40.0 * geo.depth_sigma
    guide = np.asarray(logd + (np.float32(1.0) - m) * np.float32(far), np.float32)
    radius = max(1, round(1.5 * sigma))
    if radius > 2:
        out = cv2.ximgproc.jointBilateralFilter(
            guide, np.ascontiguousarray(src), 2 * radius + 1, geo.depth_sigma, sigma
        )
        return normalize_field(np.asarray(out, np.float32), m)
    h, w = m.shape
    border = cv2.BORDER_REFLECT_101
    guide_p = cv2.copyMakeBorder(guide, 2, 2, 2, 2, border)
    src_p = cv2.copyMakeBorder(np.ascontiguousarray(src, np.float32), 2, 2, 2, 2, border)
    src_p = src_p.reshape(h + 4, 3 * (w + 4))
    sw = np.array(
        [
            math.exp(-0.5 * (dy * dy + dx * dx) / (sigma * sigma))
            if dy * dy + dx * dx <= radius * radius
            else 0.0
            for dy, dx in _JBF_TAPS
        ],
        np.float32,
    )
    c = np.float32(0.5 / (geo.depth_sigma * geo.depth_sigma))
    res = np.empty((h, w, 3), np.float32)
    flat = res.reshape(h, 3 * w)

    def strip(r0: int, r1: int) -> None:
        _jbf_rows(guide_p[r0 : r1 + 4], src_p[r0 : r1 + 4], m[r0:r1], sw, c, flat[r0:r1])

    run_strips(h, strip, rows=strip_rows(w, STRIP_PIXELS // 4))
    return res


def multiscale_normals(
    normal: np.ndarray,
    depth: np.ndarray,
    mask: np.ndarray | None = None,
    *,
    scales: int = DEFAULT_SCALES,
    base: float = DEFAULT_BASE,
    factor: float = DEFAULT_FACTOR,
    depth_sigma: float = DEFAULT_DEPTH_SIGMA,
) -> list[F32]:
    """[n_1, …, n_S]: multi-scale normals at full resolution (LLA §5; see :func:`normal_pyramid`).

    n_{i+1} = normalize(Σ_q G_{σ_i}(p − q) G_{depth_sigma}(log d_p − log d_q) n_i(q)),
    σ_i = ``base`` · H · ``factor``^(i−1) (Mestres et al. 2021, §5). Each (H, W, 3) float32,
    unit length on surfaces, 0 on background; n_1 is the input.
    """
    return normal_pyramid(
        normal, depth, mask, scales=scales, base=base, factor=factor, depth_sigma=depth_sigma
    ).full_list()
