"""The compiled row kernels of Radiance Scaling on renderer lobes: the banded percentile count and
Eq. 2 fused with Eq. 4 over all lobes in one pass per strip."""

from __future__ import annotations

import numpy as np

from ops.jit import inline_kernel, kernel
from ops.numerics import dot3_row, expf
from ops.pyramid.upsample import upsample_row
from ops.radiance_scaling._common import _ACC_BEAUTY, _ACC_LOBES


@kernel
def _count_rows(rows, m8, wid, step, lo, hi, lw, out):
    """:func:`_count` on every ``step``-th of ``rows`` ((n, W) values or (n, 3W) RGB; ``m8``
    uint8 coverage, or no rows; ``lw`` the (3,) float32 luminance weights): (counted, below
    ``lo``, in [``lo``, ``hi``]), those in the band packed into ``out`` unless it is empty. The
    counts are vectorised reductions that also flag the values in the band; only the 8-byte
    words of flags that hold one are looked at to pack them."""
    y = np.empty(wid, np.float32)
    ones = np.ones(wid, np.uint8)
    nw = (wid + 7) // 8
    flags = np.zeros(8 * nw, np.uint8)
    words = flags.view(np.uint64)
    w0, w1, w2 = lw[0], lw[1], lw[2]
    big = np.float32(np.inf)
    pack = out.shape[0] > 0
    counted = below = inside = k = 0
    for i in range(0, rows.shape[0], step):
        if rows.shape[1] == wid:
            y[:] = rows[i]
        else:
            dot3_row(rows[i], w0, w1, w2, y)
        mr = m8[i] if m8.shape[0] else ones
        n_in = 0
        for j in range(wid):
            v = y[j]
            ok = (abs(v) < big) & (mr[j] != 0)
            band = ok & (v >= lo) & (v <= hi)
            counted += ok
            below += ok & (v < lo)
            n_in += band
            flags[j] = band
        inside += n_in
        if n_in and pack:
            for q in range(nw):
                if words[q]:
                    for j in range(8 * q, min(8 * q + 8, wid)):
                        if flags[j]:
                            out[k] = y[j]
                            k += 1
    return counted, below, inside


@inline_kernel
def _exp_row(kappa, gamma, lim, e):
    """e[j] = e^{−γκ_j}, γκ clipped to ±``lim`` and NaN κ counted as 0 (as :func:`_exp_term`)."""
    zero = np.float32(0.0)
    for j in range(e.shape[0]):
        x = -gamma * kappa[j]
        x = x if x == x else zero
        e[j] = expf(min(max(x, -lim), lim))


@inline_kernel
def _times_row(x, k, out):
    """out = k · x."""
    for j in range(out.shape[0]):
        out[j] = k * x[j]


@inline_kernel
def _sigma_row(d, e, pf, qf, s):
    """Eq. 2 per pixel: σ = (P'E + Q') / (P' + Q'E), δ̄ = clip(d, 0, 1) (NaN → 0),
    P' = ``pf``(1 − δ̄), Q' = ``qf`` δ̄ (see :func:`scale_lobes`)."""
    zero, one = np.float32(0.0), np.float32(1.0)
    for j in range(s.shape[0]):
        x = d[j]
        x = x if x > zero else zero
        x = x if x < one else one
        p = pf * (one - x)
        q = qf * x
        s[j] = (p * e[j] + q) / (p + q * e[j])


@inline_kernel
def _put_scaled(acc, src, lobe, s, less):
    """acc = src + (s − ``less``) · lobe on flat RGB rows (s per pixel; ``src`` may be ``acc``)."""
    for j in range(s.shape[0]):
        f = s[j] - less
        for c in range(3):
            m = 3 * j + c
            acc[m] = src[m] + f * lobe[m]


@inline_kernel
def _put_scaled3(acc, src, l0, l1, l2, s0, s1, s2, less):
    """:func:`_put_scaled` of three lobes at once (one pass over ``acc``)."""
    for j in range(s0.shape[0]):
        f0, f1, f2 = s0[j] - less, s1[j] - less, s2[j] - less
        for c in range(3):
            m = 3 * j + c
            acc[m] = src[m] + f0 * l0[m] + f1 * l1[m] + f2 * l2[m]


