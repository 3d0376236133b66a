"""Apparent Relief: a view-dependent shape descriptor, Apparent Relief Maps and shading styles.

Reference: R. Vergne, P. Barla, X. Granier, C. Schlick, "Apparent Relief: a Shape Descriptor for
Stylized Shading", NPAR 2008 (``papers/apparent-relief.txt``), §2 and Figs. 1-2.

The descriptor (§2). Per pixel, from the view-centred principal curvatures κ1 ≥ κ2 (per unit
image height, > 0 on convexities; :func:`ops.curvature.principal_curvatures`, computed from
Gaussian derivatives of the camera-space normals at a scale relative to the image height)::

    K = (κ1, κ2),   D = K / |K|  (D = 0 where |K| = 0),   S = D · L

with L the curvedness of Koenderink & van Doorn, ``sqrt((κ1² + κ2²) / 2)`` times the curvature
reliability weight (0 on background and at depth discontinuities), normalised to [0, 1] by
``min(L / L_norm, 1)``. As long as L < L_norm, ``S = K / (√2 · L_norm)``: the descriptor is the
curvature vector itself, scaled, and clamped radially to the unit disc. The derivative scale being
a fixed fraction of the image height, a detail that gets small on screen is smoothed away
(automatic level of detail, §2).

The descriptor domain (Fig. 1a). The axes are κ1 (horizontal) and κ2 (vertical). The polar angle
θ = atan2(S2, S1) gives the shape (Koenderink's shape index is ``2θ/π + 1/2``), |S| the curvedness:

=========  ===============  ==========================================  ==========
region     θ (S1, S2)       surface                                     colour
=========  ===============  ==========================================  ==========
plane      |S| < 0.25       flat (the centre)                           white
cap        45°   (1, 1)     κ1 = κ2 > 0, a sphere seen from outside     yellow
convex     0°    (1, 0)     κ1 > 0 = κ2, a cylinder / ridge             green
saddle     −45°  (1, −1)    κ1 > 0 > κ2                                 blue
concave    −90°  (0, −1)    0 = κ1 > κ2, a trough / valley              red
cup        −135° (−1, −1)   κ1 = κ2 < 0, a bowl                         pink
=========  ===============  ==========================================  ==========

Caps and cups lie on the symmetry axis κ1 = κ2; saddles separate the convex from the concave
regions. Since κ1 ≥ κ2, S only reaches the half of the disc below that diagonal; the other half
(κ2 > κ1) is its mirror image, unused by lookups (the template shows it dimmed, region
classification and painting mirror it).

ARM texture coordinates. An Apparent Relief Map (ARM) is an image of any size (h, w) indexed by S
through ``u = (S1 + 1) / 2`` (left → right) and ``v = (S2 + 1) / 2`` (bottom → top), i.e. the
texel at column ``x = u · (w − 1)``, row ``y = (1 − v) · (h − 1)`` (row 0 at the top, as every
image): κ1 grows to the right, κ2 upwards, the plane is the image centre, caps are towards the
top-right corner, cups towards the bottom-left one, saddles towards the bottom-right one, and the
reached half is the lower-right triangle. The lookup is bilinear (edge texels replicated).

Use. ``curv = principal_curvatures(normal, depth, mask, scale=DEFAULT_SCALE)``, then either
``r = relief(curv, arm).r`` (fused, fast: the operator's path) or ``s = descriptor(curv).s`` and
``r = arm_lookup(s, arm)`` (S itself is needed for :func:`descriptor_colors` and :func:`pick`);
then a style: :func:`cel`, :func:`counter_shading`, :func:`xtoon` (with :func:`default_toon`) or
:func:`masked` over another operator's result. Counter shading and X-Toon take n·ℓ, or the normals
and a directional light (``normal=``, ``light=``) to compute it in their own pass, strip by strip
on both cores (the operator's path: no full-size n·ℓ or texture-coordinate map is written).
Shipped ARMs: :data:`SHIPPED_ARMS`, :func:`shipped_arm_path`, :func:`make_arm`; the painting
template: :func:`arm_template`; "pick a feature": :func:`pick` and :func:`paint_arm`.
"""

from __future__ import annotations

import functools
import math
import pathlib
from collections.abc import Callable, Sequence
from typing import Any, Literal, NamedTuple

import cv2
import numpy as np
from numpy.typing import NDArray

from ops.checks import CURVEDNESS_NORM, FRACTION, PERCENTILE
from ops.color import REC709_Y
from ops.curvature import Curvature
from ops.jit import kernel
from ops.parallel import run_strips, strip_rows

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

_ARM_DIR = pathlib.Path(__file__).resolve().parent / "data" / "arm"
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


# -- the descriptor --------------------------------------------------------------------------------


