"""The filtering core: reductions, upsampling and masked smoothing of a frame's planes.

What the operators share to work at several scales without mixing surfaces or the background:

* :mod:`.reduce` — :func:`halve` (2×2 area average, odd sizes zero-padded), :func:`box_downsample`
  (2^k box average), :func:`gaussian_blur` (a Gaussian of any width at bounded cost, through
  a reduction);
* :mod:`.upsample` — :class:`Upsampled` and :func:`upsample_row`: bilinear upsampling by an
  integer factor, a row at a time inside compiled kernels;
* :mod:`.masked` — :func:`masked_gaussian`: averages over the covered pixels only.

Users: the curvature (:mod:`ops.curvature`: working grid by :func:`box_downsample`, κ read
through :class:`Upsampled`), Radiance Scaling on lobes (:class:`Upsampled` κ, masked δ̄),
unsharp masking (its surface pyramid reduces with :func:`halve`; the baselines blur with
:func:`gaussian_blur`; the fine signal is a :func:`masked_gaussian`) and the lighting
correction;
* :mod:`.depth` — :class:`DepthPyramid`: 2×2 reductions that keep the front-most surface of each
  block and edge-aware upsampling across depth jumps (Local Light Alignment's multi-scale normals,
  :mod:`ops.filtering`, and the light carried between its levels), and :func:`normalize_field`.
"""

from ops.pyramid.depth import DepthPyramid, normalize_field
from ops.pyramid.masked import masked_gaussian
from ops.pyramid.reduce import box_downsample, gaussian_blur, halve
from ops.pyramid.upsample import Upsampled, upsample_row

__all__ = [
    "DepthPyramid",
    "Upsampled",
    "box_downsample",
    "gaussian_blur",
    "halve",
    "masked_gaussian",
    "normalize_field",
    "upsample_row",
]
