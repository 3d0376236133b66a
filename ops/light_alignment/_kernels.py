"""The compiled kernels of Local Light Alignment: one scale of Eq. 1 per pixel in one pass over each
strip row (:func:`_eq1_rows`), the guides of §6 and the output writers."""

from __future__ import annotations

import math

import numpy as np

from ops.jit import inline_kernel, kernel
from ops.numerics import atan2_upper, sincos_upper

# -- compiled kernels (ops.jit): Eq. 1 per pixel, one pass over each strip row --------------------

_DIFFUSE, _SPECULAR, _TRANSMISSION = 0, 1, 2
_GUIDE_CODE = {"diffuse": _DIFFUSE, "specular": _SPECULAR, "transmission": _TRANSMISSION}

_F0, _F1, _F2 = np.float32(0.0), np.float32(1.0), np.float32(2.0)
_TINY = np.float32(1e-12)
_SMALL = np.float32(1e-6)
_TWO_OVER_PI_F = np.float32(2.0 / math.pi)


@kernel
def _reflect_px(nx, ny, nz, vx, vy, vz):
    """r = 2 (n·v) n − v (:func:`ops.shading.reflect`)."""
    two = _F2 * (nx * vx + ny * vy + nz * vz)
    return two * nx - vx, two * ny - vy, two * nz - vz


@kernel
def _refract_px(nx, ny, nz, vx, vy, vz, eta):
    """t = −η v + (η cos_i − √k) n, cos_i = n·v, k = 1 − η² (1 − cos_i²), 0 where k < 0
    (:func:`ops.shading.refract`)."""
    cos_i = nx * vx + ny * vy + nz * vz
    k = _F1 - eta * eta * (_F1 - cos_i * cos_i)
    ok = k >= _F0
    m = eta * cos_i - np.sqrt(k if ok else _F0)
    tx = m * nx - eta * vx
    ty = m * ny - eta * vy
    tz = m * nz - eta * vz
    return (tx if ok else _F0), (ty if ok else _F0), (tz if ok else _F0)


@kernel
def _inv_norm(x, y, z, tiny2):
    """1/√max(|v|², ``tiny2``): 0 vectors (background) stay 0."""
    n2 = x * x + y * y + z * z
    return _F1 / np.sqrt(n2 if n2 > tiny2 else tiny2)


_FIELD_TINY2 = np.float32(1e-12)  # |n| ≥ 1e-6 for upsampled fields
_LIGHT_TINY2 = np.float32(1e-24)  # |ℓ| ≥ 1e-12 for upsampled lights


@inline_kernel
def _deinterleave(src, dst):
    """The first ``dst.shape[1]`` XYZ triples of the flat row ``src`` into planes ``dst`` (3, w)."""
    for j in range(dst.shape[1]):
        dst[0, j], dst[1, j], dst[2, j] = src[3 * j], src[3 * j + 1], src[3 * j + 2]


