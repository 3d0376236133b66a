"""Unsharp masking that follows surfaces (3D unsharp masking) and its image-space baselines.

Three operators, all on CIELAB lightness with the chroma scaled so that saturation is kept:

* :func:`unsharp_masking` - 3D Unsharp Masking (Ritschel, Smith, Ihrke, Grosch, Myszkowski,
  Seidel, SIGGRAPH 2008, ``papers/3d-unsharp-masking.txt`` §4-5, Eq. 1), adapted to image space:
  the smooth signal S_σ is computed along the visible surfaces with a domain transform whose
  arc length is the surface's own (depth steps count as distance), its width given in scene
  units and converted per pixel, so it neither mixes an object with what lies behind it nor
  shrinks with distance.
* :func:`depth_unsharp_masking` - the depth-buffer baseline of Luft, Colditz and Deussen
  (SIGGRAPH 2006): ΔD = G∗D − D on normalised depth, darkening where ΔD < 0.
* :func:`plain_unsharp_mask` - a plain 2-D unsharp mask of L*, for comparisons.

:func:`surface_blur` exposes the surface-following smoothing itself.

Colour handling (paper §4): with φ the centred CIELAB cube-root coordinates
(:func:`ops.color.rgb_to_lab_phi`, L* = 116 φ_y, a* = 500 (φ_x − φ_y), b* = 200 (φ_y − φ_z)),
the enhanced colour is (U(L*), k a*, k b*) with k = U(L*)/L*, i.e. φ' = k φ: the hue angle
atan2(b*, a*) and the saturation √(a*² + b*²)/L* are unchanged. U is clamped at 0 (no negative
lightness); k = U / max(L*, 1e-3) (black stays black). Only L* is ever formed on the way in
(:func:`ops.color.lightness`); on the way out :func:`ops.color.scale_lab` applies φ' = k φ strip
by strip, with k (and the gain, Eq. 1) formed for each strip of rows while it is in cache: L*_σ
and √(1 + Var) are upsampled to the strip there, in the strip's columns that hold some surface
(the others are returned as they are, not converted).

Modules: :mod:`.surface` (3D unsharp masking, :func:`surface_blur`), :mod:`.depth` (the
image-space baselines); the surface pyramid behind :func:`surface_blur` is private
(:mod:`._surface`, :mod:`._levels`, :mod:`._upsample`, :mod:`._pyramid`).
"""

from ops.unsharp.depth import depth_unsharp_masking, plain_unsharp_mask
from ops.unsharp.surface import (
    SurfaceBlurRows,
    surface_blur,
    surface_blur_rows,
    surface_blurs,
    unsharp_lightness,
    unsharp_masking,
)

__all__ = [
    "SurfaceBlurRows",
    "depth_unsharp_masking",
    "plain_unsharp_mask",
    "surface_blur",
    "surface_blur_rows",
    "surface_blurs",
    "unsharp_lightness",
    "unsharp_masking",
]