def curvedness(curv: Curvature) -> F32:
    """Koenderink's curvedness ``L = sqrt((κ1² + κ2²) / 2) · weight`` (Apparent Relief §2).

    Per unit image height, (H, W) float32, 0 where the curvature weight is 0 (background, depth
    discontinuities). This is the unnormalised length of the descriptor S.
    """
    mag = cv2.magnitude(curv.k1, curv.k2)
    return np.asarray(cv2.multiply(mag, curv.weight, scale=_SQRT1_2), np.float32)


def _auto_norm(k1: np.ndarray, k2: np.ndarray, weight: np.ndarray, percentile: float) -> float:
    """The ``percentile`` of the curvedness ``|K| · weight / √2`` over covered pixels (weight >
    0.5), on a regular subsample of at most ~_PERCENTILE_SAMPLES pixels (|K| computed there
    only), floored at AUTO_NORM_FLOOR."""
    step = max(1, math.ceil(math.sqrt(k1.size / _PERCENTILE_SAMPLES)))
    sub_w = weight[::step, ::step]
    mag = cv2.magnitude(
        np.ascontiguousarray(k1[::step, ::step]), np.ascontiguousarray(k2[::step, ::step])
    )
    sel = (mag * sub_w)[sub_w > 0.5] * np.float32(_SQRT1_2)
    if sel.size == 0 or np.isnan(sel).any():
        return AUTO_NORM_FLOOR
    value = _percentile(sel, percentile)
    return max(value, AUTO_NORM_FLOOR) if math.isfinite(value) else AUTO_NORM_FLOOR


def _percentile(a: np.ndarray, percentile: float) -> float:
    """``float(np.percentile(a, percentile))`` of a 1-D float32 array without NaN, bit for bit
    (NumPy's default "linear" method: a partition and the same float32 lerp), without NumPy's
    generic quantile machinery (~0.15 ms a call, more than the partition itself)."""
    pos = (a.size - 1) * float(np.true_divide(percentile, 100))
    lo = math.floor(pos)
    hi = min(lo + 1, a.size - 1)
    part = np.partition(a, (lo, hi))
    below, above, t = part[lo], part[hi], pos - lo
    diff = above - below
    return float(above - diff * (1 - t)) if t >= 0.5 else float(below + diff * t)


@kernel
def _descriptor_rows(k1, k2, wgt, c, ax, ay, s1, s2, mx, my):  # type: ignore[no-untyped-def]
    """Rows of :func:`_grid_descriptor`: ``S = K · g``, ``g = w·c / max(|K|·w·c, 1)`` =
    min(weight / (√2 L_norm), 1 / |K|) with ``c = 1 / (√2 L_norm)`` (S = 0 where K = 0: g is
    finite there), into ``s1``, ``s2``; when ``mx`` has rows, also the ARM texel coordinates
    ``x = ax·S1 + ax``, ``y = ay − ay·S2`` into ``mx``, ``my`` (else into a scratch row: no
    branch in the loop)."""
    one = np.float32(1.0)
    keep = mx.shape[0] > 0
    wid = s1.shape[1]
    scratch_x = np.empty(wid, np.float32)
    scratch_y = np.empty(wid, np.float32)
    for i in range(s1.shape[0]):
        a, b, w = k1[i], k2[i], wgt[i]
        o1, o2 = s1[i], s2[i]
        px = mx[i] if keep else scratch_x
        py = my[i] if keep else scratch_y
        for j in range(wid):
            wc = w[j] * c
            t = np.sqrt(a[j] * a[j] + b[j] * b[j]) * wc
            t = t if t > one else one
            g = wc / t
            u = a[j] * g
            v = b[j] * g
            o1[j] = u
            o2[j] = v
            px[j] = u * ax + ax
            py[j] = ay - v * ay


