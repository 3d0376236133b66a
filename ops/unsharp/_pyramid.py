"""The surface pyramid (:func:`_surface_pyramid`), in short: level k holds cells of 2^k pixels that
each keep the front-most surface of their block (depth steps are told from steep surfaces by
extrapolating each cell's plane, from its normal); each level is smoothed by a domain transform
guided by the depth (so its distances are the surface's own); levels are combined coarse to
fine, each pixel mixing the two levels around its σ_px = σ / pixel_size, with an upsampling that
only interpolates between cells of the pixel's own surface. Only the bounding box of the
surface is processed, and a level only where some pixel needs it. The full-resolution fields
(depth guide, L*, the averages that make level 1) are formed in one pass over strips of rows.
The domain transforms (OpenCV, without the GIL) run on a thread of their own, each as soon as
its level is made, while the next levels are made and the upsamplings' re-weighted pixels are
found (NumPy, and compiled kernels on strips): the two kinds of work share the cores instead of
taking turns.
"""

from __future__ import annotations

import math
from concurrent.futures import Future, wait
from typing import Any

import cv2
import numpy as np

from ops.unsharp._common import _BOX_MARGIN, _LEVEL_SIGMA, _LN2, _MIN_LEVEL_SIDE, Array
from ops.unsharp._levels import _finish_first_level, _reduce_selective, _smooth_level, _smoother
from ops.unsharp._surface import _crop, _Level, _Surface
from ops.unsharp._upsample import _Upsampler

_cv: Any = cv2  # OpenCV's stubs reject scalar operands (cv2.max(a, 0.0))


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
    lums: list[Array],
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
    h, wd = lums[0].shape
    n = len(lums)  # signals smoothed alike (one when the variance is wanted)
    kmax = 0
    while min(h, wd) // 2 ** (kmax + 1) >= _MIN_LEVEL_SIDE:
        kmax += 1
    if kmax == 0:
        return None
    m_lo, m_hi = _level_span(sigma, surf, kmax)
    v_lo, v_hi = _variance_span(var_sigma, surf, kmax)
    k_lo, k_hi = min(m_lo, v_lo), max(m_hi, v_hi)

    assert first is not None and len(first.sig) == (n if var_sigma is None else 2)
    assert n == 1 or var_sigma is None
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
            smoothed[k] = _smoother().submit(_smooth_level, lv, 2 if in_v else n, normal_sigma, box)

    levels: dict[int, _Level] = {}
    lv = first
    try:
        _finish_first_level(lv, surf, lums)
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
                fallback = (lv.sig[:n] if run_m else []) + (lv.sig[:2] if run_v else [])
                ups_of[k] = _Upsampler(levels[k + 1], lv.iz, lv.valid_u8, k, fallback)
        full = _Upsampler(levels[m_lo], surf.iz, surf.valid, 0, lums)
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
        up_m, up_v = (ups[:n], ups[n:]) if run_m else ([], ups)
        if k not in smoothed:
            # nothing needs this level: the coarser level carries on
            main = up_m if run_m else main
            var = up_v if run_v else var
            continue
        sm = smoothed[k].result()
        if in_m:
            main = _blend(up_m, sm[:n], lv, sigma, box) if run_m else sm[:n]
        if in_v:
            assert var_sigma is not None
            var = _blend(up_v, sm[:2], lv, var_sigma, box) if run_v else [sm[0].copy(), sm[1]]
    assert main is not None
    full.bind(main)
    return full, None if var is None else (v_lo, _variance(var, levels[v_lo]))


def _variance_span(var_sigma: float | None, surf: _Surface, kmax: int) -> tuple[int, int]:
    """The levels of the variance's chain (:func:`_level_span`; none: (kmax + 1, 0))."""
    if var_sigma is None:
        return kmax + 1, 0
    v_lo, v_hi = _level_span(var_sigma, surf, kmax)
    # the variance is a gain modulator: it starts at level 2 (σ ≈ 8 pixels), whose cells
    # already hold the 4×4-pixel means of L and L², so no half-resolution filtering for it
    v_lo = min(max(v_lo, 2), kmax)
    return v_lo, max(v_hi, v_lo)


def _variance(means: list[Array], lv: _Level) -> Array:
    """Var = E[L²] − E[L]² from the smoothed ``means`` (E[L], E[L²]) of level ``lv``, ≥ 0, and 0
    in its empty cells."""
    v = _cv.subtract(means[1], _cv.multiply(means[0], means[0]))
    _cv.max(v, 0.0, dst=v)
    v[~lv.valid] = 0.0
    return v


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
