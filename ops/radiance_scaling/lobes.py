"""Radiance Scaling as a post-process of a renderer's lobes (§5.3, Eq. 4): δ̄ = lobe light / white
level, each lobe scaled by σ, the beauty rebuilt."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from ops.checks import ALPHA, GAMMA, PERCENTILE, WHITE
from ops.color import REC709_Y, luminance
from ops.parallel import run_strips
from ops.pyramid.upsample import Upsampled
from ops.radiance_scaling._common import (
    _ACC_BEAUTY,
    _ACC_LOBES,
    _ACC_REMAINDER,
    _MAX_EXP,
    _STRIP_ROWS,
)
from ops.radiance_scaling._kernels import _count_rows, _scale_rows
from ops.radiance_scaling.sigma import _clip01

__all__ = ["covered_percentile", "reflectance_delta", "scale_lobes", "white_level"]

# -- reflectance mapping for renderer lobes (Eq. 4) ----------------------------------------------


Weights = tuple[float, float, float]


def white_level(
    values: np.ndarray,
    mask: np.ndarray | None = None,
    percentile: float = 99.0,
    weights: Weights = REC709_Y,
) -> float:
    """'auto' white level: the ``percentile`` of the covered pixels' values.

    ``values`` is (H, W) or (H, W, 3) (its luminance with ``weights``, the working space's, is
    used). Only finite values of
    covered pixels (``mask`` > 0.5 or True; all pixels without a mask) count, so NaN/inf and the
    background do not move it; a high percentile rather than the maximum ignores fireflies. When
    nothing positive remains the level is 1.0 (δ̄ is then the light itself). Batch mode computes it
    once and pins it for a sequence (DESIGN.md), so frames do not flicker.

    Parameters
    ----------
    percentile : float
        In (0, 100].
    """
    level = covered_percentile(values, mask, percentile, weights)
    return level if level > 0.0 else 1.0  # (also when nothing counts: NaN)


def covered_percentile(
    values: np.ndarray,
    mask: np.ndarray | None = None,
    percentile: float = 50.0,
    weights: Weights = REC709_Y,
) -> float:
    """``np.percentile`` (linear) of the finite values of the covered pixels (``mask`` as in
    :func:`white_level`; RGB: their luminance with ``weights``), exactly, in two compiled
    passes over the frame instead of gathering and sorting every value; NaN when none counts."""
    p = PERCENTILE.check(percentile, "percentile")
    vals, m8, wid = _counting(values, mask)
    lw = np.asarray(weights, np.float32)
    level = _banded_percentile(vals, m8, wid, p, lw)
    if level is None:  # small, or the bracket missed: np.percentile of all the counted values
        y = _count(vals, m8, wid, lw)[3]
        level = float(np.percentile(y, p, overwrite_input=True)) if y.size else math.nan
    return level


_BAND_MIN = 1 << 16  # below this many values np.percentile is cheap enough
_SAMPLE_ROWS = 32  # rows of the sample that brackets the percentile
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
    vals: np.ndarray,
    m8: np.ndarray,
    wid: int,
    lw: np.ndarray,
    lo: float = -_INF,
    hi: float = _INF,
    pack: bool = True,
) -> tuple[int, int, int, np.ndarray]:
    """Over the counted pixels (finite values of covered pixels; RGB: their luminance): how
    many there are, how many are below ``lo``, how many in [lo, hi], and (``pack``) those, in
    row order (1-D; empty without ``pack``)."""
    hgt = vals.shape[0]
    buf = np.empty(hgt * wid if pack else 0, np.float32)
    starts = range(0, hgt, _STRIP_ROWS)
    res = np.zeros((len(starts), 3), np.int64)
    lo32, hi32 = np.float32(lo), np.float32(hi)

    def strip(r0: int, r1: int) -> None:
        rows = m8[r0:r1] if m8.shape[0] else m8
        out = buf[r0 * wid : r1 * wid]
        res[r0 // _STRIP_ROWS] = _count_rows(vals[r0:r1], rows, wid, 1, lo32, hi32, lw, out)

    run_strips(hgt, strip, _STRIP_ROWS)
    inside = int(res[:, 2].sum())
    if not pack:
        return int(res[:, 0].sum()), int(res[:, 1].sum()), inside, buf
    pieces = [buf[a * wid : a * wid + n] for a, n in zip(starts, res[:, 2], strict=True)]
    return int(res[:, 0].sum()), int(res[:, 1].sum()), inside, np.concatenate(pieces)


def _banded_percentile(
    vals: np.ndarray, m8: np.ndarray, wid: int, p: float, lw: np.ndarray
) -> float | None:
    """``np.percentile`` (linear) of the counted values, exactly, without gathering them all:
    the counted values of every (H / 32)-th row bracket the two order statistics the
    percentile interpolates; one pass counts the values and those below the bracket and keeps
    the few inside it, and only those are partitioned (numpy's own interpolation of the two
    gives the result). None when the frame is small or the bracket misses them."""
    hgt = vals.shape[0]
    if hgt * wid < _BAND_MIN:
        return None
    step = max(1, hgt // _SAMPLE_ROWS)
    sample = np.empty(((hgt + step - 1) // step) * wid, np.float32)
    ns = _count_rows(vals, m8, wid, step, np.float32(-_INF), np.float32(_INF), lw, sample)[2]
    if ns < _SAMPLE_MIN:
        return None
    sample = sample[:ns]
    q = np.true_divide(p, 100)
    centre = q * (ns - 1)
    margin = 8.0 * math.sqrt(ns * q * (1.0 - q)) + 32.0  # order-statistic spread, with room
    lo_r, hi_r = max(0, int(centre - margin)), min(ns - 1, int(centre + margin) + 1)
    sample.partition([lo_r, hi_r])
    lo, hi = sample[lo_r], sample[hi_r]
    # a bracket of one value (many pixels alike: a flat wall, a clipped light) holds nothing
    # but that value: counting the band is enough
    n, n_below, inside, band = _count(vals, m8, wid, lw, lo, hi, pack=bool(lo != hi))
    g = (n - 1) * q  # numpy's virtual index for the linear method
    k = math.floor(g)
    if n < _BAND_MIN or k + 1 > n - 1 or not (n_below <= k and n_below + inside > k + 1):
        return None
    if lo == hi:
        return float(lo)
    band.partition([k - n_below, k + 1 - n_below])
    pair = np.array([band[k - n_below], band[k + 1 - n_below]], np.float32)
    # quantile of the pair at the fractional part: numpy's lerp, with the same (weak) weight.
    return float(np.quantile(pair, float(g - k)))


def reflectance_delta(light: np.ndarray, white: float, weights: Weights = REC709_Y) -> np.ndarray:
    """δ̄ = luminance(light) / white clipped to [0, 1] (RS §5.3: δ̄_d = L̄(n) / L̄*).

    ``light`` is a lobe's incoming light without its colour (H, W, 3); ``white`` (> 0) the level
    mapped to δ̄ = 1 (see :func:`white_level`); ``weights`` the working space's luminance
    weights. NaN gives 0, +inf 1.
    """
    s = np.float32(1.0 / WHITE.check(white, "white"))
    lw = np.asarray(weights, np.float32)
    return _clip01(luminance(light, (lw[0] * s, lw[1] * s, lw[2] * s)))


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
    weights: Weights = REC709_Y,
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
    lights : dict name -> (H, W, 3) or (H, W) float32
        Light of each lobe without its colour, or its luminance (with ``weights``; all δ̄ reads
        of it); a lobe missing here uses its own radiance.
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
    weights : the working space's luminance weights (δ̄ is a luminance).

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
    alphas, gammas, whites = _lobe_parameters(names, alpha, gamma, white)

    def rgb(x: np.ndarray, what: str) -> np.ndarray:
        x = np.ascontiguousarray(x, dtype=np.float32)
        if x.shape != (hgt, wid, 3):
            raise ValueError(f"{what} must have shape {(hgt, wid, 3)}, got {x.shape}")
        return x

    lobe_arr = {n: rgb(lobes[n], f"lobes[{n!r}]") for n in names}
    light_in = {n: np.asarray(lights[n]) if n in lights else lobe_arr[n] for n in names}
    for n, x in light_in.items():
        if x.shape != (hgt, wid):
            light_in[n] = rgb(x, f"lights[{n!r}] (or its luminance, {(hgt, wid)})")
    levels = {
        n: white_level(light_in[n], mask, weights=weights) if isinstance(w, str) else float(w)  # type: ignore[arg-type]
        for n, w in whites.items()
    }
    light_arr, per_white = _delta_inputs(light_in, levels, weights)
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
        [[per_white[n], *_pq_factors(alphas[n])] for n in names],
        np.float32,
    ).reshape(nl, 3)
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


def _lobe_parameters(
    names: list[str],
    alpha: Mapping[str, float] | float,
    gamma: Mapping[str, float] | float,
    white: Mapping[str, float | str] | float | str,
) -> tuple[dict[str, float], dict[str, float], dict[str, object]]:
    """:func:`scale_lobes`' α, γ and white level per lobe, checked (ValueError naming the lobe
    and the value)."""
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
    return alphas, gammas, whites


def _delta_inputs(
    lights: Mapping[str, np.ndarray], levels: Mapping[str, float], weights: Weights
) -> tuple[dict[str, np.ndarray], dict[str, np.float32]]:
    """Per lobe, what :func:`scale_lobes` reads δ̄ from before its clip, as (plane, factor) with
    δ̄ = factor · plane: a luminance plane and 1 / white, or an RGB light's luminance with the
    weights over the white level and 1 (one rounding less)."""
    luma = np.asarray(weights, np.float32)
    planes, factors = {}, {}
    for n, light in lights.items():
        white = np.float32(levels[n])
        if light.ndim == 2:
            planes[n], factors[n] = np.ascontiguousarray(light, np.float32), np.float32(1.0) / white
        else:
            planes[n], factors[n] = luminance(light, tuple(luma / white)), np.float32(1.0)
    return planes, factors


def _pq_factors(alpha: float) -> tuple[float, float]:
    """(P'/(1 - δ), Q'/δ) of :func:`scale_lobes`: α(1 - δ) and (1 - α)δ over max(α, 1 - α)."""
    if alpha > 0.5:
        return 1.0, (1.0 - alpha) / alpha
    if alpha < 0.5:
        return alpha / (1.0 - alpha), 1.0
    return 1.0, 1.0
