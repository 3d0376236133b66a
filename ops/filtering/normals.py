"""The multi-scale normals n_1 … n_S of LLA §5 (joint bilateral filtering on log depth, run on the
depth-aware pyramid), and unit-field normalisation."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from ops.checks import FACTOR, LLA_BASE, LLA_DEPTH_SIGMA, SCALES
from ops.filtering._common import (
    _MAX_LEVEL_SIGMA,
    DEFAULT_BASE,
    DEFAULT_DEPTH_SIGMA,
    DEFAULT_FACTOR,
    DEFAULT_SCALES,
    F32,
)
from ops.filtering._kernels import _JBF_TAPS, _jbf_rows
from ops.parallel import STRIP_PIXELS, run_strips, strip_rows
from ops.pyramid.depth import DepthPyramid, normalize_field

__all__ = ["NormalPyramid", "multiscale_normals", "normal_pyramid", "scale_sigmas_px"]


@dataclass
class NormalPyramid:
    """Multi-scale normals n_1 … n_S, each stored at the pyramid level it was filtered at.

    Attributes
    ----------
    geometry : the :class:`DepthPyramid` (log depth and coverage per level).
    normals : n_i (0-based list) at level ``levels[i]``, (h, w, 3) float32, unit, 0 on background.
    levels : pyramid level of each n_i (n_1 at level 0).
    sigmas_px : spatial σ (full-resolution pixels) of each filter n_i → n_{i+1}.
    """

    geometry: DepthPyramid
    normals: list[F32]
    levels: list[int]
    sigmas_px: list[float]
    _planes: dict[int, tuple[F32, F32, F32]] = field(default_factory=dict, repr=False)

    def planes(self, i: int) -> tuple[F32, F32, F32]:
        """n_{i+1} (0-based ``i``) at its level as three (h, w) planes (cached)."""
        got = self._planes.get(i)
        if got is None:
            x, y, z = (np.asarray(c, np.float32) for c in cv2.split(self.normals[i]))
            got = self._planes[i] = (x, y, z)
        return got

    @property
    def scales(self) -> int:
        return len(self.normals)

    @property
    def shape(self) -> tuple[int, int]:
        return self.geometry.shape(0)

    @property
    def mask(self) -> np.ndarray:
        """(H, W) bool coverage."""
        return self.geometry.mask[0] > 0

    def at(self, i: int, k: int, rows: tuple[int, int] | None = None) -> F32:
        """n_{i+1} (0-based ``i``) at pyramid level ``k`` (edge-aware up- or downsampled)."""
        lvl = self.levels[i]
        out = (
            self.geometry.down(self.normals[i], lvl, k)
            if k >= lvl
            else self.geometry.up(self.normals[i], lvl, k)
        )
        return out if rows is None else out[rows[0] : rows[1]]

    def full(self, i: int) -> F32:
        """n_{i+1} (0-based ``i``) at full resolution, unit length, 0 on background."""
        return self.at(i, 0)

    def full_list(self) -> list[F32]:
        """[n_1, …, n_S] at full resolution."""
        return [self.full(i) for i in range(self.scales)]


def scale_sigmas_px(height: int, scales: int, base: float, factor: float) -> list[float]:
    """σ_i = base · H · factor^(i−1), i = 1 … S−1, in pixels (LLA §5: × 1.7 per scale)."""
    return [base * height * factor**i for i in range(scales - 1)]


def _level_for(sigma_px: float, max_level: int) -> int:
    k = 0
    while k < max_level and sigma_px / (1 << k) > _MAX_LEVEL_SIGMA:
        k += 1
    return k


def _validate(
    normal: np.ndarray,
    depth: np.ndarray,
    scales: int,
    base: float,
    factor: float,
    depth_sigma: float,
) -> tuple[F32, F32]:
    normal = np.asarray(normal, np.float32)
    depth = np.asarray(depth, np.float32)
    if normal.ndim != 3 or normal.shape[2] != 3:
        raise ValueError(f"normal must be (H, W, 3), got shape {normal.shape}")
    if depth.shape != normal.shape[:2]:
        raise ValueError(f"depth must be (H, W) = {normal.shape[:2]}, got shape {depth.shape}")
    if isinstance(scales, bool) or not isinstance(scales, int | np.integer) or scales not in SCALES:
        raise ValueError(f"scales must be an integer in {SCALES}, got {scales!r}")
    LLA_BASE.check(base, "base")
    FACTOR.check(factor, "factor")
    LLA_DEPTH_SIGMA.check(depth_sigma, "depth_sigma")
    return normal, depth


def normal_pyramid(
    normal: np.ndarray,
    depth: np.ndarray,
    mask: np.ndarray | None = None,
    *,
    scales: int = DEFAULT_SCALES,
    base: float = DEFAULT_BASE,
    factor: float = DEFAULT_FACTOR,
    depth_sigma: float = DEFAULT_DEPTH_SIGMA,
) -> NormalPyramid:
    """Multi-scale normals by successive depth-guided bilateral filtering (LLA §5).

    n_1 = ``normal``; n_{i+1} = normalize(Σ_q G_{σ_i}(p − q) G_{depth_sigma}(log d_p − log d_q)
    n_i(q)), σ_i = ``base`` · H · ``factor``^(i−1) pixels (Mestres et al. 2021, §5,
    "Implementation details": bilateral filtering with the range kernel on depth, spatial size
    × 1.7 per coarser scale). Each filter runs at the pyramid level where σ_i ≤ 1.5 px.

    Parameters
    ----------
    normal : (H, W, 3) camera-space unit normals (background ignored).
    depth : (H, W) planar depth, +inf (or ≤ 0, NaN) on background.
    mask : optional (H, W) coverage; pixels where it is 0/False are background.
    scales : S, number of normal fields (2 … 12).
    base : σ_1 relative to the image height, in (0, 1].
    factor : growth of σ per scale, in [1, 4].
    depth_sigma : range-kernel σ on log depth (relative depth), in (0, 10].

    Returns
    -------
    NormalPyramid
        ``.full_list()`` gives the (H, W, 3) fields; :func:`ops.light_alignment.align_light`
        uses the pyramid directly to align coarse scales at low resolution.
    """
    normal, depth = _validate(normal, depth, scales, base, factor, depth_sigma)
    h = normal.shape[0]
    sig = scale_sigmas_px(h, int(scales), base, factor)
    max_level = max(0, math.floor(math.log2(max(1, min(normal.shape[:2]) // 4))))
    levels = [0] + [_level_for(s, max_level) for s in sig]
    geo = DepthPyramid.build(depth, mask, max(levels), depth_sigma)
    # n_1 is the input as is: background pixels have zero weight in every block average.
    normals: list[F32] = [normal]
    for i, s in enumerate(sig):
        k = levels[i + 1]
        src = geo.down(normals[i], levels[i], k) if k > levels[i] else normals[i]
        normals.append(_bilateral(src, geo, k, s / (1 << k)))
    return NormalPyramid(geometry=geo, normals=normals, levels=levels, sigmas_px=sig)


def _bilateral(src: F32, geo: DepthPyramid, k: int, sigma: float) -> F32:
    """Joint bilateral filter of a unit-vector field at level k, guided by log depth, then
    renormalised and 0 on background (LLA §5).

    Weights G_σ(p − q) G_r(g_p − g_q) over the circular window of radius
    max(1, round(1.5 σ)) (that of ``cv2.ximgproc.jointBilateralFilter``, borders reflected; at
    most the level's longer side),
    G_r of standard deviation ``depth_sigma`` on the guide g: log depth, background far behind
    every surface. Radii ≤ 2 (every level the pyramid picks, σ ≤ 1.5) run the compiled
    :func:`_jbf_rows` on row strips, with G_r evaluated to 2e-7 (:func:`ops.numerics.exp_neg`);
    larger ones (levels capped by a small image) ``cv2.ximgproc.jointBilateralFilter``.
    """
    m = geo.mask[k]
    valid = m > 0
    if not np.any(valid):
        return np.zeros_like(src)
    # background: far behind everything (its range weight to surfaces is e^-800)
    logd = geo.logd[k] if k > 0 else np.where(valid, geo.logd[0], np.float32(0.0))
    far = max(float(logd.max()), 0.0) + 40.0 * geo.depth_sigma
    guide = np.asarray(logd + (np.float32(1.0) - m) * np.float32(far), np.float32)
    # (a window wider than the level only adds reflected copies of it: at most one each side,
    # whatever σ, or its padded copy would grow with σ², to tens of GB at the widest scales)
    radius = min(max(1, round(1.5 * sigma)), max(m.shape))
    if radius > 2:
        out = cv2.ximgproc.jointBilateralFilter(
            guide, np.ascontiguousarray(src), 2 * radius + 1, geo.depth_sigma, sigma
        )
        return normalize_field(np.asarray(out, np.float32), m)
    h, w = m.shape
    border = cv2.BORDER_REFLECT_101
    guide_p = cv2.copyMakeBorder(guide, 2, 2, 2, 2, border)
    src_p = cv2.copyMakeBorder(np.ascontiguousarray(src, np.float32), 2, 2, 2, 2, border)
    src_p = src_p.reshape(h + 4, 3 * (w + 4))
    sw = np.array(
        [
            math.exp(-0.5 * (dy * dy + dx * dx) / (sigma * sigma))
            if dy * dy + dx * dx <= radius * radius
            else 0.0
            for dy, dx in _JBF_TAPS
        ],
        np.float32,
    )
    c = np.float32(0.5 / (geo.depth_sigma * geo.depth_sigma))
    res = np.empty((h, w, 3), np.float32)
    flat = res.reshape(h, 3 * w)

    def strip(r0: int, r1: int) -> None:
        _jbf_rows(guide_p[r0 : r1 + 4], src_p[r0 : r1 + 4], m[r0:r1], sw, c, flat[r0:r1])

    run_strips(h, strip, rows=strip_rows(w, STRIP_PIXELS // 4))
    return res


def multiscale_normals(
    normal: np.ndarray,
    depth: np.ndarray,
    mask: np.ndarray | None = None,
    *,
    scales: int = DEFAULT_SCALES,
    base: float = DEFAULT_BASE,
    factor: float = DEFAULT_FACTOR,
    depth_sigma: float = DEFAULT_DEPTH_SIGMA,
) -> list[F32]:
    """[n_1, …, n_S]: multi-scale normals at full resolution (LLA §5; see :func:`normal_pyramid`).

    n_{i+1} = normalize(Σ_q G_{σ_i}(p − q) G_{depth_sigma}(log d_p − log d_q) n_i(q)),
    σ_i = ``base`` · H · ``factor``^(i−1) (Mestres et al. 2021, §5). Each (H, W, 3) float32,
    unit length on surfaces, 0 on background; n_1 is the input.
    """
    return normal_pyramid(
        normal, depth, mask, scales=scales, base=base, factor=factor, depth_sigma=depth_sigma
    ).full_list()
