"""The compiled joint bilateral filter of the multi-scale normals (a circular window of radius 1
or 2 on a pyramid level, range weights on log depth)."""

from __future__ import annotations

import numpy as np

from ops.jit import kernel
from ops.numerics import exp_neg

_F0 = np.float32(0.0)


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
def _jb_tap(gc, g, x, y, z, j, sw, c, ax, ay, az):
    """(ax, ay, az) plus tap j of guide row ``g`` and planes ``x``, ``y``, ``z``: spatial
    weight ``sw`` times the range weight e^{−c (g[j] − gc)²}."""
    d = g[j] - gc
    wt = sw * exp_neg(d * d * c)
    return ax + wt * x[j], ay + wt * y[j], az + wt * z[j]


@kernel
def _jb_planes(b, r, dx):
    """Guide and x, y, z rows of window row ``r`` in the chunk buffer ``b`` of
    :func:`_jbf_rows`, from column 2 + ``dx`` on."""
    o = 4 * r * _JBF_RS + 2 + dx
    return b[o:], b[o + _JBF_RS :], b[o + 2 * _JBF_RS :], b[o + 3 * _JBF_RS :]


@kernel
def _jbf_rows(guide, src, mask, sw, c, out):
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
