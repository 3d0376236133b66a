"""Local Light Alignment (Mestres et al., "Local Light Alignment for Multi-Scale Shape Depiction",
EG 2021, §4-6).

At each pixel the light direction ℓ is rotated, scale by scale from the coarsest to the finest,
towards a guiding vector g so that one side of every feature faces the light and the other side
is grazed by it. With the multi-scale fields a_1 (finest) … a_S (coarsest) — the normals n_i for
the diffuse component, the reflected view vectors r_i = reflect(v, n_i) for the specular one and
the refracted view vectors t_i = refract(v, n_i, ior) for transmission (§6) — scale i uses the
local frame (§5)::

    z_i = a_{i+1},   x_i = normalize(a_i − z_i (a_i·z_i)),   y_i = x_i × z_i

and (§4, Eq. 1)::

    g_i = a_i                    if ℓ̄_{i+1}·x_i ≥ 0   (the lit side: face the light)
          R(y_i, −π/2) a_i       otherwise            (the other side: the tangent of the
                                                       (x_i, z_i) plane perpendicular to a_i)
    ℓ_i = R(ℓ_{i+1} × g_i, θ_i) ℓ_{i+1},   θ_i = σ_i W_γ(λ1 λ2) ∠(ℓ_{i+1}, g_i)
    W_γ(λ) = λ / (e^{−γ}(1 − λ) + λ),   λ1 = 1 − 2∠(ℓ̄, ḡ)/π,   λ2 = |ā_i|

where v̄ is the projection of v on the (x_i, y_i) plane, ℓ_S = ℓ, and the output ℓ_1.

Notes on the exact geometry (the paper's figures fix what the text leaves open):

- The tangent on the unlit side is t = (z − (a·z) a)/|ā|, the unit vector perpendicular to a in
  the (x, z) plane on the side of z (above the base). It is the tangent that the light reaches by
  turning away from a: rotating ℓ towards it lowers a·ℓ monotonically to 0, whereas the opposite
  tangent would swing the light through a (brightening the dark side first). The paper's
  "R(y, −π/2)" names this rotation in its figure's orientation (y = x × z makes (x, y, z)
  left-handed).
- ℓ̄·x has the sign of a·ℓ − (a·z)(z·ℓ); ḡ is along +x on the lit side and −x on the other, so
  ∠(ℓ̄, ḡ) = atan2(|ℓ·y|, |ℓ·x|) and λ1 = (2/π) atan2(|ℓ·x|, |ℓ·y|) ∈ [0, 1] (0 where ℓ̄ = 0:
  the light along the base normal has no side to turn to).
- λ2 = |ā| = sin ∠(a_i, a_{i+1}) measures how much the feature protrudes from its base.
- Mirror symmetry: a configuration symmetric about a plane containing the light (the ridge of
  Fig. 2 lit exactly along its bisector) stays symmetric — both sides are treated alike. A
  light off the bisector by more than the base normals lean makes one side bright and the
  other dark, as in Fig. 2 b-c.

``σ_i`` is given per scale, finest first: ``sigmas[0]`` rotates towards a_1 within the frame of
a_2 (the paper's Figs. 7, 9, 10 list σ_1 … σ_{S−1} in this order). Background pixels keep the
original light; the output directions are unit length.

Speed: given a :class:`ops.filtering.NormalPyramid`, each scale is aligned at the pyramid level
its fine field lives on (coarse scales are smooth) and the light is carried to finer levels by
the pyramid's edge-aware upsampling; only the scales of the full-resolution field n_1 run at
full resolution. Every level runs the same way (:class:`_Stage`): row strips (restricted to the
columns that hold surfaces) on all cores, where the coarser fields and lights are upsampled
(all planes of a level in one resize) into reused scratch buffers, and each scale of Eq. 1 is
one compiled pass over the strip's rows (:func:`_eq1_rows`, an :func:`ops.jit.kernel`: guides,
renormalisation of upsampled vectors and the rotation per pixel in registers, reading n_1 and
the view interleaved as they are); at full resolution :func:`_write_rows` writes the
interleaved output, the original light on background pixels. The angles are vectorised
polynomials (atan2 and sin / cos, errors ~1e-7 rad, below float32 rounding of the inputs'
dot products). Given a plain list of (H, W, 3) fields, every scale runs at full resolution
(the reference path).

Rounding: √(1 − (a_i·z)²) amplifies the last bits of nearly parallel fields, and λ1 has no limit
where ℓ̄ → 0 (the light along the frame's z, e.g. at a highlight's centre), so a few pixels of a
frame move by up to ~1e-2 under any change of float32 rounding (a 1e-7 rad turn of the input
light does the same); the fields entering a_i·z are therefore normalised with fixed rounding.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Mapping, Sequence
from typing import Any, Literal

import cv2
import numpy as np

from ops.checks import IOR, LLA_GAMMA, LLA_SIGMA, check_sequence
from ops.filtering import F32, NormalPyramid, normalize_field
from ops.jit import inline_kernel, kernel
from ops.numerics import atan2_upper, sincos_upper
from ops.parallel import run_strips
from ops.shading import Light, light_vectors

Guide = Literal["diffuse", "specular", "transmission"]
GUIDES: tuple[str, ...] = ("diffuse", "specular", "transmission")
DEFAULT_GAMMA = 3.0

SoA = tuple[F32, F32, F32]


def w_gamma(lam: np.ndarray | float, gamma: float = DEFAULT_GAMMA) -> np.ndarray:
    """Confidence weighting W_γ(λ) = λ / (e^{−γ}(1 − λ) + λ) (Mestres et al. 2021, §4).

    Maps [0, 1] onto [0, 1] monotonically with W(0) = 0 and W(1) = 1; W_0 is the identity and a
    larger γ narrows the transition between the bright and the dark side of features.

    Parameters
    ----------
    lam : confidence λ = λ1 λ2 in [0, 1] (array or scalar; clipped to [0, 1]).
    gamma : γ in :data:`ops.checks.LLA_GAMMA` (the paper uses 3).
    """
    gamma = LLA_GAMMA.check(gamma, "gamma")
    lam_a = np.clip(np.asarray(lam, np.float32), 0.0, 1.0)
    e = np.float32(math.exp(-gamma))
    return np.asarray(lam_a / (e + lam_a * (np.float32(1.0) - e)), np.float32)


def _check_sigmas(sigmas: Sequence[float], scales: int, name: str = "sigmas") -> list[float]:
    vals = [float(s) for s in sigmas]
    if len(vals) != scales - 1:
        raise ValueError(
            f"{name} must have one value per scale transition: {scales - 1} for {scales} "
            f"normal fields, got {len(vals)}"
        )
    return check_sequence(vals, LLA_SIGMA, name)


def _check_guide(guide: str) -> str:
    if guide not in GUIDES:
        raise ValueError(f"guide must be one of {', '.join(GUIDES)}; got {guide!r}")
    return guide


def _soa(arr: np.ndarray) -> SoA:
    return (
        np.ascontiguousarray(arr[..., 0]),
        np.ascontiguousarray(arr[..., 1]),
        np.ascontiguousarray(arr[..., 2]),
    )


class _Work:
    """Scratch buffers for strips of one shape, reused between calls (one set per thread).

    Temporaries of ~100 KB-1 MB would otherwise be fresh allocations (page faults) at every op.
    Buffers are flat and grow as needed; each call hands out a contiguous view of the current
    strip shape (:meth:`get` sets it), so strips of any width share the same memory.
    """

    _local = threading.local()

    def __init__(self, shape: tuple[int, int]) -> None:
        self._flat: dict[str, np.ndarray] = {}
        self._views: dict[str, F32] = {}
        self.shape = (0, 0)
        self.reshape(shape)

    def reshape(self, shape: tuple[int, int]) -> None:
        if shape == self.shape:
            return
        self.shape = shape
        self._views.clear()

    def __call__(self, name: str) -> F32:
        """A (rows, w) view of buffer ``name`` (C-contiguous)."""
        view = self._views.get(name)
        if view is None:
            n = self.shape[0] * self.shape[1]
            flat = self._flat.get(name)
            if flat is None or flat.size < n:
                flat = self._flat[name] = np.empty(max(n, 1), np.float32)
            view = self._views[name] = flat[:n].reshape(self.shape)
        return view

    def vec(self, name: str) -> SoA:
        return (self(name + ".x"), self(name + ".y"), self(name + ".z"))

    def arr(self, name: str, shape: tuple[int, ...]) -> F32:
        """A contiguous scratch array of any shape."""
        n = int(np.prod(shape))
        flat = self._flat.get("@" + name)
        if flat is None or flat.size < n:
            flat = self._flat["@" + name] = np.empty(max(n, 1), np.float32)
        return flat[:n].reshape(shape)

    @classmethod
    def get(cls, shape: tuple[int, int]) -> _Work:
        """This thread's workspace, set to strips of ``shape``."""
        work: _Work | None = getattr(cls._local, "work", None)
        if work is None:
            work = cls._local.work = cls(shape)
        work.reshape(shape)
        return work


