"""The compiled row kernels of Apparent Relief: the descriptor with its ARM texel coordinates, and
the counter-shading and X-Toon styles fused with n·ℓ."""

from __future__ import annotations

import numpy as np

from ops.jit import kernel


@kernel
def _descriptor_rows(k1, k2, wgt, c, ax, ay, s1, s2, mx, my):
    """Rows of :func:`_grid_descriptor`: ``S = K · g``, ``g = w·c / max(|K|·w·c, 1)`` =
    min(weight / (√2 L_norm), 1 / |K|) with ``c = 1 / (√2 L_norm)`` (S = 0 where K = 0: g is
    finite there), into ``s1``, ``s2``; when ``mx`` has rows, also the ARM texel coordinates
    ``x = ax·S1 + ax``, ``y = ay − ay·S2`` into ``mx``, ``my`` (else into a scratch row: no
    branch in the loop)."""
    one = np.float32(1.0)
    keep = mx.shape[0] > 0
    wid = s1.shape[1]
    scratch_x = np.empty(wid, np.float32)
    scratch_y = np.empty(wid, np.float32)
    for i in range(s1.shape[0]):
        a, b, w = k1[i], k2[i], wgt[i]
        o1, o2 = s1[i], s2[i]
        px = mx[i] if keep else scratch_x
        py = my[i] if keep else scratch_y
        for j in range(wid):
            wc = w[j] * c
            t = np.sqrt(a[j] * a[j] + b[j] * b[j]) * wc
            t = t if t > one else one
            g = wc / t
            u = a[j] * g
            v = b[j] * g
            o1[j] = u
            o2[j] = v
            px[j] = u * ax + ax
            py[j] = ay - v * ay


@kernel
def _ndotl_row(nrm, nl, light, from_normal, i, out):
    """Row ``i`` of n·ℓ clamped to [0, 1] into ``out`` (W,): ``light · n`` from the (rows, 3W)
    normals ``nrm`` (RGB rows indexed flat, so that LLVM vectorises the loop) with
    ``from_normal``, else the (rows, W) ``nl``. NaN counts as 0."""
    zero, one = np.float32(0.0), np.float32(1.0)
    if from_normal:
        lx, ly, lz = light[0], light[1], light[2]
        row = nrm[i]
        for j in range(out.shape[0]):
            d = lx * row[3 * j] + ly * row[3 * j + 1] + lz * row[3 * j + 2]
            d = d if d > zero else zero
            out[j] = d if d < one else one
    else:
        given = nl[i]
        for j in range(out.shape[0]):
            d = given[j]
            d = d if d > zero else zero
            out[j] = d if d < one else one


@kernel
def _counter_rows(r, nrm, nl, light, from_normal, thr, out):
    """Rows of :func:`counter_shading`: ``I = n·ℓ + r (1 − 2 n·ℓ)``, 1 where I > ``thr`` else 0,
    n·ℓ from :func:`_ndotl_row` (a row in L1)."""
    zero, one, two = np.float32(0.0), np.float32(1.0), np.float32(2.0)
    wid = out.shape[1]
    d = np.empty(wid, np.float32)
    for i in range(out.shape[0]):
        _ndotl_row(nrm, nl, light, from_normal, i, d)
        rr, oo = r[i], out[i]
        for j in range(wid):
            v = d[j] + rr[j] * (one - two * d[j])
            oo[j] = one if v > thr else zero


@kernel
def _toon_coords(r, nrm, nl, light, from_normal, sx, sy, mx, my):
    """Rows of :func:`xtoon`'s texel coordinates: ``mx = n·ℓ · sx`` (n·ℓ from
    :func:`_ndotl_row`), ``my = sy − sy · r`` with r clamped to [0, 1] (NaN counts as 0): the
    texels the edge-replicating lookup reads outside anyway, on cv2.remap's fast in-range path."""
    zero, one = np.float32(0.0), np.float32(1.0)
    for i in range(mx.shape[0]):
        px, py, rr = mx[i], my[i], r[i]
        _ndotl_row(nrm, nl, light, from_normal, i, px)
        for j in range(px.shape[0]):
            px[j] = px[j] * sx
            v = rr[j]
            v = v if v > zero else zero
            v = v if v < one else one
            py[j] = sy - sy * v