@kernel
def _eq1_rows(na, nb, view, light, out, flat_a, flat_v, offs, guide, par, norm):
    """One scale of Eq. 1 (§4-6) on rows of structure-of-arrays planes.

    ``na``, ``nb``, ``view``, ``light``: tuples of three C-contiguous (rows, ·) planes, read
    from columns ``offs`` = (oa, ob, ov, ol) on, except that ``na`` / ``view`` are taken from
    the interleaved flat rows (rows, 3 W) ``flat_a`` / ``flat_v`` when those have rows (read
    from pixel oa / ov on, split per row in L1); ``out``: three (rows, w) planes; ``guide``:
    _DIFFUSE, _SPECULAR or _TRANSMISSION; ``par`` = (η = 1/ior, σ, e^{−γ}); ``norm`` =
    (norm_b, norm_l). Per row, a first pass makes the guides a_i, a_{i+1} (§6) of the fields
    (a_{i+1} renormalised if norm_b) into row buffers, a second applies Eq. 1 (the light
    renormalised first if norm_l) and writes unit ℓ_i.

    With c = a·z, the side test p = |ā| (ℓ·x) = a·ℓ − c (z·ℓ), |ā| = √(1 − c²) = λ2 and
    q = |ā| |ℓ·y| = √(|ā|² (1 − (z·ℓ)²) − p²): λ1 = (2/π) atan2(|p|, q); g = a where p > 0
    (at p = 0, λ1 = 0 and θ = 0), else the tangent t = (z − c a)/|ā|; Ω = ∠(ℓ, g) and the
    rotation is the slerp ℓ_i ∝ sin(Ω − θ) ℓ + sin θ g with θ = σ W_γ(λ1 λ2) Ω. Every pixel
    is rotated: callers put the original light back on background pixels.
    """
    oa, ob, ov, ol = offs
    eta, sigma, egam = par
    norm_b, norm_l = norm
    wd = out[0].shape[1]
    ga = np.empty((3, wd), np.float32)
    gb = np.empty((3, wd), np.float32)
    fa = np.empty((3, wd), np.float32)
    fv = np.empty((3, wd), np.float32)
    use_fa = flat_a.shape[0] > 0
    use_fv = flat_v.shape[0] > 0 and guide != _DIFFUSE
    for i in range(out[0].shape[0]):
        # rows sliced at their offsets: indices from 0 (an index ``o + j`` is not provably
        # non-negative, so its wraparound check stops vectorisation)
        if use_fa:
            _deinterleave(flat_a[i][3 * oa :], fa)
            ax_r, ay_r, az_r = fa[0], fa[1], fa[2]
        else:
            ax_r, ay_r, az_r = na[0][i][oa:], na[1][i][oa:], na[2][i][oa:]
        if use_fv:
            _deinterleave(flat_v[i][3 * ov :], fv)
            vx_r, vy_r, vz_r = fv[0], fv[1], fv[2]
        else:
            vx_r, vy_r, vz_r = view[0][i][ov:], view[1][i][ov:], view[2][i][ov:]
        bx_r, by_r, bz_r = nb[0][i][ob:], nb[1][i][ob:], nb[2][i][ob:]
        gax, gay, gaz = ga[0], ga[1], ga[2]
        gbx, gby, gbz = gb[0], gb[1], gb[2]
        if guide == _DIFFUSE:
            for j in range(wd):
                bx, by, bz = bx_r[j], by_r[j], bz_r[j]
                inv = _inv_norm(bx, by, bz, _FIELD_TINY2) if norm_b else _F1
                gax[j], gay[j], gaz[j] = ax_r[j], ay_r[j], az_r[j]
                gbx[j], gby[j], gbz[j] = bx * inv, by * inv, bz * inv
        elif guide == _SPECULAR:
            for j in range(wd):
                vx, vy, vz = vx_r[j], vy_r[j], vz_r[j]
                bx, by, bz = bx_r[j], by_r[j], bz_r[j]
                inv = _inv_norm(bx, by, bz, _FIELD_TINY2) if norm_b else _F1
                rx, ry, rz = _reflect_px(ax_r[j], ay_r[j], az_r[j], vx, vy, vz)
                gax[j], gay[j], gaz[j] = rx, ry, rz
                rx, ry, rz = _reflect_px(bx * inv, by * inv, bz * inv, vx, vy, vz)
                gbx[j], gby[j], gbz[j] = rx, ry, rz
        else:
            for j in range(wd):
                vx, vy, vz = vx_r[j], vy_r[j], vz_r[j]
                bx, by, bz = bx_r[j], by_r[j], bz_r[j]
                inv = _inv_norm(bx, by, bz, _FIELD_TINY2) if norm_b else _F1
                ax, ay, az = ax_r[j], ay_r[j], az_r[j]
                rx, ry, rz = _refract_px(ax, ay, az, vx, vy, vz, eta)
                gax[j], gay[j], gaz[j] = rx, ry, rz
                rx, ry, rz = _refract_px(bx * inv, by * inv, bz * inv, vx, vy, vz, eta)
                gbx[j], gby[j], gbz[j] = rx, ry, rz
        lx_r, ly_r, lz_r = light[0][i][ol:], light[1][i][ol:], light[2][i][ol:]
        ox_r, oy_r, oz_r = out[0][i], out[1][i], out[2][i]
        for j in range(wd):
            ax, ay, az = gax[j], gay[j], gaz[j]
            bx, by, bz = gbx[j], gby[j], gbz[j]
            lx, ly, lz = lx_r[j], ly_r[j], lz_r[j]
            inv = _inv_norm(lx, ly, lz, _LIGHT_TINY2) if norm_l else _F1
            lx, ly, lz = lx * inv, ly * inv, lz * inv
            c = ax * bx + ay * by + az * bz  # a·z
            al = ax * lx + ay * ly + az * lz  # a·ℓ
            bl = bx * lx + by * ly + bz * lz  # z·ℓ
            p = al - c * bl  # |ā| (ℓ·x): the side test
            s = _F1 - c * c  # |ā|² = 1 − (a·z)²
            s = s if s > _F0 else _F0
            q = s * (_F1 - bl * bl) - p * p  # (|ā| |ℓ·y|)²
            q = np.sqrt(q if q > _F0 else _F0)
            lam2 = np.sqrt(s)  # λ2 = |ā|
            lam = atan2_upper(abs(p), q) * _TWO_OVER_PI_F * lam2  # λ = λ1 λ2
            k = sigma * lam / (egam + lam * (_F1 - egam))  # σ W_γ(λ)
            lit = p > _F0  # ℓ̄·x > 0: g = a; else the tangent t = (z − c a)/|ā|
            isd = _F0 if lit else _F1 / (lam2 if lam2 > _TINY else _TINY)
            gl = al if lit else isd * (bl - c * al)  # g·ℓ = cos Ω
            gl = gl if gl < _F1 else _F1
            gl = gl if gl > -_F1 else -_F1
            sin_o = _F1 - gl * gl
            sin_o = np.sqrt(sin_o if sin_o > _F0 else _F0)
            theta = atan2_upper(sin_o, gl) * k  # θ = σ W_γ Ω
            sin_t, cos_t = sincos_upper(theta)
            sin_o = sin_o if sin_o > _SMALL else _SMALL
            # ℓ_i ∝ sin(Ω − θ) ℓ + sin θ g,  g = h a + isd z,  h = 1 (lit) or −c/|ā|
            coef_l = cos_t * sin_o - gl * sin_t
            coef_a = ((_F1 if lit else _F0) - c * isd) * sin_t
            coef_b = isd * sin_t
            ox = coef_l * lx + coef_a * ax + coef_b * bx
            oy = coef_l * ly + coef_a * ay + coef_b * by
            oz = coef_l * lz + coef_a * az + coef_b * bz
            norm = np.sqrt(ox * ox + oy * oy + oz * oz)
            inv = _F1 / (norm if norm > _TINY else _TINY)
            ox_r[j], oy_r[j], oz_r[j] = ox * inv, oy * inv, oz * inv


