"""Radiance Scaling: the scaling function σ (Eq. 2) and its post-process form on lobes (Eq. 4).

Reference: R. Vergne, R. Pacanowski, P. Barla, X. Granier, C. Schlick, "Improving Shape Depiction
under Arbitrary Rendering", IEEE TVCG 17(8), 2011 (``papers/radiance-scaling.txt``), §4 (Eq. 2)
and §5.3 (Eq. 4, precomputed radiance: σ̄ taken out of the integral, δ̄ = lobe light / white).

Sign of κ. Eq. 2 is printed with ``e^{γκ}``. Evaluated with κ > 0 on convexities (the convention
the paper states for κ, and Depict's), that would *darken* intensities above α on convex features,
the opposite of the paper's own text ("For convex features, reflected lighting intensities above
α are brightened and those below α are darkened") and of the authors' shaders (MeshLab's Radiance
Scaling plugin evaluates it with ``exp(-β)`` / ``exp(gamma*(-k))`` of a convex-positive κ). The
printed sign goes with the paper's ``H = ∇(-(n_x, n_y)/n_z)``, negative on bumps in a camera
space whose +z points at the viewer. Depict keeps κ > 0 on convexities (``ops.curvature``) and
evaluates Eq. 2 with ``e^{-γκ}``, so convexities brighten what is above α, as the text says.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import cv2
import numpy as np
from numpy.typing import ArrayLike

from ops.bilinear import Upsampled, upsample_row
from ops.checks import ALPHA, GAMMA, PERCENTILE, WHITE
from ops.color import REC709_Y, luminance
from ops.jit import inline_kernel, kernel
from ops.numerics import dot3_row, expf
from ops.parallel import run_strips

_LUMA = np.array(REC709_Y, dtype=np.float32)  # for kernels
_MAX_EXP = 80.0  # |γκ| is clipped here: e^80 stays finite in float32
_STRIP_ROWS = 64  # rows per strip in scale_lobes
_ACC_LOBES, _ACC_REMAINDER, _ACC_BEAUTY = 0, 1, 2  # what _scale_rows adds the lobes to


def _clip01(x: np.ndarray) -> np.ndarray:
    """Clip to [0, 1] in place (+inf -> 1, NaN -> 0)."""
    cv2.patchNaNs(x, 0.0)
    np.clip(x, np.float32(0.0), np.float32(1.0), out=x)
    return x


def _exp_term(kappa: np.ndarray, gamma: float) -> np.ndarray:
    """e^{-γκ} for κ clipped to [-1, 1] (float32, 2-D; NaN κ counts as 0)."""
    arg = np.multiply(kappa, np.float32(-gamma), dtype=np.float32)
    cv2.patchNaNs(arg, 0.0)
    lim = np.float32(min(gamma, _MAX_EXP))
    np.clip(arg, -lim, lim, out=arg)
    return np.asarray(cv2.exp(arg, dst=arg), np.float32)


def _sigma_from(
    expk: np.ndarray,
    delta: np.ndarray,
    alpha: float,
    *,
    scratch: np.ndarray | None = None,
    consume: bool = False,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """Eq. 2 from E = e^{-γκ} and δ in [0, 1] (both (H, W) float32), in the cancellation-free
    form σ = (P·E + Q) / (P + Q·E), P = α(1 - δ), Q = (1 - α)δ.

    ``scratch`` is an optional buffer like ``delta``; with ``consume`` ``delta`` is overwritten;
    ``out`` receives σ.
    (NumPy for the scalar operations: cv2 is slower with Python scalars.)
    """
    # Coefficients rounded to float32 each way, so that swapping α and 1 - α swaps them exactly
    # and, at δ = α, α(1 - δ) and (1 - α)δ round alike (σ = 1).
    p = np.subtract(np.float32(1.0), delta, out=scratch, dtype=np.float32)
    np.multiply(p, np.float32(alpha), out=p)
    q = np.multiply(delta, np.float32(1.0 - alpha), out=delta if consume else None)
    num = cv2.multiply(p, expk, dst=out)
    cv2.add(num, q, dst=num)
    cv2.accumulateProduct(q, expk, p)  # p <- P + Q·E (the denominator)
    return np.asarray(cv2.divide(num, p, dst=num), np.float32)


def _as_2d(x: np.ndarray) -> np.ndarray:
    if x.ndim == 2:
        return np.ascontiguousarray(x)
    return np.ascontiguousarray(x).reshape(1, -1) if x.size else x.reshape(1, 0)


def sigma(kappa: ArrayLike, delta: ArrayLike, alpha: float, gamma: float) -> np.ndarray:
    """Scaling function σ_{α,γ}(κ, δ) of Radiance Scaling (TVCG 2011, §4, Eq. 2)::

        σ_{α,γ}(κ, δ) = (α e^{γκ'} + δ(1 − α(1 + e^{γκ'}))) / (α + δ(e^{γκ'} − α(1 + e^{γκ'})))

    with κ' = −κ (κ > 0 on convexities, see the module docstring), evaluated as
    ``(P·E + Q) / (P + Q·E)`` with E = e^{−γκ}, P = α(1 − δ), Q = (1 − α)δ (the same function,
    without cancellation). Properties: σ = 1 where κ = 0 or δ = α; σ(κ, δ)·σ(−κ, δ) = 1;
    σ_α(κ, 1 − δ) = 1 / σ_{1−α}(κ, δ); monotonic in δ (increasing for κ > 0: on convexities δ > α
    is brightened, δ < α darkened; decreasing for κ < 0); σ(κ, 0) = e^{−γκ}, σ(κ, 1) = e^{γκ};
    γ = 0 gives σ ≡ 1.

    Parameters
    ----------
    kappa : array or float
        Mapped curvature, clipped to [-1, 1].
    delta : array or float
        Reflectance mapping δ, clipped to [0, 1] (NaN counts as 0).
    alpha : float
        Scaling-invariant point α in (0, 1).
    gamma : float
        Scaling magnitude γ in [0, 1e4] (γκ is clipped to ±80).

    Returns
    -------
    float32 array of the broadcast shape of ``kappa`` and ``delta``.
    """
    a = ALPHA.check(alpha, "alpha")
    g = GAMMA.check(gamma, "gamma")
    k, d = np.broadcast_arrays(np.asarray(kappa, np.float32), np.asarray(delta, np.float32))
    shape = k.shape
    k2 = _as_2d(k)
    d2 = _clip01(_as_2d(d).copy())
    out = _sigma_from(_exp_term(k2, g), d2, a)
    return out.reshape(shape)


# -- reflectance mapping for renderer lobes (Eq. 4) ----------------------------------------------


def white_level(
    values: np.ndarray, mask: np.ndarray | None = None, percentile: float = 99.0
) -> float:
    """'auto' white level: the ``percentile`` of the covered pixels' values.

    ``values`` is (H, W) or (H, W, 3) (its Rec. 709 luminance is used). Only finite values of
    covered pixels (``mask`` > 0.5 or True; all pixels without a mask) count, so NaN/inf and the
    background do not move it; a high percentile rather than the maximum ignores fireflies. When
    nothing positive remains the level is 1.0 (δ̄ is then the light itself). Batch mode computes it
    once and pins it for a sequence (DESIGN.md), so frames do not flicker.

    Parameters
    ----------
    percentile : float
        In (0, 100].
    """
    p = PERCENTILE.check(percentile, "percentile")
    vals, m8, wid = _counting(values, mask)
    level = _banded_percentile(vals, m8, wid, p)
    if level is None:  # small, or the bracket missed: np.percentile of all the counted values
        y = _count(vals, m8, wid)[2]
        level = float(np.percentile(y, p, overwrite_input=True)) if y.size else 0.0
    return level if level > 0.0 else 1.0


_BAND_MIN = 1 << 16  # below this many values np.percentile is cheap enough
_SAMPLE_ROWS = 128  # rows of the sample that brackets the percentile
_SAMPLE_MIN = 1024  # fewer sampled values than this bracket nothing
_NO_MASK = np.empty((0, 0), np.uint8)
_INF = float("inf")


def _counting(values: np.ndarray, mask: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, int]:
    """``values`` as rows of (W) values or (3W) RGB, float32, the mask as uint8 rows (no rows:
    every pixel counts) and W."""
    vals = np.ascontiguousarray(values, dtype=np.float32)
    if vals.ndim not in (2, 3) or (vals.ndim == 3 and vals.shape[2] != 3):
        raise ValueError(f"expected an (H, W) or (H, W, 3) array, got shape {vals.shape}")
    shape = vals.shape[:2]
    m8 = _NO_MASK
    if mask is not None:
        m = np.asarray(mask)
        if m.shape != shape:
            raise ValueError(f"mask must have shape {shape}, got {m.shape}")
        m8 = np.ascontiguousarray(m if m.dtype == np.bool_ else m > 0.5).view(np.uint8)
    return vals.reshape(shape[0], -1), m8, shape[1]


def _count(
    vals: np.ndarray, m8: np.ndarray, wid: int, lo: float = -_INF, hi: float = _INF
) -> tuple[int, int, np.ndarray]:
    """Over the counted pixels (finite values of covered pixels; RGB: their luminance): how
    many there are, how many are below ``lo``, and those in [lo, hi], in row order (1-D)."""
    hgt = vals.shape[0]
    buf = np.empty(hgt * wid, np.float32)
    starts = range(0, hgt, _STRIP_ROWS)
    res = np.zeros((len(starts), 3), np.int64)
    lo32, hi32 = np.float32(lo), np.float32(hi)

    def strip(r0: int, r1: int) -> None:
        rows = m8[r0:r1] if m8.shape[0] else m8
        out = buf[r0 * wid : r1 * wid]
        res[r0 // _STRIP_ROWS] = _count_rows(vals[r0:r1], rows, wid, 1, lo32, hi32, out)

    run_strips(hgt, strip, _STRIP_ROWS)
    pieces = [buf[a * wid : a * wid + n] for a, n in zip(starts, res[:, 2], strict=True)]
    return int(res[:, 0].sum()), int(res[:, 1].sum()), np.concatenate(pieces)


def _banded_percentile(vals: np.ndarray, m8: np.ndarray, wid: int, p: float) -> float | None:
    """``np.percentile`` (linear) of the counted values, exactly, without gathering them all:
    the counted values of every (H / 128)-th row bracket the two order statistics the
    percentile interpolates; one pass counts the values and those below the bracket and keeps
    the few inside it, and only those are partitioned (numpy's own interpolation of the two
    gives the result). None when the frame is small or the bracket misses them."""
    hgt = vals.shape[0]
    if hgt * wid < _BAND_MIN:
        return None
    step = max(1, hgt // _SAMPLE_ROWS)
    sample = np.empty(((hgt + step - 1) // step) * wid, np.float32)
    ns = _count_rows(vals, m8, wid, step, np.float32(-_INF), np.float32(_INF), sample)[2]
    if ns < _SAMPLE_MIN:
        return None
    sample = sample[:ns]
    q = np.true_divide(p, 100)
    centre = q * (ns - 1)
    margin = 8.0 * math.sqrt(ns * q * (1.0 - q)) + 32.0  # order-statistic spread, with room
    lo_r, hi_r = max(0, int(centre - margin)), min(ns - 1, int(centre + margin) + 1)
    sample.partition([lo_r, hi_r])
    n, n_below, band = _count(vals, m8, wid, sample[lo_r], sample[hi_r])
    g = (n - 1) * q  # numpy's virtual index for the linear method
    k = math.floor(g)
    if n < _BAND_MIN or k + 1 > n - 1 or not (n_below <= k and n_below + band.size > k + 1):
        return None
    band.partition([k - n_below, k + 1 - n_below])
    pair = np.array([band[k - n_below], band[k + 1 - n_below]], np.float32)
    # quantile of the pair at the fractional part: numpy's lerp, with the same (weak) weight.
    return float(np.quantile(pair, float(g - k)))


@kernel
def _count_rows(rows, m8, wid, step, lo, hi, out):  # type: ignore[no-untyped-def]
    """:func:`_count` on every ``step``-th of ``rows`` ((n, W) values or (n, 3W) RGB; ``m8``
    uint8 coverage, or no rows): (counted, below ``lo``, packed into ``out``). The counts are
    vectorised reductions that also flag the values in the band; only the 8-byte words of flags
    that hold one are looked at to pack them."""
    y = np.empty(wid, np.float32)
    ones = np.ones(wid, np.uint8)
    nw = (wid + 7) // 8
    flags = np.zeros(8 * nw, np.uint8)
    words = flags.view(np.uint64)
    w0, w1, w2 = _LUMA
    big = np.float32(np.inf)
    counted = below = k = 0
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
        if n_in:
            for q in range(nw):
                if words[q]:
                    for j in range(8 * q, min(8 * q + 8, wid)):
                        if flags[j]:
                            out[k] = y[j]
                            k += 1
    return counted, below, k


def reflectance_delta(light: np.ndarray, white: float) -> np.ndarray:
    """δ̄ = luminance(light) / white clipped to [0, 1] (RS §5.3: δ̄_d = L̄(n) / L̄*).

    ``light`` is a lobe's incoming light without its colour (H, W, 3); ``white`` (> 0) the level
    mapped to δ̄ = 1 (see :func:`white_level`). NaN gives 0, +inf 1.
    """
    s = np.float32(1.0 / WHITE.check(white, "white"))
    return _clip01(luminance(light, (_LUMA[0] * s, _LUMA[1] * s, _LUMA[2] * s)))


# -- scaling renderer lobes -----------------------------------------------------------------------


def _per_lobe(value: object, names: list[str], what: str) -> dict[str, object]:
    if isinstance(value, Mapping):
        missing = [n for n in names if n not in value]
        if missing:
            raise ValueError(f"{what} has no value for lobe(s) {missing}; give one per lobe")
        return {n: value[n] for n in names}
    return dict.fromkeys(names, value)


def scale_lobes(
    lobes: Mapping[str, np.ndarray],
    lights: Mapping[str, np.ndarray],
    kappa: np.ndarray | Upsampled,
    alpha: Mapping[str, float] | float,
    gamma: Mapping[str, float] | float,
    white: Mapping[str, float | str] | float | str = "auto",
    remainder: np.ndarray | None = None,
    *,
    mask: np.ndarray | None = None,
    beauty: np.ndarray | None = None,
    with_sigmas: bool = True,
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Radiance Scaling as a post-process on renderer lobes (RS §5.3, Eq. 4)::

        beauty' = Σ_j σ_{α_j,γ_j}(κ, δ̄_j) · lobe_j + remainder,   δ̄_j = lum(light_j) / white_j

    Each lobe's radiance is scaled by σ̄ (Eq. 2, :func:`sigma`) outside the integral, its
    reflectance mapping δ̄_j being the lobe's light without its colour over a white level, so a
    lobe's colour (albedo) does not change how it is scaled.

    Parameters
    ----------
    lobes : dict name -> (H, W, 3) float32
        Radiance of each lobe (``diffuse``, ``specular``, ...).
    lights : dict name -> (H, W, 3) float32
        Light of each lobe without its colour; a lobe missing here uses its own radiance.
    kappa : (H, W) float32 or Upsampled
        Mapped curvature in [-1, 1] (e.g. :func:`ops.curvature.isotropic`), or the same on a
        coarser grid (:func:`ops.curvature.isotropic_field`), interpolated row by row here.
    alpha, gamma : float or dict name -> float
        α in (0, 1) and γ in [0, inf), for all lobes or per lobe.
    white : float, "auto" or dict name -> (float or "auto")
        White level(s) of δ̄; "auto" = :func:`white_level` of the lobe's light (over ``mask``).
    remainder : (H, W, 3) float32, optional
        What the beauty holds besides the lobes (emission, environment): added unchanged.
    mask : (H, W) bool or float, optional
        Covered pixels, for the "auto" white levels.
    beauty : (H, W, 3) float32, optional
        Instead of ``remainder``: the beauty the lobes are part of, so the result is
        ``beauty + Σ_j (σ̄_j - 1) · lobe_j`` (the same sum, without forming the remainder).
    with_sigmas : bool
        Also return the σ of each lobe (else an empty dict, and one pass less to memory).

    Returns
    -------
    beauty : (H, W, 3) float32
    sigmas : dict name -> (H, W) float32, the σ applied to each lobe.
    """
    if isinstance(kappa, Upsampled):
        grid, factor, (hgt, wid) = kappa.grid, kappa.factor, kappa.shape
    else:
        grid, factor = np.ascontiguousarray(kappa, dtype=np.float32), 1
        if grid.ndim != 2:
            raise ValueError(f"kappa must have shape (H, W), got {grid.shape}")
        hgt, wid = grid.shape
    names = list(lobes)
    alphas = {
        n: ALPHA.check(v, f"alpha[{n!r}]") for n, v in _per_lobe(alpha, names, "alpha").items()
    }
    gammas = {
        n: GAMMA.check(v, f"gamma[{n!r}]") for n, v in _per_lobe(gamma, names, "gamma").items()
    }
    whites = _per_lobe(white, names, "white")
    for n, w in whites.items():
        if isinstance(w, str):
            if w != "auto":
                raise ValueError(f"white[{n!r}]={w!r} must be a number > 0 or 'auto'")
        else:
            WHITE.check(w, f"white[{n!r}]")

    def rgb(x: np.ndarray, what: str) -> np.ndarray:
        x = np.ascontiguousarray(x, dtype=np.float32)
        if x.shape != (hgt, wid, 3):
            raise ValueError(f"{what} must have shape {(hgt, wid, 3)}, got {x.shape}")
        return x

    lobe_arr = {n: rgb(lobes[n], f"lobes[{n!r}]") for n in names}
    light_arr = {n: rgb(lights[n], f"lights[{n!r}]") if n in lights else lobe_arr[n] for n in names}
    levels = {
        n: white_level(light_arr[n], mask) if isinstance(w, str) else float(w)  # type: ignore[arg-type]
        for n, w in whites.items()
    }
    if remainder is not None and beauty is not None:
        raise ValueError("give the remainder or the beauty the lobes are part of, not both")
    base = None
    mode = _ACC_LOBES
    if remainder is not None:
        base, mode = rgb(remainder, "remainder"), _ACC_REMAINDER
    elif beauty is not None:
        base, mode = rgb(beauty, "beauty"), _ACC_BEAUTY
    out = np.empty((hgt, wid, 3), np.float32)
    nl = len(names)
    sig = np.empty((nl, hgt, wid) if with_sigmas else (nl, 0, 0), np.float32)
    sigmas = {n: sig[i] for i, n in enumerate(names)} if with_sigmas else {}
    distinct = sorted(set(gammas.values()))
    which = np.array([distinct.index(gammas[n]) for n in names], np.intp)
    # Eq. 2 per lobe as σ = (P'E + Q') / (P' + Q'E): P', Q' the P = α(1 - δ̄), Q = (1 - α)δ̄ of
    # _sigma_from over max(α, 1 - α), so σ is exactly 1 where E = e^{-γκ} is 1; δ̄ = the light's
    # luminance over its white level (as reflectance_delta).
    coef = np.array(
        [[*(_LUMA / np.float32(levels[n])), *_pq_factors(alphas[n])] for n in names],
        np.float32,
    ).reshape(nl, 5)
    lobe_t = tuple(lobe_arr[n] for n in names)
    light_t = tuple(light_arr[n] for n in names)
    none = np.empty((0, 0, 3), np.float32)

    gam = np.array([(g, min(g, _MAX_EXP)) for g in distinct], np.float32).reshape(-1, 2)

    def strip(r0: int, r1: int) -> None:
        r = slice(r0, r1)
        _scale_rows(
            tuple(x[r] for x in lobe_t),
            tuple(x[r] for x in light_t),
            grid,
            factor,
            gam,
            coef,
            which,
            none if base is None else base[r],
            mode,
            out[r],
            sig,
            r0,
        )

    if not names:
        out[...] = 0.0 if base is None else base
        return out, sigmas
    run_strips(hgt, strip, _STRIP_ROWS)
    return out, sigmas


