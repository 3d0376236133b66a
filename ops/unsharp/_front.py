"""Compiled passes of the first level's front-most cells (``_levels._front_most_cells``): the
cells that straddle a depth step, re-averaged from their 2×2 pixels keeping the front-most
surface only. One pass finds each cell's pixels and their weights (:func:`front_weights`), one
per field sums the weighted pixels into the level's cells (:func:`front_sums`). Both run on
ranges of cells over the shared pool (tens of thousands of cells at 1080p; each cell is written
by one range only), with the numbers of the NumPy chain they replace: each product and sum
rounded on its own, the four taps summed in order (tl, tr, bl, br).
"""

from __future__ import annotations

import numpy as np

from ops.jit import exact_kernel
from ops.parallel import run_strips

Array = np.ndarray

#: What :func:`front_sums` sums: the field where the pixel is on the surface (0 elsewhere), its
#: square there, the field as it is, or the field with NaN read as 0.
ON_SURFACE, SQUARED, AS_IS, NAN_AS_ZERO = 0, 1, 2, 3

_F0 = np.float32(0.0)
_F1 = np.float32(1.0)
_F2 = np.float32(2.0)
_HALF = np.float32(0.5)
_FLOOR = np.float32(1e-6)
_BIG = np.float32(1.0e30)


def front_taps(
    cx: Array, cy: Array, valid: Array, iz: Array, grad: tuple[Array, Array] | None, thr: float
) -> tuple[Array, Array, Array, Array, Array]:
    """The taps of level-1 cells (columns ``cx``, rows ``cy``) on the full-resolution surface
    (``valid`` uint8 0/1, depth guide ``iz``): per cell (N, 4) the pixels' rows and columns
    (clamped to the image), whether each is on the surface, and its weight; and (N,) the sum n
    of the unnormalised weights. A pixel's weight is 1 within ``thr``/2 (plus twice the cell's
    slope |∂I/∂column| + |∂I/∂row| from ``grad``) of the cell's front-most pixel, fading to 0
    at ``thr``, 0 off the surface, divided by max(n, 1e-6)."""
    n = int(cx.shape[0])
    py, px = np.empty((n, 4), np.intp), np.empty((n, 4), np.intp)
    ok = np.empty((n, 4), np.uint8)
    wk = np.empty((n, 4), np.float32)
    total = np.empty(n, np.float32)
    none = np.zeros((0, 0), np.float32)
    gx, gy = grad if grad is not None else (none, none)
    t = np.float32(thr)

    def cells(a: int, b: int) -> None:
        at = slice(a, b)
        outs = (py[at], px[at], ok[at], wk[at], total[at])
        front_weights(cx[at], cy[at], valid, iz, gx, gy, t, *outs)

    run_strips(n, cells, CELLS)
    return py, px, ok, wk, total


#: Cells per range of :func:`front_taps` and of the callers of :func:`front_sums`.
CELLS = 1 << 13


@exact_kernel
def front_weights(cx, cy, valid, iz, gx, gy, thr, py, px, ok, wk, total):  # type: ignore[no-untyped-def]
    """:func:`front_taps` into ``py``, ``px``, ``ok``, ``wk`` (N, 4) and ``total`` (N,); ``gx``,
    ``gy``: the level's slopes, or empty."""
    hf, wf = iz.shape
    has_grad = gx.shape[0] > 0
    half = _HALF * thr
    keep = np.empty(4, np.float32)
    for c in range(cx.shape[0]):
        front = _BIG
        for q in range(4):
            x, y = 2 * cx[c] + (q & 1), 2 * cy[c] + (q >> 1)
            inside = (x < wf) & (y < hf)
            x, y = min(x, wf - 1), min(y, hf - 1)
            px[c, q], py[c, q] = x, y
            on = inside & (valid[y, x] != 0)
            ok[c, q] = on
            if on and iz[y, x] < front:
                front = iz[y, x]
        slope = abs(gx[cy[c], cx[c]]) + abs(gy[cy[c], cx[c]]) if has_grad else _F0
        reach = (front + thr) + _F2 * slope
        n = _F0
        for q in range(4):
            k = (reach - iz[py[c, q], px[c, q]]) / half
            k = min(max(k, _F0), _F1)
            k = k * (_F1 if ok[c, q] else _F0)
            keep[q] = k
            n = k if q == 0 else n + k
        inv = max(n, _FLOOR)
        for q in range(4):
            wk[c, q] = keep[q] / inv
        total[c] = n


@exact_kernel
def front_sums(field, py, px, ok, wk, mode, cy, cx, out):  # type: ignore[no-untyped-def]
    """out[cy[c], cx[c]] = Σ_q wk[c, q] · v_q (a cell c of the level ``out``), the taps q in
    order, v_q the (H, W) ``field`` at the tap read as ``mode`` says (:data:`ON_SURFACE`,
    :data:`SQUARED`, :data:`AS_IS`, :data:`NAN_AS_ZERO`)."""
    for c in range(cy.shape[0]):
        s = _F0
        for q in range(4):
            v = field[py[c, q], px[c, q]]
            if mode == ON_SURFACE or mode == SQUARED:
                v = v if ok[c, q] else _F0
                if mode == SQUARED:
                    v = v * v
            elif mode == NAN_AS_ZERO and v != v:
                v = _F0
            t = wk[c, q] * v
            s = t if q == 0 else s + t
        out[cy[c], cx[c]] = s
