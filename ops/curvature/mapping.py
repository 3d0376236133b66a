"""Curvature mappings of Radiance Scaling §4: κ = tanh(s·(κ1 + κ2)) (isotropic) and the
light-dependent anisotropic κ(ℓ)."""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np

from ops.checks import ANISOTROPY, CURVATURE_GAIN
from ops.curvature import _common
from ops.curvature._common import DEFAULT_GAIN
from ops.curvature.result import _FIELDS, Curvature, half_angle_row
from ops.jit import kernel
from ops.numerics import expf, magnitude
from ops.parallel import run_strips
from ops.pyramid.upsample import Upsampled, upsample_row

#: cv2 for calls with Python scalars or None where its stubs only list arrays (Scalar arguments,
#: default kernels); same module, untyped.
_cv: Any = cv2

__all__ = ["anisotropic", "isotropic", "isotropic_field", "mean_curvature_layers"]

# -- curvature mappings ----------------------------------------------------------------------------


def _tanh_weighted(x: np.ndarray, s: float, weight: np.ndarray) -> np.ndarray:
    """tanh(s·x) · weight of (h, w) planes (NaN x counts as 0), float32, in one compiled pass."""
    x = np.ascontiguousarray(x, dtype=np.float32)
    weight = np.ascontiguousarray(weight, dtype=np.float32)
    out = np.empty(x.shape, np.float32)
    s2 = np.float32(2.0 * s)
    run_strips(
        x.shape[0],
        lambda r0, r1: _tanh_weighted_rows(x[r0:r1], s2, weight[r0:r1], out[r0:r1]),
        _common._STRIP_ROWS,
    )
    return out


@kernel
def _tanh_weighted_rows(x, s2, weight, out):  # type: ignore[no-untyped-def]
    """out = tanh(s2/2 · x) · weight as 1 − 2 / (e^{s2·x} + 1), which saturates cleanly (the
    exponent is clamped to ±87 by :func:`expf`), and is exactly 0 at x = 0."""
    zero, one, two = np.float32(0.0), np.float32(1.0), np.float32(2.0)
    for i in range(out.shape[0]):
        xr, wr, o = x[i], weight[i], out[i]
        for j in range(o.shape[0]):
            a = s2 * xr[j]
            a = a if a == a else zero
            o[j] = (one - two / (expf(a) + one)) * wr[j]


def isotropic(curv: Curvature, gain: float = DEFAULT_GAIN) -> np.ndarray:
    """Isotropic curvature mapping κ = tanh(s·(κ1 + κ2)) · weight (Radiance Scaling §4).

    The paper writes κ(p) = tanh(κu + κv), "mean curvature mapped to [-1, 1]"; κ1 + κ2 is twice
    the mean curvature. ``gain`` s in (0, 100] rescales it since κ is per unit image height (a
    sphere spanning half the image height has κ1 + κ2 = 8; the default 0.03 maps it to 0.24).

    Returns
    -------
    (H, W) float32 in [-1, 1], 0 where ``curv.weight`` is 0.
    """
    return np.asarray(isotropic_field(curv, gain))


def isotropic_field(curv: Curvature, gain: float = DEFAULT_GAIN) -> Upsampled:
    """:func:`isotropic` left on the working grid: the tanh is mapped there and the result is
    read through bilinear upsampling (:class:`ops.pyramid.Upsampled`), so a kernel that
    consumes κ (:func:`ops.radiance_scaling.scale_lobes`) interpolates each row as it needs it
    instead of reading a full-resolution plane; ``np.asarray`` of it is :func:`isotropic`."""
    s = CURVATURE_GAIN.check(gain, "gain")
    coarse = curv._coarse_for("k1", "k2", "weight")
    if coarse is not None:
        return Upsampled(_tanh_weighted(coarse.trace, s, coarse.weight), coarse.size)
    trace = cv2.add(curv.k1, curv.k2)
    return Upsampled(_tanh_weighted(trace, s, curv.weight), trace.shape)


