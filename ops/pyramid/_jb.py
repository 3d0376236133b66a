"""Joint bilateral upsampling weights (Kopf et al. 2007) of the depth-aware pyramid's sparse
upsampling: the rule in NumPy (:func:`jb_weights`) and the same numbers from compiled passes over
ranges of points on every core (:func:`jb_weights_fast`), the exponential still NumPy's."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ops.jit import exact_kernel
from ops.parallel import run_strips

F32 = NDArray[np.float32]
I64 = NDArray[np.int64]

#: A pixel whose 2×2 footprint weighs less than this in all has no sample on its surface.
_FAR = np.float32(1e-4)
#: Points per task of :func:`jb_weights_fast` (its (9, N) arrays stay in the caches).
_POINTS = 8192


def jb_weights(
    logd_k: F32, mask_k: F32, depth_sigma: float, f: int, ys: I64, xs: I64, logd: F32
) -> tuple[I64, F32]:
    """Joint bilateral upsampling weights of the samples of a level (log depth ``logd_k`` and
    coverage ``mask_k``, (h_k, w_k)) for the pixels (ys, xs) of log depth ``logd`` of the level
    ``f`` times finer: the bilinear (tent) weights of the 2×2 footprint times a range term of
    the log-depth difference Δ over covered samples, exp(−max(|Δ| − 2σ, 0)² / 2σ²) with
    σ = ``depth_sigma``, renormalised — plain bilinear where all four are on the pixel's
    surface. Where none is, the 3×3 nearest samples with a Gaussian spatial weight (σ one
    sample) and a softmax on the depth term, so the sample closest in depth wins.
    Returns flat sample indices and weights, (9, N).
    """
    h_k, w_k = logd_k.shape
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
    dl = np.abs(logd_k.reshape(-1)[idx] - logd)
    dl = np.maximum(dl - np.float32(2.0 * depth_sigma), np.float32(0.0))
    inv_r = np.float32(0.5 / (depth_sigma * depth_sigma))
    range_log = -inv_r * dl * dl
    covered = mask_k.reshape(-1)[idx] > 0
    range_log[~covered] = -np.inf
    wts = (tent.reshape(9, -1) * np.exp(range_log)).astype(np.float32)
    total = wts.sum(axis=0)
    far = total < _FAR
    if np.any(far):
        logw = np.float32(-0.5) * spatial[:, far] + range_log[:, far]
        logw -= logw.max(axis=0, keepdims=True)
        wts[:, far] = np.exp(logw)
        total[far] = wts[:, far].sum(axis=0)
    wts /= total
    return idx, wts


@exact_kernel
def _footprint(ys, xs, f):  # type: ignore[no-untyped-def]
    """The point's position on the level (sy, sx: float32, as :func:`jb_weights` makes them)
    and the first row and column of its 3×3 nearest samples (unclipped)."""
    sy = (np.float32(ys) + np.float32(0.5)) / np.float32(f) - np.float32(0.5)
    sx = (np.float32(xs) + np.float32(0.5)) / np.float32(f) - np.float32(0.5)
    return sy, sx, np.int64(np.rint(sy)) - 1, np.int64(np.rint(sx)) - 1


@exact_kernel
def _range_logs(ys, xs, logd, logd_k, mask_k, f, h_k, w_k, par, idx, range_log):  # type: ignore[no-untyped-def]
    """:func:`jb_weights`' sample indices and range term (its log) of each point; ``par`` =
    (2σ, 1/2σ²) as float32."""
    two_sigma, inv_r = par
    for n in range(ys.shape[0]):
        _, _, y0, x0 = _footprint(ys[n], xs[n], f)
        for a in range(3):
            ny = min(max(y0 + a, 0), h_k - 1)
            for b in range(3):
                i = ny * w_k + min(max(x0 + b, 0), w_k - 1)
                idx[3 * a + b, n] = i
                dl = abs(logd_k[i] - logd[n]) - two_sigma
                if dl < np.float32(0.0):  # (NaN stays NaN, as with np.maximum)
                    dl = np.float32(0.0)
                range_log[3 * a + b, n] = -inv_r * dl * dl if mask_k[i] > 0 else -np.inf


@exact_kernel
def _weigh(ys, xs, f, ranges, wts, far):  # type: ignore[no-untyped-def]
    """:func:`jb_weights`' weights of each point from the exponentials of its range terms
    (``ranges``): the tent (float64, as NumPy promotes it) times each, their sum in tap order,
    each divided by it; ``far`` 1 where the sum is below _FAR (left to :func:`jb_weights`)."""
    for n in range(ys.shape[0]):
        sy, sx, y0, x0 = _footprint(ys[n], xs[n], f)
        total = np.float32(0.0)
        for a in range(3):
            ty = max(1.0 - abs(np.float64(y0 + a) - np.float64(sy)), 0.0)
            for b in range(3):
                tx = max(1.0 - abs(np.float64(x0 + b) - np.float64(sx)), 0.0)
                w = np.float32(ty * tx * np.float64(ranges[3 * a + b, n]))
                wts[3 * a + b, n] = w
                total += w
        far[n] = total < _FAR
        for t in range(9):
            wts[t, n] /= total


def jb_weights_fast(
    logd_k: F32, mask_k: F32, depth_sigma: float, f: int, ys: I64, xs: I64, logd: F32
) -> tuple[I64, F32]:
    """:func:`jb_weights`, bit for bit, by compiled passes over ranges of points on every core
    (NumPy's exponential between them; the few points with no sample on their surface from
    :func:`jb_weights` itself)."""
    n = ys.size
    idx = np.empty((9, n), np.int64)
    wts = np.empty((9, n), np.float32)
    far = np.empty(n, np.bool_)
    h_k, w_k = logd_k.shape
    flat_d, flat_m = logd_k.reshape(-1), mask_k.reshape(-1)
    par = (np.float32(2.0 * depth_sigma), np.float32(0.5 / (depth_sigma * depth_sigma)))

    def points(n0: int, n1: int) -> None:
        at = slice(n0, n1)
        ranges = np.empty((9, n1 - n0), np.float32)
        _range_logs(ys[at], xs[at], logd[at], flat_d, flat_m, f, h_k, w_k, par, idx[:, at], ranges)
        np.exp(ranges, out=ranges)
        _weigh(ys[at], xs[at], f, ranges, wts[:, at], far[at])

    run_strips(n, points, _POINTS)
    if far.any():
        wts[:, far] = jb_weights(logd_k, mask_k, depth_sigma, f, ys[far], xs[far], logd[far])[1]
    return idx, wts
