"""Radiance Scaling in the rendering scenarios of §5 (Vergne et al., TVCG 2011).

Each function shades (or re-weights precomputed radiance) with the scaled reflected-radiance
equation, Eq. 1, L'(p→e) = ∫ ρ(e,ℓ)(n·ℓ) σ(p,e,ℓ) L(p←ℓ) dℓ, specialised as the paper does:

* :func:`phong` — §5.1, one or several lights, Phong lobes with δ_j = ρ_j (ambient ρ_a = 1,
  diffuse ρ_d = n·ℓ, specular ρ_s = (r·ℓ)^η with r the mirror view direction), a separate γ per
  lobe; the sub-Lambertian material ρ_sl = (n·ℓ)^ζ (δ_sl = ρ_sl) and toon shading (quantise the
  scaled intensity) are options of the same function;
* :func:`ashikhmin_shirley` — §5.2, Eq. 3: δ_d = ℓ·n, δ_s = h·n;
* :func:`precomputed_diffuse` — §5.3.1: L' ≈ σ̄ ρ_d A(p) L̄(n) with δ̄_d = L̄(n)/L̄*, for ambient
  occlusion and a prefiltered environment (irradiance from spherical harmonics);
* :func:`lit_sphere` — §5.3.1, a Lit Sphere / matcap: L' = σ̄ L_ls(n), δ̄ = L_ls(n)/L*_ls;
* :func:`environment` — §5.3.2, perfect mirror or refraction: L' = σ̄ L_env(r),
  δ̄_s = L_env(r)/L*_env with r the reflected / refracted view direction.

The renderer-lobe post-process (Eq. 4 on a renderer's own passes) is :func:`scale_lobes`. κ is
the mapped view-centred curvature of :mod:`ops.curvature` (isotropic, or anisotropic per light
when ``lam`` ≠ 0) and σ is :func:`sigma` (Eq. 2; as printed: :func:`scaling_function`).

All directions are camera space (OpenGL). Environment maps are equirectangular (lat-long) images
with +y up; ``camera_to_world`` (3×3) turns camera-space directions into the map's frame.

Modules: :mod:`.sigma` (Eq. 2), :mod:`.lobes` (Eq. 4 on a renderer's lobes), :mod:`.scenarios`
(§5.1-5.2), :mod:`.precomputed` (§5.3); compiled kernels in :mod:`._kernels`.
"""

from ops.radiance_scaling.lobes import (
    covered_percentile,
    reflectance_delta,
    scale_lobes,
    white_level,
)
from ops.radiance_scaling.precomputed import (
    environment,
    latlong_lookup,
    lit_sphere,
    precomputed_diffuse,
    rotate_directions,
    sh_irradiance,
    sky_environment,
    studio_matcap,
)
from ops.radiance_scaling.scenarios import Scaled, ashikhmin_shirley, phong, quantise
from ops.radiance_scaling.sigma import scaling_function, sigma

__all__ = [
    "Scaled",
    "ashikhmin_shirley",
    "covered_percentile",
    "environment",
    "latlong_lookup",
    "lit_sphere",
    "phong",
    "precomputed_diffuse",
    "quantise",
    "reflectance_delta",
    "rotate_directions",
    "scale_lobes",
    "scaling_function",
    "sh_irradiance",
    "sigma",
    "sky_environment",
    "studio_matcap",
    "white_level",
]
