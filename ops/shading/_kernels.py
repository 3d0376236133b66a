"""The compiled row kernels of the multi-light shaders: per-light terms, their sums, lobe radiance
and the ratio relighting."""

from __future__ import annotations

import numpy as np

from ops.jit import inline_kernel, kernel

#: Largest exponent raised by :func:`_ipow_row` (cv2.pow takes larger ones).
MAX_INT_POWER = 1 << 16


@kernel
def _terms_rows(nrm, ld, ldc, ls, lsc, v, vc, half, spec, d_term, nh, gate):
    """Per pixel of the rows of (rows, 3W) ``nrm``: the diffuse term max(n·ℓ_d, 0) (Lambert) or
    ((n·ℓ_d + 1)/2)² (half-Lambert, ``half``) times the coverage (|n|² > 0.25) into ``d_term``;
    with ``spec``, n·h = max((n·ℓ_s + n·v)/|ℓ_s + v|, 0) (0 where |ℓ_s + v| <= 1e-6) into ``nh``
    and the coverage where n·ℓ_s > 0 into ``gate`` (Blinn-Phong's (n·h)^s is ``nh`` to the s).
    ``ld``, ``ls``, ``v`` are rows like ``nrm``, or one row used for all (``ldc``, ``lsc``,
    ``vc``): the formulas of :func:`lambert`, :func:`half_lambert` and :func:`blinn_phong`."""
    zero, one, two, half_ = np.float32(0.0), np.float32(1.0), np.float32(2.0), np.float32(0.5)
    quarter, tiny = np.float32(0.25), np.float32(1e-6)
    for i in range(nrm.shape[0]):
        n = nrm[i]
        a = ld[0 if ldc else i]
        b = ls[0 if lsc else i]
        w = v[0 if vc else i]
        dt, hr, gr = d_term[i], nh[i], gate[i]
        for j in range(dt.shape[0]):
            nx, ny, nz = n[3 * j], n[3 * j + 1], n[3 * j + 2]
            cov = one if nx * nx + ny * ny + nz * nz > quarter else zero
            nd = nx * a[3 * j] + ny * a[3 * j + 1] + nz * a[3 * j + 2]
            hl = (nd + one) * half_
            d = hl * hl if half else max(nd, zero)
            dt[j] = d * cov
        if not spec:
            continue
        for j in range(dt.shape[0]):
            nx, ny, nz = n[3 * j], n[3 * j + 1], n[3 * j + 2]
            cov = one if nx * nx + ny * ny + nz * nz > quarter else zero
            lx, ly, lz = b[3 * j], b[3 * j + 1], b[3 * j + 2]
            vx, vy, vz = w[3 * j], w[3 * j + 1], w[3 * j + 2]
            nl = nx * lx + ny * ly + nz * lz
            nv = nx * vx + ny * vy + nz * vz
            lv = lx * vx + ly * vy + lz * vz
            length = np.sqrt(max(two * lv + two, zero))
            inv = one / max(length, tiny) if length > tiny else zero
            hr[j] = max((nl + nv) * inv, zero)
            gr[j] = cov if nl > zero else zero


def int_power(p: float) -> int:
    """``p`` as the exponent :func:`_ipow_row` raises to in the kernels, or 0 where it does not
    (not a whole number from 1 to :data:`MAX_INT_POWER`: the caller raises with cv2.pow)."""
    return int(p) if float(p).is_integer() and 1 <= p <= MAX_INT_POWER else 0


@inline_kernel
def _fold(acc, b, started):
    """``acc`` = ``acc`` × ``b``, or ``b`` where nothing is in ``acc`` yet (cv2.pow's 1 · b:
    the same number)."""
    if started:
        for j in range(b.shape[0]):
            acc[j] = acc[j] * b[j]
    else:
        for j in range(b.shape[0]):
            acc[j] = b[j]


@inline_kernel
def _ipow_row(b, p, acc):
    """``acc`` = ``b`` ** ``p`` for a whole ``p`` ≥ 1 by binary powers, the products cv2.pow
    takes for a whole exponent (1 · b, then b², b⁴, … times in order: bit for bit its result);
    ``b`` is overwritten."""
    started = False
    q = p
    while q > 1:
        if q & 1:
            _fold(acc, b, started)
            started = True
        for j in range(b.shape[0]):
            b[j] = b[j] * b[j]
        q >>= 1
    _fold(acc, b, started)


@inline_kernel
def _gated_power(base, power, gate, acc, out):
    """A row ``out`` = ``base`` ** ``power`` × ``gate`` (``power`` 0: ``base`` as it is),
    ``acc`` a scratch row (``out`` may be it); ``base`` is overwritten."""
    if power > 0:
        _ipow_row(base, power, acc)
        for j in range(base.shape[0]):
            out[j] = acc[j] * gate[j]
    else:
        for j in range(base.shape[0]):
            out[j] = base[j] * gate[j]


@kernel
def _add_terms(d_term, nh, gate, e, first, spec, power, od, os_):
    """``od`` (=, or += unless ``first``) d_term × E and, with ``spec``, ``os_`` nh^power × gate
    × E (``power`` 0: ``nh`` is raised already), E = ``e`` (3,) the light's irradiance; outputs
    (rows, 3W); ``nh`` is overwritten."""
    e0, e1, e2 = e[0], e[1], e[2]
    for i in range(od.shape[0]):
        _add_row(d_term[i], e0, e1, e2, first, od[i])
        if spec:
            t = d_term[i]  # d_term's row is free now: nh^power × gate there
            _gated_power(nh[i], power, gate[i], t, t)
            _add_row(t, e0, e1, e2, first, os_[i])