# -- compiled kernels (ops.jit): Eq. 1 per pixel, one pass over each strip row --------------------

_DIFFUSE, _SPECULAR, _TRANSMISSION = 0, 1, 2
_GUIDE_CODE = {"diffuse": _DIFFUSE, "specular": _SPECULAR, "transmission": _TRANSMISSION}

_F0, _F1, _F2 = np.float32(0.0), np.float32(1.0), np.float32(2.0)
_TINY = np.float32(1e-12)
_SMALL = np.float32(1e-6)
_TWO_OVER_PI_F = np.float32(2.0 / math.pi)


@kernel
def _reflect_px(nx, ny, nz, vx, vy, vz):  # type: ignore[no-untyped-def]
    """r = 2 (n·v) n − v (:func:`ops.shading.reflect`)."""
    two = _F2 * (nx * vx + ny * vy + nz * vz)
    return two * nx - vx, two * ny - vy, two * nz - vz


@kernel
def _refract_px(nx, ny, nz, vx, vy, vz, eta):  # type: ignore[no-untyped-def]
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
def _inv_norm(x, y, z, tiny2):  # type: ignore[no-untyped-def]
    """1/√max(|v|², ``tiny2``): 0 vectors (background) stay 0."""
    n2 = x * x + y * y + z * z
    return _F1 / np.sqrt(n2 if n2 > tiny2 else tiny2)


