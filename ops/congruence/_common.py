"""Constants of the congruence score."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ops.color import REC709_Y

F32 = NDArray[np.float32]

#: Rec. 709 / sRGB luminance weights of linear RGB.
_LUMA = np.array([REC709_Y], dtype=np.float32)  # (1, 3) for cv2.transform

# Relative floor under which a tensor is treated as zero (float32 rounding noise).
_REL_FLOOR = 1e-10
# With normals: the pixels whose shape strength exceeds this fraction of the largest set the
# shape's scale, and those whose normalised shape strength exceeds _SHAPE_COUNTED the shading's.
_REL_CURVED = 1e-4
_SHAPE_COUNTED = 0.1
