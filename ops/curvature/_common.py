"""Defaults and internal constants of the view-centred curvature."""

from __future__ import annotations

from typing import Any

import cv2

#: cv2 for calls with Python scalars or None where its stubs only list arrays (Scalar arguments,
#: default kernels); same module, untyped.
_cv: Any = cv2


#: Default derivative scale, relative to the image height (σ = 3.2 px at 1080p).
DEFAULT_SCALE = 0.003
#: Default foreshortening f (0: curvature of the projected normal field; 1: Hessian of depth).
DEFAULT_FORESHORTENING = 0.0
#: Default relative depth jump |Δ log d| between neighbours at an occlusion (module docstring).
DEFAULT_DEPTH_JUMP = 0.03
#: Default gain s of the mapping tanh(s·(κ1 + κ2)): a sphere spanning half the image height has
#: κ1 + κ2 = 8 per unit image height, mapped to tanh(0.24) ≈ 0.24. On renders of detailed meshes
#: (bunny, ogre, igea, Nefertiti, spot) it keeps the median |κ| at 0.25–0.5, in tanh's
#: near-linear range, where 0.1 saturated over half of their pixels (|κ| > 0.75).
DEFAULT_GAIN = 0.03

_NZ_MIN = 1e-2  # n_z is clamped to this before n_z^f (f > 0); |q| ≤ 1 / _NZ_MIN^f
_TARGET_SIGMA = 1.5  # downsample while σ stays >= this many working pixels
_MIN_SIDE = 16  # never downsample below this many pixels per side
_STRIP_ROWS = 135  # working-grid rows per strip (4 strips at 1080p, level 1)
_LIMB_RATIO = 3.0  # a jump this many times the step before it is not a limb (<= 1 + sqrt 2)
