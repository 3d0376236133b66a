"""View-centred curvature (Radiance Scaling §4) and its curvature mappings κ.

Reference: R. Vergne, R. Pacanowski, P. Barla, X. Granier, C. Schlick, "Improving Shape Depiction
under Arbitrary Rendering", IEEE TVCG 17(8), 2011 (``papers/radiance-scaling.txt``), §4.

The paper computes, from the camera-space normal n, a relative depth gradient
``g = -(n_x, n_y) / n_z^f`` (f: foreshortening) and its derivative ``H = ∇ᵀg`` (the Hessian of the
depth field), whose eigenvalues are the principal curvatures κu ≥ κv. In Depict's OpenGL camera
space (+z towards the viewer) ``-(n_x, n_y) / n_z`` is the gradient of z, the height *towards*
the viewer, whose Hessian is negative on bumps. Depict differentiates
``q = -g = (n_x, n_y) / n_z^f``, the gradient of the depth ``-z`` (what the paper's "Hessian of
the depth field" and MeshLab's shader, which negates its sum, compute), so κ > 0 on convexities (a
sphere seen from outside), κ < 0 in concavities, κ1 > 0 > κ2 on a saddle and 0 on a plane
(DESIGN.md sign convention).

Units and scale. Derivatives are taken per unit of *image height* (pixel derivatives times the
image height in pixels), so a frame and its half-size proxy give the same values: an orthographic
sphere of radius R spanning an image ``h`` scene units high has κ1 = κ2 = h / R (at f = 0, exactly;
at the centre for any f). They are taken at a scale ``scale`` (relative to the image height): the
normals are smoothed by a Gaussian of σ = scale · image_height pixels by normalised convolution,
``n = G*(n·w) / G*w``, whose weight w excludes background and a band around depth discontinuities,
so no smoothing mixes surfaces; then differentiated by central differences. When σ is several
pixels the work runs on a box-downsampled grid where σ is about 1.5 pixels (the result is smooth at
that scale anyway; the box and difference filters' own variance is subtracted from σ²), and the
full-resolution fields are interpolated bilinearly (the direction from the interpolated
doubled-angle vector), lazily, on first access (:class:`Curvature`).

Discontinuities. An occlusion (one surface in front of another, a silhouette against a farther
surface) is a relative depth jump ``|Δ log d| > depth_jump`` between neighbouring samples
(MeshLab's Radiance Scaling shader likewise weights each of the 8 neighbours by its depth jump)
that the surfaces do not explain: along a row or a column, the far sample lies behind both of its
neighbours, ``2d - d- - d+ > (1 - e^-depth_jump)·d`` (:func:`_mark_occlusions`). A jump alone is
not enough, since the depth change per pixel of a slanted surface grows as the image shrinks (a
receding ground plane changes by several per cent per pixel at 120 px high); but a plane's depth
is affine in the image (orthographic) or convex (perspective), and near its occluding contour so
is any smooth surface's, so that second difference never has that sign on them, at any slant or
resolution. Between fronto-parallel surfaces the test is the jump alone. The samples on both
sides of an occlusion, widened by 1.5σ, and the background are cut out of the smoothing, and
``weight`` fades from 1 on reliable pixels to 0 about 1 + 1.65σ pixels from them (0 on background
and on the first covered pixel), so no curvature appears at silhouettes or occlusion boundaries
and nothing of one surface leaks into another.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from ops.bilinear import Upsampled
from ops.jit import expf, inline_kernel, kernel
from ops.parallel import run_strips

#: cv2 for calls with Python scalars or None where its stubs only list arrays (Scalar arguments,
#: default kernels); same module, untyped.
_cv: Any = cv2

#: Default derivative scale, relative to the image height (σ = 3.2 px at 1080p).
DEFAULT_SCALE = 0.003
#: Default foreshortening f (0: curvature of the projected normal field; 1: Hessian of depth).
DEFAULT_FORESHORTENING = 0.0
#: Default relative depth jump |Δ log d| between neighbours at an occlusion (module docstring).
DEFAULT_DEPTH_JUMP = 0.03
#: Default gain s of the mapping tanh(s·(κ1 + κ2)): a sphere spanning half the image height has
#: κ1 + κ2 = 8 per unit image height, mapped to tanh(0.24) ≈ 0.24. On renders of detailed meshes
#: (bunny, ogre, igea, Nefertiti, spot) it keeps the median |κ| at 0.25–0.5, in tanh's
#: near-linear range, where 0.1 saturated over half of their pixels (|κ| > 0.75).
DEFAULT_GAIN = 0.03

_FLT_MAX = float(np.finfo(np.float32).max)
_NZ_MIN = 1e-2  # n_z is clamped to this before n_z^f (f > 0); |q| ≤ 1 / _NZ_MIN^f
_TARGET_SIGMA = 1.5  # downsample while σ stays >= this many working pixels
_MIN_SIDE = 16  # never downsample below this many pixels per side
_STRIP_ROWS = 135  # working-grid rows per strip (4 strips at 1080p, level 1)
_LIMB_RATIO = 3.0  # a jump this many times the step before it is not a limb (<= 1 + sqrt 2)


@dataclass(init=False)
class Curvature:
    """Principal view-centred curvatures (RS §4) per unit of image height.

    Attributes
    ----------
    k1, k2 : (H, W) float32
        Principal curvatures, k1 >= k2, > 0 on convexities; per unit image height.
    dir_x, dir_y : (H, W) float32
        Unit direction of k1 in camera x (right) / y (up); defined up to sign (dir_y >= 0).
    weight : (H, W) float32
        Reliability in [0, 1]: 0 on background and near depth discontinuities, 1 inside.

    Notes
    -----
    :func:`principal_curvatures` may compute on a coarser working grid; the full-resolution
    fields are then interpolated on first access (k1, k2, weight bilinearly; the direction from
    the bilinearly interpolated doubled-angle vector) and cached, so consumers that only need
    :func:`isotropic` never pay for them. Constructing ``Curvature(k1, k2, dir_x, dir_y, weight)``
    directly works as for any dataclass.
    """

    k1: np.ndarray
    k2: np.ndarray
    dir_x: np.ndarray
    dir_y: np.ndarray
    weight: np.ndarray

    def __init__(
        self,
        k1: np.ndarray,
        k2: np.ndarray,
        dir_x: np.ndarray,
        dir_y: np.ndarray,
        weight: np.ndarray,
    ) -> None:
        self.k1, self.k2, self.dir_x, self.dir_y, self.weight = k1, k2, dir_x, dir_y, weight

    @classmethod
    def _lazy(cls, coarse: _Coarse) -> Curvature:
        obj = cls.__new__(cls)
        obj.__dict__["_coarse"] = coarse
        return obj

    def __getattr__(self, name: str) -> np.ndarray:
        # Only reached for attributes not yet set: the lazily interpolated fields.
        coarse = self.__dict__.get("_coarse")
        if coarse is None or name not in _FIELDS:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        if name in ("dir_x", "dir_y"):
            self.dir_x, self.dir_y = coarse.directions()
        else:
            setattr(self, name, coarse.upsample(getattr(coarse, name)))
        value: np.ndarray = self.__dict__[name]
        return value

    def _coarse_for(self, *names: str) -> _Coarse | None:
        """The working-grid data, if none of ``names`` was materialised (and so maybe edited)."""
        coarse: _Coarse | None = self.__dict__.get("_coarse")
        if coarse is None or any(n in self.__dict__ for n in names):
            return None
        return coarse


_FIELDS = ("k1", "k2", "dir_x", "dir_y", "weight")


@dataclass
class _Coarse:
    """Working-grid results and the full size (H, W) they are interpolated to.

    The Hessian H = ∇q = [[a, b], [b, c]] is kept as the field q it differentiates and its
    trace a + c (all :func:`isotropic` needs); d = (a - c)/2, b and the principal curvatures
    κ1,2 = trace/2 ± sqrt(d² + b²) are derived on first access (the same arithmetic as in
    :func:`_hessian_rows`).
    """

    qx: np.ndarray
    qy: np.ndarray
    weight: np.ndarray
    trace: np.ndarray
    size: tuple[int, int]
    sx: float  # derivative scales of q (see _Params)
    sy: float

    @functools.cached_property
    def d(self) -> np.ndarray:
        """(a - c) / 2 of the Hessian."""
        n = self.qx.shape[0]
        a = _deriv_x(self.qx, self.sx)
        c = _deriv_y(self.qy, 0, n, -self.sy)
        return np.asarray(cv2.addWeighted(a, 0.5, c, -0.5, 0.0), np.float32)

    @functools.cached_property
    def b(self) -> np.ndarray:
        """The off-diagonal term of the (symmetrised) Hessian."""
        n = self.qx.shape[0]
        by = _deriv_y(self.qx, 0, n, -0.5 * self.sy)
        return np.asarray(cv2.add(by, _deriv_x(self.qy, 0.5 * self.sx)), np.float32)

    @functools.cached_property
    def _radius(self) -> np.ndarray:
        return np.asarray(cv2.magnitude(self.d, self.b), np.float32)

    @functools.cached_property
    def k1(self) -> np.ndarray:
        return np.asarray(cv2.scaleAdd(self.trace, 0.5, self._radius), np.float32)

    @functools.cached_property
    def k2(self) -> np.ndarray:
        return np.asarray(cv2.scaleAdd(self._radius, -2.0, self.k1), np.float32)

    def upsample(self, img: np.ndarray) -> np.ndarray:
        return np.asarray(Upsampled(img, self.size))

    def directions(self) -> tuple[np.ndarray, np.ndarray]:
        """Direction of k1 from the interpolated (d, b): θ = ½·atan2(b, d) in [0, π), so that
        dir_y >= 0 (:func:`_half_angle_rows`)."""
        d, b = self.upsample(self.d), self.upsample(self.b)
        dx, dy = np.empty_like(d), np.empty_like(d)
        run_strips(
            d.shape[0],
            lambda r0, r1: _half_angle_rows(d[r0:r1], b[r0:r1], dx[r0:r1], dy[r0:r1]),
            _STRIP_ROWS,
        )
        return dx, dy


@kernel
def _half_angle_rows(d, b, dx, dy):  # type: ignore[no-untyped-def]
    """(cos θ, sin θ) of θ = ½·atan2(b, d) taken in [0, π), without trigonometry: with
    c = cos 2θ = d / r and s = sin 2θ = b / r (r = |(d, b)|; c = 1 where r = 0), the larger of
    cos θ, sin θ from the half-angle formula (√((1 ± c)/2)) and the other from s = 2 sin θ cos θ,
    which keeps both accurate; θ < 0 is turned by π (the direction of a line)."""
    zero, one, half = np.float32(0.0), np.float32(1.0), np.float32(0.5)
    for i in range(d.shape[0]):
        dr, br, xr, yr = d[i], b[i], dx[i], dy[i]
        for j in range(dr.shape[0]):
            r = np.sqrt(dr[j] * dr[j] + br[j] * br[j])
            inv = one / r if r > zero else zero
            c = dr[j] * inv if r > zero else one
            s = br[j] * inv
            big = np.sqrt(max((one + abs(c)) * half, half))  # cos θ (c >= 0) or sin θ (c < 0)
            small = abs(s) / (big + big)
            neg = s < zero
            xr[j] = (-big if neg else big) if c >= zero else (-small if neg else small)
            yr[j] = small if c >= zero else big


# -- validation ----------------------------------------------------------------------------------


def _check_range(name: str, value: float, lo: float, hi: float, lo_open: bool = False) -> float:
    v = float(value)
    ok = (v > lo if lo_open else v >= lo) and v <= hi and math.isfinite(v)
    if not ok:
        bracket = "(" if lo_open else "["
        raise ValueError(f"{name}={value!r} is outside the allowed range {bracket}{lo}, {hi}]")
    return v


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


def _downsample(img: np.ndarray, level: int, size: tuple[int, int]) -> np.ndarray:
    """Box average over 2^level x 2^level blocks (``size`` = (w, h) of the result).

    For exact halvings, bilinear resizing by 1/2 samples the middle of each 2x2 block, which is
    their average (and faster than INTER_AREA); other sizes use INTER_AREA.
    """
    h, w = img.shape[:2]
    k = 2**level
    if h % k or w % k:
        return cv2.resize(img, size, interpolation=cv2.INTER_AREA)
    for _ in range(level):
        h, w = h // 2, w // 2
        img = cv2.resize(img, (w, h), interpolation=cv2.INTER_LINEAR)
    return img


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


def principal_curvatures(
    normal: np.ndarray,
    depth: np.ndarray,
    mask: np.ndarray | None = None,
    *,
    scale: float = DEFAULT_SCALE,
    foreshortening: float = DEFAULT_FORESHORTENING,
    image_height: int | None = None,
    depth_jump: float = DEFAULT_DEPTH_JUMP,
) -> Curvature:
    """View-centred principal curvatures (Radiance Scaling §4).

    Computes ``q = (n_x, n_y) / n_z^f`` from the smoothed camera-space normal (the paper's
    ``g = -(n_x, n_y) / n_z^f`` with the sign that makes convexities positive, see the module
    docstring), ``H = ∇q`` in camera x/y per unit image height (rows grow downward:
    ∂/∂y = -∂/∂row), symmetrised, and its eigen-decomposition in closed form::

        H = [[a, b], [b, c]],  κ1,2 = (a + c)/2 ± sqrt(((a - c)/2)² + b²),
        dir(κ1) = (cos θ, sin θ),  θ = ½·atan2(b, (a - c)/2)

    Parameters
    ----------
    normal : (H, W, 3) float32
        Camera-space unit normals (OpenGL, +z towards the camera).
    depth : (H, W) float32
        Planar depth, positive, +inf (or NaN, <= 0) on background.
    mask : (H, W) bool or float, optional
        Coverage; pixels with mask <= 0.5 are background.
    scale : float
        Derivative scale relative to the image height, in [0, 0.1]: Gaussian σ = scale ·
        image_height pixels (0: plain central differences).
    foreshortening : float
        f in [0, 1]; n_z is clamped to >= 0.01 before n_z^f.
    image_height : int, optional
        Height in pixels of the full image these buffers belong to (a crop or tile passes the full
        height); default ``H``. Sets the units (per image height) and σ in pixels.
    depth_jump : float
        Relative depth jump ``|Δ log d|`` between neighbouring samples above which they belong to
        different surfaces, in (0, 10], provided the farther one also lies behind its other
        neighbour (``2d - d- - d+ > (1 - e^-depth_jump)·d`` along a row or column): a slanted
        or curved surface, however fast its depth changes per pixel, is not cut; between
        fronto-parallel surfaces it is the jump alone (module docstring).

    Returns
    -------
    Curvature
        k1 >= k2 per unit image height, the direction of k1, and the reliability weight.
    """
    scale = _check_range("scale", scale, 0.0, 0.1)
    f = _check_range("foreshortening", foreshortening, 0.0, 1.0)
    depth_jump = _check_range("depth_jump", depth_jump, 0.0, 10.0, lo_open=True)
    normal, depth, mask = _check_buffers(normal, depth, mask)
    hgt, wid = depth.shape
    img_h = float(hgt if image_height is None else image_height)
    if not img_h >= 1:
        raise ValueError(f"image_height={image_height!r} must be a positive pixel count")

    sigma_px = scale * img_h
    level = _working_level(sigma_px, (hgt, wid))
    k = 2**level
    exact = hgt % k == 0 and wid % k == 0
    h_l, w_l = (hgt // k, wid // k) if exact else (max(1, round(hgt / k)), max(1, round(wid / k)))
    box_var = (k * k - 1) / 12.0
    # σ in working pixels, less the smoothing of the box downsampling and the central difference.
    var = sigma_px * sigma_px - box_var - k * k / 3.0
    sigma_l = math.sqrt(var) / k if var > 0.0 else 0.0
    if not exact:  # working-grid inputs for the whole frame at once
        whole_n = _downsample(normal, level, (w_l, h_l))
        whole_c = _working_coverage(depth, mask, level, (w_l, h_l))

    def weighted(a0: int, a1: int, c0: int, c1: int, covp: np.ndarray, nch: int) -> np.ndarray:
        """(nch + 1, rows, cols): the first ``nch`` working-grid normal components of rows
        a0..a1, columns c0..c1, times w = [covp != 0], and w (:func:`_weigh_blocks`)."""
        out = np.empty((nch + 1, a1 - a0, c1 - c0), np.float32)
        if exact:
            _weigh_blocks(normal[a0 * k : a1 * k], k, c0, covp, nch, out)
        else:
            _weigh_blocks(whole_n[a0:a1], 1, c0, covp, nch, out)
        return out

    def coverage(a0: int, a1: int) -> tuple[np.ndarray, np.ndarray]:
        """Working-grid coverage and depth of working rows a0..a1."""
        if not exact:
            return whole_c[0][a0:a1], whole_c[1][a0:a1]
        rows = slice(a0 * k, a1 * k)  # box blocks never straddle strips
        if mask is None:
            m8 = _NO_MASK
        elif mask.dtype == np.bool_:  # True is a non-zero byte, all _block_coverage asks
            m8 = np.ascontiguousarray(mask[rows]).view(np.uint8)
        else:
            m8 = _mask_u8(mask[rows])
        cov = np.empty((a1 - a0, w_l), np.uint8)
        depth_l = np.empty((a1 - a0, w_l), np.float32)
        _block_coverage(depth[rows], m8, k, cov, depth_l)
        return cov, depth_l

    radius = max(1, round(1.5 * sigma_l))
    ks = 2 * math.ceil(2.5 * sigma_l) + 1 if sigma_l > 0.0 else 1
    prm = _Params(
        f=f,
        sigma=sigma_l,
        ksize=ks,
        radius=radius,
        depth_jump=depth_jump,
        sx=0.5 * img_h * w_l / wid,  # [-1, 0, 1] spans 2 working pixels
        sy=0.5 * img_h * h_l / hgt,
    )
    # Row strips (with a halo covering every neighbourhood the chain uses) keep the working
    # set in cache and run on parallel threads; the result is the same as one whole pass.
    # The smoothing needs normals 1 + g rows around the strip (g: the kernel's half size), the
    # jump band coverage and depth 3 + radius rows further (the occlusion test reads 2 rows
    # either way, its result is widened by 1 row, then by the radius).
    nhalo = 1 + max(ks // 2, 2)
    halo = 3 + radius + nhalo
    outs = [np.empty((h_l, w_l), np.float32) for _ in range(4)]

    # Only the columns around the covered pixels of a strip are computed: normals count only
    # where covered (away from jumps), so beyond the reach of the smoothing and of the stencils
    # that follow (g + 2 pixels), and again as far from the crop's edge, everything is 0.
    margin = 2 * (nhalo + 1) + radius + 3

    def strip(r0: int, r1: int) -> None:
        a0, a1 = max(0, r0 - halo), min(h_l, r1 + halo)
        cov, depth_l = coverage(a0, a1)
        x, _, bw, _ = cv2.boundingRect(cov)
        rows = [o[r0:r1] for o in outs]
        c0, c1 = (max(0, x - margin), min(w_l, x + bw + margin)) if bw else (0, 0)
        for o in rows:
            o[:, :c0] = 0.0
            o[:, c1:] = 0.0
        if c1 <= c0:
            return
        if (c0, c1) != (0, w_l):
            cov = np.ascontiguousarray(cov[:, c0:c1])
            depth_l = np.ascontiguousarray(depth_l[:, c0:c1])
        weigh = functools.partial(weighted, max(0, r0 - nhalo), min(h_l, r1 + nhalo), c0, c1)
        _hessian_rows(weigh, cov, depth_l, prm, r0 - a0, r1 - a0, [o[:, c0:c1] for o in rows])

    run_strips(h_l, strip, _STRIP_ROWS)
    trace, qx, qy, wgt = outs
    coarse = _Coarse(qx=qx, qy=qy, weight=wgt, trace=trace, size=(hgt, wid), sx=prm.sx, sy=prm.sy)
    return Curvature._lazy(coarse)


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
    cov = cv2.inRange(dbox, 1e-30, _FLT_MAX)
    if mask is not None:
        m = _downsample(_mask_u8(mask), level, size)
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
    lo, hi = np.float32(1e-30), np.float32(_FLT_MAX)
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
    """(trace, q_x, q_y, weight) of rows o0..o1 of a block of working-grid rows into ``out`` (RS §4,
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
def _trace_rows(smooth, nch, wsw, covp, f, rows, coef, trace, qx_out, qy_out, wgt):  # type: ignore[no-untyped-def]
    """The end of :func:`_hessian_rows` in one pass. From the smoothed planes N_x, N_y[, N_z] and
    W = ``smooth[nch]`` (the rows of q): q = (N_x, N_y) / W, times (N_z / W)^-f with N_z / W
    clamped to >= _NZ_MIN when ``nch`` is 3; on q's rows ``rows[0]..rows[1]``, the trace of H = ∇q,
    ``coef[2]``·∂q_x/∂col - ``coef[3]``·∂q_y/∂row (central differences, one-sided and doubled on
    the first and last column and on the first and last row of q), q itself, and the weight
    t²(3 - 2t)·[3x3 of ``covp`` all covered], t = clip((``wsw`` - coef[0])·coef[1], 0, 1)."""
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
        tr, px, py, wg = trace[i], qx_out[i], qy_out[i], wgt[i]
        cx = qx[r]
        up = qy[r - 1] if r > 0 else qy[r]
        dn = qy[r + 1] if r + 1 < nq else qy[r]
        ys = sy if 0 < r < nq - 1 else two * sy
        if nq < 2:
            ys = zero
        for j in range(1, wid - 1):
            tr[j] = sx * (cx[j + 1] - cx[j - 1]) - ys * (dn[j] - up[j])
        if wid >= 2:
            tr[0] = two * sx * (cx[1] - cx[0]) - ys * (dn[0] - up[0])
            tr[wid - 1] = two * sx * (cx[wid - 1] - cx[wid - 2]) - ys * (dn[wid - 1] - up[wid - 1])
        else:
            tr[0] = zero
        px[:] = cx
        py[:] = qy[r]
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


def _phi(x: float) -> float:
    """Standard normal CDF."""
    return 0.5 * (1.0 + math.erf(x / math.sqrt(2.0)))


def _deriv_x(q: np.ndarray, scale: float) -> np.ndarray:
    """``scale`` · (q[:, x+1] - q[:, x-1]); one-sided (doubled) on the first and last column."""
    out = np.empty_like(q)
    w = q.shape[1]
    if w >= 3:
        cv2.addWeighted(q[:, 2:], scale, q[:, :-2], -scale, 0.0, dst=out[:, 1:-1])
    if w >= 2:
        s2 = np.float32(2.0 * scale)
        np.multiply(np.subtract(q[:, 1], q[:, 0]), s2, out=out[:, 0])
        np.multiply(np.subtract(q[:, -1], q[:, -2]), s2, out=out[:, -1])
    else:
        out[...] = 0.0
    return out


def _deriv_y(q: np.ndarray, r0: int, r1: int, scale: float) -> np.ndarray:
    """``scale`` · (q[y+1] - q[y-1]) for rows r0..r1 of ``q``; one-sided (doubled) on the first and
    last row of ``q`` (the image's: inner strips always have a neighbour row)."""
    n = q.shape[0]
    out = np.empty((r1 - r0, q.shape[1]), np.float32)
    lo, hi = max(r0, 1), min(r1, n - 1)
    if hi > lo:
        cv2.addWeighted(
            q[lo + 1 : hi + 1], scale, q[lo - 1 : hi - 1], -scale, 0.0, dst=out[lo - r0 : hi - r0]
        )
    if n >= 2:
        s2 = np.float32(2.0 * scale)
        if r0 == 0:
            np.multiply(np.subtract(q[1], q[0]), s2, out=out[0])
        if r1 == n:
            np.multiply(np.subtract(q[n - 1], q[n - 2]), s2, out=out[-1])
    else:
        out[...] = 0.0
    return out


# -- curvature mappings ----------------------------------------------------------------------------


def _tanh_weighted(x: np.ndarray, s: float, weight: np.ndarray) -> np.ndarray:
    """tanh(s·x) · weight of (h, w) planes (NaN x counts as 0), float32, in one compiled pass."""
    x = np.ascontiguousarray(x, dtype=np.float32)
    weight = np.ascontiguousarray(weight, dtype=np.float32)
    out = np.empty(x.shape, np.float32)
    s2 = np.float32(2.0 * s)
    run_strips(
        x.shape[0],
        lambda r0, r1: _tanh_weighted_rows(x[r0:r1], s2, weight[r0:r1], out[r0:r1]),
        _STRIP_ROWS,
    )
    return out


@kernel
def _tanh_weighted_rows(x, s2, weight, out):  # type: ignore[no-untyped-def]
    """out = tanh(s2/2 · x) · weight as 1 − 2 / (e^{s2·x} + 1), which saturates cleanly (the
    exponent is clamped to ±87 by :func:`expf`), and is exactly 0 at x = 0."""
    zero, one, two = np.float32(0.0), np.float32(1.0), np.float32(2.0)
    for i in range(out.shape[0]):
        xr, wr, o = x[i], weight[i], out[i]
        for j in range(o.shape[0]):
            a = s2 * xr[j]
            a = a if a == a else zero
            o[j] = (one - two / (expf(a) + one)) * wr[j]


def _check_gain(gain: float) -> float:
    return _check_range("gain", gain, 0.0, 1e6)


def isotropic(curv: Curvature, gain: float = DEFAULT_GAIN) -> np.ndarray:
    """Isotropic curvature mapping κ = tanh(s·(κ1 + κ2)) · weight (Radiance Scaling §4).

    The paper writes κ(p) = tanh(κu + κv), "mean curvature mapped to [-1, 1]"; κ1 + κ2 is twice
    the mean curvature. ``gain`` s in [0, 1e6] rescales it since κ is per unit image height (a
    sphere spanning half the image height has κ1 + κ2 = 8; the default 0.03 maps it to 0.24).

    Returns
    -------
    (H, W) float32 in [-1, 1], 0 where ``curv.weight`` is 0.
    """
    return np.asarray(isotropic_field(curv, gain))


def isotropic_field(curv: Curvature, gain: float = DEFAULT_GAIN) -> Upsampled:
    """:func:`isotropic` left on the working grid: the tanh is mapped there and the result is
    read through bilinear upsampling (:class:`ops.bilinear.Upsampled`), so a kernel that
    consumes κ (:func:`ops.scaling.scale_lobes`) interpolates each row as it needs it instead of
    reading a full-resolution plane; ``np.asarray`` of it is :func:`isotropic`."""
    s = _check_gain(gain)
    coarse = curv._coarse_for("k1", "k2", "weight")
    if coarse is not None:
        return Upsampled(_tanh_weighted(coarse.trace, s, coarse.weight), coarse.size)
    trace = cv2.add(curv.k1, curv.k2)
    return Upsampled(_tanh_weighted(trace, s, curv.weight), trace.shape)


def anisotropic(
    curv: Curvature,
    light_dir: np.ndarray,
    gain: float = DEFAULT_GAIN,
    lam: float = 0.0,
) -> np.ndarray:
    """Anisotropic curvature mapping κ(p, ℓ) (Radiance Scaling §4)::

        κ(p, ℓ) = tanh((H + λΔκ)·ℓu² + (H − λΔκ)·ℓv² + H·ℓz²),  H = κu + κv,  Δκ = κu − κv

    with ℓ = (ℓu, ℓv, ℓz) the unit light direction in the frame of the principal directions u (of
    κ1), v and the view axis z, and λ ∈ [-1, 1]: λ = 0 gives the isotropic tanh(H) for every ℓ,
    λ = 1 favours the curvature along the light's projection, λ = -1 the one across it. As ℓ is
    unit, the argument is H + λΔκ(ℓu² − ℓv²). (The paper's "κ(p, u) = tanh(κu)" for λ = 1 reads
    tanh(2κu) with H = κu + κv as written; Depict keeps the formula, so that λ = 0 matches the
    isotropic mapping.) The argument is multiplied by ``gain`` and the result by ``curv.weight``.

    Parameters
    ----------
    curv : Curvature
    light_dir : (3,) or (H, W, 3)
        Camera-space direction towards the light (normalised here).
    gain : float
        s in [0, 1e6], as in :func:`isotropic`.
    lam : float
        λ in [-1, 1].
    """
    s = _check_gain(gain)
    lam = _check_range("lam", lam, -1.0, 1.0)
    ell = np.asarray(light_dir, dtype=np.float32)
    if ell.shape == (3,):
        norm = float(np.linalg.norm(ell))
        if not norm > 0.0 or not math.isfinite(norm):
            raise ValueError("light_dir must be a non-zero finite 3-vector")
        lx, ly = float(ell[0]) / norm, float(ell[1]) / norm
        # With θ the angle of u and φ = 2θ: ℓu² − ℓv² = (lx² − ly²)·cos φ + 2·lx·ly·sin φ, and
        # Δκ·(cos φ, sin φ) = 2·(d, b) for the Hessian's (a − c)/2 = d and off-diagonal b.
        cx, cy = lx * lx - ly * ly, 2.0 * lx * ly
        coarse = curv._coarse_for(*_FIELDS)
        if coarse is not None:  # on the working grid, interpolated once
            arg = cv2.addWeighted(coarse.d, 2.0 * lam * cx, coarse.b, 2.0 * lam * cy, 0.0)
            cv2.add(arg, coarse.trace, dst=arg)
            return coarse.upsample(_tanh_weighted(arg, s, coarse.weight))
        c2 = cv2.subtract(
            cv2.multiply(curv.dir_x, curv.dir_x), cv2.multiply(curv.dir_y, curv.dir_y)
        )
        s2 = cv2.multiply(curv.dir_x, curv.dir_y, scale=2.0)
        proj = cv2.addWeighted(c2, cx, s2, cy, 0.0)
    elif ell.shape == (*curv.k1.shape, 3):
        ex, ey, ez = cv2.split(np.ascontiguousarray(ell))
        inv = cv2.magnitude(cv2.magnitude(ex, ey), ez)
        np.maximum(inv, np.float32(1e-20), out=inv)
        np.divide(np.float32(1.0), inv, out=inv)
        lu = cv2.add(cv2.multiply(ex, curv.dir_x), cv2.multiply(ey, curv.dir_y))
        lv = cv2.subtract(cv2.multiply(ey, curv.dir_x), cv2.multiply(ex, curv.dir_y))
        cv2.multiply(lu, inv, dst=lu)
        cv2.multiply(lv, inv, dst=lv)
        proj = cv2.subtract(cv2.multiply(lu, lu), cv2.multiply(lv, lv))
    else:
        raise ValueError(
            f"light_dir must have shape (3,) or {(*curv.k1.shape, 3)}, got {ell.shape}"
        )
    trace = cv2.add(curv.k1, curv.k2)
    delta = cv2.subtract(curv.k1, curv.k2)
    arg = cv2.add(trace, cv2.multiply(delta, proj, scale=lam))
    return _tanh_weighted(arg, s, curv.weight)


def mean_curvature_layers(curv: Curvature, gain: float = DEFAULT_GAIN) -> dict[str, np.ndarray]:
    """Output layers of the ``curvature`` operator.

    Returns ``{"H": isotropic(curv, gain), "k1": k1·weight, "k2": k2·weight, "dir.X": dir_x,
    "dir.Y": dir_y}`` (float32, (H, W)); H is the mapped curvature tanh(s·(κ1 + κ2)) in [-1, 1]
    (Radiance Scaling §4), k1/k2 are per unit image height and 0 where the weight is 0.
    """
    # + 0.0 turns the -0.0 of a negative k times a zero weight into 0.0: the values under a zero
    # weight are left over from the working grid, and their sign must not reach the file
    return {
        "H": isotropic(curv, gain),
        "k1": cv2.add(cv2.multiply(curv.k1, curv.weight), 0.0),
        "k2": cv2.add(cv2.multiply(curv.k2, curv.weight), 0.0),
        "dir.X": curv.dir_x.copy(),
        "dir.Y": curv.dir_y.copy(),
    }
