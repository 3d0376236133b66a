"""The maths of Depict: NumPy/OpenCV functions and the Numba kernels that fuse them.

One package per technique, its paper's equations as public functions beside private kernels:

* :mod:`ops.radiance_scaling` — Radiance Scaling (Vergne et al. 2011): Eq. 2, Eq. 4 on lobes,
  the shading scenarios of §5;
* :mod:`ops.curvature` — view-centred principal curvatures and RS §4's mappings;
* :mod:`ops.light_alignment` — Local Light Alignment (Mestres et al. 2021), Eq. 1;
* :mod:`ops.filtering` — LLA §5's depth-guided multi-scale normals;
* :mod:`ops.congruence` — LLA Eq. 2, the congruence of shading and shape flows;
* :mod:`ops.unsharp` — 3D unsharp masking (Ritschel et al. 2008) and its image-space baselines;
* :mod:`ops.relief` — Apparent Relief (Vergne et al. 2008);
* :mod:`ops.baselines` — Exaggerated Shading and Light Warping;
* :mod:`ops.shading` — lights, BRDF terms and the deferred shaders.

Shared: :mod:`ops.checks` (parameter ranges), :mod:`ops.numerics` (the kernels' polynomials),
:mod:`ops.pyramid` (the filtering core), :mod:`ops.color` (luminance, CIELAB),
:mod:`ops.lighting`, :mod:`ops.ambient_occlusion`, :mod:`ops.directions`, :mod:`ops.parallel`
(row strips) and :mod:`ops.jit` (the kernels' compile options).
"""