_FIELD_TINY2 = np.float32(1e-12)  # |n| ≥ 1e-6 for upsampled fields
_LIGHT_TINY2 = np.float32(1e-24)  # |ℓ| ≥ 1e-12 for upsampled lights


@inline_kernel
def _deinterleave(src, dst):  # type: ignore[no-untyped-def]
    """The first ``dst.shape[1]`` XYZ triples of the flat row ``src`` into planes ``dst`` (3, w)."""
    for j in range(dst.shape[1]):
        dst[0, j], dst[1, j], dst[2, j] = src[3 * j], src[3 * j + 1], src[3 * j + 2]


@kernel
def _eq1_rows(na, nb, view, light, out, flat_a, flat_v, offs, guide, par, norm):  # type: ignore[no-untyped-def]
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
def _guide_rows(n, view, guide, eta, out):  # type: ignore[no-untyped-def]
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
def _write_rows(light, ol, norm_l, mask, orig, out, x0, wd):  # type: ignore[no-untyped-def]
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
def _store_rows(light, ol, norm_l, mask, out, x0, wd):  # type: ignore[no-untyped-def]
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


def _guide_soa(guide: str, n: SoA, view: SoA | None, ior: float, out: SoA, ws: _Work) -> SoA:
    """a_i for a guide (§6) on structure-of-arrays planes: n_i (diffuse), the reflected view
    vector (specular) or the refracted view vector (transmission) — the formulas of
    :func:`ops.shading.reflect` / :func:`ops.shading.refract` (the tests hold them equal), by
    the per-pixel functions :func:`_eq1_rows` uses.

    specular: r = 2 (n·v) n − v;  transmission: t = −η v + (η cos_i − √k) n, η = 1/ior,
    cos_i = n·v, k = 1 − η² (1 − cos_i²), t = 0 where k < 0.
    """
    if guide == "diffuse":
        return n
    assert view is not None
    _guide_rows(n, view, _GUIDE_CODE[guide], np.float32(1.0 / ior), out)
    return out


def _const_or_field(light_dir: np.ndarray, shape: tuple[int, int]) -> tuple[F32 | None, F32 | None]:
    arr = np.asarray(light_dir, np.float32)
    if arr.shape == (3,):
        norm = float(np.linalg.norm(arr))
        if not (math.isfinite(norm) and norm > 1e-12):
            raise ValueError("light_dir must be a finite non-zero vector")
        return (arr / norm).astype(np.float32), None
    if arr.shape != (*shape, 3):
        raise ValueError(f"light_dir must be (3,) or (H, W, 3) = {(*shape, 3)}, got {arr.shape}")
    return None, normalize_field(arr)


