"""Where an OpenCV call's result ends up.

Given ``dst=`` a view, OpenCV writes through it when its rows are contiguous (a strip of rows,
a box of columns whose rows have a stride) and allocates a new array otherwise (a view of
channels, a shape or type it changes). :func:`written` puts the result where it was asked to go
either way. No Numba here: the camera uses it, and a frame's import must not load Numba.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["written"]


def written(res: np.ndarray, dst: np.ndarray, at: Any = ...) -> None:
    """Make sure ``dst[at]`` holds ``res``, the result of a cv2 call given ``dst=dst[at]``
    (copied there only where OpenCV allocated anew)."""
    if not np.shares_memory(res, dst):
        dst[at] = res
