"""Radiance Scaling of deferred shading (§5.1-5.2): Phong lobes with δ_j = ρ_j (with the
sub-Lambertian and toon options) and Ashikhmin-Shirley (Eq. 3)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ops.checks import FRACTION, TOON_LEVELS
from ops.curvature import Curvature, anisotropic, isotropic
from ops.radiance_scaling.sigma import sigma
from ops.shading import (
    Light,
    dot,
    light_irradiance,
    light_vectors,
    normalize,
    reflect,
)
from ops.shading import ashikhmin_shirley as as_brdf

__all__ = ["Scaled", "ashikhmin_shirley", "phong", "quantise"]


@dataclass(frozen=True)
class Scaled:
    """Enhanced radiance per lobe, their sum, and the mean σ of each lobe (for debug layers)."""

    lobes: dict[str, np.ndarray]
    sigmas: dict[str, np.ndarray]

    @property
    def beauty(self) -> np.ndarray:
        total = np.zeros_like(next(iter(self.lobes.values())))
        for lobe in self.lobes.values():
            total += lobe
        return total


def _kappa(curv: Curvature, light_dir: np.ndarray, gain: float, lam: float) -> np.ndarray:
    """κ for one light: isotropic when λ = 0, else the anisotropic mapping of §4."""
    if lam == 0.0:
        return isotropic(curv, gain)
    return anisotropic(curv, light_dir, gain, lam)


def quantise(intensity: np.ndarray, levels: int) -> np.ndarray:
    """Toon quantisation of an intensity in [0, 1] into ``levels`` bands (0 → 0, 1 → 1)."""
    bands = np.minimum(np.floor(np.clip(intensity, 0.0, 1.0) * levels), levels - 1)
    return (bands / np.float32(levels - 1)).astype(np.float32)


def phong(
    normal: np.ndarray,
    position: np.ndarray,
    view: np.ndarray,
    lights: Sequence[Light],
    curv: Curvature,
    *,
    albedo: np.ndarray | Sequence[float] = (0.8, 0.8, 0.8),
    ambient: float = 0.1,
    specular: float = 0.3,
    shininess: float = 32.0,
    alpha: float = 0.5,
    gamma_ambient: float = 1.0,
    gamma_diffuse: float = 1.0,
    gamma_specular: float = 1.0,
    gain: float = 1.0,
    lam: float = 0.0,
    zeta: float = 1.0,
    toon_levels: int = 0,
) -> Scaled:
    """Radiance Scaling of Phong shading, §5.1 (Vergne et al. 2011).

    L'(p→e) = Σ_j ρ_j(e, ℓ) σ_j(p, e, ℓ) L_j(ℓ) for j ∈ {a, d, s}, with the reflectance mapping
    δ_j = ρ_j: ρ_a = 1, ρ_d = (n·ℓ)^ζ (ζ = 1: Lambert; ζ ∈ [0, 1): the sub-Lambertian material
    ρ_sl of §5.1), ρ_s = (r·ℓ)^η with r = 2(n·e)n − e. Several lights are summed. With
    ``toon_levels`` ≥ 2 the scaled diffuse intensity ρ_d σ_d is quantised ("one only has to
    quantize the scaled reflected intensity", §5.1).

    Parameters
    ----------
    normal, position, view : (H, W, 3) camera-space normal, position, unit vector to the eye.
    lights : directional / point lights (:class:`ops.shading.Light`).
    curv : view-centred curvature of the frame.
    albedo : (H, W, 3) or RGB diffuse colour; ``ambient`` and ``specular`` are k_a and k_s.
    alpha, gamma_* : σ's invariant point and the magnitude per lobe (Eq. 2).
    gain, lam : curvature gain of the tanh mapping and anisotropy λ ∈ [−1, 1] (§4).
    """
    FRACTION.check(zeta, "zeta")
    if toon_levels != 0:  # 0: no toon shading
        TOON_LEVELS.check(toon_levels, "toon_levels")
    covered = np.linalg.norm(normal, axis=2) > 0.5
    alb = np.broadcast_to(np.asarray(albedo, np.float32), normal.shape)
    r = normalize(reflect(view, normal))
    k_iso = isotropic(curv, gain)
    ones = np.ones(normal.shape[:2], np.float32)
    sig_a = sigma(k_iso, ones, alpha, gamma_ambient)
    amb = alb * (np.float32(ambient) * sig_a)[..., None]
    diff = np.zeros_like(alb)
    spec = np.zeros_like(alb)
    sig_d = np.zeros_like(ones)
    sig_s = np.zeros_like(ones)
    for light in lights:
        ell = light_vectors(light, position)
        e = np.broadcast_to(light_irradiance(light, position), normal.shape)
        kappa = _kappa(curv, ell, gain, lam)
        nl = np.clip(dot(normal, ell), 0.0, 1.0)
        # (n·ℓ)^ζ over the lit hemisphere only: 0^0 would light the far side when ζ = 0.
        rho_d = nl if zeta == 1.0 else np.power(nl, np.float32(zeta)) * (nl > 0)
        s_d = sigma(kappa, rho_d, alpha, gamma_diffuse)
        d_term = rho_d * s_d
        if toon_levels:
            d_term = quantise(d_term, toon_levels)
        rho_s = np.power(np.clip(dot(r, ell), 0.0, 1.0), np.float32(shininess)) * (nl > 0)
        s_s = sigma(kappa, rho_s, alpha, gamma_specular)
        diff += alb * d_term[..., None] * e
        spec += np.float32(specular) * (rho_s * s_s)[..., None] * e
        sig_d += s_d / len(lights)
        sig_s += s_s / len(lights)
    lobes = {"ambient": amb, "diffuse": diff, "specular": spec}
    for lobe in lobes.values():
        lobe[~covered] = 0.0
    return Scaled(lobes, {"ambient": sig_a, "diffuse": sig_d, "specular": sig_s})


def ashikhmin_shirley(
    normal: np.ndarray,
    position: np.ndarray,
    view: np.ndarray,
    lights: Sequence[Light],
    curv: Curvature,
    *,
    albedo: np.ndarray | Sequence[float] = (0.8, 0.8, 0.8),
    exponent: float = 100.0,
    rs: float = 0.05,
    alpha: float = 0.5,
    gamma_diffuse: float = 1.0,
    gamma_specular: float = 1.0,
    gain: float = 1.0,
    lam: float = 0.0,
) -> Scaled:
    """Radiance Scaling with the Ashikhmin-Shirley BRDF and N lights, §5.2, Eq. 3.

    L' = Σ_i ρ_d(ℓ_i) σ_d(p, ℓ_i) L(ℓ_i) + Σ_i ρ_s(e, ℓ_i) σ_s(p, e, ℓ_i) L(ℓ_i), where the lobes
    may leave [0, 1], so the reflectance mappings use each lobe's reference direction:
    δ_d = ℓ_i·n and δ_s = h_i·n (h_i the half vector of ℓ_i and e).
    """
    alb = np.broadcast_to(np.asarray(albedo, np.float32), normal.shape)
    diff = np.zeros(normal.shape, np.float32)
    spec = np.zeros(normal.shape, np.float32)
    sig_d = np.zeros(normal.shape[:2], np.float32)
    sig_s = np.zeros(normal.shape[:2], np.float32)
    for light in lights:
        ell = light_vectors(light, position)
        e = np.broadcast_to(light_irradiance(light, position), normal.shape)
        kappa = _kappa(curv, ell, gain, lam)
        rho_d, rho_s = as_brdf(normal, ell, view, exponent=exponent, rs=rs)
        h = normalize(ell + view)
        s_d = sigma(kappa, np.clip(dot(ell, normal), 0.0, 1.0), alpha, gamma_diffuse)
        s_s = sigma(kappa, np.clip(dot(h, normal), 0.0, 1.0), alpha, gamma_specular)
        diff += alb * (rho_d * s_d)[..., None] * e
        spec += (rho_s * s_s)[..., None] * e
        sig_d += s_d / len(lights)
        sig_s += s_s / len(lights)
    return Scaled({"diffuse": diff, "specular": spec}, {"diffuse": sig_d, "specular": sig_s})
