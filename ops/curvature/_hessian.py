"""The working grid's coverage and normals, and the Gaussian derivatives of the normals' screen
gradient field (the Hessian of RS §4), fused in compiled row kernels."""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from ops.checks import FLOAT32_MAX
from ops.curvature._common import _NZ_MIN
from ops.curvature._jumps import _jump_band, _mask_u8
from ops.jit import inline_kernel, kernel
from ops.pyramid.reduce import box_downsample

#: cv2 for calls with Python scalars or None where its stubs only list arrays (Scalar arguments,
#: default kernels); same module, untyped.
_cv: Any = cv2


def _working_coverage(
    depth: np.ndarray, mask: np.ndarray | None, level: int, size: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray]:
    """Coverage (uint8 255 where the whole block is covered) and depth sampled once per block
    (nearest: a jump stays a jump), for a frame whose size 2^level does not divide (``size`` =
    (w, h) of the working grid; :func:`_block_coverage` does the exact case)."""
    # Non-finite depth (inf/NaN) propagates through the area average; the mask's 255 only
    # survives when the whole block is 255.
    dbox = cv2.resize(depth, size, interpolation=cv2.INTER_AREA)
    depth_l = cv2.resize(depth, size, interpolation=cv2.INTER_NEAREST)
    cov = cv2.inRange(dbox, 1e-30, FLOAT32_MAX)
    if mask is not None:
        m = box_downsample(_mask_u8(mask), level, size)
        cv2.bitwise_and(cov, _cv.compare(m, 250, cv2.CMP_GT), dst=cov)
    return cov, depth_l


_NO_MASK = np.empty((0, 0), np.uint8)


@kernel
def _weigh_blocks(normal, k, c0, covp, nch, out):  # type: ignore[no-untyped-def]
    """The box averages over k x k blocks of ``normal`` (rows, W, 3), from block column ``c0``
    on, of its first ``nch`` components, times w = [``covp`` != 0] into ``out[:nch]``, and w into
    ``out[nch]`` (``out``: (nch + 1, rows / k, cols)). A non-finite product (a non-finite normal
    in the block) is set to 0, so it counts nowhere."""
    wid = normal.shape[1]
    cols = out.shape[2]
    x0 = 3 * k * c0  # first value of the first block in a flat row
    inv = np.float32(1.0 / (k * k))
    zero, one, big = np.float32(0.0), np.float32(1.0), np.float32(np.inf)
    acc = np.empty(3 * k * cols, np.float32)
    box = np.empty((3, cols), np.float32)
    for i in range(out.shape[1]):
        cr, wr = covp[i], out[nch, i]
        for j in range(cols):
            wr[j] = one if cr[j] != 0 else zero
        px, py, pz = box[0], box[1], box[2]
        if k == 2:  # both rows at once, without the row sum; all three components even when
            # n_z is not needed: that loop reads whole 6-value groups and vectorises (measured:
            # n_x, n_y alone ran twice as slow)
            ra = normal[2 * i].reshape(3 * wid)[x0:]
            rb = normal[2 * i + 1].reshape(3 * wid)[x0:]
            for j in range(cols):
                px[j] = (ra[6 * j] + ra[6 * j + 3] + rb[6 * j] + rb[6 * j + 3]) * inv
                py[j] = (ra[6 * j + 1] + ra[6 * j + 4] + rb[6 * j + 1] + rb[6 * j + 4]) * inv
                pz[j] = (ra[6 * j + 2] + ra[6 * j + 5] + rb[6 * j + 2] + rb[6 * j + 5]) * inv
        else:
            acc[:] = normal[i * k].reshape(3 * wid)[x0 : x0 + acc.shape[0]]
            for dy in range(1, k):
                row = normal[i * k + dy].reshape(3 * wid)[x0:]
                for x in range(acc.shape[0]):
                    acc[x] += row[x]
            for j in range(cols):
                sx = sy = sz = np.float32(0.0)
                for dx in range(k):
                    o = 3 * (j * k + dx)
                    sx += acc[o]
                    sy += acc[o + 1]
                    sz += acc[o + 2]
                px[j] = sx * inv
                py[j] = sy * inv
                pz[j] = sz * inv
        for c in range(nch):  # the weighting, on rows in L1
            o, bc = out[c, i], box[c]
            for j in range(cols):
                v = bc[j] * wr[j]
                o[j] = v if abs(v) < big else zero