def anisotropic(
    curv: Curvature,
    light_dir: np.ndarray,
    gain: float = DEFAULT_GAIN,
    lam: float = 0.0,
) -> np.ndarray:
    """Anisotropic curvature mapping κ(p, ℓ) (Radiance Scaling §4)::

        κ(p, ℓ) = tanh((H + λΔκ)·ℓu² + (H − λΔκ)·ℓv² + H·ℓz²),  H = κu + κv,  Δκ = κu − κv

    with ℓ = (ℓu, ℓv, ℓz) the unit light direction in the frame of the principal directions u (of
    κ1), v and the view axis z, and λ ∈ [-1, 1]: λ = 0 gives the isotropic tanh(H) for every ℓ,
    λ = 1 favours the curvature along the light's projection, λ = -1 the one across it. As ℓ is
    unit, the argument is H + λΔκ(ℓu² − ℓv²). (The paper's "κ(p, u) = tanh(κu)" for λ = 1 reads
    tanh(2κu) with H = κu + κv as written; Depict keeps the formula, so that λ = 0 matches the
    isotropic mapping.) The argument is multiplied by ``gain`` and the result by ``curv.weight``.

    Parameters
    ----------
    curv : Curvature
    light_dir : (3,) or (H, W, 3)
        Camera-space direction towards the light (normalised here).
    gain : float
        s in (0, 100], as in :func:`isotropic`.
    lam : float
        λ in [-1, 1].
    """
    s = CURVATURE_GAIN.check(gain, "gain")
    lam = ANISOTROPY.check(lam, "lam")
    ell = np.asarray(light_dir, dtype=np.float32)
    if ell.shape == (3,):
        norm = float(np.linalg.norm(ell))
        if not norm > 0.0 or not math.isfinite(norm):
            raise ValueError("light_dir must be a non-zero finite 3-vector")
        lx, ly = float(ell[0]) / norm, float(ell[1]) / norm
        # With θ the angle of u and φ = 2θ: ℓu² − ℓv² = (lx² − ly²)·cos φ + 2·lx·ly·sin φ, and
        # Δκ·(cos φ, sin φ) = 2·(d, b) for the Hessian's (a − c)/2 = d and off-diagonal b.
        cx, cy = lx * lx - ly * ly, 2.0 * lx * ly
        coarse = curv._coarse_for(*_FIELDS)
        if coarse is not None:  # on the working grid, interpolated once
            arg = cv2.addWeighted(coarse.d, 2.0 * lam * cx, coarse.b, 2.0 * lam * cy, 0.0)
            cv2.add(arg, coarse.trace, dst=arg)
            return coarse.upsample(_tanh_weighted(arg, s, coarse.weight))
        c2 = cv2.subtract(
            cv2.multiply(curv.dir_x, curv.dir_x), cv2.multiply(curv.dir_y, curv.dir_y)
        )
        s2 = cv2.multiply(curv.dir_x, curv.dir_y, scale=2.0)
        proj = cv2.addWeighted(c2, cx, s2, cy, 0.0)
    elif ell.shape == (*curv.k1.shape, 3):
        ex, ey, ez = cv2.split(np.ascontiguousarray(ell))
        inv = magnitude(ex, ey, ez)
        np.maximum(inv, np.float32(1e-20), out=inv)
        np.divide(np.float32(1.0), inv, out=inv)
        lu = cv2.add(cv2.multiply(ex, curv.dir_x), cv2.multiply(ey, curv.dir_y))
        lv = cv2.subtract(cv2.multiply(ey, curv.dir_x), cv2.multiply(ex, curv.dir_y))
        cv2.multiply(lu, inv, dst=lu)
        cv2.multiply(lv, inv, dst=lv)
        proj = cv2.subtract(cv2.multiply(lu, lu), cv2.multiply(lv, lv))
    else:
        raise ValueError(
            f"light_dir must have shape (3,) or {(*curv.k1.shape, 3)}, got {ell.shape}"
        )
    trace = cv2.add(curv.k1, curv.k2)
    delta = cv2.subtract(curv.k1, curv.k2)
    arg = cv2.add(trace, cv2.multiply(delta, proj, scale=lam))
    return _tanh_weighted(arg, s, curv.weight)