@kernel
def _guide_rows(n, view, guide, eta, out):
    """The guide a_i (§6) of a unit field ``n`` on planes (the formulas of :func:`_eq1_rows`)."""
    wd = out[0].shape[1]
    for i in range(out[0].shape[0]):
        nx_r, ny_r, nz_r = n[0][i], n[1][i], n[2][i]
        vx_r, vy_r, vz_r = view[0][i], view[1][i], view[2][i]
        ox_r, oy_r, oz_r = out[0][i], out[1][i], out[2][i]
        for j in range(wd):
            nx, ny, nz, vx, vy, vz = nx_r[j], ny_r[j], nz_r[j], vx_r[j], vy_r[j], vz_r[j]
            if guide == _SPECULAR:
                rx, ry, rz = _reflect_px(nx, ny, nz, vx, vy, vz)
            elif guide == _TRANSMISSION:
                rx, ry, rz = _refract_px(nx, ny, nz, vx, vy, vz, eta)
            else:
                rx, ry, rz = nx, ny, nz
            ox_r[j], oy_r[j], oz_r[j] = rx, ry, rz


@kernel
def _write_rows(light, ol, norm_l, mask, orig, out, x0, wd):
    """Level-0 output rows (interleaved, flat (rows, 3 W)): the aligned ``light`` planes (read
    from column ``ol`` on, renormalised if ``norm_l``) on the covered pixels (``mask`` 1, not 0)
    of columns x0 … x0 + wd, the original light ``orig`` (flat rows) everywhere else."""
    for i in range(out.shape[0]):
        o_r, g_r = out[i], orig[i]
        for t in range(3 * x0):
            o_r[t] = g_r[t]
        o_w, g_w, m_w = o_r[3 * x0 :], g_r[3 * x0 :], mask[i][x0:]
        lx_r, ly_r, lz_r = light[0][i][ol:], light[1][i][ol:], light[2][i][ol:]
        for j in range(wd):
            lx, ly, lz = lx_r[j], ly_r[j], lz_r[j]
            inv = _inv_norm(lx, ly, lz, _LIGHT_TINY2) if norm_l else _F1
            # the coverage is 0 or 1: an exact choice by arithmetic (a select between loaded
            # values does not vectorise here)
            m = m_w[j]
            inv *= m
            keep = _F1 - m
            o_w[3 * j] = lx * inv + g_w[3 * j] * keep
            o_w[3 * j + 1] = ly * inv + g_w[3 * j + 1] * keep
            o_w[3 * j + 2] = lz * inv + g_w[3 * j + 2] * keep
        o_t, g_t = o_r[3 * (x0 + wd) :], g_r[3 * (x0 + wd) :]
        for t in range(o_t.shape[0]):
            o_t[t] = g_t[t]


@kernel
def _store_rows(light, ol, norm_l, mask, out, x0, wd):
    """Coarse-level state rows: ``out`` planes (columns x0 … x0 + wd) = the aligned ``light``
    (from column ``ol`` on, renormalised if ``norm_l``) × the coverage ``mask`` (full rows)."""
    for i in range(out[0].shape[0]):
        lx_r, ly_r, lz_r = light[0][i][ol:], light[1][i][ol:], light[2][i][ol:]
        ox_r, oy_r, oz_r = out[0][i][x0:], out[1][i][x0:], out[2][i][x0:]
        m_r = mask[i][x0:]
        for j in range(wd):
            lx, ly, lz = lx_r[j], ly_r[j], lz_r[j]
            inv = _inv_norm(lx, ly, lz, _LIGHT_TINY2) if norm_l else _F1
            m = m_r[j] * inv
            ox_r[j], oy_r[j], oz_r[j] = lx * m, ly * m, lz * m