@inline_kernel
def _nonzero_span(x):
    """(j0, j1): the first and one past the last index where ``x`` is not 0 ((0, 0) if none)."""
    n = x.shape[0]
    lo, hi = n, 0
    for j in range(n):
        nz = x[j] != np.float32(0.0)
        lo = min(lo, j if nz else n)
        hi = max(hi, j + 1 if nz else 0)
    return (lo, hi) if lo < hi else (0, 0)


@kernel
def _scale_rows(lobes, lights, grid, f, gammas, coef, which, base, mode, out, sig, r0):
    """Rows ``r0 ..`` of :func:`scale_lobes`: ``out`` = (0 | base) + Σ_k σ_k · lobe_k with
    ``mode`` _ACC_LOBES | _ACC_REMAINDER, or base + Σ_k (σ_k - 1) · lobe_k with _ACC_BEAUTY.
    κ is the ``grid`` upsampled ``f`` times (:func:`ops.pyramid.upsample_row`; f = 1: κ
    itself); σ_k of lobe k from E = e^{−γκ} of γ = ``gammas[which[k], 0]``, γκ clipped to
    ± ``gammas[which[k], 1]``, and δ̄ = clip(coef[k, 0] · light_k, 0, 1) (``lights``: the lobes'
    light luminances, (H, W) each), P' = coef[k, 1](1 - δ̄), Q' = coef[k, 2] δ̄; σ_k also into
    row ``r0 + i`` of ``sig[k]`` when it has rows.

    σ = 1 exactly where κ = 0 (E = 1), so on each row only the span between the first and the
    last pixel of non-zero κ is computed: outside it no light is read, and with _ACC_BEAUTY no
    lobe either (the beauty is copied). Background, where κ is 0, costs a copy. Each step is its
    own loop over the span (E per γ, δ̄, σ, the sum), each vectorised by LLVM; RGB rows are
    indexed flat (3j + c)."""
    zero, one = np.float32(0.0), np.float32(1.0)
    keep = sig.shape[1] > 0
    less = one if mode == _ACC_BEAUTY else zero
    wid = out.shape[1]
    nl = len(lobes)
    e = np.empty((gammas.shape[0], wid), np.float32)
    d = np.empty(wid, np.float32)
    zeros = np.zeros(3 * wid, np.float32)
    s = np.empty((nl, wid), np.float32)  # σ of the row's lobes (contiguous rows)
    v = np.empty(grid.shape[1], np.float32)
    kr = np.empty(wid if f > 1 else 0, np.float32)
    for i in range(out.shape[0]):
        if f > 1:
            upsample_row(grid, f, r0 + i, v, kr)
            kappa = kr
        else:
            kappa = grid[r0 + i]
        j0, j1 = _nonzero_span(kappa)
        for g in range(gammas.shape[0]):
            _exp_row(kappa[j0:j1], gammas[g, 0], gammas[g, 1], e[g, j0:j1])
        for k in range(nl):
            sk = s[k]
            sk[:j0] = one
            sk[j1:] = one
            _times_row(lights[k][i, j0:j1], coef[k, 0], d[j0:j1])
            _sigma_row(d[j0:j1], e[which[k], j0:j1], coef[k, 1], coef[k, 2], sk[j0:j1])
            if keep:
                sig[k, r0 + i] = sk
        acc = out[i].reshape(3 * wid)
        src = zeros if mode == _ACC_LOBES else base[i].reshape(3 * wid)
        a, b = 0, wid
        if mode == _ACC_BEAUTY:  # σ - 1 = 0 outside the span: the beauty as it is
            a, b = j0, j1
            acc[: 3 * a] = src[: 3 * a]
            acc[3 * b :] = src[3 * b :]
        acc, src = acc[3 * a : 3 * b], src[3 * a : 3 * b]
        k = 0
        while k + 3 <= nl:  # three lobes per pass over the row, then the rest one by one
            _put_scaled3(
                acc,
                src,
                lobes[k][i].reshape(3 * wid)[3 * a : 3 * b],
                lobes[k + 1][i].reshape(3 * wid)[3 * a : 3 * b],
                lobes[k + 2][i].reshape(3 * wid)[3 * a : 3 * b],
                s[k, a:b],
                s[k + 1, a:b],
                s[k + 2, a:b],
                less,
            )
            src = acc
            k += 3
        while k < nl:
            _put_scaled(acc, src, lobes[k][i].reshape(3 * wid)[3 * a : 3 * b], s[k, a:b], less)
            src = acc
            k += 1
