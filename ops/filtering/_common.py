"""Defaults and constants of the depth-guided multi-scale normals."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]

#: Spatial σ of the first filter (n_1 → n_2), relative to the image height.
DEFAULT_BASE = 0.005
#: Growth of the spatial σ per scale (the paper's 1.7).
DEFAULT_FACTOR = 1.7
#: Standard deviation of the range kernel on log depth (≈ 3 % relative depth).
DEFAULT_DEPTH_SIGMA = 0.03
#: Default number of scales S (the paper finds 5-7 enough).
DEFAULT_SCALES = 6

# A scale is filtered at the coarsest level where its σ is at most this many pixels.
_MAX_LEVEL_SIGMA = 1.5
