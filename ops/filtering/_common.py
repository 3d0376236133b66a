"""Defaults, constants and unit-field normalisation of the depth-guided multi-scale normals."""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

__all__ = [
    "BACKGROUND",
    "DEFAULT_BASE",
    "DEFAULT_DEPTH_SIGMA",
    "DEFAULT_FACTOR",
    "DEFAULT_SCALES",
    "F32",
    "STRIP_ROWS",
    "normalize_field",
]

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


#: Log depth of background pixels at level 0 is at least this (a finite sentinel, so that
#: products with zero weights stay 0).
BACKGROUND = np.float32(1e30)


_F0 = np.float32(0.0)
_F1 = np.float32(1.0)
_QUARTER = np.float32(0.25)
_INF = np.float32(np.inf)
