"""The compiled kernels of the depth-aware pyramid: front-most block selection, the 2×2 reductions
of geometry and unit fields, and the joint bilateral filter on a level."""

from __future__ import annotations

import numpy as np

from ops.filtering._common import _F0, _INF, _QUARTER, BACKGROUND
from ops.jit import kernel
from ops.numerics import exp_neg


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