def _grid_descriptor(
    curv: Curvature,
    curvedness_norm: float | str,
    percentile: float,
    texture: tuple[int, int] | None = None,
) -> tuple[F32, F32, float, Callable[[np.ndarray], np.ndarray] | None, F32 | None, F32 | None]:
    """(S1, S2) on the curvature's working grid, the L_norm used, the bilinear upsampling from
    that grid to full resolution (None when the curvature is at full resolution) and, for a
    ``texture`` of (h, w) texels, the texel coordinates (x, y) of S there (else None, None); one
    pass of :func:`_descriptor_rows` in row strips on both cores."""
    p = PERCENTILE.check(percentile, "percentile")
    if isinstance(curvedness_norm, str):
        if curvedness_norm != "auto":
            raise ValueError(
                f"curvedness_norm={curvedness_norm!r} must be 'auto' or a number in "
                f"{CURVEDNESS_NORM}"
            )
    else:
        norm = CURVEDNESS_NORM.check(curvedness_norm, "curvedness_norm")
    coarse = curv._coarse_for("k1", "k2", "weight")
    if coarse is not None:
        k1, k2, wgt = coarse.k1, coarse.k2, coarse.weight
    else:
        k1, k2, wgt = curv.k1, curv.k2, curv.weight
    k1 = np.ascontiguousarray(k1, dtype=np.float32)
    k2 = np.ascontiguousarray(k2, dtype=np.float32)
    wgt = np.ascontiguousarray(wgt, dtype=np.float32)
    if isinstance(curvedness_norm, str):
        norm = _auto_norm(k1, k2, wgt, p)
    c = np.float32(_SQRT1_2 / norm)
    hgt, wid = k1.shape
    s1 = np.empty((hgt, wid), np.float32)
    s2 = np.empty((hgt, wid), np.float32)
    if texture is None:
        ax = ay = np.float32(0.0)
        mx = my = np.empty((0, wid), np.float32)
    else:
        ax, ay = np.float32(0.5 * (texture[1] - 1)), np.float32(0.5 * (texture[0] - 1))
        mx = np.empty((hgt, wid), np.float32)
        my = np.empty((hgt, wid), np.float32)

    def strip(r0: int, r1: int) -> None:
        m = slice(r0, r1) if texture is not None else slice(0, 0)
        _descriptor_rows(
            k1[r0:r1], k2[r0:r1], wgt[r0:r1], c, ax, ay, s1[r0:r1], s2[r0:r1], mx[m], my[m]
        )

    run_strips(hgt, strip, strip_rows(wid))
    up = None if coarse is None else coarse.upsample
    if texture is None:
        return s1, s2, norm, up, None, None
    return s1, s2, norm, up, mx, my


def descriptor(
    curv: Curvature,
    *,
    curvedness_norm: float | Literal["auto"] = "auto",
    percentile: float = DEFAULT_PERCENTILE,
) -> Descriptor:
    """Apparent Relief descriptor ``S = D · L`` (Apparent Relief §2, Fig. 1a-b).

    ::

        D = (κ1, κ2) / |(κ1, κ2)|   (0 where |(κ1, κ2)| = 0)
        L = min(sqrt((κ1² + κ2²) / 2) · weight / L_norm, 1)
        S = D · L = (κ1, κ2) · min(weight / (√2 · L_norm), 1 / |(κ1, κ2)|)

    Parameters
    ----------
    curv : Curvature
        View-centred principal curvatures (:func:`ops.curvature.principal_curvatures`; its
        ``scale``, relative to the image height, sets the level of detail).
    curvedness_norm : "auto" or float
        L_norm, the curvedness (per unit image height) that reaches the rim of the descriptor
        domain, in (0, 1e6]; ``"auto"``: the ``percentile`` of the covered pixels' (weight > 0.5)
        curvedness, at least :data:`AUTO_NORM_FLOOR`. Pin it (the returned ``norm``) so a
        sequence does not flicker.
    percentile : float
        In (0, 100], used by ``"auto"``.

    Returns
    -------
    Descriptor
        ``s``: (H, W, 2) float32 (S1, S2) with |S| <= 1, S1 >= S2, 0 on background;
        ``norm``: the L_norm used.

    Notes
    -----
    When the curvature was computed on a coarser working grid, S is computed there and
    interpolated bilinearly (S is linear in κ below the rim, so this matches interpolating κ).
    """
    s1, s2, norm, up, _, _ = _grid_descriptor(curv, curvedness_norm, percentile)
    if up is not None:
        s1, s2 = up(s1), up(s2)
    return Descriptor(np.asarray(cv2.merge([s1, s2]), np.float32), norm)


def _polar(s: F32) -> tuple[F32, F32]:
    """(|S| clipped to 1, t) with t in [0, 180] degrees the *folded* shape angle: 0 cap, 45 convex,
    90 saddle, 135 concave, 180 cup; the unreached half (S2 > S1) is mirrored onto the other."""
    s1, s2 = cv2.split(np.ascontiguousarray(s, dtype=np.float32))
    rho = np.minimum(cv2.magnitude(s1, s2), np.float32(1.0))
    phase = np.asarray(cv2.phase(s1, s2, angleInDegrees=True), np.float32)  # [0, 360)
    phase += np.float32(135.0)
    np.subtract(phase, np.float32(360.0), out=phase, where=phase >= 360.0)
    phase -= np.float32(180.0)
    t = np.abs(phase)
    return np.asarray(rho, np.float32), np.asarray(t, np.float32)


def shape_index(s: NDArray[np.generic]) -> F32:
    """Koenderink's shape index of the descriptor, ``2θ/π + 1/2`` with θ = atan2(S2, S1):
    1 on caps, 0.5 convex, 0 saddles, -0.5 concave, -1 cups (0 where S = 0). (H, W) float32."""
    arr = _check_s(s)
    rho, t = _polar(arr)
    si = cv2.addWeighted(t, -1.0 / 90.0, t, 0.0, 1.0)
    si[rho <= 0.0] = 0.0
    return np.asarray(si, np.float32)


