"""The compiled passes of the surface pyramid's selective reduction (``_reduce_selective``): the
weight each cell keeps in its 2×2 block, and the weighted block averages of each field.

Both run on one thread (a level is at most a quarter of the frame: a pass over it costs less
than handing strips to the pool) and replace a chain of OpenCV and NumPy calls
(:func:`ops.jit.exact_kernel`: each product and sum rounded on its own) with the same numbers:
the 2×2 average is summed in pairs, ((a + b) + (c + d)) / 4, an odd level padded with zeros, as
OpenCV's area resize sums at exactly one half in its vector loop (the last few columns of a
row, which it leaves to a scalar loop summing in order, may differ by a rounding).
"""

from __future__ import annotations

import numpy as np

from ops.jit import exact_kernel

Array = np.ndarray

_F0 = np.float32(0.0)
_F1 = np.float32(1.0)
_F2 = np.float32(2.0)
_QUARTER = np.float32(0.25)
_EPS = np.float32(1e-12)


def block_weights(
    cov: Array, iz: Array, grad: tuple[Array, Array] | None, k: int, jump: float, big: float
) -> tuple[Array, Array, Array]:
    """For the cells of a level k (``cov``, depth guide ``iz``, its slopes ``grad`` or None):
    each cell's weight ``sel`` = cov · keep in its 2×2 block (keep: 1 within ``jump``/2 · 2^k of
    the block's nearest prediction of the guide at its centre, fading to 0 at ``jump`` · 2^k;
    empty cells predict ``big``), the next level's coverage (the blocks' average of ``sel``)
    and the inverse of that coverage (floored at 1e-12)."""
    h, w = cov.shape
    hc, wc = (h + 1) // 2, (w + 1) // 2
    sel = np.empty((h, w), np.float32)
    cov_next = np.empty((hc, wc), np.float32)
    inv = np.empty((hc, wc), np.float32)
    none = np.zeros((0, 0), np.float32)
    gx, gy = grad if grad is not None else (none, none)
    half = np.float32(0.5 * jump * 2**k)
    offset = np.float32(0.5 * 2**k)  # a cell's distance from its block's centre, image pixels
    _weights_rows(cov, iz, gx, gy, offset, half, np.float32(big), 0, hc, sel, cov_next, inv)
    return sel, cov_next, inv


def block_average(field: Array, sel: Array, inv: Array) -> Array:
    """The next level of ``field``: its 2×2 block sums weighted by ``sel``, times ``inv``."""
    hc, wc = int(inv.shape[0]), int(inv.shape[1])
    out = np.empty((hc, wc), np.float32)
    _average_rows(field, sel, inv, 0, hc, out)
    return out


@exact_kernel
def _weights_rows(cov, iz, gx, gy, offset, half, big, r0, r1, sel, cov_next, inv):  # type: ignore[no-untyped-def]
    """:func:`block_weights` for blocks of rows r0 … r1 − 1."""
    h, w = cov.shape
    has_grad = gx.shape[0] > 0
    p = np.empty(4, np.float32)
    s = np.empty(4, np.float32)
    for bi in range(r0, r1):
        for bj in range(cov_next.shape[1]):
            near = big
            for t in range(4):
                i, j = 2 * bi + t // 2, 2 * bj + t % 2
                v = big
                if i < h and j < w and cov[i, j] > _F0:
                    v = iz[i, j]
                    if has_grad:  # (I + g_x · ±d/2) + g_y · ±d/2, as two roundings
                        v = v + gx[i, j] * (offset if j % 2 == 0 else -offset)
                        v = v + gy[i, j] * (offset if i % 2 == 0 else -offset)
                p[t] = v
                near = min(near, v)
            near = near + _F2 * half
            for t in range(4):
                i, j = 2 * bi + t // 2, 2 * bj + t % 2
                if i < h and j < w:
                    keep = (near - p[t]) / half
                    keep = _F0 if keep < _F0 else keep  # (NaN stays NaN, as np.maximum)
                    keep = _F1 if keep > _F1 else keep
                    s[t] = cov[i, j] * keep
                    sel[i, j] = s[t]
                else:
                    s[t] = _F0
            c = ((s[0] + s[1]) + (s[2] + s[3])) * _QUARTER
            cov_next[bi, bj] = c
            inv[bi, bj] = _F1 / (c if c > _EPS else _EPS)


@exact_kernel
def _average_rows(field, sel, inv, r0, r1, out):  # type: ignore[no-untyped-def]
    """:func:`block_average` for blocks of rows r0 … r1 − 1 (the full blocks in a loop without
    branches; a last odd row or column is padded with zeros)."""
    h, w = field.shape
    wf = w // 2  # blocks with both columns
    for bi in range(r0, r1):
        i0 = 2 * bi
        f0, s0, o, q = field[i0], sel[i0], out[bi], inv[bi]
        if i0 + 1 < h:
            f1, s1 = field[i0 + 1], sel[i0 + 1]
            for bj in range(wf):
                a = f0[2 * bj] * s0[2 * bj]
                b = f0[2 * bj + 1] * s0[2 * bj + 1]
                c = f1[2 * bj] * s1[2 * bj]
                d = f1[2 * bj + 1] * s1[2 * bj + 1]
                o[bj] = (((a + b) + (c + d)) * _QUARTER) * q[bj]
            if wf < out.shape[1]:  # the padded column
                a, c = f0[w - 1] * s0[w - 1], f1[w - 1] * s1[w - 1]
                o[wf] = (((a + _F0) + (c + _F0)) * _QUARTER) * q[wf]
        else:  # the padded row
            for bj in range(wf):
                a = f0[2 * bj] * s0[2 * bj]
                b = f0[2 * bj + 1] * s0[2 * bj + 1]
                o[bj] = (((a + b) + (_F0 + _F0)) * _QUARTER) * q[bj]
            if wf < out.shape[1]:
                o[wf] = (((f0[w - 1] * s0[w - 1] + _F0) + (_F0 + _F0)) * _QUARTER) * q[wf]
