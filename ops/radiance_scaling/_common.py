"""Constants shared by Radiance Scaling's functions and kernels."""

from __future__ import annotations

_MAX_EXP = 80.0  # |γκ| is clipped here: e^80 stays finite in float32
_STRIP_ROWS = 64  # rows per strip in scale_lobes
_ACC_LOBES, _ACC_REMAINDER, _ACC_BEAUTY = 0, 1, 2  # what _scale_rows adds the lobes to
