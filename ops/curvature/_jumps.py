"""Argument checks, the working level, and the depth jumps (occlusions) the curvature does not
cross."""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np

from ops.curvature._common import _LIMB_RATIO, _MIN_SIDE, _TARGET_SIGMA
from ops.jit import kernel

#: cv2 for calls with Python scalars or None where its stubs only list arrays (Scalar arguments,
#: default kernels); same module, untyped.
_cv: Any = cv2

# -- validation ----------------------------------------------------------------------------------


def _check_buffers(
    normal: np.ndarray, depth: np.ndarray, mask: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    normal = np.asarray(normal)
    depth = np.asarray(depth)
    if normal.ndim != 3 or normal.shape[2] != 3:
        raise ValueError(f"normal must have shape (H, W, 3), got {normal.shape}")
    if depth.shape != normal.shape[:2]:
        raise ValueError(f"depth must have shape {normal.shape[:2]}, got {depth.shape}")
    if mask is not None:
        mask = np.asarray(mask)
        if mask.shape != depth.shape:
            raise ValueError(f"mask must have shape {depth.shape}, got {mask.shape}")
    normal = np.ascontiguousarray(normal, dtype=np.float32)
    depth = np.ascontiguousarray(depth, dtype=np.float32)
    return normal, depth, mask


def _mask_u8(mask: np.ndarray) -> np.ndarray:
    """255 where mask > 0.5 (bool: True), else 0."""
    if mask.dtype == np.bool_:
        return _cv.compare(np.ascontiguousarray(mask).view(np.uint8), 0, cv2.CMP_GT)
    return _cv.compare(np.ascontiguousarray(mask, dtype=np.float32), 0.5, cv2.CMP_GT)


# -- principal curvatures --------------------------------------------------------------------------


def _working_level(sigma_px: float, shape: tuple[int, int]) -> int:
    level = 0
    while (
        sigma_px / 2 ** (level + 1) >= _TARGET_SIGMA and min(shape) / 2 ** (level + 1) >= _MIN_SIDE
    ):
        level += 1
    return level


def _jump_band(depth_l: np.ndarray, cov: np.ndarray, depth_jump: float, radius: int) -> np.ndarray:
    """uint8 255 on pixels within ``radius`` of a depth discontinuity (module docstring).

    Candidates are the pixels whose 3x3 neighbourhood holds a relative jump ``log d_max - log
    d_min > depth_jump`` between covered pixels (tested without logarithms as ``e^-depth_jump ·
    d_max > d_min``): cheap, and on most frames rare. Among them :func:`_mark_occlusions` keeps
    the two sides of the jumps that the surfaces do not explain.
    """
    hi = np.empty_like(depth_l)
    lo = np.empty_like(depth_l)
    jump: np.ndarray = np.empty(depth_l.shape, np.uint8)
    if _jump_candidates(depth_l, cov, np.float32(math.exp(-depth_jump)), hi, lo, jump):
        _mark_occlusions(jump, cov, lo, depth_jump)
    if radius > 0 and cv2.countNonZero(jump):
        k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
        jump = cv2.dilate(jump, k)
    return jump


@kernel
def _jump_candidates(depth_l, cov, e, hi, lo, jump):  # type: ignore[no-untyped-def]
    """Candidates of :func:`_jump_band` into ``jump`` (uint8 255 where ``e``·max > min of the
    covered depth over the 3x3 neighbourhood, pixels outside the image ignored), the covered
    depth into ``hi`` (0 elsewhere, below any covered depth) and ``lo`` (+inf elsewhere);
    returns how many candidates there are."""
    zero, big = np.float32(0.0), np.float32(np.inf)
    full, empty = np.uint8(255), np.uint8(0)
    n, wid = depth_l.shape
    for i in range(n):
        d, c, h, lw = depth_l[i], cov[i], hi[i], lo[i]
        for j in range(wid):
            h[j] = d[j] if c[j] != 0 else zero
            lw[j] = d[j] if c[j] != 0 else big
    vmax = np.empty(wid, np.float32)
    vmin = np.empty(wid, np.float32)
    count = 0
    for i in range(n):
        ha, hb, hc = hi[max(i - 1, 0)], hi[i], hi[min(i + 1, n - 1)]
        la, lb, lc = lo[max(i - 1, 0)], lo[i], lo[min(i + 1, n - 1)]
        for j in range(wid):
            vmax[j] = max(max(ha[j], hb[j]), hc[j])
            vmin[j] = min(min(la[j], lb[j]), lc[j])
        out = jump[i]
        for j in range(1, wid - 1):
            dmax = max(max(vmax[j - 1], vmax[j]), vmax[j + 1])
            dmin = min(min(vmin[j - 1], vmin[j]), vmin[j + 1])
            out[j] = full if e * dmax > dmin else empty
        for j in (0, wid - 1):
            jl, jr = max(j - 1, 0), min(j + 1, wid - 1)
            dmax = max(max(vmax[jl], vmax[j]), vmax[jr])
            dmin = min(min(vmin[jl], vmin[j]), vmin[jr])
            out[j] = full if e * dmax > dmin else empty
        for j in range(wid):
            count += out[j] != 0
    return count


def _mark_occlusions(jump: np.ndarray, cov: np.ndarray, lo: np.ndarray, depth_jump: float) -> None:
    """Keep the candidates in ``jump`` (uint8 255) that are next to the far side of an
    occlusion and clear the others; ``cov`` is the coverage (uint8), ``lo`` the covered depth,
    +inf elsewhere.

    Along a row or a column, a covered pixel of depth d whose two neighbours d-, d+ are covered
    (and inside the image) is the far side of an occlusion when it lies behind both of them by
    more than its own surface can, the nearer one a jump away::

        d- + d+ < (1 + e^-t)·d    and    min(d-, d+) < e^-t·d,    t = depth_jump

    (the first is a second difference of depth, ``2d - d- - d+ > (1 - e^-t)·d``). A plane's
    depth is affine in the image (orthographic camera) or convex (perspective: 1/d is affine),
    and near an occluding contour the visible sheet's depth is convex too, so none of them is a
    far side however fast its depth grows per pixel, at any slant or resolution; at a step
    between fronto-parallel surfaces both conditions read ``|Δ log d| > t``. With one neighbour
    missing (background or outside the image), the other, d-, a jump nearer and its own other
    neighbour d-- covered, the pixel is a far side when that jump is over ``_LIMB_RATIO`` times
    the step before it, ``d - d- > 3·(d- - d--)``: the last steps of a limb (a square-root
    profile) grow by at most 1 + √2 times, and a far surface seen as a thin strip between an
    occluder and the background is still cut off.

    Kept are the candidates within one pixel (3x3) of a far side: both sides of the jump, as the
    3x3 test marks them at an occlusion. The covered candidates are listed (cv2.findNonZero), a
    compiled loop reads their neighbours (work proportional to the candidates; outside the image
    counts as missing), and a 3x3 dilation of the far sides selects the candidates kept.
    """
    pts = cv2.findNonZero(cv2.bitwise_and(jump, cov))  # (x, y) of the covered candidates
    if pts is None:
        jump[...] = 0
        return
    e = math.exp(-depth_jump)
    far = np.zeros(jump.shape, np.uint8)
    _far_sides(pts.reshape(-1, 2), lo, np.float32(e), np.float32(1.0 + e), far)
    cv2.bitwise_and(jump, _cv.dilate(far, None), dst=jump)


@kernel
def _far_sides(pts, lo, e, e1, far):  # type: ignore[no-untyped-def]
    """``far`` = 255 at the points ``pts`` ((x, y) rows) that are the far side of an occlusion
    (:func:`_mark_occlusions`; ``e`` = e^-t, ``e1`` = 1 + e^-t)."""
    n, w = lo.shape
    big = np.float32(np.inf)
    limb = np.float32(_LIMB_RATIO)
    for p in range(pts.shape[0]):
        x, y = pts[p, 0], pts[p, 1]
        row = lo[y]
        d = row[x]
        for axis in range(2):  # along the row, then along the column
            if axis == 0:
                dm = row[x - 1] if x >= 1 else big
                dp = row[x + 1] if x + 1 < w else big
                dmm = row[x - 2] if x >= 2 else big
                dpp = row[x + 2] if x + 2 < w else big
            else:
                dm = lo[y - 1, x] if y >= 1 else big
                dp = lo[y + 1, x] if y + 1 < n else big
                dmm = lo[y - 2, x] if y >= 2 else big
                dpp = lo[y + 2, x] if y + 2 < n else big
            near = min(dm, dp)
            if not near < e * d:
                continue
            pair = dm + dp  # +inf when a neighbour is missing
            if pair < e1 * d:
                far[y, x] = 255
                break
            if pair == big:  # the far side from the near one and its other neighbour
                dnn = dmm if dm < dp else dpp
                if dnn < big and d - near > limb * (near - dnn):
                    far[y, x] = 255
                    break
