"""Lights, vector helpers and BRDF terms on per-pixel fields, and a multi-light lobe shader.

Conventions (DESIGN.md): OpenGL camera space, arrays float32, ``n`` the unit normal, ``l`` the unit
direction from the surface **towards** the light, ``v`` the unit direction from the surface
**towards** the eye. Vector fields are (H, W, 3); a direction that is the same everywhere (a
directional light, an orthographic view) may be given as a (3,) vector instead. Every BRDF term
returns an (H, W) float32 array, already multiplied by the cosine n·l where the model calls for
it, so that ``radiance = colour * irradiance * term`` (terms are scaled by π where needed so that a
white Lambertian surface under a unit light gives max(n·l, 0)).

Where a model is used in the papers:

* Phong lobes (Radiance Scaling §5.1: δ_j = ρ_j, so these terms stay in [0, 1]);
* Ashikhmin-Shirley (Radiance Scaling §5.2, Eq. 3, with δ_d = ℓ·n and δ_s = h·n);
* half-Lambertian shading (Exaggerated Shading, Rusinkiewicz et al. 2006, used as a baseline by
  Local Light Alignment §7);
* refraction / transmission (Radiance Scaling §5.4 Fig. 9 "simple one-bounce" refraction; Local
  Light Alignment §6 uses the refracted view vector as the transmission guide).

No shadows are cast: the shader is local, as in the papers' screen-space use.

Modules: :mod:`.lights`, :mod:`.vectors`, :mod:`.brdf` (the terms), :mod:`.lobes` (deferred
shading into lobes), :mod:`.directions` (per-pixel light directions), :mod:`.relight` (lobe
radiance, ratio relighting); compiled kernels in :mod:`._kernels`.
"""

from ops.shading.brdf import (
    ashikhmin_shirley,
    blinn_phong,
    ggx,
    half_lambert,
    lambert,
    phong,
    transmission,
)
from ops.shading.directions import (
    DIFFUSE_MODELS,
    SPECULAR_MODELS,
    MadeShading,
    Shading,
    shade_directions,
    shading,
)
from ops.shading.lights import (
    LIGHT_SYNTAX,
    Light,
    light_direction,
    light_irradiance,
    light_vectors,
    need_positions,
    parse_light,
)
from ops.shading.lobes import MODELS, Model, shade_lobes
from ops.shading.relight import Relit, apply_gain, lobe_radiance, ratio_relight
from ops.shading.vectors import Vec3, dot, normalize, reflect, refract

__all__ = [
    "DIFFUSE_MODELS",
    "LIGHT_SYNTAX",
    "MODELS",
    "SPECULAR_MODELS",
    "Light",
    "MadeShading",
    "Model",
    "Relit",
    "Shading",
    "Vec3",
    "apply_gain",
    "ashikhmin_shirley",
    "blinn_phong",
    "dot",
    "ggx",
    "half_lambert",
    "lambert",
    "light_direction",
    "light_irradiance",
    "light_vectors",
    "lobe_radiance",
    "need_positions",
    "normalize",
    "parse_light",
    "phong",
    "ratio_relight",
    "reflect",
    "refract",
    "shade_directions",
    "shade_lobes",
    "shading",
    "transmission",
]
