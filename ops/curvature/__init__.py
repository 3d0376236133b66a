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

Modules: :mod:`.principal` (:func:`principal_curvatures`), :mod:`.result` (:class:`Curvature`),
:mod:`.mapping` (the §4 mappings); the working grid, its jumps and the compiled derivative
kernels are private (:mod:`._jumps`, :mod:`._hessian`).
"""

from ops.curvature._common import (
    DEFAULT_DEPTH_JUMP,
    DEFAULT_FORESHORTENING,
    DEFAULT_GAIN,
    DEFAULT_SCALE,
)
from ops.curvature.mapping import anisotropic, isotropic, isotropic_field, mean_curvature_layers
from ops.curvature.principal import principal_curvatures
from ops.curvature.result import Curvature

__all__ = [
    "DEFAULT_DEPTH_JUMP",
    "DEFAULT_FORESHORTENING",
    "DEFAULT_GAIN",
    "DEFAULT_SCALE",
    "Curvature",
    "anisotropic",
    "isotropic",
    "isotropic_field",
    "mean_curvature_layers",
    "principal_curvatures",
]