@kernel
def _block_coverage(depth, m8, k, cov, depth_l):  # type: ignore[no-untyped-def]
    """Per k x k block of ``depth`` (rows, W): ``cov`` 255 where the block's mean depth lies in
    [1e-30, FLT_MAX] (every sample finite, the block in front of the camera) and, when ``m8``
    (uint8, like ``depth``) has rows, all its mask bytes are non-zero, else 0; ``depth_l`` the
    block's top-left depth (nearest sampling: a jump stays a jump)."""
    wid = depth.shape[1]
    wl = wid // k
    inv = np.float32(1.0 / (k * k))
    lo, hi = np.float32(1e-30), np.float32(FLOAT32_MAX)
    has_mask = m8.shape[0] > 0
    full, empty = np.uint8(255), np.uint8(0)
    acc = np.empty(wid, np.float32)
    mrow = np.empty(wid, np.uint8)
    ones = np.full(wid, full, np.uint8)
    for i in range(cov.shape[0]):
        top = depth[i * k]
        out, dl = cov[i], depth_l[i]
        if k == 2:  # both rows at once, without the row sums
            bot = depth[2 * i + 1]
            ma = m8[2 * i] if has_mask else ones
            mb = m8[2 * i + 1] if has_mask else ones
            for j in range(wl):
                d = (top[2 * j] + top[2 * j + 1] + bot[2 * j] + bot[2 * j + 1]) * inv
                m = ma[2 * j] & ma[2 * j + 1] & mb[2 * j] & mb[2 * j + 1]
                ok = (d >= lo) & (d <= hi) & (m != 0)
                out[j] = full if ok else empty
                dl[j] = top[2 * j]
            continue
        acc[:] = top
        for dy in range(1, k):
            row = depth[i * k + dy]
            for x in range(wid):
                acc[x] += row[x]
        if has_mask:
            mrow[:] = m8[i * k]
            for dy in range(1, k):
                mr = m8[i * k + dy]
                for x in range(wid):
                    mrow[x] &= mr[x]
        else:
            mrow[:] = full
        for j in range(wl):
            d = np.float32(0.0)
            m = full
            for dx in range(k):
                d += acc[j * k + dx]
                m &= mrow[j * k + dx]
            d *= inv
            ok = (d >= lo) & (d <= hi) & (m != 0)
            out[j] = full if ok else empty
            dl[j] = top[j * k]


@dataclass(frozen=True)
class _Params:
    f: float  # foreshortening
    sigma: float  # Gaussian σ in working pixels
    ksize: int  # its kernel size
    radius: int  # widening of depth jumps, working pixels
    depth_jump: float
    sx: float  # derivative scales (per unit image height, sign of camera y included below)
    sy: float


