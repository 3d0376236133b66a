"""Apparent Relief's constants, result types and argument checks."""

from __future__ import annotations

import math
import pathlib
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]

#: Recommended curvature scale for the descriptor (``principal_curvatures(scale=...)``, relative
#: to the image height; σ = 6.5 px at 1080p). The paper measures the variation of normals "in an
#: extended pixel neighborhood": twice ``ops.curvature.DEFAULT_SCALE`` keeps the selected features
#: whole rather than speckled, and lets the curvature run on a 4x coarser working grid (about half
#: its cost at 1080p).
DEFAULT_SCALE = 0.006
#: Default percentile of the covered pixels' curvedness used as L_norm when it is ``"auto"``.
DEFAULT_PERCENTILE = 95.0
#: ``"auto"`` never normalises by less than this curvedness (per unit image height: a radius of
#: curvature of 100 image heights), so a flat frame does not blow its noise up to full relief.
AUTO_NORM_FLOOR = 1e-2
#: |S| below which the descriptor is "plane" (region classification, shipped ARMs, template).
PLANE_RADIUS = 0.25

#: Region names; :func:`classify` returns their index.
REGIONS: tuple[str, ...] = ("plane", "cap", "convex", "saddle", "concave", "cup")
#: θ of each non-planar region's centre in the (κ1, κ2) plane, degrees (regions are ±22.5°).
REGION_ANGLES: dict[str, float] = {
    "cap": 45.0,
    "convex": 0.0,
    "saddle": -45.0,
    "concave": -90.0,
    "cup": -135.0,
}
#: Fig. 1a colour code (linear RGB in [0, 1]); the plane (centre) is white.
REGION_COLORS: dict[str, tuple[float, float, float]] = {
    "plane": (1.0, 1.0, 1.0),
    "cap": (1.0, 0.86, 0.05),
    "convex": (0.15, 0.72, 0.2),
    "saddle": (0.15, 0.35, 0.95),
    "concave": (0.9, 0.12, 0.1),
    "cup": (1.0, 0.45, 0.78),
}

#: Apparent Relief Maps shipped as package data (``ops/data/arm/<name>.png``, 8-bit grey).
SHIPPED_ARMS: tuple[str, ...] = (
    "convex_black_concave_white",
    "planar_filtered",
    "saddles_only",
    "caps_and_cups",
    "convex_only",
)
#: Side of the shipped ARM images, texels.
SHIPPED_ARM_SIZE = 128

_ARM_DIR = pathlib.Path(__file__).resolve().parents[1] / "data" / "arm"
_SQRT1_2 = 1.0 / math.sqrt(2.0)
_PERCENTILE_SAMPLES = 1 << 15  # the auto percentile is taken on at most ~this many pixels
_MAX_TEX = 32000  # cv2.remap sources must stay below 32767 texels per side
_PAD = 2  # replicated texels below and right of a lookup texture (see _prepare)
_PAD_MAX_TEXELS = 1 << 20  # larger textures are looked up as they are (no padded copy)
_STRIP_ROWS = 64  # full-resolution rows per strip of the fused styles (both cores, in cache)


class Descriptor(NamedTuple):
    """Result of :func:`descriptor`: ``s`` (H, W, 2) float32 in the unit disc and ``norm``, the
    curvedness L_norm (per unit image height) that maps to |S| = 1 (pin it for a sequence)."""

    s: F32
    norm: float


class Relief(NamedTuple):
    """Result of :func:`relief`: ``r`` the relief value (H, W) in [0, 1], ``norm`` the L_norm
    used (as in :class:`Descriptor`) and, when asked for, the descriptor planes ``s1``, ``s2``
    (H, W) at full resolution."""

    r: F32
    norm: float
    s1: F32 | None = None
    s2: F32 | None = None


class Pick(NamedTuple):
    """The descriptor under a pixel (:func:`pick`) and the ARM texture coordinates it maps to
    (``u`` left → right, ``v`` bottom → top, both in [0, 1])."""

    s1: float
    s2: float
    u: float
    v: float


# -- validation ----------------------------------------------------------------------------------


def _cv(value: object) -> Any:
    """A scalar (or None) operand for cv2 functions, whose stubs only type array operands."""
    return value


def _f32(a: NDArray[np.generic], name: str, ndim: tuple[int, ...]) -> F32:
    arr = np.asarray(a)
    if arr.ndim not in ndim:
        raise ValueError(
            f"{name} must have {' or '.join(map(str, ndim))} dimensions, got {arr.shape}"
        )
    if arr.dtype.kind not in "fiub":
        raise ValueError(f"{name} must be numeric, got dtype {arr.dtype}")
    return np.ascontiguousarray(arr, dtype=np.float32)


def _f32_rows(a: NDArray[np.generic], name: str, ndim: tuple[int, ...]) -> F32:
    """As :func:`_f32`, but a float32 array whose rows are each contiguous (a crop of an image:
    only the row stride is larger) is taken as it is, not copied: cv2 reads such views in place."""
    arr = np.asarray(a)
    if arr.dtype == np.float32 and arr.ndim in ndim and arr.ndim >= 2 and arr.size:
        pixel = arr.itemsize * (arr.shape[2] if arr.ndim == 3 else 1)
        inner = arr.strides[-1] == arr.itemsize and (arr.ndim == 2 or arr.strides[1] == pixel)
        if inner and arr.strides[0] >= pixel * arr.shape[1]:
            return arr
    return _f32(a, name, ndim)


def _check_s(s: NDArray[np.generic]) -> F32:
    arr = _f32(s, "S", (3,))
    if arr.shape[2] != 2:
        raise ValueError(f"S must have shape (H, W, 2), got {arr.shape}")
    return arr


def _check_same(a: F32, name: str, shape: tuple[int, ...]) -> None:
    if a.shape[:2] != shape[:2]:
        raise ValueError(f"{name} must have shape {shape[:2]} (H, W), got {a.shape}")


def _check_unit_image(img: NDArray[np.generic], name: str) -> F32:
    """An (h, w) or (h, w, C <= 4) float32 image with finite values in [0, 1]."""
    arr = _f32(img, name, (2, 3))
    h, w = arr.shape[:2]
    if not (2 <= h <= _MAX_TEX and 2 <= w <= _MAX_TEX):
        raise ValueError(f"{name} must be between 2 and {_MAX_TEX} texels per side, got {h}x{w}")
    if arr.ndim == 3 and not 1 <= arr.shape[2] <= 4:
        raise ValueError(f"{name} must have 1 to 4 channels, got {arr.shape[2]}")
    lo, hi = float(arr.min()), float(arr.max())
    if not (lo >= 0.0 and hi <= 1.0):  # also rejects NaN
        raise ValueError(f"{name} values must be finite and in [0, 1], got [{lo}, {hi}]")
    return arr
