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

from ops.curvature import DEFAULT_GAIN, DEFAULT_SCALE, isotropic, principal_curvatures
from ops.shading import dot, lambert, normalize

F32 = NDArray[np.float32]

#: Default smoothing scales of Exaggerated Shading (Gaussian σ relative to the image height).
ES_SCALES: tuple[float, ...] = (0.0025, 0.005, 0.01, 0.02, 0.04)


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


def _unit_field(v: F32) -> F32:
    """Unit vectors of an (H, W, 3) field (0 where the vector is ~0), with cv2 reductions."""
    len2 = dot(v, v)
    inv = np.divide(1.0, cv2.sqrt(len2), out=np.zeros_like(len2), where=len2 > 1e-12)
    return np.asarray(v * inv[..., None], np.float32)


def _masked_blur_stack(stack: F32, sigma_px: float) -> F32:
    """Gaussian blur of an (H, W, 4) stack (field × coverage, coverage), normalised:
    G*(f m) / G*m (0 where no coverage is near). Large σ are blurred on an area-downsampled
    copy (σ ≈ 4 px there) and the normalised result is upsampled, so every σ costs about the
    same."""
    h, w = stack.shape[:2]
    f = max(1, int(sigma_px / 4.0))
    f = min(f, max(1, h // 4), max(1, w // 4))
    small = stack
    if f > 1:
        small = np.asarray(
            cv2.resize(stack, (max(w // f, 1), max(h // f, 1)), interpolation=cv2.INTER_AREA),
            np.float32,
        )
    small = np.asarray(cv2.GaussianBlur(small, (0, 0), sigma_px / f), np.float32)
    wsum = small[..., 3:]
    out = np.divide(small[..., :3], wsum, out=np.zeros_like(small[..., :3]), where=wsum > 1e-6)
    if f > 1:
        out = cv2.resize(out, (w, h), interpolation=cv2.INTER_LINEAR)
    return np.asarray(out, np.float32)


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
    stack = np.asarray(cv2.merge([cv2.multiply(n, cv2.merge([cov, cov, cov])), cov]), np.float32)
    out = []
    for s in scales:
        sm = _unit_field(_masked_blur_stack(stack, float(s) * href))
        out.append(np.asarray(sm * cov[..., None], np.float32))
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
    if not sc or any(not (0.0 < s <= 0.5) for s in sc) or not increasing:
        raise ValueError(f"scales must be increasing values in (0, 0.5], got {scales!r}")
    if not (np.isfinite(contrast) and contrast > 0):
        raise ValueError(f"contrast must be > 0, got {contrast!r}")
    if not (np.isfinite(weight_exponent) and -4.0 <= weight_exponent <= 4.0):
        raise ValueError(f"weight_exponent must be in [-4, 4], got {weight_exponent!r}")
    if not (np.isfinite(ambient) and 0.0 <= ambient <= 1.0):
        raise ValueError(f"ambient must be in [0, 1], got {ambient!r}")
    light = _light(light_dir)

    levels = [n * cov[..., None], *smoothed_normals(n, cov, sc, image_height=image_height)]
    sigmas = np.array([sc[0] / 2.0, *sc], np.float64)
    k = sigmas**weight_exponent
    k = (k / k.sum()).astype(np.float32)

    # n_i·ℓ_{i+1} = (n_i·ℓ − (ℓ·n_{i+1})(n_i·n_{i+1})) / √(1 − (ℓ·n_{i+1})²) for unit n_{i+1}
    nl = [dot(lv, light) for lv in levels]
    acc = k[-1] * nl[-1]  # base term: coarsest normals, unmodified light
    for i in range(len(levels) - 1):
        lc = nl[i + 1]
        norm = cv2.sqrt(np.maximum(1.0 - lc * lc, 0.0))
        num = nl[i] - lc * dot(levels[i], levels[i + 1])
        proj = np.divide(num, norm, out=np.zeros_like(num), where=norm > 1e-6)
        acc += k[i] * np.clip(np.float32(contrast) * proj, -1.0, 1.0)
    img = np.clip(np.float32(ambient) + 0.5 * acc, 0.0, 1.0)
    return np.where(cov, img, 0).astype(np.float32)


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
    if not (np.isfinite(strength) and 0.0 <= strength <= 10.0):
        raise ValueError(f"strength must be in [0, 10], got {strength!r}")
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