def _hessian_rows(
    weigh: Callable[[np.ndarray, int], np.ndarray],
    cov: np.ndarray,
    depth_l: np.ndarray,
    prm: _Params,
    o0: int,
    o1: int,
    out: list[np.ndarray],
) -> None:
    """(trace, d, b, weight) of rows o0..o1 of a block of working-grid rows into ``out`` (RS §4,
    see :func:`principal_curvatures`); the block (``cov``, ``depth_l``) holds the neighbourhoods
    those rows need; ``weigh(covp, nch)`` gives the weighted normals of its rows b0..b1 (below)
    for their reliable coverage ``covp``: n_x·w, n_y·w[, n_z·w], w.

    Each step runs only on the rows the next one needs: the jump band on the whole block, the
    smoothing on ``o0 - 1 - g .. o1 + 1 + g`` (g: the kernel's half size; the rows it gets wrong
    at a cut-off edge are not used), q on ``o0 - 1 .. o1 + 1``, derivatives and weight on o0..o1.
    """
    n = cov.shape[0]
    band = _jump_band(depth_l, cov, prm.depth_jump, prm.radius)
    covp = cv2.subtract(cov, band)  # covered and away from depth jumps (saturating)
    ks, sigma = prm.ksize, prm.sigma
    g = max(ks // 2, 2)
    q0, q1 = max(0, o0 - 1), min(n, o1 + 1)
    b0, b1 = max(0, q0 - g), min(n, q1 + g)
    covp = covp[b0:b1]
    nch = 3 if prm.f > 0.0 else 2  # n_z is only needed for the foreshortening
    weighted = weigh(covp, nch)
    assert weighted.shape == (nch + 1, *covp.shape)

    # Normalised convolution of the normals with the weight map, G*(n·w) / G*w, on rows q0..q1.
    qa, qb = q0 - b0, q1 - b0
    if sigma > 0.0:
        smooth = np.empty((nch + 1, qb - qa, covp.shape[1]), np.float32)
        _gaussian_rows(weighted, _gaussian_kernel(ks, sigma), qa, smooth)
    else:
        smooth = np.ascontiguousarray(weighted[:, qa:qb])
    # Weight: 0 on the border pixels of the coverage (whose derivative stencil reaches outside
    # it; this also keeps an interpolated weight off the background), rising to 1 over about
    # 1.65 σ inside: a smoothstep of the smoothed coverage W (smoothed over >= 1 px) between the
    # values W takes 1 px and 1 + 1.65σ px inside a straight edge, Φ(1/σ) and Φ(1/σ + 1.65).
    sigma_w = sigma
    wsw = smooth[nch]
    if sigma < 1.0:
        sigma_w = 1.0
        w5 = np.empty((1, qb - qa, covp.shape[1]), np.float32)
        _gaussian_rows(weighted[nch:], _gaussian_kernel(5, 1.0), qa, w5)
        wsw = w5[0]
    w0, w1 = _phi(1.0 / sigma_w), _phi(1.0 / sigma_w + 1.65)
    _trace_rows(
        smooth,
        nch,
        wsw,
        covp[qa:qb],
        np.float32(prm.f),
        (o0 - q0, o1 - q0),
        np.array([w0, 1.0 / (w1 - w0), prm.sx, prm.sy], np.float32),
        *out,
    )


@functools.lru_cache(maxsize=32)
def _gaussian_kernel(ksize: int, sigma: float) -> np.ndarray:
    """cv2.GaussianBlur's 1-D kernel (``cv2.getGaussianKernel``), float32."""
    return np.ascontiguousarray(cv2.getGaussianKernel(ksize, sigma, cv2.CV_32F)[:, 0])


@kernel
def _reflect101(i, n):  # type: ignore[no-untyped-def]
    """Index ``i`` reflected into 0..n-1 without repeating the edge (cv2's BORDER_REFLECT_101)."""
    if n == 1:
        return 0
    while i < 0 or i >= n:
        i = -i if i < 0 else 2 * n - 2 - i
    return i


@inline_kernel
def _taps(out, r0, r1, r2, r3, r4, k, first):  # type: ignore[no-untyped-def]
    """``out`` = (or += unless ``first``) k[0]·r0 + … + k[4]·r4, five taps of a filter summed in
    registers per store."""
    k0, k1, k2, k3, k4 = k[0], k[1], k[2], k[3], k[4]
    if first:
        for x in range(out.shape[0]):
            out[x] = k0 * r0[x] + k1 * r1[x] + k2 * r2[x] + k3 * r3[x] + k4 * r4[x]
    else:
        for x in range(out.shape[0]):
            out[x] += k0 * r0[x] + k1 * r1[x] + k2 * r2[x] + k3 * r3[x] + k4 * r4[x]


@kernel
def _gaussian_rows(src, kern, a, dst):  # type: ignore[no-untyped-def]
    """``dst[c, i]`` = row ``a + i`` of the separable convolution of plane ``src[c]`` with
    ``kern`` ⊗ ``kern`` (odd length), edges reflected as cv2's default BORDER_REFLECT_101: what
    cv2.GaussianBlur gives on those rows, up to rounding.

    Taps go five at a time, summed in registers (a row accumulated tap by tap in memory runs
    five times slower); the kernel is padded with zero taps to a multiple of five (a 9-tap
    Gaussian takes two passes over each row)."""
    nc, n, wid = src.shape
    g = kern.shape[0] // 2
    nt = (kern.shape[0] + 4) // 5 * 5
    kp = np.zeros(nt, np.float32)
    kp[: kern.shape[0]] = kern
    col = np.zeros(wid + nt + g, np.float32)  # a row of the vertical pass, reflected, 0 after
    mid = col[g : g + wid]  # (slices, not offsets: an index of unknown sign does not vectorise)
    idx = np.empty(nt, np.int64)
    for c in range(nc):
        for i in range(dst.shape[1]):
            for t in range(nt):
                idx[t] = _reflect101(a + i + min(t, 2 * g) - g, n)
            for t in range(0, nt, 5):
                r0, r1, r2 = src[c, idx[t]], src[c, idx[t + 1]], src[c, idx[t + 2]]
                r3, r4 = src[c, idx[t + 3]], src[c, idx[t + 4]]
                _taps(mid, r0, r1, r2, r3, r4, kp[t : t + 5], t == 0)
            for t in range(1, g + 1):
                col[g - t] = mid[_reflect101(-t, wid)]
                col[g + wid - 1 + t] = mid[_reflect101(wid - 1 + t, wid)]
            out = dst[c, i]
            for t in range(0, nt, 5):
                s0, s1, s2 = col[t : t + wid], col[t + 1 : t + 1 + wid], col[t + 2 : t + 2 + wid]
                s3, s4 = col[t + 3 : t + 3 + wid], col[t + 4 : t + 4 + wid]
                _taps(out, s0, s1, s2, s3, s4, kp[t : t + 5], t == 0)


@kernel
def _trace_rows(smooth, nch, wsw, covp, f, rows, coef, trace, d_out, b_out, wgt):  # type: ignore[no-untyped-def]
    """The end of :func:`_hessian_rows` in one pass. From the smoothed planes N_x, N_y[, N_z] and
    W = ``smooth[nch]`` (the rows of q): q = (N_x, N_y) / W, times (N_z / W)^-f with N_z / W
    clamped to >= _NZ_MIN when ``nch`` is 3; on q's rows ``rows[0]..rows[1]``, of the symmetrised
    H = ∇q = [[a, b], [b, c]] with a = ``coef[2]``·∂q_x/∂col and c = -``coef[3]``·∂q_y/∂row
    (central differences, one-sided and doubled on the first and last column and on the first and
    last row of q): the trace a + c, d = (a - c)/2 and b = (∂q_x/∂y + ∂q_y/∂x)/2 in the same
    units; and the weight t²(3 - 2t)·[3x3 of ``covp`` all covered],
    t = clip((``wsw`` - coef[0])·coef[1], 0, 1)."""
    zero, one, two, three = np.float32(0.0), np.float32(1.0), np.float32(2.0), np.float32(3.0)
    oa, ob = rows
    w0, wscale, sx, sy = coef[0], coef[1], coef[2], coef[3]
    nq, wid = smooth.shape[1], smooth.shape[2]
    qx = np.empty((nq, wid), np.float32)
    qy = np.empty((nq, wid), np.float32)
    vmin = np.empty(wid, np.uint8)  # 3x1, then 3x3 minima of the coverage
    hmin = np.empty(wid, np.uint8)
    for r in range(nq):
        nx, ny, nz, wr = smooth[0, r], smooth[1, r], smooth[nch - 1, r], smooth[nch, r]
        ox, oy = qx[r], qy[r]
        if nch == 3:
            for j in range(wid):
                inv = one / max(wr[j], np.float32(1e-6))
                inv *= max(nz[j] * inv, np.float32(_NZ_MIN)) ** (-f)
                ox[j] = nx[j] * inv
                oy[j] = ny[j] * inv
        else:
            for j in range(wid):
                inv = one / max(wr[j], np.float32(1e-6))
                ox[j] = nx[j] * inv
                oy[j] = ny[j] * inv
    for i in range(ob - oa):
        r = oa + i  # the row in q
        wg = wgt[i]
        up, dn = max(r - 1, 0), min(r + 1, nq - 1)
        rows_q = (qx[r], qy[r], qx[up], qy[up], qx[dn], qy[dn])
        ys = sy if 0 < r < nq - 1 else two * sy
        if nq < 2:
            ys = zero
        outs = (trace[i], d_out[i], b_out[i])
        for j in range(1, wid - 1):  # (vectorised)
            _hessian_at(rows_q, j, j - 1, j + 1, sx, ys, outs)
        if wid >= 2:  # one-sided, doubled, on the first and last column
            _hessian_at(rows_q, 0, 0, 1, two * sx, ys, outs)
            _hessian_at(rows_q, wid - 1, wid - 2, wid - 1, two * sx, ys, outs)
        else:  # one column: no derivative along it (a = 0); the trace is taken as 0
            _hessian_at(rows_q, 0, 0, 0, zero, ys, outs)
            outs[0][0] = zero
        # 3x3 erosion of the coverage (replicated at the edges of q's rows and of the image).
        ca = covp[max(r - 1, 0)]
        cb = covp[r]
        cc = covp[min(r + 1, nq - 1)]
        for j in range(wid):
            vmin[j] = min(min(ca[j], cb[j]), cc[j])
        hmin[0] = min(vmin[0], vmin[min(1, wid - 1)])
        hmin[wid - 1] = min(vmin[wid - 1], vmin[max(wid - 2, 0)])
        for j in range(1, wid - 1):
            hmin[j] = min(min(vmin[j - 1], vmin[j]), vmin[j + 1])
        ww = wsw[r]
        for j in range(wid):
            t = (ww[j] - w0) * wscale
            t = min(max(t, zero), one)
            wg[j] = t * t * (three - two * t) if hmin[j] != 0 else zero


@inline_kernel
def _hessian_at(rows_q, j, jl, jr, xs, ys, outs):  # type: ignore[no-untyped-def]
    """Column ``j`` of the trace a + c, d = (a - c)/2 and b into ``outs``, with
    a = ``xs``·(q_x[jr] - q_x[jl]) and c = -``ys``·(q_y below - q_y above); ``rows_q``: q_x and
    q_y of the row, of the row above and of the row below."""
    qx, qy, qx_up, qy_up, qx_dn, qy_dn = rows_q
    half = np.float32(0.5)
    a = xs * (qx[jr] - qx[jl])
    c = -(ys * (qy_dn[j] - qy_up[j]))
    outs[0][j] = a + c
    outs[1][j] = (a - c) * half
    outs[2][j] = (xs * (qy[jr] - qy[jl]) - ys * (qx_dn[j] - qx_up[j])) * half


def _phi(x: float) -> float:
    """Standard normal CDF."""
    return 0.5 * (1.0 + math.erf(x / math.sqrt(2.0)))