def align_components(
    light_dir: np.ndarray,
    normals: Sequence[np.ndarray] | NormalPyramid,
    components: Mapping[str, Sequence[float]],
    gamma: float = DEFAULT_GAMMA,
    view: np.ndarray | None = None,
    ior: float = 1.5,
    mask: np.ndarray | None = None,
) -> dict[str, F32]:
    """Aligned light directions for several shading components at once (LLA §4-6, Eq. 1).

    Parameters
    ----------
    light_dir : (3,) direction towards the light, or (H, W, 3) per pixel (point lights).
    normals : a :class:`~ops.filtering.NormalPyramid` (fast: coarse scales at low resolution)
        or the list [n_1, …, n_S] of (H, W, 3) fields (every scale at full resolution).
    components : guide name ("diffuse", "specular", "transmission") -> σ_1 … σ_{S−1}
        (finest first), each in [0, 1].
    gamma : γ of W_γ, in [0, 20].
    view : (H, W, 3) or (3,) unit directions towards the eye (needed by "specular" and
        "transmission").
    ior : index of refraction of the transmission guide, in (0, 10].
    mask : (H, W) coverage for a plain list (default: pixels where n_1 is non-zero).

    Returns
    -------
    dict guide -> (H, W, 3) float32 unit directions ℓ_1; background keeps ``light_dir``.
    """
    gamma = LLA_GAMMA.check(gamma, "gamma")
    ior = IOR.check(ior, "ior")
    pyr = normals if isinstance(normals, NormalPyramid) else None
    fields = None
    if pyr is None:
        assert not isinstance(normals, NormalPyramid)
        fields = [np.asarray(n, np.float32) for n in normals]
    if fields is not None:
        if len(fields) < 2:
            raise ValueError(f"normals must hold at least 2 fields, got {len(fields)}")
        shape = fields[0].shape[:2]
        for f in fields:
            if f.shape != (*shape, 3):
                raise ValueError(f"every normal field must be (H, W, 3) = {(*shape, 3)}")
        scales = len(fields)
    else:
        assert pyr is not None
        shape = pyr.shape
        scales = pyr.scales
    if not components:
        raise ValueError("components must name at least one guide")
    comps = {
        _check_guide(g): _check_sigmas(s, scales, f"sigmas of {g!r}") for g, s in components.items()
    }
    needs_view = any(g != "diffuse" for g in comps)
    view_f: F32 | None = None
    view_c: F32 | None = None
    if needs_view:
        if view is None:
            raise ValueError("view is required by the specular and transmission guides")
        view_a = np.asarray(view, np.float32)
        if view_a.shape == (3,):
            norm = float(np.linalg.norm(view_a))
            if not (math.isfinite(norm) and norm > 1e-12):
                raise ValueError("view must be a finite non-zero vector")
            view_c = (view_a / norm).astype(np.float32)
        elif view_a.shape == (*shape, 3):
            view_f = view_a
        else:
            raise ValueError(f"view must be (3,) or (H, W, 3) = {(*shape, 3)}, got {view_a.shape}")
    const, lfield = _const_or_field(light_dir, shape)
    if fields is not None:
        if mask is None:
            n1 = fields[0]
            m0 = (
                n1[..., 0] * n1[..., 0] + n1[..., 1] * n1[..., 1] + n1[..., 2] * n1[..., 2]
            ) > 0.25
        else:
            m0 = np.asarray(mask) > 0
            if m0.shape != shape:
                raise ValueError(f"mask must be (H, W) = {shape}, got {m0.shape}")
        inp = _Inputs(
            shape,
            comps,
            math.exp(-gamma),
            ior,
            view_f,
            view_c,
            const,
            lfield,
            fields=[np.asarray(f, np.float32) for f in fields],
            mask=m0.astype(np.float32),
        )
        return _align_full(inp)
    assert pyr is not None
    inp = _Inputs(shape, comps, math.exp(-gamma), ior, view_f, view_c, const, lfield, pyr=pyr)
    return _align_pyramid(inp)


def _fill(vec: SoA, value: np.ndarray) -> SoA:
    for comp, val in zip(vec, value, strict=True):
        comp.fill(float(val))
    return vec


def _copy_in(vec: SoA, arr: np.ndarray) -> SoA:
    """Interleaved (h, w, 3) rows into structure-of-arrays buffers (``cv2.split`` into
    preallocated planes: ~5x faster than strided NumPy copies)."""
    if arr.dtype != np.float32 or arr.strides[1:] != (12, 4):
        arr = np.ascontiguousarray(arr, np.float32)
    cv2.split(arr, list(vec))  # rows may be strided (a column window)
    return vec


def _rows(v: SoA, r0: int, r1: int) -> SoA:
    """Rows r0:r1 of planes (C-contiguous views: the kernels take a column offset)."""
    return (v[0][r0:r1], v[1][r0:r1], v[2][r0:r1])


Win = tuple[int, int, int, int]  # rows r0:r1, columns x0:x1 (at the stage's level)
State = tuple[int, SoA]  # a component's light aligned so far: (level, planes, 0 on background)
# a strip's input to the kernels: planes, the window's first column in them, renormalise?, and
# the interleaved rows (rows, 3 W) the kernel reads instead of the planes (or None)
Src = tuple[SoA, int, bool, F32 | None]
_NO_PLANES: SoA = (np.zeros((1, 1), np.float32),) * 3
_NO_FLAT: F32 = np.zeros((0, 3), np.float32)


