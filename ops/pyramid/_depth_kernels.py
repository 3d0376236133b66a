"""The compiled kernels of the depth-aware pyramid: front-most block selection and the 2×2
reductions of geometry and unit fields, and the gather of unit vectors for its upsampling."""

from __future__ import annotations

import numpy as np

from ops.jit import exact_kernel, kernel

#: Log depth of background pixels at level 0 is at least this (a finite sentinel, so that
#: products with zero weights stay 0).
BACKGROUND = np.float32(1e30)


_F0 = np.float32(0.0)
_F1 = np.float32(1.0)
_QUARTER = np.float32(0.25)
_INF = np.float32(np.inf)


@kernel
def _gather_unit(idx, w, x, y, z, out, c0, n0, n1):
    """out[n, c0 + c] = Σ_t w[t, n] (x, y, z)[c][idx[t, n]] for the points n0 ≤ n < n1 (the
    weighted samples of :meth:`DepthPyramid.up_sparse` for one unit-vector field given as three
    flat planes), renormalised as by :func:`normalize_field` (0 where |v|² ≤ 1e-20). One field
    per call: the kernel has one signature whatever the number of fields upsampled together."""
    for n in range(n0, n1):
        ax = np.float32(0.0)
        ay = np.float32(0.0)
        az = np.float32(0.0)
        for t in range(idx.shape[0]):
            i = idx[t, n]
            ax += w[t, n] * x[i]
            ay += w[t, n] * y[i]
            az += w[t, n] * z[i]
        n2 = ax * ax + ay * ay + az * az
        inv = np.float32(1.0) / np.sqrt(n2) if n2 > np.float32(1e-20) else np.float32(0.0)
        out[n, c0], out[n, c0 + 1], out[n, c0 + 2] = ax * inv, ay * inv, az * inv


@kernel
def _block_row(la, lb, thr, front, ka, kb, cover, low, m_low, lost):
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
def _build01_rows(depth, mask8, thr, logd0, mask0, keep0, cover, logd1, mask1, excl1):
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
def _down_geometry_rows(logd, m, excl, thr, keep, cover, logd_low, m_low, excl_low):
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
def _down_unit_rows(v, keep, out):
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


@kernel
def _children(dirty, mask_to, logd_to, f, ys, xs, logd):
    """The covered (``mask_to`` > 0) level-k_to pixels of the ``f`` × ``f`` blocks under the
    level-k samples where ``dirty`` (uint8) is set, by row, then column: their rows ``ys``,
    columns ``xs`` and ``logd_to`` there (each sized for every pixel of those blocks); the
    count written."""
    h_to, w_to = mask_to.shape
    n = 0
    for py in range(dirty.shape[0]):
        for oy in range(f):
            y = py * f + oy
            if y >= h_to:
                break
            for px in range(dirty.shape[1]):
                if dirty[py, px] == 0:
                    continue
                for ox in range(f):
                    x = px * f + ox
                    if x >= w_to:
                        break
                    if mask_to[y, x] > 0:
                        ys[n], xs[n], logd[n] = y, x, logd_to[y, x]
                        n += 1
    return n


@exact_kernel
def _jump_rows(logd, m, tau, step, r0, r1, out):
    """Rows r0 … r1 − 1 of :meth:`~ops.pyramid.depth.DepthPyramid._jumps` (``m`` bool
    coverage): a covered sample whose second difference of ``logd`` along a row or column,
    between two covered neighbours, exceeds ``tau``, or whose step to a covered 4-neighbour
    exceeds ``step``. Each difference rounded as NumPy rounds it (no fused multiply-add)."""
    h, w = logd.shape
    two = np.float32(2.0)
    for i in range(r0, r1):
        for j in range(w):
            if not m[i, j]:
                out[i, j] = False
                continue
            c = logd[i, j]
            hit = False
            if 0 < j < w - 1 and m[i, j - 1] and m[i, j + 1]:
                hit = abs(logd[i, j - 1] + logd[i, j + 1] - two * c) > tau
            if not hit and 0 < i < h - 1 and m[i - 1, j] and m[i + 1, j]:
                hit = abs(logd[i - 1, j] + logd[i + 1, j] - two * c) > tau
            if not hit and j > 0 and m[i, j - 1]:
                hit = abs(c - logd[i, j - 1]) > step
            if not hit and j < w - 1 and m[i, j + 1]:
                hit = abs(logd[i, j + 1] - c) > step
            if not hit and i > 0 and m[i - 1, j]:
                hit = abs(c - logd[i - 1, j]) > step
            if not hit and i < h - 1 and m[i + 1, j]:
                hit = abs(logd[i + 1, j] - c) > step
            out[i, j] = hit