def mean_curvature_layers(curv: Curvature, gain: float = DEFAULT_GAIN) -> dict[str, np.ndarray]:
    """Output layers of the ``curvature`` operator.

    Returns ``{"H": isotropic(curv, gain), "k1": k1·weight, "k2": k2·weight, "dir.X": dir_x,
    "dir.Y": dir_y}`` (float32, (H, W)); H is the mapped curvature tanh(s·(κ1 + κ2)) in [-1, 1]
    (Radiance Scaling §4), k1/k2 are per unit image height and 0 where the weight is 0.

    From a result still on its working grid (none of its fields read), the five planes are
    written in one compiled pass that upsamples each row of the grid's fields as it goes
    (:func:`_layer_rows`: the same interpolation and arithmetic as reading the fields one by
    one, without their full-resolution copies).
    """
    s = CURVATURE_GAIN.check(gain, "gain")
    coarse = curv._coarse_for(*_FIELDS)
    if coarse is not None:
        (h, w), (gh, gw) = coarse.size, coarse.trace.shape
        f = h // gh
        if f > 1 and (h, w) == (f * gh, f * gw):
            field = _tanh_weighted(coarse.trace, s, coarse.weight)
            grids = (field, coarse.k1, coarse.k2, coarse.weight, coarse.d, coarse.b)
            return _layers_on_grid(tuple(np.ascontiguousarray(g) for g in grids), f)
    # -0.0 (a negative k times a zero weight) is written as 0.0: the values under a zero weight
    # are left over from the working grid, and their sign must not reach the file
    return {
        "H": isotropic(curv, gain),
        "k1": _cv.add(cv2.multiply(curv.k1, curv.weight), 0.0),
        "k2": _cv.add(cv2.multiply(curv.k2, curv.weight), 0.0),
        "dir.X": curv.dir_x.copy(),
        "dir.Y": curv.dir_y.copy(),
    }


LAYERS = ("H", "k1", "k2", "dir.X", "dir.Y")


def _layers_on_grid(grids: tuple[np.ndarray, ...], f: int) -> dict[str, np.ndarray]:
    """:data:`LAYERS` from the working grid's (H, k1, k2, weight, d, b), upsampled ``f`` times."""
    h, w = f * grids[0].shape[0], f * grids[0].shape[1]
    outs = tuple(np.empty((h, w), np.float32) for _ in LAYERS)
    run_strips(
        h,
        lambda r0, r1: _layer_rows(grids, f, r0, tuple(o[r0:r1] for o in outs)),
        _common._STRIP_ROWS,
    )
    return dict(zip(LAYERS, outs, strict=True))


@kernel
def _layer_rows(grids, f, r0, outs):  # type: ignore[no-untyped-def]
    """Rows ``r0 ..`` of the layers: each grid's row upsampled (:func:`upsample_row`), then
    H as it is, k·weight (0 where the weight is 0) and the direction from (d, b)
    (:func:`ops.curvature.result.half_angle_row`)."""
    zero = np.float32(0.0)
    wide = outs[0].shape[1]
    v = np.empty(grids[0].shape[1], np.float32)
    k1, k2, wt = np.empty(wide, np.float32), np.empty(wide, np.float32), np.empty(wide, np.float32)
    d, b = np.empty(wide, np.float32), np.empty(wide, np.float32)
    for i in range(outs[0].shape[0]):
        y = r0 + i
        upsample_row(grids[0], f, y, v, outs[0][i])
        upsample_row(grids[1], f, y, v, k1)
        upsample_row(grids[2], f, y, v, k2)
        upsample_row(grids[3], f, y, v, wt)
        upsample_row(grids[4], f, y, v, d)
        upsample_row(grids[5], f, y, v, b)
        o1, o2 = outs[1][i], outs[2][i]
        for j in range(wide):
            weight = wt[j]
            o1[j] = k1[j] * weight if weight != zero else zero
            o2[j] = k2[j] * weight if weight != zero else zero
        half_angle_row(d, b, outs[3][i], outs[4][i])
