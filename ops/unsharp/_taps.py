"""The surface-compatible taps of the upsampling's re-weighted pixels, compiled: per pixel the
2×2 bilinear taps, or where none of those lies on the pixel's surface a 4×4 tent of radius 2
cells (:class:`ops.unsharp._upsample._FixupTaps` gives the rule)."""

from __future__ import annotations

import numpy as np

from ops.jit import inline_kernel, kernel
from ops.pyramid.upsample import upsample_row

#: Taps of the wider (4×4) pass: the columns of the tap arrays.
MAX_TAPS = 16

#: A pixel's weights summing to this or less have no compatible tap in that pass.
_FOUND = np.float32(1e-4)


@kernel
def fixup_taps(xx, yy, inv_f, iz_p, izc, grad_x, grad_y, valid_c, wc, d, inv_thr, taps, wts, count):  # type: ignore[no-untyped-def]
    """Taps and normalised weights of the pixels (``xx``, ``yy``) of a grid ``1 / inv_f`` times
    finer than the level's cells (row-major flat cell indices ``taps``, weights ``wts``, each
    (N, MAX_TAPS)) and how many taps each pixel has (``count``, (N,) int8: 4, 16, or 0 where no
    cell around it lies on its surface). ``izc``, ``grad_x``, ``grad_y``, ``valid_c``: the
    level's depth guide, its slopes per image pixel (empty arrays: none) and uint8 cover,
    flattened; ``d``: image pixels per cell; ``iz_p``: each pixel's own depth guide."""
    hc = izc.shape[0] // wc
    half = np.float32(0.5)
    for i in range(xx.shape[0]):
        count[i] = 0
        u = (np.float32(xx[i]) + half) * inv_f - half
        v = (np.float32(yy[i]) + half) * inv_f - half
        x0, y0 = int(np.floor(u)), int(np.floor(v))
        iz = iz_p[i]
        for m in (2, 4):
            first = 0 if m == 2 else -1
            guide = (iz, izc, grad_x, grad_y, valid_c, d, inv_thr)
            sw = _weigh(u, v, x0 + first, y0 + first, m, guide, hc, wc, taps[i], wts[i])
            if sw > _FOUND:
                for t in range(m * m):
                    wts[i, t] /= sw
                count[i] = m * m
                break


@inline_kernel
def _weigh(u, v, cx0, cy0, m, guide, hc, wc, taps, wts):  # type: ignore[no-untyped-def]
    """The ``m``×``m`` taps from cell (cx0, cy0) of one pixel at (u, v) in cell units, into
    ``taps`` and ``wts``: tent (radius m / 2) × (1 − (miss / thr)²)₊ × cover, where miss is
    how far the tap's plane, extrapolated to the pixel, passes from its guide ``iz``; returns
    the weights' sum. ``guide``: (iz, then the arguments of :func:`fixup_taps` of that name)."""
    iz, izc, grad_x, grad_y, valid_c, d, inv_thr = guide
    zero, one = np.float32(0.0), np.float32(1.0)
    inv_r = np.float32(2.0 / m)
    sw = zero
    for a in range(m):
        cy = cy0 + a
        dy = v - np.float32(cy)
        ty = max(zero, one - abs(dy) * inv_r) if 0 <= cy < hc else zero
        row = min(max(cy, 0), hc - 1) * wc
        for b in range(m):
            cx = cx0 + b
            dx = u - np.float32(cx)
            tx = max(zero, one - abs(dx) * inv_r) if 0 <= cx < wc else zero
            flat = row + min(max(cx, 0), wc - 1)
            pred = izc[flat]
            if grad_x.shape[0]:
                pred += grad_x[flat] * (dx * d) + grad_y[flat] * (dy * d)
            miss = (pred - iz) * inv_thr
            w = max(zero, one - miss * miss) * (ty * tx) if valid_c[flat] else zero
            taps[a * m + b] = flat
            wts[a * m + b] = w
            sw += w
    return sw


@kernel
def apply_taps(arr, taps, wts, count, out):  # type: ignore[no-untyped-def]
    """``out[i]`` = Σ_t wts[i, t] · arr[taps[i, t]] over the ``count[i]`` taps of each pixel
    (NaN where it has none); ``arr`` flat."""
    for i in range(out.shape[0]):
        c = count[i]
        if c == 0:
            out[i] = np.float32(np.nan)
            continue
        s = np.float32(0.0)
        for t in range(c):
            s += wts[i, t] * arr[taps[i, t]]
        out[i] = s


@kernel
def fine_fixups(blocks, fine_valid, fine_iz, iz_c, f, thr, r0, r1, out):  # type: ignore[no-untyped-def]
    """The re-weighted pixels of rows r0..r1 of a grid ``f`` (>= 4) times finer than the level's
    cells, as row-major flat indices into ``out`` (ascending; returns how many): the pixels on
    a surface (``fine_valid``) whose 2×2 block of cells is flagged (``blocks``, (hc + 1, wc + 1):
    block (i, j) holds cells i−1…i, j−1…j) or whose own depth guide ``fine_iz`` departs by more
    than ``thr`` from the level's ``iz_c`` upsampled bilinearly (:func:`upsample_row`, as
    cv2.resize): a small object inside a cell."""
    wf = fine_iz.shape[1]
    bcol = np.empty(wf, np.int64)
    for x in range(wf):
        bcol[x] = (x + f // 2) // f
    scratch = np.empty(iz_c.shape[1], np.float32)
    near = np.empty(f * iz_c.shape[1], np.float32)  # the row of the upsampled guide
    need = np.empty(wf, np.bool_)
    n = 0
    for y in range(r0, r1):
        brow = blocks[(y + f // 2) // f]
        upsample_row(iz_c, f, y, scratch, near)
        ok, iz = fine_valid[y], fine_iz[y]
        for x in range(wf):  # (vectorised)
            need[x] = (ok[x] != 0) & ((brow[bcol[x]] != 0) | (abs(iz[x] - near[x]) > thr))
        for x in range(wf):
            if need[x]:
                out[n] = y * wf + x
                n += 1
    return n