def classify(s: NDArray[np.generic]) -> NDArray[np.int8]:
    """Region index (into :data:`REGIONS`) of each descriptor: 0 plane (|S| < PLANE_RADIUS),
    then cap, convex, saddle, concave, cup, each ±22.5° around its angle (Fig. 1a); S2 > S1 is
    classified as its mirror image (S2, S1)."""
    arr = _check_s(s)
    rho, t = _polar(arr)
    sector = np.minimum(np.floor((t + 22.5) / 45.0), 4.0).astype(np.int8) + 1
    return np.where(rho < PLANE_RADIUS, np.int8(0), sector).astype(np.int8)


# -- colour code (Fig. 1a) ------------------------------------------------------------------------


def _hue_lut() -> F32:
    """(1, 181, 3) RGB of the folded angle t = 0..180 degrees: cap, convex, saddle, concave, cup
    colours at 0, 45, 90, 135, 180, linearly interpolated."""
    names = ("cap", "convex", "saddle", "concave", "cup")
    anchors = np.array([0.0, 45.0, 90.0, 135.0, 180.0])
    cols = np.array([REGION_COLORS[n] for n in names])
    t = np.arange(181.0)
    lut = np.stack([np.interp(t, anchors, cols[:, c]) for c in range(3)], axis=-1)
    return lut.reshape(1, 181, 3).astype(np.float32)


_LUT = _hue_lut()


