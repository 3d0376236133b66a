"""View-centred principal curvatures of a G-buffer (Radiance Scaling §4)."""

from __future__ import annotations

import functools
import math
from typing import Any

import cv2
import numpy as np

from ops.checks import CURVATURE_DEPTH_JUMP, CURVATURE_SCALE, FRACTION
from ops.curvature import _common
from ops.curvature._common import (
    DEFAULT_DEPTH_JUMP,
    DEFAULT_FORESHORTENING,
    DEFAULT_SCALE,
)
from ops.curvature._hessian import (
    _NO_MASK,
    _block_coverage,
    _hessian_rows,
    _Params,
    _weigh_blocks,
    _working_coverage,
)
from ops.curvature._jumps import _check_buffers, _mask_u8, _working_level
from ops.curvature.result import Curvature, _Coarse
from ops.parallel import run_strips
from ops.pyramid.reduce import box_downsample

#: cv2 for calls with Python scalars or None where its stubs only list arrays (Scalar arguments,
#: default kernels); same module, untyped.
_cv: Any = cv2

__all__ = ["principal_curvatures"]


def _working_grid(
    sigma_px: float, shape: tuple[int, int]
) -> tuple[int, bool, tuple[int, int], float]:
    """The level whose grid the curvature is computed on (cells of 2^level pixels), whether its
    cells divide the image exactly, that grid's (rows, columns) and the Gaussian σ left to
    apply there, in its pixels: ``sigma_px`` less the smoothing of the box downsampling and of
    the central difference."""
    hgt, wid = shape
    level = _working_level(sigma_px, shape)
    k = 2**level
    exact = hgt % k == 0 and wid % k == 0
    h_l, w_l = (hgt // k, wid // k) if exact else (max(1, round(hgt / k)), max(1, round(wid / k)))
    box_var = (k * k - 1) / 12.0
    var = sigma_px * sigma_px - box_var - k * k / 3.0
    return level, exact, (h_l, w_l), math.sqrt(var) / k if var > 0.0 else 0.0


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
    scale = CURVATURE_SCALE.check(scale, "scale")
    f = FRACTION.check(foreshortening, "foreshortening")
    depth_jump = CURVATURE_DEPTH_JUMP.check(depth_jump, "depth_jump")
    normal, depth, mask = _check_buffers(normal, depth, mask)
    hgt, wid = depth.shape
    img_h = float(hgt if image_height is None else image_height)
    if not img_h >= 1:
        raise ValueError(f"image_height={image_height!r} must be a positive pixel count")

    level, exact, (h_l, w_l), sigma_l = _working_grid(scale * img_h, (hgt, wid))
    k = 2**level
    if not exact:  # working-grid inputs for the whole frame at once
        whole_n = box_downsample(normal, level, (w_l, h_l))
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

    run_strips(h_l, strip, _common._STRIP_ROWS)
    trace, d, b, wgt = outs
    coarse = _Coarse(trace=trace, d=d, b=b, weight=wgt, size=(hgt, wid))
    return Curvature._lazy(coarse)