def _pq_factors(alpha: float) -> tuple[float, float]:
    """(P'/(1 - δ), Q'/δ) of :func:`scale_lobes`: α(1 - δ) and (1 - α)δ over max(α, 1 - α)."""
    if alpha > 0.5:
        return 1.0, (1.0 - alpha) / alpha
    if alpha < 0.5:
        return alpha / (1.0 - alpha), 1.0
    return 1.0, 1.0


@inline_kernel
def _exp_row(kappa, gamma, lim, e):  # type: ignore[no-untyped-def]
    """e[j] = e^{−γκ_j}, γκ clipped to ±``lim`` and NaN κ counted as 0 (as :func:`_exp_term`)."""
    zero = np.float32(0.0)
    for j in range(e.shape[0]):
        x = -gamma * kappa[j]
        x = x if x == x else zero
        e[j] = expf(min(max(x, -lim), lim))


@inline_kernel
def _sigma_row(d, e, pf, qf, s):  # type: ignore[no-untyped-def]
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
def _put_scaled(acc, src, lobe, s, less):  # type: ignore[no-untyped-def]
    """acc = src + (s − ``less``) · lobe on flat RGB rows (s per pixel; ``src`` may be ``acc``)."""
    for j in range(s.shape[0]):
        f = s[j] - less
        for c in range(3):
            m = 3 * j + c
            acc[m] = src[m] + f * lobe[m]


