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

Modules: :mod:`.shape` (the descriptor), :mod:`.arm` (ARM lookup, picking), :mod:`.shipped`
(shipped ARMs, template), :mod:`.styles`; compiled kernels in :mod:`._kernels`.
"""

from ops.relief._common import (
    AUTO_NORM_FLOOR,
    DEFAULT_PERCENTILE,
    DEFAULT_SCALE,
    PLANE_RADIUS,
    REGION_ANGLES,
    REGION_COLORS,
    REGIONS,
    SHIPPED_ARM_SIZE,
    SHIPPED_ARMS,
    Descriptor,
    Pick,
    Relief,
)
from ops.relief.arm import (
    arm_coords,
    arm_from_image,
    arm_lookup,
    paint_arm,
    pick,
    relief,
    s_to_uv,
    uv_to_texel,
)
from ops.relief.shape import (
    classify,
    curvedness,
    descriptor,
    descriptor_colors,
    relief_vector,
    shape_index,
)
from ops.relief.shipped import SHIPPED_ARM_VALUES, arm_template, make_arm, shipped_arm_path
from ops.relief.styles import cel, counter_shading, default_toon, masked, xtoon

__all__ = [
    "AUTO_NORM_FLOOR",
    "DEFAULT_PERCENTILE",
    "DEFAULT_SCALE",
    "PLANE_RADIUS",
    "REGIONS",
    "REGION_ANGLES",
    "REGION_COLORS",
    "SHIPPED_ARMS",
    "SHIPPED_ARM_SIZE",
    "SHIPPED_ARM_VALUES",
    "Descriptor",
    "Pick",
    "Relief",
    "arm_coords",
    "arm_from_image",
    "arm_lookup",
    "arm_template",
    "cel",
    "classify",
    "counter_shading",
    "curvedness",
    "default_toon",
    "descriptor",
    "descriptor_colors",
    "make_arm",
    "masked",
    "paint_arm",
    "pick",
    "relief",
    "relief_vector",
    "s_to_uv",
    "shape_index",
    "shipped_arm_path",
    "uv_to_texel",
    "xtoon",
]