@kernel
def _add_row(t, e0, e1, e2, first, o):
    """A row of (3W) ``o`` = (or += unless ``first``) ``t`` × (e0, e1, e2)."""
    if first:
        for j in range(t.shape[0]):
            o[3 * j] = t[j] * e0
            o[3 * j + 1] = t[j] * e1
            o[3 * j + 2] = t[j] * e2
    else:
        for j in range(t.shape[0]):
            o[3 * j] += t[j] * e0
            o[3 * j + 1] += t[j] * e1
            o[3 * j + 2] += t[j] * e2


@kernel
def _transmission_rows(nrm, lt, ltc, v, vc, eta, base, gate):
    """Per pixel of the rows of (rows, 3W) ``nrm``: max(t·ℓ_t, 0) into ``base`` (to be raised to
    the lobe's exponent; 0 outside the gate) and, into ``gate``, the coverage (|n|² > 0.25)
    where the view ray enters (k >= 0): :func:`ops.shading.brdf.transmission`'s
    t·ℓ = (η n·v − √k) n·ℓ − η ℓ·v, k = 1 − η²(1 − (n·v)²), η = 1/ior. ``lt`` and ``v`` as
    ``ld`` in :func:`_terms_rows`."""
    zero, one, quarter = np.float32(0.0), np.float32(1.0), np.float32(0.25)
    for i in range(nrm.shape[0]):
        n, b, w = nrm[i], lt[0 if ltc else i], v[0 if vc else i]
        tr, gr = base[i], gate[i]
        for j in range(tr.shape[0]):
            nx, ny, nz = n[3 * j], n[3 * j + 1], n[3 * j + 2]
            lx, ly, lz = b[3 * j], b[3 * j + 1], b[3 * j + 2]
            vx, vy, vz = w[3 * j], w[3 * j + 1], w[3 * j + 2]
            nl = nx * lx + ny * ly + nz * lz
            nv = nx * vx + ny * vy + nz * vz
            lv = lx * vx + ly * vy + lz * vz
            k = one - eta * eta * (one - nv * nv)
            root = np.sqrt(max(k, zero))
            g = one if (nx * nx + ny * ny + nz * nz > quarter) and k >= zero else zero
            # (0 where the gate is: with a small ior, η t·ℓ of a ray that does not enter is
            # large enough for its power to overflow, and inf × 0 would be NaN)
            tr[j] = max((eta * nv - root) * nl - eta * lv, zero) * g
            gr[j] = g


@kernel
def _add_gated(term, gate, e, first, power, out):
    """``out`` (=, or += unless ``first``) term^power × gate × E (``power`` 0: ``term`` is
    raised already), E = ``e`` (3,); ``term`` is overwritten by that product before E;
    ``out`` (rows, 3W)."""
    e0, e1, e2 = e[0], e[1], e[2]
    acc = np.empty(term.shape[1], np.float32)
    for i in range(out.shape[0]):
        t = term[i]
        _gated_power(t, power, gate[i], acc, t)
        _add_row(t, e0, e1, e2, first, out[i])


@kernel
def _radiance_rows(lit, col, const, rad, beauty, first):
    """Rows (3W) of :func:`lobe_radiance`: ``rad`` = lit × col (``col`` one row for all with
    ``const``), ``beauty`` = (or += unless ``first``) rad."""
    for i in range(lit.shape[0]):
        a, c, r, b = lit[i], col[0 if const else i], rad[i], beauty[i]
        if first:
            for j in range(a.shape[0]):
                v = a[j] * c[j]
                r[j] = v
                b[j] = v
        else:
            for j in range(a.shape[0]):
                v = a[j] * c[j]
                r[j] = v
                b[j] += v


@kernel
def _ratio_rows(lobe, light, a, o, eps, rmax, new, new_light, acc):
    """Rows (3W) of :func:`ratio_relight` for one lobe: ``new`` = ρ·lobe, ``acc`` += new − lobe
    and, when ``light`` has rows, ``new_light`` = ρ·light."""
    zero = np.float32(0.0)
    with_light = light.shape[0] > 0
    ratio = np.empty(lobe.shape[1], np.float32)
    for i in range(lobe.shape[0]):
        lb, ar, orow, nw, ac = lobe[i], a[i], o[i], new[i], acc[i]
        for j in range(lb.shape[0]):
            r = (ar[j] + eps) / (orow[j] + eps)
            r = min(max(r, zero), rmax)
            ratio[j] = r
            v = lb[j] * r
            nw[j] = v
            ac[j] += v - lb[j]
        if with_light:
            lt, nlt = light[i], new_light[i]
            for j in range(lt.shape[0]):
                nlt[j] = lt[j] * ratio[j]


@kernel
def _gain_rows(x, gain, add, out):
    """Rows (3W) of ``x`` × ``gain`` (rows of W) in place and, with ``add``, the change
    x·gain − x added to ``out`` (rows like ``x``)."""
    for i in range(x.shape[0]):
        xr, g, o = x[i], gain[i], out[i]
        for j in range(g.shape[0]):
            for c in range(3):
                m = 3 * j + c
                old = xr[m]
                new = old * g[j]
                xr[m] = new
                if add:
                    o[m] += new - old
