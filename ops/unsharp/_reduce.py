"""Compiled passes over the cells of a surface pyramid's level: the first level's averages of
full-resolution rows (``_surface``), the selective reduction of the others
(``_reduce_selective``: the weight each cell keeps in its 2×2 block, and the weighted block
averages of each field) and the flags of the blocks that are not one surface (``_block_flags``).

The first level's passes run on ``_surface``'s strips of rows, the block flags and the
selective reduction on strips of block rows over the shared pool (a level too small to be
shared is one strip). Each replaces a chain
of OpenCV and NumPy calls (:func:`ops.jit.exact_kernel`: each product and sum rounded on its
own) with the same numbers:
the 2×2 average is summed in pairs, ((a + b) + (c + d)) / 4, an odd level padded with zeros, as
OpenCV's area resize sums at exactly one half in its vector loop (the last few columns of a
row, which it leaves to a scalar loop summing in order, may differ by a rounding).
"""

from __future__ import annotations

import numpy as np

from ops.jit import exact_kernel
from ops.parallel import run_strips, strip_rows

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
    b = np.float32(big)
    run_strips(
        hc,
        lambda r0, r1: _weights_rows(cov, iz, gx, gy, offset, half, b, r0, r1, sel, cov_next, inv),
        _block_rows(wc),
    )
    return sel, cov_next, inv


def block_averages(fields: list[Array], sel: Array, inv: Array) -> list[Array]:
    """The next level of each of ``fields``: its 2×2 block sums weighted by ``sel``, times
    ``inv``; every field on each strip of block rows."""
    hc, wc = int(inv.shape[0]), int(inv.shape[1])
    outs = [np.empty((hc, wc), np.float32) for _ in fields]

    def strip(r0: int, r1: int) -> None:
        for field, out in zip(fields, outs, strict=True):
            _average_rows(field, sel, inv, r0, r1, out)

    run_strips(hc, strip, _block_rows(wc))
    return outs


def _block_rows(blocks_per_row: int) -> int:
    """Block rows per strip: at least 16 and about 2^16 blocks (a strip's work then outweighs
    handing it to the pool)."""
    return max(16, strip_rows(blocks_per_row, 1 << 16))


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
    """:func:`block_averages` of one field for blocks of rows r0 … r1 − 1 (the full blocks in a
    loop without branches; a last odd row or column is padded with zeros)."""
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


def step_flags(
    cov: Array, iz: Array, grad: tuple[Array, Array] | None, k: int, thr: float
) -> Array:
    """uint8 (h + 1, w + 1): 1 for each 2×2 block of cells (cells i − 1 … i, j − 1 … j, clamped
    at the borders) holding an empty cell, or whose four cells' predictions of the depth guide
    at the block's centre, I + (±½, ±½) 2^k ∇I (``grad``; I alone without), spread over more
    than ``thr``. Strips of block rows on the shared pool."""
    h, w = cov.shape
    out = np.empty((h + 1, w + 1), np.uint8)
    none = np.zeros((0, 0), np.float32)
    gx, gy = grad if grad is not None else (none, none)
    hd, t = np.float32(0.5 * 2**k), np.float32(thr)
    rows = _block_rows(w + 1)
    run_strips(h + 1, lambda a, b: _flags_rows(cov, iz, gx, gy, hd, t, a, b, out), rows)
    return out


@exact_kernel
def _flags_rows(cov, iz, gx, gy, hd, thr, r0, r1, out):  # type: ignore[no-untyped-def]
    """:func:`step_flags` for block rows r0 … r1 − 1; ``hd`` = 2^k / 2 (a power of two: the
    products are exact). Block (i, j) reads cells (i − 1 … i, j − 1 … j), clamped: per block
    row, the two cell rows, and each block's left and right cells at columns j − 1 and j."""
    h, w = cov.shape
    has_grad = gx.shape[0] > 0
    ta = np.empty(w + 1, np.float32)  # the cells' predictions at the corner: top-left, …
    tb = np.empty(w + 1, np.float32)
    ba = np.empty(w + 1, np.float32)
    bb = np.empty(w + 1, np.float32)
    bad = np.empty(w + 1, np.bool_)
    for bi in range(r0, r1):
        ia, ib = max(bi - 1, 0), min(bi, h - 1)
        ca, cb, za, zb = cov[ia], cov[ib], iz[ia], iz[ib]
        for j in range(w):  # cell j as the right (top, bottom) and the left cell of a block
            if has_grad:
                xa, ya, xb, yb = gx[ia, j] * hd, gy[ia, j] * hd, gx[ib, j] * hd, gy[ib, j] * hd
                ta[j] = ya + (-xa + za[j])  # top row, right cell of block j: tr
                tb[j + 1] = ya + (xa + za[j])  # top row, left cell of block j + 1: tl
                ba[j] = -yb + (-xb + zb[j])  # br
                bb[j + 1] = -yb + (xb + zb[j])  # bl
            else:
                ta[j] = za[j]
                tb[j + 1] = za[j]
                ba[j] = zb[j]
                bb[j + 1] = zb[j]
            bad[j] = (ca[j] <= _F0) | (cb[j] <= _F0)
        ta[w], tb[0], ba[w], bb[0] = ta[w - 1], tb[1], ba[w - 1], bb[1]  # replicated borders
        bad[w] = bad[w - 1]
        o = out[bi]
        o[0] = bad[0]
        for j in range(1, w + 1):
            o[j] = bad[j - 1] | bad[j]
        for j in range(w + 1):
            hi = max(max(tb[j], ta[j]), max(bb[j], ba[j]))
            lo = min(min(tb[j], ta[j]), min(bb[j], ba[j]))
            o[j] = o[j] | ((hi - lo) > thr)