def _flat_rows(arr: np.ndarray, r0: int, r1: int) -> F32 | None:
    """Rows r0:r1 of an (H, W, 3) float32 array as flat (rows, 3 W) rows, or None when it is
    not C-contiguous float32 (then it is split into planes)."""
    if arr.dtype != np.float32 or not arr.flags.c_contiguous:
        return None
    return np.asarray(arr[r0:r1].reshape(r1 - r0, 3 * arr.shape[1]), np.float32)


# Rows per strip, and at least this many pixels per strip (coarse levels are narrow): each call
# then works long enough for the two threads to overlap rather than wait on each other.
_ROWS = 64
_STRIP_PIXELS = 1 << 15


def _strip_rows(width: int) -> int:
    return max(_ROWS, -(-_STRIP_PIXELS // max(1, width)))


class _Inputs:
    """What every stage of one :func:`align_components` call shares."""

    def __init__(
        self,
        shape: tuple[int, int],
        comps: dict[str, list[float]],
        egam: float,
        ior: float,
        view: F32 | None,
        view_const: F32 | None,
        const: F32 | None,
        lfield: F32 | None,
        pyr: NormalPyramid | None = None,
        fields: list[F32] | None = None,
        mask: F32 | None = None,
    ) -> None:
        self.shape = shape
        self.comps = comps
        self.egam = egam
        self.ior = ior
        self.view = view
        self.view_const = view_const
        self.const = const
        self.lfield = lfield
        self.pyr = pyr
        self.fields = fields
        if pyr is not None:
            self.masks = pyr.geometry.mask
        else:
            assert mask is not None
            self.masks = [mask]
        self._views: dict[int, SoA] = {}
        self._lights: dict[int, SoA] = {}
        self.rows: F32 | None = None
        if const is not None:  # a strip of the constant light (level-0 rows are copied from it)
            self.rows = np.empty((min(shape[0], _strip_rows(shape[1])), shape[1], 3), np.float32)
            self.rows[:] = np.tile(const, (shape[1], 1))
        self.outs = {g: np.empty((*shape, 3), np.float32) for g in comps}

    def needs_view(self, comps: Sequence[str]) -> bool:
        return any(g != "diffuse" for g in comps)

    def view_planes(self, k: int) -> SoA:
        """The view at level k > 0 (the field is smooth: plain area averaging, each level from
        the finest one already made), renormalised, as planes (cached)."""
        got = self._views.get(k)
        if got is None:
            assert self.view is not None and self.pyr is not None
            hk, wk = self.pyr.geometry.shape(k)
            src = max((lv for lv in self._views if lv < k), default=0)
            base = self.view if src == 0 else cv2.merge(list(self._views[src]))
            f = 1 << (k - src)
            if base.shape[:2] == (hk * f, wk * f) and base.flags.c_contiguous:
                # an exact f×f block average: row strips on all cores give the same result
                small = np.empty((hk, wk, 3), np.float32)

                def strip(a: int, b: int) -> None:
                    cv2.resize(
                        base[a * f : b * f], (wk, b - a), small[a:b], interpolation=cv2.INTER_AREA
                    )

                run_strips(hk, strip, rows=max(1, _strip_rows(base.shape[1]) // f))
            else:
                small = np.asarray(
                    cv2.resize(base, (wk, hk), interpolation=cv2.INTER_AREA), np.float32
                )
            got = self._views[k] = _soa(normalize_field(small))
        return got

    def light_planes(self, k: int) -> SoA:
        """The original (per-pixel) light at level k > 0, 0 on background (cached)."""
        got = self._lights.get(k)
        if got is None:
            assert self.lfield is not None and self.pyr is not None
            got = self._lights[k] = _soa(self.pyr.geometry.down(self.lfield, 0, k))
        return got


class _Stage:
    """The scales aligned at one pyramid level k, strip by strip, on the columns that hold
    surfaces: per strip the fields (those of coarser levels upsampled edge-aware and
    renormalised), the view and the incoming light of each component become
    structure-of-arrays buffers, and Eq. 1 is applied from the coarsest scale of the level to
    the finest. At level 0 the result is written to the outputs, whose other pixels (background,
    components left unchanged) keep the original light; at coarser levels it becomes the
    components' new states (0 on background)."""

    def __init__(
        self, inp: _Inputs, k: int, steps: list[int], states: dict[str, State | None]
    ) -> None:
        self.inp = inp
        self.k = k
        self.steps = sorted(steps, reverse=True)
        self.states = states
        comps = inp.comps
        active = [g for g, sig in comps.items() if any(sig[j] > 0.0 for j in steps)]
        if k == 0:
            active = [g for g in comps if g in active or states.get(g) is not None]
        self.active = active
        self.mask = inp.masks[k]
        self.shape = (int(self.mask.shape[0]), int(self.mask.shape[1]))
        self.new: dict[str, SoA] = {}
        if k > 0:
            for g in active:
                self.new[g] = (
                    np.zeros(self.shape, np.float32),
                    np.zeros(self.shape, np.float32),
                    np.zeros(self.shape, np.float32),
                )
        # what comes from coarser levels: the fields z = a_{j+1} and the lights aligned so far
        by_level: dict[int, list[tuple[str, SoA]]] = {}
        pyr = inp.pyr
        if pyr is not None:
            for j in steps:
                if pyr.levels[j + 1] > k and any(comps[g][j] > 0.0 for g in active):
                    by_level.setdefault(pyr.levels[j + 1], []).append(
                        (f"n{j + 1}", pyr.planes(j + 1))
                    )
            for g in active:
                state = states.get(g)
                if state is not None:
                    by_level.setdefault(state[0], []).append((f"light:{g}", state[1]))
        self.sources: list[tuple[int, list[str], list[F32], tuple[Any, Any, Any]]] = []
        for lvl, items in sorted(by_level.items()):
            planes = [plane for _, vec in items for plane in vec]
            assert pyr is not None
            sparse = pyr.geometry.up_sparse(planes, lvl, k)
            self.sources.append((lvl, [n for n, _ in items], planes, sparse))
        self.with_view = inp.needs_view(active)

    # -- inputs of a strip: (planes, first column of the window in them, renormalise?) ------

    def upsample(self, win: Win, ws: _Work) -> dict[str, Src]:
        """The fields and lights of coarser levels on the window, bilinear + edge-aware, not
        yet renormalised (the kernels do it: bilinear shortens unit vectors, to 0 … 1 next to
        background)."""
        r0, r1, x0, x1 = win
        ups: dict[str, Src] = {}
        if not self.sources:
            return ups
        assert self.inp.pyr is not None
        geo = self.inp.pyr.geometry
        for lvl, names, planes_k, sparse in self.sources:
            planes, c = geo.up_rows_wide(
                planes_k, lvl, (r0, r1), ws.arr, sparse, k_to=self.k, cols=(x0, x1)
            )
            for i, name in enumerate(names):
                ups[name] = ((planes[3 * i], planes[3 * i + 1], planes[3 * i + 2]), c, True, None)
        return ups

    def field(self, i: int, win: Win, ws: _Work, ups: dict[str, Src]) -> Src:
        r0, r1, x0, x1 = win
        inp = self.inp
        if inp.fields is not None:
            return _copy_in(ws.vec(f"n{i}"), inp.fields[i][r0:r1, x0:x1]), 0, False, None
        assert inp.pyr is not None
        lvl = inp.pyr.levels[i]
        if lvl > self.k:
            return ups[f"n{i}"]
        if self.k == 0:
            flat = _flat_rows(inp.pyr.normals[i], r0, r1)
            if flat is not None:
                return _NO_PLANES, x0, False, flat
            return _copy_in(ws.vec(f"n{i}"), inp.pyr.normals[i][r0:r1, x0:x1]), 0, False, None
        return _rows(inp.pyr.planes(i), r0, r1), x0, False, None

    def field_planes(self, i: int, win: Win, ws: _Work) -> Src:
        """Level-0 field n_{i+1} of the pyramid split into planes (for the frame's z)."""
        r0, r1, x0, x1 = win
        assert self.inp.pyr is not None
        return _copy_in(ws.vec(f"n{i}"), self.inp.pyr.normals[i][r0:r1, x0:x1]), 0, False, None

    def view(self, win: Win, ws: _Work) -> Src:
        r0, r1, x0, x1 = win
        inp = self.inp
        if inp.view is None:
            assert inp.view_const is not None
            return _fill(ws.vec("view"), inp.view_const), 0, False, None
        if self.k == 0:
            flat = _flat_rows(inp.view, r0, r1)
            if flat is not None:
                return _NO_PLANES, x0, False, flat
            return _copy_in(ws.vec("view"), inp.view[r0:r1, x0:x1]), 0, False, None
        return _rows(inp.view_planes(self.k), r0, r1), x0, False, None

    def light(self, g: str, win: Win, ws: _Work, ups: dict[str, Src]) -> Src:
        if self.states.get(g) is not None:
            return ups[f"light:{g}"]
        r0, r1, x0, x1 = win
        inp = self.inp
        if inp.lfield is None:
            assert inp.const is not None
            return _fill(ws.vec("light_in"), inp.const), 0, False, None
        if self.k == 0:
            return _copy_in(ws.vec("light_in"), inp.lfield[r0:r1, x0:x1]), 0, False, None
        return _rows(inp.light_planes(self.k), r0, r1), x0, False, None

    # -- a strip ------------------------------------------------------------------------------

    def fill(self, out: F32, r0: int, r1: int, x0: int, x1: int) -> None:
        """Level 0: the original light on rows r0:r1, columns x0:x1 of an output."""
        inp = self.inp
        if x1 <= x0:
            return
        if inp.lfield is not None:
            np.copyto(out[r0:r1, x0:x1], inp.lfield[r0:r1, x0:x1])
        else:  # from rows of the light (a (3,) broadcast over (h, w, 3) is ~10x slower)
            assert inp.rows is not None
            out[r0:r1, x0:x1] = inp.rows[: r1 - r0, x0:x1]

    def strip(self, r0: int, r1: int) -> None:
        k = self.k
        inp = self.inp
        width = self.shape[1]
        cols = np.flatnonzero(self.mask[r0:r1].max(axis=0)) if self.active else np.zeros(0, int)
        if not cols.size:
            if k == 0:  # all background, or no component changes
                for dst in inp.outs.values():
                    self.fill(dst, r0, r1, 0, width)
            return
        # window width rounded up (a few scratch-buffer shapes serve every strip)
        x0 = int(cols[0])
        step = 128 if k == 0 else 16
        wd = min(width, -(-(int(cols[-1]) + 1 - x0) // step) * step)
        x0 = min(x0, width - wd)
        win = (r0, r1, x0, x0 + wd)
        if k == 0:  # components left unchanged keep the original light (the others: write)
            for g, dst in inp.outs.items():
                if g not in self.active:
                    self.fill(dst, r0, r1, 0, width)
        ws = _Work.get((r1 - r0, wd))
        ups = self.upsample(win, ws)
        view = self.view(win, ws) if self.with_view else None
        fields: dict[int, Src] = {}
        eta = np.float32(1.0 / inp.ior)
        egam = np.float32(inp.egam)
        for g in self.active:
            light = self.light(g, win, ws, ups)
            ping = 0
            for j in self.steps:
                sig = inp.comps[g][j]
                if sig <= 0.0:
                    continue
                for i in (j, j + 1):
                    if i not in fields:
                        fields[i] = self.field(i, win, ws, ups)
                if fields[j + 1][3] is not None:  # z = a_{i+1} is read from planes
                    fields[j + 1] = self.field_planes(j + 1, win, ws)
                na, oa, _, fa = fields[j]
                nb, ob, norm_b, _ = fields[j + 1]
                vw, ov, _, fv = view if view is not None else (_NO_PLANES, 0, False, None)
                out = ws.vec(f"light{ping}")
                _eq1_rows(
                    na, nb, vw, light[0], out,
                    _NO_FLAT if fa is None else fa, _NO_FLAT if fv is None else fv,
                    (oa, ob, ov, light[1]), _GUIDE_CODE[g], (eta, np.float32(sig), egam),
                    (norm_b, light[2]),
                )  # fmt: skip
                light = (out, 0, False, None)
                ping = 1 - ping
            self.write(g, light, win)

    def write(self, g: str, light: Src, win: Win) -> None:
        r0, r1, x0, x1 = win
        inp = self.inp
        planes, ol, norm_l, _ = light
        if self.k == 0:  # the window's covered pixels; the original light everywhere else
            out = inp.outs[g][r0:r1]
            if inp.lfield is not None:
                orig = inp.lfield[r0:r1]
            else:
                assert inp.rows is not None
                orig = inp.rows[: r1 - r0]
            flat = (r1 - r0, 3 * self.shape[1])
            _write_rows(
                planes, ol, norm_l, self.mask[r0:r1], orig.reshape(flat), out.reshape(flat),
                x0, x1 - x0,
            )  # fmt: skip
            return
        _store_rows(planes, ol, norm_l, self.mask[r0:r1], _rows(self.new[g], r0, r1), x0, x1 - x0)

    def run(self) -> None:
        rows = _strip_rows(self.shape[1])
        run_strips(self.shape[0], self.strip, rows=rows)
        for g, planes in self.new.items():
            self.states[g] = (self.k, planes)


def _align_full(inp: _Inputs) -> dict[str, F32]:
    """Every scale at full resolution, strip by strip."""
    assert inp.fields is not None
    _Stage(inp, 0, list(range(len(inp.fields) - 1)), {}).run()
    return inp.outs


def _align_pyramid(inp: _Inputs) -> dict[str, F32]:
    """Each scale at the level of its fine field, coarsest first, and the lights carried to
    finer levels by the pyramid's edge-aware upsampling; level 0 writes the outputs."""
    pyr = inp.pyr
    assert pyr is not None
    active = [j for j in range(pyr.scales - 1) if any(sig[j] > 0.0 for sig in inp.comps.values())]
    states: dict[str, State | None] = {g: None for g in inp.comps}
    for k in sorted({pyr.levels[j] for j in active} | {0}, reverse=True):
        if k > 0 and inp.needs_view(list(inp.comps)):
            for lv in sorted({pyr.levels[j] for j in active if 0 < pyr.levels[j] <= k}):
                if inp.view is not None:
                    inp.view_planes(lv)  # finest first: each from the previous
        _Stage(inp, k, [j for j in active if pyr.levels[j] == k], states).run()
    return inp.outs


def align_light(
    light_dir: np.ndarray,
    normals: Sequence[np.ndarray] | NormalPyramid,
    sigmas: Sequence[float],
    gamma: float = DEFAULT_GAMMA,
    guide: Guide | str = "diffuse",
    view: np.ndarray | None = None,
    ior: float = 1.5,
    mask: np.ndarray | None = None,
) -> F32:
    """Light direction aligned with the shape at every scale (LLA §4-6, Eq. 1).

    ℓ_S = ℓ;  ℓ_i = R(ℓ_{i+1} × g_i, σ_i W_γ(λ1 λ2) ∠(ℓ_{i+1}, g_i)) ℓ_{i+1},  i = S−1 … 1
    (Mestres et al. 2021, Eq. 1 and §5; guides of §6). See the module docstring for the frame,
    the guide g_i and λ1, λ2.

    Parameters
    ----------
    light_dir : (3,) unit direction towards the light, or (H, W, 3) per pixel.
    normals : :class:`~ops.filtering.NormalPyramid` or the list [n_1, …, n_S] of (H, W, 3).
    sigmas : σ_1 … σ_{S−1} in [0, 1], finest first (all 0: the light is unchanged).
    gamma : γ of W_γ (paper: 3).
    guide : "diffuse" (normals), "specular" (reflected view vectors) or "transmission"
        (refracted view vectors, index ``ior``).
    view : (H, W, 3) or (3,) unit directions towards the eye (specular / transmission).
    ior : index of refraction for the transmission guide.
    mask : coverage when ``normals`` is a list (default: n_1 non-zero).

    Returns
    -------
    (H, W, 3) float32 unit aligned directions; background keeps ``light_dir``.
    """
    guide = _check_guide(str(guide))
    return align_components(
        light_dir, normals, {guide: sigmas}, gamma=gamma, view=view, ior=ior, mask=mask
    )[guide]


def align_lights(
    lights: Sequence[Light],
    normals: Sequence[np.ndarray] | NormalPyramid,
    position: np.ndarray,
    view: np.ndarray | None,
    components: Mapping[str, Sequence[float]],
    gamma: float = DEFAULT_GAMMA,
    ior: float = 1.5,
    mask: np.ndarray | None = None,
) -> dict[str, list[F32]]:
    """Aligned directions of every light for every shading component (LLA §4-6, Eq. 1).

    Directional lights use their direction; point lights the per-pixel direction towards their
    position from ``position`` (:func:`ops.shading.light_vectors`).

    Parameters
    ----------
    lights : :class:`ops.shading.Light` list (camera space).
    normals : :class:`~ops.filtering.NormalPyramid` or [n_1, …, n_S].
    position : (H, W, 3) camera-space positions (used by point lights).
    view : (H, W, 3) or (3,) directions towards the eye (specular / transmission).
    components : guide -> σ_1 … σ_{S−1}, e.g. ``{"diffuse": [...], "specular": [...]}``.
    gamma, ior, mask : as in :func:`align_components`.

    Returns
    -------
    dict guide -> one (H, W, 3) float32 field of unit directions per light, in ``lights`` order.
    """
    out: dict[str, list[F32]] = {g: [] for g in components}
    for light in lights:
        if light.kind == "directional":
            ldir: np.ndarray = np.asarray(light.vector, np.float32)
        else:
            ldir = light_vectors(light, np.asarray(position, np.float32))
        res = align_components(
            ldir, normals, components, gamma=gamma, view=view, ior=ior, mask=mask
        )
        for g in components:
            out[g].append(res[g])
    return out
