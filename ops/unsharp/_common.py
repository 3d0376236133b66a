"""Constants, argument checks and the CIELAB lightness round trip shared by the unsharp masks."""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np

from ops import color
from ops.colorspace import ColorSpace
from ops.numerics import clip_new_negatives

_cv: Any = cv2  # OpenCV's stubs reject scalar operands (cv2.max(a, 0.0))


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


def _lightness(beauty: Array, white: float, space: ColorSpace) -> Array:
    """L* (H, W) of linear RGB relative to ``white`` in the working ``space`` (a*, b* are never
    formed)."""
    return color.lightness(beauty, white, rgb_to_xyz=space.matrix)


def _with_lightness(
    beauty: Array,
    lum: Array,
    new_lum: Array,
    white: float,
    keep: Array | None,
    space: ColorSpace,
    out: Array | None = None,
) -> Array:
    """Linear RGB with L* replaced by ``new_lum`` and (a*, b*) scaled by k = new/old (§4).

    U is clamped at 0; k = U / max(L*, 1e-3) (below L* = 1e-3, black, the scaling saturates);
    the changed values are clipped at 0 (:func:`_clip_new_negatives`).
    ``new_lum`` is consumed. Pixels where ``keep`` (uint8, non-zero) get ``beauty`` back bit
    for bit. ``out``: where to write (an (H, W, 3) view), else a new array.
    """
    _cv.max(new_lum, 0.0, dst=new_lum)
    k = _cv.divide(new_lum, _cv.max(lum, _L_EPS), dst=new_lum)
    res = color.scale_lab(beauty, k, white, keep=keep, out=out, rgb_to_xyz=space.matrix)
    return _clip_new_negatives(res, beauty)


def _clip_new_negatives(out: Array, beauty: Array) -> Array:
    """``out`` with its changed values below 0 made 0, in place
    (:func:`ops.numerics.clip_new_negatives`): a saturated colour can leave the RGB cube below 0
    when its lightness drops (and the CIELAB round trip rounds a black channel to −1e-9); the
    values kept bit for bit, negative ones included, are left as they came."""
    clipped = clip_new_negatives(out, beauty, in_place=True)
    if clipped is not out:  # (a view that is not C-contiguous float32: clipped in a copy)
        out[...] = clipped
    return out


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