def masked_rows(src: Array, valid: Array, fill: float, out: Array) -> None:
    """out = ``src`` where ``valid`` (uint8), else ``fill``: rows, before their logarithm.

    Here and below, inputs that are views with a row stride (a crop of the frame) are copied:
    the kernels are compiled for C-contiguous rows only (one set of types, loaded once)."""
    c = np.ascontiguousarray
    _masked_rows(c(src), c(valid), np.float32(fill), out)


def masked_vectors(src: Array, valid: Array) -> Array:
    """(h, w, 3) rows ``src`` where ``valid`` (uint8), else 0: normals off the surface, which
    may be anything, kept out of the cells' averages."""
    c = np.ascontiguousarray
    out = np.empty(src.shape, np.float32)
    _masked_vector_rows(c(src), c(valid), out)
    return out


@exact_kernel
def _masked_vector_rows(src, valid, out):  # type: ignore[no-untyped-def]
    for i in range(out.shape[0]):
        s, v, o = src[i], valid[i], out[i]
        for j in range(o.shape[0]):
            keep = v[j] != 0
            o[j, 0] = s[j, 0] if keep else _F0
            o[j, 1] = s[j, 1] if keep else _F0
            o[j, 2] = s[j, 2] if keep else _F0


def cell_coverage(valid: Array, cov: Array, inv: Array) -> None:
    """The first level's coverage of full-resolution rows ``valid`` (uint8 0/1): each cell's
    share of valid pixels, and its inverse (floored at 1e-12)."""
    _coverage_rows(np.ascontiguousarray(valid), cov, inv)


def cell_average(
    src: Array, valid: Array | None, inv: Array, out: Array, square: bool = False
) -> None:
    """``out`` = the 2×2 averages of rows ``src`` (0 where ``valid`` is 0, when given; squared
    after that with ``square``) times ``inv``."""
    c = np.ascontiguousarray
    none = np.zeros((0, 0), np.uint8)
    _average_cells(c(src), none if valid is None else c(valid), square, inv, out)


def cell_planes(n3: Array, inv: Array, out: list[Array]) -> None:
    """Each channel of (h, w, 3) averaged normals times ``inv``, into three planes."""
    _planes_rows(np.ascontiguousarray(n3), inv, out[0], out[1], out[2])


@exact_kernel
def _masked_rows(src, valid, fill, out):  # type: ignore[no-untyped-def]
    for i in range(out.shape[0]):
        s, v, o = src[i], valid[i], out[i]
        for j in range(o.shape[0]):
            o[j] = s[j] if v[j] != 0 else fill


@exact_kernel
def _coverage_rows(valid, cov, inv):  # type: ignore[no-untyped-def]
    n, w = valid.shape
    wf = w // 2  # blocks with both columns
    for bi in range(cov.shape[0]):
        i0 = 2 * bi
        full = i0 + 1 < n  # (else the padded row: 0)
        va, vb, c, q = valid[i0], valid[i0 + 1 if full else i0], cov[bi], inv[bi]
        low = _F1 if full else _F0
        for bj in range(wf + (w % 2)):
            j0 = 2 * bj
            j1 = j0 + 1 if j0 + 1 < w else j0
            right = _F1 if j0 + 1 < w else _F0  # 0: the padded column
            a = np.float32(va[j0] != 0)
            b = np.float32(va[j1] != 0) * right
            d = np.float32(vb[j0] != 0) * low
            e = np.float32(vb[j1] != 0) * (low * right)
            x = ((a + b) + (d + e)) * _QUARTER
            c[bj] = x
            q[bj] = _F1 / (x if x > _EPS else _EPS)


@exact_kernel
def _average_cells(src, valid, square, inv, out):  # type: ignore[no-untyped-def]
    n, w = src.shape
    masked = valid.shape[0] > 0
    wf = w // 2  # blocks with both columns
    every = np.ones(w, np.uint8)
    for bi in range(out.shape[0]):
        i0 = 2 * bi
        full = i0 + 1 < n  # (else the padded row: 0)
        i1 = i0 + 1 if full else i0
        s0, s1, o, q = src[i0], src[i1], out[bi], inv[bi]
        v0 = valid[i0] if masked else every
        v1 = valid[i1] if masked else every
        for bj in range(wf + (w % 2)):
            j0 = 2 * bj
            pair = j0 + 1 < w  # (else the padded column: 0)
            j1 = j0 + 1 if pair else j0
            a, b, c, d = s0[j0], s0[j1], s1[j0], s1[j1]
            if masked:
                a = a if v0[j0] != 0 else _F0
                b = b if v0[j1] != 0 else _F0
                c = c if v1[j0] != 0 else _F0
                d = d if v1[j1] != 0 else _F0
            if square:
                a, b, c, d = a * a, b * b, c * c, d * d
            b = b if pair else _F0
            c = c if full else _F0
            d = d if pair and full else _F0
            o[bj] = (((a + b) + (c + d)) * _QUARTER) * q[bj]


@exact_kernel
def _planes_rows(n3, inv, x, y, z):  # type: ignore[no-untyped-def]
    for i in range(inv.shape[0]):
        for j in range(inv.shape[1]):
            q = inv[i, j]
            x[i, j] = n3[i, j, 0] * q
            y[i, j] = n3[i, j, 1] * q
            z[i, j] = n3[i, j, 2] * q
