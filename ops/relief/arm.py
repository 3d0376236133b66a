"""Apparent Relief Maps: texture coordinates of the descriptor, the (fused) lookup, ARMs from
images, and picking a feature to paint (§2, Fig. 1)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Literal, NamedTuple

import cv2
import numpy as np
from numpy.typing import NDArray

from ops.checks import FRACTION
from ops.color import REC709_Y
from ops.curvature import Curvature
from ops.relief._common import (
    _MAX_TEX,
    _PAD,
    _PAD_MAX_TEXELS,
    DEFAULT_PERCENTILE,
    F32,
    Pick,
    Relief,
    _check_s,
    _check_unit_image,
    _cv,
)
from ops.relief.shape import _grid_descriptor

__all__ = [
    "arm_coords",
    "arm_from_image",
    "arm_lookup",
    "paint_arm",
    "pick",
    "relief",
    "s_to_uv",
    "uv_to_texel",
]

# -- ARM coordinates and lookup -------------------------------------------------------------------


def s_to_uv(s1: float, s2: float) -> tuple[float, float]:
    """ARM texture coordinates of a descriptor value: ``u = (S1 + 1) / 2``, ``v = (S2 + 1) / 2``."""
    return (float(s1) + 1.0) / 2.0, (float(s2) + 1.0) / 2.0


def uv_to_texel(u: float, v: float, shape: tuple[int, ...]) -> tuple[float, float]:
    """(column x, row y) of texture coordinates in an ARM of ``shape`` (h, w[, C]):
    ``x = u · (w − 1)``, ``y = (1 − v) · (h − 1)`` (row 0 at the top, v = 1 at the top)."""
    h, w = shape[0], shape[1]
    return float(u) * (w - 1), (1.0 - float(v)) * (h - 1)


def arm_coords(size: int | tuple[int, int]) -> F32:
    """The descriptor S = (S1, S2) at each texel centre of an ARM of ``size`` (side, or (h, w)):
    (h, w, 2) float32, the inverse of the lookup mapping (corners outside the unit disc)."""
    h, w = (size, size) if isinstance(size, int) else size
    if not (2 <= h <= _MAX_TEX and 2 <= w <= _MAX_TEX):
        raise ValueError(f"ARM size must be between 2 and {_MAX_TEX} texels per side, got {size!r}")
    s1 = np.linspace(-1.0, 1.0, w, dtype=np.float32)
    s2 = np.linspace(1.0, -1.0, h, dtype=np.float32)
    g1, g2 = np.meshgrid(s1, s2)
    return np.ascontiguousarray(np.stack([g1, g2], axis=-1), dtype=np.float32)


def _texel_map(s: F32, h: int, w: int) -> F32:
    """cv2.remap map (H, W, 2) = (x, y) texel coordinates of S in an h x w ARM."""
    ax, ay = 0.5 * (w - 1), 0.5 * (h - 1)
    m = np.array([[ax, 0.0, ax], [0.0, -ay, ay]], np.float32)
    return np.asarray(cv2.transform(s, m), np.float32)


def arm_lookup(s: NDArray[np.generic], arm: NDArray[np.generic]) -> F32:
    """Relief value r = ARM(S) by bilinear lookup (Apparent Relief §2, "S can easily be used as a
    texture coordinate to lookup a relief value r ∈ [0, 1]").

    Parameters
    ----------
    s : (H, W, 2) descriptor (:func:`descriptor`).
    arm : (h, w) or (h, w, C) image, C <= 4, values in [0, 1], any size >= 2x2 (see
        :func:`arm_from_image` for 8/16-bit or colour images). Indexed with
        ``x = (S1 + 1)/2 · (w − 1)``, ``y = (1 − (S2 + 1)/2) · (h − 1)``.

    Returns
    -------
    (H, W) float32 r in [0, 1] (or (H, W, C) for a multi-channel ARM).
    """
    arr = _check_s(s)
    tex = _check_arm(arm)
    h, w = tex.shape[:2]
    return _lookup(_prepare(tex), _texel_map(arr, h, w), None)


class _Texture(NamedTuple):
    """A lookup texture as :func:`_lookup` reads it (see :func:`_prepare`)."""

    planes: tuple[F32, ...]
    chans: int  # channels of the looked-up values


def _prepare(tex: F32) -> _Texture:
    """A texture ready for :func:`_lookup`, bilinear, edge-replicating cv2.remap in float precision.

    OpenCV 5 interpolates a 2-channel source in fixed point, with 1/32-texel steps: its channels
    are remapped one by one. A 3-channel source is remapped as RGBA, whose vectorised path is ~2x
    faster even with the conversion back. A texture of at most _PAD_MAX_TEXELS texels also gets
    _PAD replicated rows below and columns to the right: the same values at every coordinate
    (BORDER_REPLICATE reads those texels there anyway; checked bit for bit), but cv2.remap then
    takes its in-range path on the last row and column (r = 0, n·ℓ = 1, S on the rim), ~30 %
    faster on a toon or ARM lookup.
    """
    chans = 1 if tex.ndim == 2 else tex.shape[2]
    if chans == 3:
        planes = [np.asarray(cv2.cvtColor(tex, cv2.COLOR_RGB2RGBA), np.float32)]
    elif chans == 2:
        planes = [np.ascontiguousarray(tex[:, :, i]) for i in range(2)]
    else:
        planes = [tex]
    if tex.shape[0] * tex.shape[1] <= _PAD_MAX_TEXELS:
        planes = [
            np.asarray(cv2.copyMakeBorder(p, 0, _PAD, 0, _PAD, cv2.BORDER_REPLICATE), np.float32)
            for p in planes
        ]
    return _Texture(tuple(planes), chans)


def _lookup(tex: _Texture, mx: np.ndarray, my: np.ndarray | None, dst: Any = None) -> F32:
    """Bilinear lookup of a :func:`_prepare` d texture at texel coordinates (``mx``, ``my``), or
    at the (H, W, 2) map ``mx`` when ``my`` is None; into ``dst`` when given (the right shape)."""
    mode = cv2.INTER_LINEAR
    border = cv2.BORDER_REPLICATE
    if tex.chans == 2:
        a, b = (cv2.remap(p, mx, _cv(my), mode, borderMode=border) for p in tex.planes)
        return np.asarray(cv2.merge([a, b], dst=dst), np.float32)
    if tex.chans == 3:
        out4 = cv2.remap(tex.planes[0], mx, _cv(my), mode, borderMode=border)
        return np.asarray(cv2.cvtColor(out4, cv2.COLOR_RGBA2RGB, dst=dst), np.float32)
    return np.asarray(cv2.remap(tex.planes[0], mx, _cv(my), mode, dst=dst, borderMode=border))


def _check_arm(arm: NDArray[np.generic]) -> F32:
    tex = _check_unit_image(arm, "arm")
    return tex[:, :, 0] if tex.ndim == 3 and tex.shape[2] == 1 else tex


def relief(
    curv: Curvature,
    arm: NDArray[np.generic],
    *,
    curvedness_norm: float | Literal["auto"] = "auto",
    percentile: float = DEFAULT_PERCENTILE,
    full_resolution: bool = False,
    with_descriptor: bool = False,
) -> Relief:
    """Relief value r = ARM(S) straight from the curvature: :func:`descriptor` and
    :func:`arm_lookup` fused (Apparent Relief §2), the operator's fast path.

    ``S = (κ1, κ2) · min(weight / (√2 · L_norm), 1 / |(κ1, κ2)|)`` is computed on the
    curvature's working grid. By default r is looked up there and interpolated bilinearly to
    full resolution: S carries no detail finer than the curvature scale (σ >= 1.5 working
    pixels), only a hard-edged ARM's transitions get ~2 px softer. ``full_resolution=True``
    interpolates the texture coordinates instead and looks up every pixel (crisp edges, about
    2x the copy unit more at 1080p). Same result as ``arm_lookup(descriptor(curv).s, arm)`` up to
    that interpolation; parameters as in :func:`descriptor` and :func:`arm_lookup`.
    ``with_descriptor=True`` also returns S itself at full resolution, as two planes (the
    channels of ``descriptor(curv).s``, bit for bit), from the same working-grid descriptor.

    Returns
    -------
    Relief
        ``r``: (H, W) float32 in [0, 1] ((H, W, C) for a multi-channel ARM); ``norm``: L_norm;
        ``s1``, ``s2``: the (H, W) descriptor planes with ``with_descriptor``, else None.
    """
    tex = _check_arm(arm)
    s1, s2, norm, up, mx, my = _grid_descriptor(curv, curvedness_norm, percentile, tex.shape[:2])
    assert mx is not None and my is not None
    if up is not None and full_resolution:
        mx, my = up(mx), up(my)
    r = _lookup(_prepare(tex), mx, my)
    if up is not None and not full_resolution:
        r = up(r)
    planes: tuple[F32 | None, F32 | None] = (None, None)
    if with_descriptor:
        planes = (s1, s2) if up is None else (up(s1), up(s2))
    return Relief(np.asarray(r, np.float32), norm, *planes)


def arm_from_image(img: NDArray[np.generic]) -> F32:
    """An ARM (h, w) float32 in [0, 1] from an image array: uint8 / 255, uint16 / 65535, float
    clipped to [0, 1]; (h, w, 3|4) RGB(A) -> Rec. 709 luminance of RGB (alpha ignored)."""
    arr = np.asarray(img)
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[:, :, 0]
    if arr.ndim == 3 and arr.shape[2] in (3, 4):
        rgb = np.ascontiguousarray(arr[:, :, :3])
        scale = 1.0
        if arr.dtype == np.uint8:
            scale = 1.0 / 255.0
        elif arr.dtype == np.uint16:
            scale = 1.0 / 65535.0
        w709 = np.array([REC709_Y], np.float32) * scale
        out = cv2.transform(rgb.astype(np.float32), w709).reshape(rgb.shape[:2])
    elif arr.ndim == 2:
        if arr.dtype == np.uint8:
            out = arr.astype(np.float32) / 255.0
        elif arr.dtype == np.uint16:
            out = arr.astype(np.float32) / 65535.0
        elif arr.dtype.kind == "f":
            out = arr.astype(np.float32)
        else:
            raise ValueError(f"ARM image dtype must be uint8, uint16 or float, got {arr.dtype}")
    else:
        raise ValueError(
            f"ARM image must be (h, w), (h, w, 1), (h, w, 3) or (h, w, 4), got {arr.shape}"
        )
    if not np.isfinite(out).all():
        raise ValueError("ARM image contains NaN or infinite values")
    return np.ascontiguousarray(np.clip(out, 0.0, 1.0), dtype=np.float32)


def pick(s: NDArray[np.generic], x: int, y: int) -> Pick:
    """ "Pick a feature" (Apparent Relief §3): the descriptor under pixel (column ``x``, row ``y``,
    from the top-left) and its ARM texture coordinates, so a client can paint the ARM there
    (:func:`paint_arm`)."""
    arr = np.asarray(s)
    if arr.ndim != 3 or arr.shape[2] != 2:
        raise ValueError(f"S must have shape (H, W, 2), got {arr.shape}")
    h, w = arr.shape[:2]
    xi, yi = math.floor(x), math.floor(y)
    if not 0 <= xi < w:
        raise ValueError(f"x={x!r} is outside the allowed range [0, {w})")
    if not 0 <= yi < h:
        raise ValueError(f"y={y!r} is outside the allowed range [0, {h})")
    s1, s2 = float(arr[yi, xi, 0]), float(arr[yi, xi, 1])
    u, v = s_to_uv(s1, s2)
    return Pick(s1, s2, u, v)


def paint_arm(
    arm: NDArray[np.generic],
    s: tuple[float, float],
    value: float | Sequence[float],
    radius: float = 0.15,
    softness: float = 0.5,
) -> F32:
    """A copy of ``arm`` with a soft disc of ``value`` painted around descriptor ``s`` and its
    mirror image (S2, S1) (the "click on a pixel" interface of Apparent Relief §3).

    Parameters
    ----------
    arm : (h, w) or (h, w, C) ARM in [0, 1].
    s : (S1, S2) the centre, each in [-1, 1], e.g. from :func:`pick`.
    value : the value painted (one per channel for a multi-channel ARM), in [0, 1].
    radius : disc radius in descriptor units, in (0, 2].
    softness : fraction of the radius over which the paint fades out, in [0, 1].
    """
    tex = _check_unit_image(arm, "arm").copy()
    rad = float(radius)
    if not 0.0 < rad <= 2.0:
        raise ValueError(f"radius={radius!r} is outside the allowed range (0, 2]")
    soft = FRACTION.check(softness, "softness")
    vals = np.atleast_1d(np.asarray(value, np.float32))
    chans = 1 if tex.ndim == 2 else tex.shape[2]
    if vals.size not in (1, chans) or not (np.all(vals >= 0.0) and np.all(vals <= 1.0)):
        raise ValueError(f"value={value!r} must be {chans} number(s) in [0, 1]")
    c1, c2 = float(s[0]), float(s[1])
    if not (-1.0 <= c1 <= 1.0 and -1.0 <= c2 <= 1.0):  # (NaN too: it painted nothing)
        raise ValueError(f"s={s!r} must be a descriptor (S1, S2), each in [-1, 1]")
    grid = arm_coords(tex.shape[:2])
    alpha = np.zeros(tex.shape[:2], np.float32)
    for a, b in ((c1, c2), (c2, c1)):
        dist = np.hypot(grid[:, :, 0] - a, grid[:, :, 1] - b)
        inner = rad * (1.0 - soft)
        ramp = (rad - dist) / max(rad - inner, 1e-6)
        alpha = np.maximum(alpha, np.clip(ramp, 0.0, 1.0))
    alpha = alpha * alpha * (3.0 - 2.0 * alpha)
    if tex.ndim == 2:
        out = tex + alpha * (float(vals[0]) - tex)
    else:
        out = tex + alpha[:, :, None] * (np.broadcast_to(vals, (chans,)) - tex)
    return np.ascontiguousarray(np.clip(out, 0.0, 1.0), dtype=np.float32)
