"""Depth-guided multi-scale normals (Mestres et al., "Local Light Alignment for Multi-Scale Shape
Depiction", EG 2021, §5 "Implementation details").

The paper builds S versions of the normal field, n_1 (the input, finest) … n_S (coarsest), "by
successive bilateral filtering operations [BCCS12] … The range kernel is applied on depth values
to preserve the silhouettes of the surface … we increased this size by a factor of 1.7 for each
coarser scale"::

    n_1 = n,    n_{i+1} = normalize( Σ_q G_{σ_i}(p − q) G_r(log d_p − log d_q) n_i(q) )

with σ_i = ``base`` · H · ``factor``^(i−1) pixels (``base`` relative to the image height H) and a
range kernel G_r on **log** depth (standard deviation ``depth_sigma``), i.e. on depth relative to
depth, so that the same parameters work at any scene scale and resolution.

Cost does not grow with the kernel size: scale i is filtered on a depth-aware pyramid, at the
level where σ_i is at most 1.5 pixels (a joint bilateral filter with the circular window of
radius 1 or 2 of ``cv2.ximgproc.jointBilateralFilter`` there, as a compiled kernel), and brought
back to full resolution by edge-aware upsampling:

- downsampling (level k → k+1) averages each 2×2 block over its covered pixels that lie on the
  front-most surface of the block (log depth within ``2·depth_sigma`` of the block's minimum),
  so no low-resolution sample mixes two surfaces across a depth jump;
- upsampling is bilinear (unit-vector fields are 0 on background and renormalised, so next to
  background only covered samples count), except for the pixels whose parent sample is within
  one sample of a depth jump (a log-depth second difference above 2 ``depth_sigma``, or a step
  above 3 ``depth_sigma``) or of a block that lost pixels to another surface: those take the
  bilinear weights times a log-depth range term (joint bilateral upsampling, Kopf et al. 2007),
  or the nearest sample closest in depth when no sample of the footprint is on their surface.

Background pixels (mask false, depth not finite or ≤ 0) never contribute and stay 0.

Modules: :mod:`.normals` (:func:`normal_pyramid`, :func:`multiscale_normals`), with the joint
bilateral filter in :mod:`._kernels`; the depth-aware pyramid they run on is
:class:`ops.pyramid.DepthPyramid`.
"""

from ops.filtering._common import (
    DEFAULT_BASE,
    DEFAULT_DEPTH_SIGMA,
    DEFAULT_FACTOR,
    DEFAULT_SCALES,
    F32,
)
from ops.filtering.normals import NormalPyramid, multiscale_normals, normal_pyramid, scale_sigmas_px

__all__ = [
    "DEFAULT_BASE",
    "DEFAULT_DEPTH_SIGMA",
    "DEFAULT_FACTOR",
    "DEFAULT_SCALES",
    "F32",
    "NormalPyramid",
    "multiscale_normals",
    "normal_pyramid",
    "scale_sigmas_px",
]
