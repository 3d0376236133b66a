"""Baseline depictions Local Light Alignment is compared with (Mestres et al. 2021, §7, Fig. 14).

- :func:`lambert_image`: the original Lambertian rendering (Fig. 14 a).
- :func:`exaggerated_shading`: Exaggerated Shading, Rusinkiewicz, Burns & DeCarlo, "Exaggerated
  Shading for Depicting Shape and Detail", ACM TOG 25(3) (SIGGRAPH 2006) (Fig. 14 c).
- :func:`light_warping`: an image-space approximation, for one directional light, of Light
  Warping, Vergne, Pacanowski, Barla, Granier & Schlick, "Light warping for enhanced surface
  depiction", ACM TOG 28(3) (SIGGRAPH 2009) (Fig. 14 d).

All work on camera-space G-buffers (OpenGL convention, DESIGN.md), take light directions pointing
from the surface towards the light, and return (H, W) float32 images that are 0 on background.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import cv2
import numpy as np
from numpy.typing import NDArray

from ops.checks import CONTRAST, ES_SCALE, FRACTION, WEIGHT, WEIGHT_EXPONENT
from ops.curvature import DEFAULT_GAIN, DEFAULT_SCALE, isotropic, principal_curvatures
from ops.parallel import run_strips
from ops.shading import dot, lambert, normalize

__all__ = [
    "ES_SCALES",
    "exaggerated_shading",
    "lambert_image",
    "light_warping",
    "smoothed_normals",
    "warp_light",
]

F32 = NDArray[np.float32]

#: Default smoothing scales of Exaggerated Shading (Gaussian σ relative to the image height).
ES_SCALES: tuple[float, ...] = (0.0025, 0.005, 0.01, 0.02, 0.04)

# Rows per strip of the per-pixel combination of the scales.
_ES_ROWS = 64


def _light(light_dir: Sequence[float] | NDArray[np.floating]) -> F32:
    arr = np.asarray(light_dir, np.float64).reshape(-1)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"light_dir must be 3 finite numbers, got {light_dir!r}")
    norm = float(np.linalg.norm(arr))
    if norm < 1e-12:
        raise ValueError("light_dir must not be (0, 0, 0)")
    return (arr / norm).astype(np.float32)


def _normal_field(normal: NDArray[np.floating], name: str = "normal") -> F32:
    n = np.asarray(normal, np.float32)
    if n.ndim != 3 or n.shape[2] != 3:
        raise ValueError(f"{name} must be (H, W, 3), got shape {n.shape}")
    if np.isnan(n).any():
        raise ValueError(f"{name} contains NaN")
    return n


def _coverage(
    normal: F32,
    depth: NDArray[np.floating] | None,
    mask: NDArray[np.generic] | None,
) -> NDArray[np.bool_]:
    """Covered pixels: non-zero normal, and finite positive depth / mask > 0.5 when given."""
    shape = normal.shape[:2]
    cov = dot(normal, normal) > 0.25
    if depth is not None:
        d = np.asarray(depth)
        if d.shape != shape:
            raise ValueError(f"depth must be (H, W) = {shape}, got shape {d.shape}")
        if np.isnan(d).any():
            raise ValueError("depth contains NaN (use +inf for background)")
        cov &= (d > 0) & (d < np.inf)
    if mask is not None:
        m = np.asarray(mask)
        if m.shape != shape:
            raise ValueError(f"mask must be (H, W) = {shape}, got shape {m.shape}")
        cov &= m > 0.5
    return np.asarray(cov)


def lambert_image(
    normal: NDArray[np.floating],
    mask: NDArray[np.generic] | None,
    light_dir: Sequence[float] | NDArray[np.floating],
    albedo: float | NDArray[np.floating] | None = None,
) -> F32:
    """Lambertian rendering ρ max(n·ℓ, 0) of one directional light (LLA §7, Fig. 14 a).

    Parameters
    ----------
    normal : (H, W, 3) camera-space unit normals.
    mask : (H, W) coverage or None (then pixels with a non-zero normal).
    light_dir : (3,) direction towards the light (normalised here).
    albedo : scalar or (H, W) albedo ρ (default 1).

    Returns
    -------
    (H, W) float32, 0 on background; uses :func:`ops.shading.lambert`.
    """
    n = _normal_field(normal)
    cov = _coverage(n, None, mask)
    img = lambert(n, _light(light_dir))
    if albedo is not None:
        alb = np.asarray(albedo, np.float32)
        if alb.ndim not in (0, 2) or (alb.ndim == 2 and alb.shape != img.shape):
            raise ValueError(f"albedo must be a scalar or (H, W) = {img.shape}, got {alb.shape}")
        if not np.all(np.isfinite(alb)) or np.any(alb < 0):
            raise ValueError("albedo must be finite and >= 0")
        img = img * alb
    return np.where(cov, img, 0).astype(np.float32)


def _f32(x: object) -> F32:
    """An OpenCV result as a float32 array (no copy)."""
    return np.asarray(x, np.float32)


def _level_factor(sigma_px: float, h: int, w: int) -> int:
    """Area-downsampling factor of the level a Gaussian of ``sigma_px`` is applied at (σ ≈ 4 px
    there), so that every σ costs about the same."""
    f = max(1, int(sigma_px / 4.0))
    return min(f, max(1, h // 4), max(1, w // 4))


def _reach(sigma: float) -> int:
    """An upper bound of the radius of OpenCV's float Gaussian kernel for ``sigma`` (its size
    is round(8σ + 1) | 1)."""
    return int(4.0 * sigma) + 1


def _box(cov: NDArray[np.bool_]) -> tuple[int, int, int, int] | None:
    """Rows and columns (y0, y1, x0, x1) of the bounding box of the covered pixels, or None."""
    x, y, bw, bh = cv2.boundingRect(cov.view(np.uint8))
    return None if bw == 0 or bh == 0 else (y, y + bh, x, x + bw)


def _grown(
    box: tuple[int, int, int, int], f: int, margin: int, shape: tuple[int, int]
) -> tuple[int, int, int, int]:
    """``box`` (full resolution) at the level downsampled by ``f`` (of ``shape``), grown by
    ``margin`` level pixels. The first column is a multiple of 16 and the box extends 16 more
    columns on the right, so that OpenCV's vectorised filters treat every column that is not 0
    with the same lanes as on the whole level (a bit-identical result)."""
    y0, y1, x0, x1 = box
    h, w = shape
    return (
        max(0, y0 // f - margin),
        min(h, -(-y1 // f) + margin),
        max(0, x0 // f - margin) // 16 * 16,
        min(w, -(-x1 // f) + margin + 16),
    )


#: One smoothed field: its three components, the G*m they are still to be divided by (or
#: None), and the full-resolution (row, column) of their first pixel.
_Part = tuple[list[F32], F32 | None, tuple[int, int]]


def _smoothed_components(
    n: F32, covf: F32, sigmas_px: Sequence[float], box: tuple[int, int, int, int]
) -> list[_Part]:
    """Mask-normalised Gaussian smoothing G*(n m) / G*m of the normals at each σ (pixels), as
    the three components at full resolution and, for the scales blurred at full resolution,
    the G*m they are still to be divided by (:func:`_unit_rows` does it, on strips).

    Large σ are blurred on an area-downsampled copy (σ ≈ 4 px there, :func:`_level_factor`),
    normalised there and upsampled bilinearly. The work is done one channel at a time
    (OpenCV's blur and resize are much faster on single channels, and its filters are
    single-threaded: the blurs of all scales and channels run on parallel threads), and
    only on the covered pixels' bounding ``box`` grown by more than the blur's reach (G*(n m)
    and G*m are exactly 0 further away): the full-resolution components only cover that.
    """
    h, w = covf.shape
    chans = [np.asarray(cv2.multiply(c, covf), np.float32) for c in cv2.split(n)] + [covf]
    plans: list[tuple[int, float, tuple[int, int], tuple[int, int, int, int], list[F32]]] = []
    for s in sigmas_px:
        f = _level_factor(s, h, w)
        shape = (max(h // f, 1), max(w // f, 1))
        y0, y1, x0, x1 = _grown(box, f, _reach(s / f) + 2, shape)
        if f == 1:
            crops = [np.ascontiguousarray(c[y0:y1, x0:x1]) for c in chans]
        elif (h % f, w % f) == (0, 0):
            # an integer area resize of the window's pixels gives the window of the level
            win = (slice(y0 * f, y1 * f), slice(x0 * f, x1 * f))
            size = (x1 - x0, y1 - y0)
            crops = [
                _f32(cv2.resize(np.ascontiguousarray(c[win]), size, interpolation=cv2.INTER_AREA))
                for c in chans
            ]
        else:
            small = [_f32(cv2.resize(c, shape[::-1], interpolation=cv2.INTER_AREA)) for c in chans]
            crops = [np.ascontiguousarray(c[y0:y1, x0:x1]) for c in small]
        plans.append((f, s / f, shape, (y0, y1, x0, x1), crops))
    # blur tasks (scale, channel), the largest first so that the threads balance
    tasks = sorted(
        ((i, j) for i in range(len(plans)) for j in range(4)),
        key=lambda t: -plans[t[0]][4][0].size * plans[t[0]][1],
    )
    blurred: list[list[F32]] = [[covf] * 4 for _ in plans]

    def blur(a: int, b: int) -> None:
        for i, j in tasks[a:b]:
            _, sig, _, _, crops = plans[i]
            blurred[i][j] = np.asarray(cv2.GaussianBlur(crops[j], (0, 0), sig), np.float32)

    run_strips(len(tasks), blur, rows=1)

    out: list[_Part] = []
    for (f, _, shape, (y0, y1, x0, x1), _), bl in zip(plans, blurred, strict=True):
        if f == 1:
            out.append((bl[:3], bl[3], (y0, x0)))
            continue
        wsum = bl[3]
        low = [np.divide(c, wsum, out=np.zeros_like(c), where=wsum > 1e-6) for c in bl[:3]]
        if (h % f, w % f) != (0, 0):
            # not an integer upsampling: the whole level, 0 outside the window
            comps = []
            for c in low:
                full = np.zeros(shape, np.float32)
                full[y0:y1, x0:x1] = c
                comps.append(_f32(cv2.resize(full, (w, h), interpolation=cv2.INTER_LINEAR)))
            out.append((comps, None, (0, 0)))
            continue
        # upsample only the box (with one level pixel around it, so that the bilinear
        # weights and neighbours are those of the whole level: the same result)
        v0, v1 = max(0, box[0] // f - 1), min(shape[0], -(-box[1] // f) + 1)
        u0, u1 = max(0, box[2] // f - 1), min(shape[1], -(-box[3] // f) + 1)
        size = ((u1 - u0) * f, (v1 - v0) * f)
        sub = (slice(v0 - y0, v1 - y0), slice(u0 - x0, u1 - x0))
        comps = [
            _f32(cv2.resize(np.ascontiguousarray(c[sub]), size, interpolation=cv2.INTER_LINEAR))
            for c in low
        ]
        out.append((comps, None, (v0 * f, u0 * f)))
    return out


def _part_rows(part: _Part, rows: slice, cols: slice) -> tuple[list[F32], F32 | None]:
    """The components (and G*m) of one smoothed field at full-resolution ``rows``, ``cols``."""
    comps, wsum, (oy, ox) = part
    r = slice(rows.start - oy, rows.stop - oy)
    c = slice(cols.start - ox, cols.stop - ox)
    return [x[r, c] for x in comps], None if wsum is None else wsum[r, c]


def _unit_rows(comps: Sequence[F32], wsum: F32 | None, covf: F32) -> F32:
    """Pixels of one smoothed field: (G*(n m) / G*m when ``wsum`` = G*m is given),
    renormalised (0 where the vector is ~0) and multiplied by the coverage: (h, w, 3)."""
    if wsum is not None:
        # at full resolution every covered pixel has G*m > 1e-6 (the blur's centre weight
        # alone is larger): dividing by max(G*m, 1e-6) instead of leaving 0 where G*m <= 1e-6
        # only changes background pixels, which the coverage sets to 0 below
        ws = np.maximum(wsum, np.float32(1e-6))
        comps = [_f32(cv2.divide(c, ws)) for c in comps]
    len2 = cv2.add(
        cv2.add(cv2.multiply(comps[0], comps[0]), cv2.multiply(comps[1], comps[1])),
        cv2.multiply(comps[2], comps[2]),
    )
    inv = np.divide(1.0, cv2.sqrt(len2), out=np.zeros_like(len2), where=len2 > 1e-12)
    g = cv2.multiply(inv, covf)
    return np.asarray(cv2.merge([cv2.multiply(c, g) for c in comps]), np.float32)


def smoothed_normals(
    normal: NDArray[np.floating],
    mask: NDArray[np.generic] | None,
    scales: Sequence[float],
    *,
    image_height: int | None = None,
) -> list[F32]:
    """Gaussian-smoothed, renormalised normals at each σ of ``scales`` (relative to image height).

    The smoothing is mask-normalised (G*(n m) / G*m, so background does not bleed in) and each
    scale is filtered from the original normals, as Exaggerated Shading §3.1 does on the mesh
    (σ growing geometrically); here the smoothing is in image space. 0 on background.
    """
    n = _normal_field(normal)
    cov = _coverage(n, None, mask).astype(np.float32)
    href = n.shape[0] if image_height is None else int(image_height)
    box = _box(cov > 0.5)
    if box is None:
        return [np.zeros_like(n) for _ in scales]
    y0, y1, x0, x1 = box
    rows, cols = slice(y0, y1), slice(x0, x1)
    out = []
    for part in _smoothed_components(n, cov, [float(s) * href for s in scales], box):
        field = np.zeros_like(n)
        field[rows, cols] = _unit_rows(*_part_rows(part, rows, cols), cov[rows, cols])
        out.append(field)
    return out


def exaggerated_shading(
    normal: NDArray[np.floating],
    depth: NDArray[np.floating] | None,
    mask: NDArray[np.generic] | None,
    light_dir: Sequence[float] | NDArray[np.floating],
    *,
    scales: Sequence[float] = ES_SCALES,
    contrast: float = 8.0,
    weight_exponent: float = -0.5,
    ambient: float = 0.5,
    image_height: int | None = None,
) -> F32:
    """Exaggerated Shading (Rusinkiewicz, Burns, DeCarlo, SIGGRAPH 2006), in image space.

    The RBD06 paper is not in ``papers/``; this follows its description in LLA §2 and §7
    (light made grazing per scale w.r.t. the next coarser normals, clamped half-Lambertian,
    renderings of all scales weighted and summed, k_i ∝ σ_i^-0.5) and RS §2 (multi-scale
    smoothed normals, half-Lambertian). With n_0 the input normals and n_1 … n_S the normals
    smoothed at σ_1 < … < σ_S::

        ℓ_{i+1} = normalize(ℓ − (ℓ·n_{i+1}) n_{i+1})          (light made grazing w.r.t. n_{i+1})
        c_i     = clamp(a · n_i·ℓ_{i+1}, −1, 1)               (clamped, exaggerated cosine)
        I       = ambient + ½ (k_S n_S·ℓ + Σ_{i=0}^{S−1} k_i c_i),   Σ k = 1,  k_i ∝ σ_i^{-0.5}

    i.e. a half-Lambertian (ambient ½ by default) sum of per-scale "local toon" terms, each
    lighting the detail n_i from a light that grazes the coarser surface n_{i+1}; the coarsest
    normals get the unmodified light (the base term). σ_0 of the unsmoothed normals is taken
    as σ_1/2 (the scale sequence continued one step down). k_i ∝ σ_i^{-0.5} is the default LLA
    §7 (Fig. 14 c) uses. The result is clipped to [0, 1].

    Parameters
    ----------
    normal : (H, W, 3) camera-space unit normals.
    depth : (H, W) planar depth or None; only used for coverage (+inf = background).
    mask : (H, W) coverage or None.
    light_dir : (3,) direction towards the light.
    scales : increasing Gaussian σ of the smoothed normals, relative to image height, each in
        (0, 0.5].
    contrast : a > 0, the exaggeration of each detail term before clamping (our default 8
        saturates a detail bent by ~7° from its coarser surface).
    weight_exponent : k_i ∝ σ_i ** weight_exponent, in [-4, 4].
    ambient : constant term in [0, 1] (½ for RBD06's half-Lambertian).
    image_height : height the relative scales refer to (default: H).

    Returns
    -------
    (H, W) float32 in [0, 1], 0 on background.
    """
    n = _normal_field(normal)
    cov = _coverage(n, depth, mask)
    sc = [float(s) for s in scales]
    increasing = all(b > a for a, b in itertools.pairwise(sc))
    if not sc or any(s not in ES_SCALE for s in sc) or not increasing:
        raise ValueError(f"scales must be increasing values in {ES_SCALE}, got {scales!r}")
    CONTRAST.check(contrast, "contrast")
    WEIGHT_EXPONENT.check(weight_exponent, "weight_exponent")
    FRACTION.check(ambient, "ambient")
    light = _light(light_dir)

    href = n.shape[0] if image_height is None else int(image_height)
    covf = cov.astype(np.float32)
    sigmas = np.array([sc[0] / 2.0, *sc], np.float64)
    k = sigmas**weight_exponent
    k = (k / k.sum()).astype(np.float32)
    out = np.zeros(cov.shape, np.float32)
    box = _box(cov)
    if box is None:
        return out
    parts = _smoothed_components(n, covf, [s * href for s in sc], box)
    y0, y1, x0, x1 = box
    cols = slice(x0, x1)

    def strip(r0: int, r1: int) -> None:
        # per-pixel work on strips of the covered box (in cache, on parallel threads)
        rows = slice(y0 + r0, y0 + r1)
        lv = [n[rows, cols] * cov[rows, cols, None]]
        for part in parts:
            lv.append(_unit_rows(*_part_rows(part, rows, cols), covf[rows, cols]))
        # n_i·ℓ_{i+1} = (n_i·ℓ − (ℓ·n_{i+1})(n_i·n_{i+1})) / √(1 − (ℓ·n_{i+1})²) for unit n_{i+1}
        nl = [dot(x, light) for x in lv]
        acc = k[-1] * nl[-1]  # base term: coarsest normals, unmodified light
        for i in range(len(lv) - 1):
            lc = nl[i + 1]
            norm = cv2.sqrt(np.maximum(1.0 - lc * lc, 0.0))
            num = nl[i] - lc * dot(lv[i], lv[i + 1])
            proj = np.divide(num, norm, out=np.zeros_like(num), where=norm > 1e-6)
            acc += k[i] * np.clip(np.float32(contrast) * proj, -1.0, 1.0)
        img = np.clip(np.float32(ambient) + 0.5 * acc, 0.0, 1.0)
        out[rows, cols] = np.where(cov[rows, cols], img, 0)

    run_strips(y1 - y0, strip, rows=_ES_ROWS)
    return out


def _warp_cos_sin(cos_t: F32, sin_t: F32, kappa: F32, strength: float) -> tuple[F32, F32]:
    """cos θ', sin θ' of tan(θ'/2) = e^{−α κ} tan(θ/2), without trigonometric functions."""
    # tan(θ/2) = sin θ / (1 + cos θ); θ' = θ when θ = π (1 + cos θ = 0: the light behind)
    t = np.divide(sin_t, 1.0 + cos_t, out=np.zeros_like(sin_t), where=(1.0 + cos_t) > 1e-6)
    t = t * cv2.exp(kappa * np.float32(-strength))
    t2 = t * t
    inv = 1.0 / (1.0 + t2)
    cos_w = (1.0 - t2) * inv
    sin_w = 2.0 * t * inv
    behind = (1.0 + cos_t) <= 1e-6
    cos_w = np.where(behind, cos_t, cos_w).astype(np.float32)
    sin_w = np.where(behind, sin_t, sin_w).astype(np.float32)
    return cos_w, sin_w


def warp_light(
    light_dir: Sequence[float] | NDArray[np.floating],
    curvature: NDArray[np.floating],
    strength: float,
    view: Sequence[float] | NDArray[np.floating] = (0.0, 0.0, 1.0),
) -> F32:
    """Per-pixel warped light directions of :func:`light_warping` (H, W, 3).

    The light is rotated in the plane of the view direction v and ℓ, keeping the angle θ to v
    in [0, π]: tan(θ'/2) = e^{−α κ} tan(θ/2), a stereographic zoom of the sphere of directions
    around v (conformal; v and −v are fixed points). κ > 0 (convex) pulls the light towards v,
    κ < 0 pushes it towards grazing and behind.
    """
    light = _light(light_dir)
    kappa = np.asarray(curvature, np.float32)
    vv = np.asarray(view, np.float32)
    if vv.ndim == 1:
        vv = np.ascontiguousarray(np.broadcast_to(_light(vv), (*kappa.shape, 3)))
    else:
        vv = normalize(_normal_field(vv, "view"))
    cos_t = np.clip(dot(vv, light), -1.0, 1.0)
    perp = light - cos_t[..., None] * vv
    sin_t = np.sqrt(dot(perp, perp))
    u = normalize(perp)  # 0 where ℓ ∥ v (then sin θ = 0 and the light is unchanged)
    cos_w, sin_w = _warp_cos_sin(cos_t, sin_t, kappa, strength)
    out = cos_w[..., None] * vv + sin_w[..., None] * u
    return np.asarray(out, np.float32)


def light_warping(
    normal: NDArray[np.floating],
    depth: NDArray[np.floating],
    mask: NDArray[np.generic] | None,
    light_dir: Sequence[float] | NDArray[np.floating],
    *,
    strength: float = 1.0,
    curvature: NDArray[np.floating] | None = None,
    curvature_scale: float = DEFAULT_SCALE,
    curvature_gain: float = DEFAULT_GAIN,
    view: Sequence[float] | NDArray[np.floating] = (0.0, 0.0, 1.0),
    image_height: int | None = None,
) -> F32:
    """Image-space approximation of Light Warping (Vergne et al., SIGGRAPH 2009) for one light.

    Light Warping warps the incoming light directions around the **view** direction by an amount
    set by the view-centred curvature, so that reflected light patterns are compressed on
    convexities and stretched in concavities; for diffuse materials under natural light the
    result is brighter convexities and darker concavities, and since the warp ignores where the
    light is, it may reverse that (Radiance Scaling, Vergne et al. 2011, §6.1, Fig. 13; LLA §7).
    We do not have the Light Warping paper's equations; this is our approximation for a single
    directional light ℓ:

    - κ = tanh(s·(κ1 + κ2)), the isotropic view-centred curvature of RS §4
      (:func:`ops.curvature.isotropic`) in [-1, 1], or the ``curvature`` given;
    - the lookup rays of a convex point are pushed away from v (patterns compressed), so the
      light the point sees moves towards v: tan(θ'/2) = e^{−α κ} tan(θ/2), θ = ∠(v, ℓ), ℓ
      rotated in the (v, ℓ) plane (:func:`warp_light`); concave points get the inverse warp;
    - the image is Lambertian: max(n·ℓ', 0).

    Flat regions (κ = 0) and frontal / back lights (θ = 0 or π) are unchanged.

    Parameters
    ----------
    normal : (H, W, 3) camera-space unit normals.
    depth : (H, W) planar depth (+inf = background).
    mask : (H, W) coverage or None.
    light_dir : (3,) direction towards the light.
    strength : α >= 0, the amount of warping (α = 0 gives Lambert), at most 10.
    curvature : optional (H, W) signed curvature in [-1, 1] (κ > 0 convex) to use instead of
        computing it.
    curvature_scale : derivative scale of :func:`ops.curvature.principal_curvatures`, relative
        to image height.
    curvature_gain : s of κ = tanh(s·(κ1 + κ2)) (:func:`ops.curvature.isotropic`; κ1 + κ2 is
        per unit image height: 8 for a sphere spanning half the image height).
    view : (3,) or (H, W, 3) direction towards the eye (default orthographic (0, 0, 1)).
    image_height : height the relative scales refer to (default: H).

    Returns
    -------
    (H, W) float32 in [0, 1], 0 on background.
    """
    n = _normal_field(normal)
    cov = _coverage(n, depth, mask)
    WEIGHT.check(strength, "strength")
    light = _light(light_dir)
    if curvature is None:
        curv = principal_curvatures(
            n,
            np.asarray(depth, np.float32),
            cov,
            scale=curvature_scale,
            image_height=image_height,
        )
        kappa = np.asarray(isotropic(curv, curvature_gain), np.float32)
    else:
        kappa = np.asarray(curvature, np.float32)
        if kappa.shape != cov.shape:
            raise ValueError(f"curvature must be (H, W) = {cov.shape}, got {kappa.shape}")
        if not np.all(np.isfinite(kappa)):
            raise ValueError("curvature contains NaN or inf")
        kappa = np.clip(kappa, -1.0, 1.0)
    kappa = np.where(cov, kappa, 0).astype(np.float32)
    vv = np.asarray(view, np.float32)
    if vv.ndim == 1:
        # one view direction: θ is the same everywhere, only κ varies per pixel
        v3 = _light(vv)
        cos_t = float(np.clip(v3 @ light, -1.0, 1.0))
        perp = light - cos_t * v3
        sin_t = float(np.linalg.norm(perp))
        u3 = perp / sin_t if sin_t > 1e-7 else np.zeros(3, np.float32)
        cos_w, sin_w = _warp_cos_sin(
            np.full_like(kappa, cos_t), np.full_like(kappa, sin_t), kappa, strength
        )
        img = cos_w * dot(n, v3) + sin_w * dot(n, u3.astype(np.float32))
    else:
        img = dot(n, warp_light(light, kappa, strength, vv))
    img = np.clip(img, 0.0, 1.0)
    return np.where(cov, img, 0).astype(np.float32)
