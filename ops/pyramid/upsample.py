"""Bilinear upsampling by an integer factor, one row at a time, inside compiled kernels.

A field computed on a coarser working grid (the mapped curvature κ of :mod:`ops.curvature`) is
needed at full resolution only by the kernel that consumes it. Upsampling the whole frame first
writes a frame-sized plane that the consumer then reads back; :class:`Upsampled` keeps the grid,
and the consumer computes each full-resolution row it needs with :func:`upsample_row`, in cache.

The interpolation is cv2.resize's ``INTER_LINEAR`` for a size ``f`` times the grid's: half-pixel
centres (output pixel x samples the grid at ``(x + 0.5)/f - 0.5``), edges replicated, the
horizontal pass then the vertical one. Results agree with cv2 to rounding (the same weights;
the order of the sums may differ by an ulp).
"""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np

from ops.jit import inline_kernel, kernel
from ops.parallel import run_strips

__all__ = ["Upsampled", "upsample_row"]

_STRIP_ROWS = 64  # output rows per strip of Upsampled.__array__


class Upsampled:
    """An (H, W) float32 image held as a grid ``f`` times smaller, read by bilinear upsampling.

    ``Upsampled(grid, (H, W))`` with ``grid`` of shape (h, w): when H = f·h and W = f·w for one
    integer f, the grid is kept and :attr:`factor` is f; any other size is interpolated once, with
    cv2.resize, and kept at full resolution (factor 1). ``np.asarray(u)`` gives the (H, W) image;
    kernels read rows through :func:`upsample_row` with :attr:`grid` and :attr:`factor`.
    """

    def __init__(self, grid: np.ndarray, size: tuple[int, int]) -> None:
        grid = np.ascontiguousarray(grid, dtype=np.float32)
        if grid.ndim != 2:
            raise ValueError(f"grid must have shape (h, w), got {grid.shape}")
        h, w = size
        f = h // grid.shape[0]
        if f >= 1 and (h, w) == (f * grid.shape[0], f * grid.shape[1]):
            self.grid, self.factor = grid, f
        else:
            self.grid, self.factor = cv2.resize(grid, (w, h), interpolation=cv2.INTER_LINEAR), 1
        self.shape = (h, w)

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        if self.factor == 1:
            out = self.grid
        else:
            out = np.empty(self.shape, np.float32)
            run_strips(
                self.shape[0],
                lambda r0, r1: _upsample_rows(self.grid, self.factor, r0, out[r0:r1]),
                _STRIP_ROWS,
            )
        return out if dtype is None else out.astype(dtype, copy=False)


@inline_kernel
def upsample_row(grid, f, y, v, out):  # type: ignore[no-untyped-def]
    """``out`` (f·w) = row ``y`` of ``grid`` (h, w) upsampled ``f`` times (module docstring);
    ``v`` is scratch of w values. For f = 1 it copies the row."""
    one = np.float32(1.0)
    hk, wk = grid.shape
    if f == 1:
        out[:] = grid[y]
        return
    sy = (y + 0.5) / f - 0.5
    y0 = math.floor(sy)
    wy = sy - y0
    if y0 < 0:  # above the first row's centre: that row (cv2 clamps the position)
        y0, wy = 0, 0.0
    if y0 >= hk - 1:
        y0, wy = hk - 1, 0.0
    y1 = min(y0 + 1, hk - 1)
    b = np.float32(wy)
    a = one - b
    top, bot = grid[y0], grid[y1]
    for j in range(wk):
        v[j] = a * top[j] + b * bot[j]
    if f == 2:  # the common case, written out so that it vectorises
        q, t = np.float32(0.25), np.float32(0.75)
        out[0] = v[0]
        for j in range(wk - 1):
            out[2 * j + 1] = t * v[j] + q * v[j + 1]
            out[2 * j + 2] = q * v[j] + t * v[j + 1]
        out[2 * wk - 1] = v[wk - 1]
        return
    for p in range(f):  # output columns f·j + p sample v between j + o and j + o + 1
        fx = (p + 0.5) / f - 0.5
        o = -1 if fx < 0.0 else 0
        r = np.float32(fx - o)
        s = one - r
        j0, j1 = -o, wk - 1 - o  # j0 <= j < j1: both samples inside the row
        for j in range(min(j0, wk)):  # before the first sample's centre: the edge
            out[f * j + p] = v[0]
        for j in range(j0, j1):
            out[f * j + p] = s * v[j + o] + r * v[j + o + 1]
        for j in range(max(j1, j0), wk):  # past the last one's
            out[f * j + p] = v[wk - 1]


@kernel
def _upsample_rows(grid, f, r0, out):  # type: ignore[no-untyped-def]
    """Rows ``r0 ..`` of the upsampled image into ``out``."""
    v = np.empty(grid.shape[1], np.float32)
    for i in range(out.shape[0]):
        upsample_row(grid, f, r0 + i, v, out[i])