@inline_kernel
def _put_scaled3(acc, src, l0, l1, l2, s0, s1, s2, less):  # type: ignore[no-untyped-def]
    """:func:`_put_scaled` of three lobes at once (one pass over ``acc``)."""
    for j in range(s0.shape[0]):
        f0, f1, f2 = s0[j] - less, s1[j] - less, s2[j] - less
        for c in range(3):
            m = 3 * j + c
            acc[m] = src[m] + f0 * l0[m] + f1 * l1[m] + f2 * l2[m]


@inline_kernel
def _nonzero_span(x):  # type: ignore[no-untyped-def]
    """(j0, j1): the first and one past the last index where ``x`` is not 0 ((0, 0) if none)."""
    n = x.shape[0]
    lo, hi = n, 0
    for j in range(n):
        nz = x[j] != np.float32(0.0)
        lo = min(lo, j if nz else n)
        hi = max(hi, j + 1 if nz else 0)
    return (lo, hi) if lo < hi else (0, 0)


@kernel
def _scale_rows(lobes, lights, grid, f, gammas, coef, which, base, mode, out, sig, r0):  # type: ignore[no-untyped-def]
    """Rows ``r0 ..`` of :func:`scale_lobes`: ``out`` = (0 | base) + Σ_k σ_k · lobe_k with
    ``mode`` _ACC_LOBES | _ACC_REMAINDER, or base + Σ_k (σ_k - 1) · lobe_k with _ACC_BEAUTY.
    κ is the ``grid`` upsampled ``f`` times (:func:`ops.bilinear.upsample_row`; f = 1: κ
    itself); σ_k of lobe k from E = e^{−γκ} of γ = ``gammas[which[k], 0]``, γκ clipped to
    ± ``gammas[which[k], 1]``, and δ̄ = clip(coef[k, :3] · light_k, 0, 1),
    P' = coef[k, 3](1 - δ̄), Q' = coef[k, 4] δ̄; σ_k also into row ``r0 + i`` of ``sig[k]`` when
    it has rows.

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
            light = lights[k][i].reshape(3 * wid)[3 * j0 : 3 * j1]
            dot3_row(light, coef[k, 0], coef[k, 1], coef[k, 2], d[j0:j1])
            _sigma_row(d[j0:j1], e[which[k], j0:j1], coef[k, 3], coef[k, 4], sk[j0:j1])
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
