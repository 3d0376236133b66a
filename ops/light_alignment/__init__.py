"""Local Light Alignment (Mestres et al., "Local Light Alignment for Multi-Scale Shape Depiction",
EG 2021, §4-6).

At each pixel the light direction ℓ is rotated, scale by scale from the coarsest to the finest,
towards a guiding vector g so that one side of every feature faces the light and the other side
is grazed by it. With the multi-scale fields a_1 (finest) … a_S (coarsest) — the normals n_i for
the diffuse component, the reflected view vectors r_i = reflect(v, n_i) for the specular one and
the refracted view vectors t_i = refract(v, n_i, ior) for transmission (§6) — scale i uses the
local frame (§5)::

    z_i = a_{i+1},   x_i = normalize(a_i − z_i (a_i·z_i)),   y_i = x_i × z_i

and (§4, Eq. 1)::

    g_i = a_i                    if ℓ̄_{i+1}·x_i ≥ 0   (the lit side: face the light)
          R(y_i, −π/2) a_i       otherwise            (the other side: the tangent of the
                                                       (x_i, z_i) plane perpendicular to a_i)
    ℓ_i = R(ℓ_{i+1} × g_i, θ_i) ℓ_{i+1},   θ_i = σ_i W_γ(λ1 λ2) ∠(ℓ_{i+1}, g_i)
    W_γ(λ) = λ / (e^{−γ}(1 − λ) + λ),   λ1 = 1 − 2∠(ℓ̄, ḡ)/π,   λ2 = |ā_i|

where v̄ is the projection of v on the (x_i, y_i) plane, ℓ_S = ℓ, and the output ℓ_1.

Notes on the exact geometry (the paper's figures fix what the text leaves open):

- The tangent on the unlit side is t = (z − (a·z) a)/|ā|, the unit vector perpendicular to a in
  the (x, z) plane on the side of z (above the base). It is the tangent that the light reaches by
  turning away from a: rotating ℓ towards it lowers a·ℓ monotonically to 0, whereas the opposite
  tangent would swing the light through a (brightening the dark side first). The paper's
  "R(y, −π/2)" names this rotation in its figure's orientation (y = x × z makes (x, y, z)
  left-handed).
- ℓ̄·x has the sign of a·ℓ − (a·z)(z·ℓ); ḡ is along +x on the lit side and −x on the other, so
  ∠(ℓ̄, ḡ) = atan2(|ℓ·y|, |ℓ·x|) and λ1 = (2/π) atan2(|ℓ·x|, |ℓ·y|) ∈ [0, 1] (0 where ℓ̄ = 0:
  the light along the base normal has no side to turn to).
- λ2 = |ā| = sin ∠(a_i, a_{i+1}) measures how much the feature protrudes from its base.
- Mirror symmetry: a configuration symmetric about a plane containing the light (the ridge of
  Fig. 2 lit exactly along its bisector) stays symmetric — both sides are treated alike. A
  light off the bisector by more than the base normals lean makes one side bright and the
  other dark, as in Fig. 2 b-c.

``σ_i`` is given per scale, finest first: ``sigmas[0]`` rotates towards a_1 within the frame of
a_2 (the paper's Figs. 7, 9, 10 list σ_1 … σ_{S−1} in this order). Background pixels keep the
original light; the output directions are unit length.

Speed: given a :class:`ops.filtering.NormalPyramid`, each scale is aligned at the pyramid level
its fine field lives on (coarse scales are smooth) and the light is carried to finer levels by
the pyramid's edge-aware upsampling; only the scales of the full-resolution field n_1 run at
full resolution. Every level runs the same way (``_stages._Stage``): row strips (restricted to
the columns that hold surfaces) on all cores, where the coarser fields and lights are upsampled
(all planes of a level in one resize) into reused scratch buffers, and each scale of Eq. 1 is
one compiled pass over the strip's rows (``_kernels._eq1_rows``, an :func:`ops.jit.kernel`:
guides, renormalisation of upsampled vectors and the rotation per pixel in registers, reading
n_1 and the view interleaved as they are); at full resolution ``_kernels._write_rows`` writes
the interleaved output, the original light on background pixels. The angles are vectorised
polynomials (:mod:`ops.numerics`: atan2 and sin / cos, errors ~1e-7 rad, below float32
rounding of the inputs' dot products). Given a plain list of (H, W, 3) fields, every scale runs
at full resolution (the reference path); :func:`align_scale` is one scale in plain NumPy.

Rounding: √(1 − (a_i·z)²) amplifies the last bits of nearly parallel fields, and λ1 has no limit
where ℓ̄ → 0 (the light along the frame's z, e.g. at a highlight's centre), so a few pixels of a
frame move by up to ~1e-2 under any change of float32 rounding (a 1e-7 rad turn of the input
light does the same); the fields entering a_i·z are therefore normalised with fixed rounding.

Modules: :mod:`.eq1` (Eq. 1 written plainly: :func:`rotate_towards`, :func:`align_scale`,
:func:`w_gamma`), :mod:`.align` (the entry points); how they run: :mod:`._stages` (strips,
pyramid levels) and :mod:`._kernels` (compiled).
"""

from ops.light_alignment._common import DEFAULT_GAMMA, GUIDES, Guide
from ops.light_alignment.align import align_components, align_light, align_lights
from ops.light_alignment.eq1 import align_scale, rotate_towards, w_gamma

__all__ = [
    "DEFAULT_GAMMA",
    "GUIDES",
    "Guide",
    "align_components",
    "align_light",
    "align_lights",
    "align_scale",
    "rotate_towards",
    "w_gamma",
]