def descriptor_colors(s: NDArray[np.generic]) -> F32:
    """Fig. 1a colour code of the descriptor: white on planes, blending with |S| towards yellow
    (caps), green (convex), blue (saddles), red (concave), pink (cups) interpolated by angle.

    ``colour = white + |S| · (hue(θ) − white)``. Returns (H, W, 3) float32 RGB in [0, 1].
    """
    arr = _check_s(s)
    rho, t = _polar(arr)
    hue = cv2.remap(_LUT, t, np.zeros_like(t), cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    hue = np.asarray(hue, np.float32).reshape(*t.shape, 3) - np.float32(1.0)
    hue *= rho[..., None]
    hue += np.float32(1.0)
    return np.asarray(np.clip(hue, 0.0, 1.0, out=hue), np.float32)


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
    s : (S1, S2) the centre, e.g. from :func:`pick`.
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


# -- shipped ARMs and the template -----------------------------------------------------------------


def _smoothstep(e0: float, e1: float, x: NDArray[np.floating]) -> F32:
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return np.asarray(t * t * (3.0 - 2.0 * t), np.float32)


def _arm_convex_black_concave_white(rho: F32, t: F32, feat: F32) -> F32:
    conv = np.clip(1.6 * np.cos(np.radians(t)), -1.0, 1.0)
    return np.asarray(0.5 - 0.5 * conv * feat, np.float32)


def _arm_planar_filtered(rho: F32, t: F32, feat: F32) -> F32:
    return feat


def _arm_saddles_only(rho: F32, t: F32, feat: F32) -> F32:
    return np.asarray(feat * (1.0 - _smoothstep(15.0, 30.0, np.abs(t - 90.0))), np.float32)


def _arm_caps_and_cups(rho: F32, t: F32, feat: F32) -> F32:
    ends = np.minimum(t, 180.0 - t)
    return np.asarray(feat * (1.0 - _smoothstep(15.0, 30.0, ends)), np.float32)


def _arm_convex_only(rho: F32, t: F32, feat: F32) -> F32:
    return np.asarray(feat * (1.0 - _smoothstep(60.0, 75.0, t)), np.float32)


_ARM_MAKERS: dict[str, Callable[[F32, F32, F32], F32]] = {
    "convex_black_concave_white": _arm_convex_black_concave_white,
    "planar_filtered": _arm_planar_filtered,
    "saddles_only": _arm_saddles_only,
    "caps_and_cups": _arm_caps_and_cups,
    "convex_only": _arm_convex_only,
}

#: The value each shipped ARM holds at the centre of each region (|S| = 1 on the region's angle,
#: S = 0 for the plane); what tests and documentation rely on.
SHIPPED_ARM_VALUES: dict[str, dict[str, float]] = {
    "convex_black_concave_white": {
        "plane": 0.5,
        "cap": 0.0,
        "convex": 0.0,
        "saddle": 0.5,
        "concave": 1.0,
        "cup": 1.0,
    },
    "planar_filtered": {
        "plane": 0.0,
        "cap": 1.0,
        "convex": 1.0,
        "saddle": 1.0,
        "concave": 1.0,
        "cup": 1.0,
    },
    "saddles_only": {
        "plane": 0.0,
        "cap": 0.0,
        "convex": 0.0,
        "saddle": 1.0,
        "concave": 0.0,
        "cup": 0.0,
    },
    "caps_and_cups": {
        "plane": 0.0,
        "cap": 1.0,
        "convex": 0.0,
        "saddle": 0.0,
        "concave": 0.0,
        "cup": 1.0,
    },
    "convex_only": {
        "plane": 0.0,
        "cap": 1.0,
        "convex": 1.0,
        "saddle": 0.0,
        "concave": 0.0,
        "cup": 0.0,
    },
}


def make_arm(name: str, size: int = SHIPPED_ARM_SIZE) -> F32:
    """Generate a shipped ARM (size x size float32 in [0, 1]); the PNGs in ``ops/data/arm`` are
    these, quantised to 8 bits (``python -m bench.make_arms`` rewrites them).

    Features (|S| > 0.3) vs planes (|S| < 0.2) fade smoothly; angular boundaries are soft over
    15° so the bilinear lookup does not alias. Values at each region's centre
    (:data:`SHIPPED_ARM_VALUES`):

    - ``convex_black_concave_white`` (Fig. 1d): caps/convex 0, cups/concave 1, saddles and
      planes 0.5, i.e. ``0.5 − 0.5 · clip(1.6 cos t, −1, 1) · feature``;
    - ``planar_filtered`` (Fig. 1c): 0 on planes, 1 on every feature;
    - ``saddles_only``: 1 within 15° of the saddle direction, 0 elsewhere;
    - ``caps_and_cups``: 1 within 15° of the symmetry axis (caps and cups), 0 elsewhere;
    - ``convex_only`` (the mask of Fig. 2c): 1 on caps and convex regions (t < 60°), 0 on
      saddles, concave regions, cups and planes.
    """
    if name not in _ARM_MAKERS:
        raise ValueError(f"ARM name {name!r} is not one of {', '.join(SHIPPED_ARMS)}")
    grid = arm_coords(int(size))
    rho, t = _polar(grid)
    feat = _smoothstep(PLANE_RADIUS - 0.05, PLANE_RADIUS + 0.05, rho)
    return np.ascontiguousarray(np.clip(_ARM_MAKERS[name](rho, t, feat), 0.0, 1.0), np.float32)


def shipped_arm_path(name: str) -> pathlib.Path:
    """Path of a shipped ARM PNG (8-bit grey, ``ops/data/arm/<name>.png``); see
    :data:`SHIPPED_ARMS`. Read it with the frame I/O and pass it through :func:`arm_from_image`."""
    if name not in SHIPPED_ARMS:
        raise ValueError(f"ARM name {name!r} is not one of {', '.join(SHIPPED_ARMS)}")
    return _ARM_DIR / f"{name}.png"


def arm_template(size: int = 256) -> F32:
    """The descriptor domain in the Fig. 1a colour code, for an artist to paint an ARM on.

    (size, size, 3) float32 RGB in [0, 1], laid out as ARMs are indexed (κ1 to the right, κ2
    upwards, plane at the centre). Marked: the κ1 and κ2 axes, the symmetry axis κ1 = κ2, the
    unit circle (|S| = 1), the plane disc (|S| = PLANE_RADIUS), the region boundaries, and region
    labels. The half above the symmetry axis (κ2 > κ1) is never looked up: it is shown dimmed
    (mirrored colours) and labelled "unused".
    """
    n = int(size)
    if not 64 <= n <= 4096:
        raise ValueError(f"size={size!r} is outside the allowed range [64, 4096]")
    grid = arm_coords(n)
    col = descriptor_colors(grid)
    s1, s2 = grid[:, :, 0], grid[:, :, 1]
    rho = np.hypot(s1, s2)
    grey = np.float32(0.62)
    unused = (s2 > s1)[:, :, None]
    col = np.where(unused, 0.45 * col + 0.55 * grey, col)
    col = np.where((rho > 1.0)[:, :, None], 0.35 * col + 0.65 * np.float32(0.9), col)
    img = np.ascontiguousarray(np.clip(col * 255.0 + 0.5, 0, 255).astype(np.uint8))

    def px(a: float, b: float) -> tuple[int, int]:
        x, y = uv_to_texel(*s_to_uv(a, b), (n, n))
        return round(x), round(y)

    ink = (40, 40, 40)
    thin = max(1, n // 256)
    aa = cv2.LINE_AA
    c = px(0.0, 0.0)
    rad_px = round((n - 1) / 2)
    cv2.line(img, px(-1.0, 0.0), px(1.0, 0.0), ink, thin, aa)  # κ2 = 0 (the κ1 axis)
    cv2.line(img, px(0.0, -1.0), px(0.0, 1.0), ink, thin, aa)  # κ1 = 0 (the κ2 axis)
    cv2.line(img, px(-1.0, -1.0), px(1.0, 1.0), (90, 90, 90), thin, aa)  # symmetry axis
    cv2.circle(img, c, rad_px, ink, thin, aa)
    cv2.circle(img, c, round(PLANE_RADIUS * (n - 1) / 2), ink, thin, aa)
    for deg in (22.5, 67.5, 112.5, 157.5):  # region boundaries in the reached half
        th = math.radians(45.0 - deg)
        a, b = math.cos(th), math.sin(th)
        cv2.line(img, px(PLANE_RADIUS * a, PLANE_RADIUS * b), px(a, b), (110, 110, 110), thin, aa)
    font = cv2.FONT_HERSHEY_SIMPLEX
    scale = n / 640.0
    # Labels at 0.68 of the radius on each region's angle, nudged off the axis lines.
    nudge = {"convex": -9.0, "concave": 9.0}
    labels = [(k, 0.68, a + nudge.get(k, 0.0)) for k, a in REGION_ANGLES.items()]
    for text, r, deg in [*labels, ("plane", 0.13, -45.0), ("unused", 0.62, 135.0)]:
        th = math.radians(deg)
        (tw, tht), _ = cv2.getTextSize(text, font, scale, thin)
        x, y = px(r * math.cos(th), r * math.sin(th))
        cv2.putText(img, text, (x - tw // 2, y + tht // 2), font, scale, ink, thin, aa)
    for text, org in (
        ("k1", (n - round(0.09 * n), c[1] - round(0.02 * n))),
        ("k2", (c[0] + round(0.02 * n), round(0.06 * n))),
    ):
        cv2.putText(img, text, org, font, scale, ink, thin, aa)
    return np.asarray(img.astype(np.float32) / 255.0, np.float32)


# -- styles (Figs. 1c-d, 2) ------------------------------------------------------------------------


def cel(r: NDArray[np.generic]) -> F32:
    """Cel shading (Apparent Relief §2, Figs. 1c-d): the relief value itself, I = r."""
    return np.asarray(np.clip(_f32(r, "r", (2, 3)), 0.0, 1.0), np.float32)


@kernel
def _ndotl_row(nrm, nl, light, from_normal, i, out):  # type: ignore[no-untyped-def]
    """Row ``i`` of n·ℓ clamped to [0, 1] into ``out`` (W,): ``light · n`` from the (rows, 3W)
    normals ``nrm`` (RGB rows indexed flat, so that LLVM vectorises the loop) with
    ``from_normal``, else the (rows, W) ``nl``. NaN counts as 0."""
    zero, one = np.float32(0.0), np.float32(1.0)
    if from_normal:
        lx, ly, lz = light[0], light[1], light[2]
        row = nrm[i]
        for j in range(out.shape[0]):
            d = lx * row[3 * j] + ly * row[3 * j + 1] + lz * row[3 * j + 2]
            d = d if d > zero else zero
            out[j] = d if d < one else one
    else:
        given = nl[i]
        for j in range(out.shape[0]):
            d = given[j]
            d = d if d > zero else zero
            out[j] = d if d < one else one


@kernel
def _counter_rows(r, nrm, nl, light, from_normal, thr, out):  # type: ignore[no-untyped-def]
    """Rows of :func:`counter_shading`: ``I = n·ℓ + r (1 − 2 n·ℓ)``, 1 where I > ``thr`` else 0,
    n·ℓ from :func:`_ndotl_row` (a row in L1)."""
    zero, one, two = np.float32(0.0), np.float32(1.0), np.float32(2.0)
    wid = out.shape[1]
    d = np.empty(wid, np.float32)
    for i in range(out.shape[0]):
        _ndotl_row(nrm, nl, light, from_normal, i, d)
        rr, oo = r[i], out[i]
        for j in range(wid):
            v = d[j] + rr[j] * (one - two * d[j])
            oo[j] = one if v > thr else zero


@kernel
def _toon_coords(r, nrm, nl, light, from_normal, sx, sy, mx, my):  # type: ignore[no-untyped-def]
    """Rows of :func:`xtoon`'s texel coordinates: ``mx = n·ℓ · sx`` (n·ℓ from
    :func:`_ndotl_row`), ``my = sy − sy · r`` with r clamped to [0, 1] (NaN counts as 0): the
    texels the edge-replicating lookup reads outside anyway, on cv2.remap's fast in-range path."""
    zero, one = np.float32(0.0), np.float32(1.0)
    for i in range(mx.shape[0]):
        px, py, rr = mx[i], my[i], r[i]
        _ndotl_row(nrm, nl, light, from_normal, i, px)
        for j in range(px.shape[0]):
            px[j] = px[j] * sx
            v = rr[j]
            v = v if v > zero else zero
            v = v if v < one else one
            py[j] = sy - sy * v


_NO_ROWS = np.empty((0, 0), np.float32)  # the operand a kernel does not read


def _lit(
    ndotl: NDArray[np.generic] | None,
    normal: NDArray[np.generic] | None,
    light: NDArray[np.generic] | Sequence[float] | None,
    shape: tuple[int, ...],
) -> Callable[[int, int], tuple[F32, F32, F32, bool]]:
    """The n·ℓ operands of :func:`_ndotl_row` on rows [r0, r1): ``(normal rows (rows, 3W),
    n·ℓ rows (rows, W), light (3,), from_normal)``, views of an (H, W) ``ndotl`` or of the
    (H, W, 3) ``normal`` field (rows may be strided: a crop is read in place) with a
    directional ``light`` (3,)."""
    if ndotl is not None:
        if normal is not None or light is not None:
            raise ValueError("give either ndotl or normal and light, not both")
        nl = _f32_rows(ndotl, "ndotl", (2,))
        _check_same(nl, "ndotl", shape)
        none = np.zeros(3, np.float32)

        def given(r0: int, r1: int) -> tuple[F32, F32, F32, bool]:
            return _NO_ROWS, nl[r0:r1], none, False

        return given
    if normal is None or light is None:
        raise ValueError("n·ℓ is needed: give ndotl, or normal and light")
    n = _f32_rows(normal, "normal", (3,))
    if n.shape[2] != 3:
        raise ValueError(f"normal must have shape (H, W, 3), got {n.shape}")
    _check_same(n, "normal", shape)
    vec = np.asarray(light, np.float32)
    if vec.shape != (3,) or not np.isfinite(vec).all():
        raise ValueError(f"light must be a finite (3,) direction, got {vec!r}")
    vec = np.ascontiguousarray(vec)
    width = n.shape[1]

    def rows(r0: int, r1: int) -> tuple[F32, F32, F32, bool]:
        return n[r0:r1].reshape(r1 - r0, 3 * width), _NO_ROWS, vec, True

    return rows


def counter_shading(
    r: NDArray[np.generic],
    ndotl: NDArray[np.generic] | None = None,
    threshold: float = 0.5,
    *,
    normal: NDArray[np.generic] | None = None,
    light: NDArray[np.generic] | Sequence[float] | None = None,
) -> F32:
    """Counter shading (Apparent Relief §2, Fig. 2b)::

        I = (1 − r) n·ℓ + r (1 − n·ℓ) = n·ℓ + r (1 − 2 n·ℓ),   output 1 where I > threshold, else 0

    Parameters
    ----------
    r : (H, W) relief value in [0, 1] (:func:`arm_lookup`), used as the contrast.
    ndotl : (H, W) n·ℓ, clamped to [0, 1] (back-facing light counts as 0).
    threshold : in [0, 1] (the paper's 0.5).
    normal, light : instead of ``ndotl``, the (H, W, 3) normals and a directional light (3,),
        unit length, camera space: n·ℓ is then computed in the same pass (no (H, W) n·ℓ
        written), with the result of ``counter_shading(r, ops.shading.dot(normal, light))`` up
        to float rounding (a pixel whose I is within rounding of the threshold may differ).

    Returns
    -------
    (H, W) float32, exactly 0 or 1.

    Notes
    -----
    One compiled pass (:func:`ops.jit.kernel`) per row strip, on both cores: n·ℓ, I and the
    threshold per row, the row in L1; (H, W) r and (H, W, 3) normals read once, the result
    written once.
    """
    rr = _f32_rows(r, "r", (2,))
    lit = _lit(ndotl, normal, light, rr.shape)
    thr = FRACTION.check(threshold, "threshold")
    out = np.empty(rr.shape, np.float32)
    t = np.float32(thr)

    def strip(r0: int, r1: int) -> None:
        _counter_rows(rr[r0:r1], *lit(r0, r1), t, out[r0:r1])

    run_strips(rr.shape[0], strip, strip_rows(rr.shape[1]))
    return out


def default_toon(width: int = 256, height: int = 64) -> F32:
    """A default X-Toon texture (Barla et al. 2006) for :func:`xtoon`: (height, width, 3) RGB.

    Column = tone n·ℓ (0 left → 1 right), row = relief r (1 at the top row, 0 at the bottom row).
    At r = 0 (features not selected) a soft, low-contrast warm gradient; at r = 1 crisp three-tone
    cel shading (dark / mid / light with narrow smooth steps), interpolated in between, so the
    selected features stand out in full contrast.
    """
    if not (2 <= width <= 4096 and 2 <= height <= 4096):
        raise ValueError(f"toon size must be in [2, 4096] per side, got {width}x{height}")
    tone = np.linspace(0.0, 1.0, width, dtype=np.float32)[None, :]
    rel = np.linspace(1.0, 0.0, height, dtype=np.float32)[:, None]
    soft = 0.55 + 0.35 * tone
    steps = 0.18 + 0.42 * _smoothstep(0.27, 0.33, tone) + 0.4 * _smoothstep(0.67, 0.73, tone)
    val = soft + rel * (steps - soft)
    tint = np.array([1.0, 0.85, 0.68], np.float32)
    return np.ascontiguousarray(np.clip(val[:, :, None] * tint, 0.0, 1.0), dtype=np.float32)


_DEFAULT_TOON_SIZE = (64, 256)  # (h, w) of default_toon()


@functools.cache
def _default_toon_texture() -> _Texture:
    """:func:`default_toon` prepared for the lookup, once (read-only arrays)."""
    tex = _prepare(default_toon(_DEFAULT_TOON_SIZE[1], _DEFAULT_TOON_SIZE[0]))
    for plane in tex.planes:
        plane.setflags(write=False)
    return tex


def xtoon(
    r: NDArray[np.generic],
    ndotl: NDArray[np.generic] | None = None,
    toon: NDArray[np.generic] | None = None,
    *,
    normal: NDArray[np.generic] | None = None,
    light: NDArray[np.generic] | Sequence[float] | None = None,
) -> F32:
    """X-Toon shading with the relief as the detail axis (Apparent Relief §2, Fig. 2a; Barla,
    Thollot & Markosian, "X-Toon: an extended toon shader", NPAR 2006)::

        I = T(n·ℓ, r),  column x = n·ℓ · (w − 1),  row y = (1 − r) · (h − 1)

    Parameters
    ----------
    r : (H, W) relief value in [0, 1].
    ndotl : (H, W) n·ℓ, clamped to [0, 1].
    toon : (h, w) or (h, w, C <= 4) texture in [0, 1], tone left → right, r = 1 on the top row;
        default :func:`default_toon`.
    normal, light : instead of ``ndotl``, the (H, W, 3) normals and a directional light (3,):
        n·ℓ is computed in the same pass as the lookup, with the result of
        ``xtoon(r, ops.shading.dot(normal, light), toon)`` up to float rounding.

    Returns
    -------
    (H, W, C) float32 (or (H, W) for a one-channel texture), bilinear lookup.

    Notes
    -----
    Strip by strip on both cores, so no full-size map is written: the texture coordinates in one
    compiled pass (:func:`ops.jit.kernel`: n·ℓ, x and y per row, r clamped to [0, 1]), then the
    bilinear lookup (one cv2.remap of the RGBA texture: its SIMD gathers beat a compiled scalar
    lookup, which LLVM does not vectorise here).
    """
    rr = _f32_rows(r, "r", (2,))
    if toon is None:
        tex, (h, w) = _default_toon_texture(), _DEFAULT_TOON_SIZE
    else:
        img = _check_unit_image(toon, "toon")
        if img.ndim == 3 and img.shape[2] == 1:
            img = img[:, :, 0]
        tex, (h, w) = _prepare(img), img.shape[:2]
    sx, sy = np.float32(w - 1), np.float32(h - 1)
    lit = _lit(ndotl, normal, light, rr.shape)
    out = np.empty(rr.shape if tex.chans == 1 else (*rr.shape, tex.chans), np.float32)

    def strip(r0: int, r1: int) -> None:
        mx = np.empty((r1 - r0, rr.shape[1]), np.float32)
        my = np.empty_like(mx)
        _toon_coords(rr[r0:r1], *lit(r0, r1), sx, sy, mx, my)
        _lookup(tex, mx, my, dst=out[r0:r1])

    run_strips(rr.shape[0], strip, _STRIP_ROWS)
    return out


def masked(r: NDArray[np.generic], base: NDArray[np.generic], effect: NDArray[np.generic]) -> F32:
    """The relief as a mask on another operator's result (Apparent Relief §2, Fig. 2c: exaggerated
    shading only on the features the ARM selects)::

        I = base · (1 − r) + effect · r

    ``base`` and ``effect``: (H, W) or (H, W, C) of the same shape; r: (H, W) in [0, 1].
    Returns float32 of ``base``'s shape.
    """
    rr = np.clip(_f32(r, "r", (2,)), 0.0, 1.0)
    b = _f32(base, "base", (2, 3))
    e = _f32(effect, "effect", (2, 3))
    if e.shape != b.shape:
        raise ValueError(f"effect must have the shape of base {b.shape}, got {e.shape}")
    _check_same(b, "base", rr.shape)
    diff = cv2.subtract(e, b)
    if b.ndim == 2:
        cv2.multiply(diff, rr, dst=diff)
    else:
        diff = diff.reshape(b.shape)  # cv2 drops a trailing channel axis of 1
        np.multiply(diff, rr[:, :, None], out=diff)
    return np.asarray(cv2.add(b, diff).reshape(b.shape), np.float32)
