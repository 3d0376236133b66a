"""Congruence between shading flow and shape flow (Mestres et al., EG 2021, §7, Eq. 2).

Local Light Alignment measures how well a shading depicts shape by comparing, per pixel, the
*shading flow* (structure tensor of the image luminance gradients) with the *shape flow*
(structure tensor of the depth gradients), following Vergne et al. 2016 [VBBF16] and the structure
tensor of Bigün 1987 [Big87]. Each flow gives a dominant eigenvector ``v`` (the direction in which
patterns are most compressed, i.e. the local gradient direction) and a strength ``e``, the mean
of the two eigenvalues. The score is Eq. 2 of the paper::

    s = Σ_i e_shape(i) (1 − ⌊e_shape(i) − e_shading(i)⌋) |v_shape(i) · v_shading(i)|
        ───────────────────────────────────────────────────────────────────────────────
                                   Σ_i e_shape(i)

where ⌊x⌋ clamps x to [0, 1]. The paper writes the shape terms with subscript ``c`` and the
shading terms with ``s``; the weights are the *shape* strengths ("a weight proportional to the
magnitude of the shape flow"), and the clamp keeps exaggeration (e_shading > e_shape) from
lowering the score.

Implementation choices (the paper does not fix them):

- Shading = luminance of linear RGB in its working space (Rec.709 weights by default,
  ``cv2.transform``).
- Shape = the **normals** when they are given: the structure tensor of the gradients of the
  camera-space normal (summed over its three components), i.e. how fast and in which direction
  the surface turns in the image. The paper computes the shape flow "using depth gradients" and
  expects that "curved surfaces will thus have much more impact on the final score than flat
  ones, for which the directions become undefined". Depth gradients give that only for planes
  facing the camera: a receding floor has a strong, well-defined depth gradient everywhere, and
  on path-traced frames with a ground plane it carried most of the weight (80 % of Σ e_shape on
  a Cycles still life), so the score mostly measured the floor's cast shadows and noise, which
  no shape enhancement should touch. The normal's gradient is 0 on every plane, whatever its
  slant, and on a curved surface points across the feature like the depth gradient does; it is
  dimensionless, like the log depth. Without normals the shape is the **log** depth, so the
  flow does not depend on the scene's units or its distance to the camera (∇log d = ∇d / d).
- Gradients at ``gradient_scale`` (a Gaussian σ relative to the image height), integration at
  ``integration_scale`` (idem). For speed the image is area-downsampled by an integer factor so
  that each σ is 1–4 px at its level; the score is evaluated at the integration level, where the
  integrated tensor is smooth, and the full-resolution maps are upsampled from it on first access.
- Background and depth discontinuities do not count: gradients are only taken where the whole 3×3
  Sobel stencil is covered and the log depth does not jump by more than ``depth_jump`` between
  neighbours; the tensors are integrated by normalised convolution over those pixels, so the
  silhouette neither produces shape flow nor bleeds background into the shading flow.
- Strengths are made comparable by dividing each by its ``percentile``-th percentile over the
  covered pixels and clipping to [0, 1]. With normals both are taken where there is shape: the
  shape's over the pixels whose shape strength is above 1e-4 of the largest (not the planes,
  where it is 0), the shading's over those whose normalised shape strength is above 0.1, so the
  shading strength of a floor's cast shadows does not set the scale the objects' shading is
  measured on. This makes the score invariant to scaling the image
  brightness (the tensor scales by k², and so does the percentile) and to the depth units.
  To compare several renderings of one frame (LLA §7), the shading strength can instead be
  divided by a reference's (``shading_norm``): then only the shape's scale is per image, and a
  rendering with more shading contrast than the reference keeps it, as the clamp of Eq. 2
  intends ("prevents the score from dropping in case of exaggeration"); with per-image
  normalisation that clamp could never act on a rendering that is only more contrasted.
  A strength below ~1e-5 of the signal's own scale (float rounding noise on a constant image or
  a fronto-parallel plane) counts as no flow: its direction is undefined and gives a dot of 0.

Speed (none of it changes the result beyond float rounding): the full-resolution pass and the
gradient level run on strips of rows (with a halo covering the filters) on parallel threads,
so the intermediates stay in the CPU cache (OpenCV's filters are single-threaded); after the
first pass only the bounding box of the covered pixels, grown by more than the filters' reach,
is processed, since everything is exactly 0 further away; OpenCV works on one channel at a time
(its area resize and blur are several times faster on single channels).

Modules: :mod:`.score` (:func:`congruence`; :func:`shape_flow`, the shape's side of Eq. 2,
computed once to score several images of one frame), :mod:`.result` (:class:`CongruenceResult`);
the flows are private (:mod:`._flow`).
"""

from ops.congruence.result import CongruenceResult
from ops.congruence.score import ShapeFlow, congruence, shape_flow

__all__ = [
    "CongruenceResult",
    "ShapeFlow",
    "congruence",
    "shape_flow",
]
