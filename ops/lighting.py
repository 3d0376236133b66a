"""What the eye reads as lighting, kept while shape detail is added.

Shape-enhancement operators (Radiance Scaling, Light Alignment, unsharp masking) should add
detail where there is relief, not relight a frame. Two pieces keep them there on path-traced
frames:

* a lobe's light averaged over covered pixels at a small scale (:func:`ops.pyramid.
  masked_gaussian`), so the reflectance mapping δ̄ of Radiance Scaling follows the lighting
  rather than each pixel's Monte-Carlo noise (the scaling σ(κ, δ̄) then multiplies the noise
  like any other light, it does not amplify it);
* :func:`luminance_gain` — the factor that divides an enhanced radiance by its low-frequency
  gain, ``out' = out · LF(Y(in)) / LF(Y(out))`` with LF a smoothing along the visible surfaces
  (:func:`ops.unsharp.surface_blur`: depth- and crease-aware, so an object and the floor it stands
  on are normalised apart), so the mean luminance of every surface region at that scale is the
  input's and only the detail finer than it changes.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from ops.color import check_in_place
from ops.jit import exact_kernel, inline_kernel, kernel
from ops.parallel import run_strips
from ops.pyramid.upsample import Upsampled, upsample_row
from ops.unsharp import surface_blur_rows

__all__ = ["apply_lighting_gain", "luminance_gain", "weighed_gain"]

F32 = NDArray[np.float32]

#: Luminance below which a region's gain is not measured (its radiance is kept as it is).
_DARK = np.float32(1e-6)

#: Rows per strip of the compiled passes.
_ROWS = 64
#: Rows per strip of the gain: each strip upsamples the smoothed levels over its rows and a
#: margin of cells (a taller strip spends less on the margin: 128 rows against 64, 0.7 ms of
#: the covered 1080p frame's 29).
_GAIN_ROWS = 128


def luminance_gain(
    y_before: np.ndarray,
    y_after: np.ndarray,
    depth: np.ndarray,
    normal: np.ndarray | None,
    mask: np.ndarray,
    *,
    sigma_scene: float,
    pixel_size: np.ndarray | float,
    full_change: float | None = None,
) -> F32:
    """The per-pixel factor that gives an enhanced luminance ``y_after`` the low-frequency
    luminance of ``y_before`` ((H, W) each, in the frame's working space)::

        gain = LF(y_before) / LF(y_after),   LF = surface_blur(·, σ = sigma_scene)

    (both smoothed on one surface pyramid). The gain is 1 on uncovered pixels and where either
    is darker than 1e-6 at that scale. See :func:`ops.unsharp.surface_blur` for ``depth``,
    ``normal``, ``mask``, ``pixel_size`` and the scale in scene units. With ``full_change``,
    the gain :func:`weighed_gain` makes of it, in the same pass.
    """
    low = surface_blur_rows(
        [y_before, y_after], depth, normal, mask, sigma_scene=sigma_scene, pixel_size=pixel_size
    )
    m = np.ascontiguousarray(mask)
    if m.dtype == np.bool_:
        m = m.view(np.uint8)
    weigh = full_change is not None
    y0, y1 = (np.ascontiguousarray(y, np.float32) for y in (y_before, y_after))
    k = np.float32(full_change if weigh else 0.0)
    out = np.empty(low.shape, np.float32)

    def strip(r0: int, r1: int) -> None:  # (each strip smoothed and used while in cache)
        lf_in, lf_out = low(r0, r1)
        _gain_rows(lf_in, lf_out, m[r0:r1], y0[r0:r1], y1[r0:r1], k, weigh, out[r0:r1])

    run_strips(out.shape[0], strip, _GAIN_ROWS)
    return out


@kernel
def _gain_rows(lf_in, lf_out, mask, y0, y1, k, weigh, out):  # type: ignore[no-untyped-def]
    """out = lf_in / lf_out where both are above _DARK and ``mask`` > 0, else 1; with ``weigh``,
    that gain weighed by the change from ``y0`` to ``y1`` (:func:`_weighed`)."""
    dark = _DARK
    for i in range(out.shape[0]):
        for j in range(out.shape[1]):
            a, b = lf_in[i, j], lf_out[i, j]
            ok = (a > dark) & (b > dark) & (mask[i, j] > 0)
            g = a / b if ok else np.float32(1.0)
            out[i, j] = _weighed(g, y0[i, j], y1[i, j], k) if weigh else g


def weighed_gain(
    gain: np.ndarray, y_before: np.ndarray, y_after: np.ndarray, full_change: float
) -> F32:
    """``gain`` weighed by how much an operator changed each pixel's luminance::

        1 + w (gain − 1),   w = min(1, |y_after − y_before| / (full_change · |y_before|))

    (w = 0 where the luminance is unchanged, so those pixels keep a gain of exactly 1; where
    ``y_before`` is 0, w = min(1, |y_after|)). All (H, W) float32; one compiled pass.
    """
    g, y0, y1 = (np.ascontiguousarray(a, dtype=np.float32) for a in (gain, y_before, y_after))
    out = np.empty_like(g)
    k = np.float32(full_change)
    run_strips(
        g.shape[0],
        lambda r0, r1: _weigh_rows(g[r0:r1], y0[r0:r1], y1[r0:r1], k, out[r0:r1]),
        _ROWS,
    )
    return out


@kernel
def _weigh_rows(gain, y0, y1, k, out):  # type: ignore[no-untyped-def]
    for i in range(out.shape[0]):
        for j in range(out.shape[1]):
            out[i, j] = _weighed(gain[i, j], y0[i, j], y1[i, j], k)


@inline_kernel
def _weighed(gain, a, b, k):  # type: ignore[no-untyped-def]
    """1 + w (``gain`` − 1), w = min(1, |b − a| / (k |a|)) (|b| where a = 0), 0 where b = a."""
    one = np.float32(1.0)
    w = abs(b - a)
    if a != 0:
        w = w / (k * abs(a))
    if w > one:
        w = one
    if b == a:
        w = np.float32(0.0)
    return one + w * (gain - one)


def apply_lighting_gain(
    out: np.ndarray,
    gain: np.ndarray,
    plus: np.ndarray | None,
    minus: Sequence[np.ndarray],
    unchanged: tuple[np.ndarray, Upsampled] | None = None,
) -> None:
    """``out`` · gain + ``plus`` − Σ ``minus``, in place, in that order (each operation rounded
    as NumPy rounds it): an enhanced sum of lobes given the kept lighting's ``gain`` (H, W),
    with what the lobes leave out of the beauty added back. ``out`` and the others (H, W, 3)
    float32, ``out`` C-contiguous. ``unchanged`` = (``original``, κ): where the gain is exactly
    1 and κ is 0 (the operator changed nothing there), ``original`` instead, bit for bit (the
    sum of lobes and the rest only rounds back to it). One compiled pass per array and strip of
    rows, while the strip is in cache."""
    hgt, wid = gain.shape
    check_in_place(out, (hgt, wid), "apply_lighting_gain")
    flat = (hgt, 3 * wid)
    o = out.reshape(flat)
    g = np.ascontiguousarray(gain, np.float32)
    p = o if plus is None else np.ascontiguousarray(plus, np.float32).reshape(flat)
    ms = [np.ascontiguousarray(x, np.float32).reshape(flat) for x in minus]
    keep = None
    if unchanged is not None:
        keep = (np.ascontiguousarray(unchanged[0], np.float32).reshape(flat), unchanged[1])

    def strip(r0: int, r1: int) -> None:
        _times_plus_rows(o[r0:r1], g[r0:r1], p[r0:r1], plus is not None)
        for m in ms:
            _minus_rows(o[r0:r1], m[r0:r1])
        if keep is not None:
            orig, kappa = keep
            _restore_rows(o[r0:r1], orig[r0:r1], g[r0:r1], kappa.grid, kappa.factor, r0)

    run_strips(hgt, strip, _ROWS)


@kernel
def _restore_rows(out, orig, gain, grid, f, r0):  # type: ignore[no-untyped-def]
    """Rows (3W) of ``out`` = ``orig`` where ``gain`` is 1 and κ (``grid`` upsampled ``f``
    times, its rows from ``r0`` on: :func:`ops.pyramid.upsample_row`, as ``np.asarray`` of the
    :class:`~ops.pyramid.Upsampled` makes them) is 0."""
    one, zero = np.float32(1.0), np.float32(0.0)
    wid = gain.shape[1]
    v = np.empty(grid.shape[1], np.float32)
    k = np.empty(wid, np.float32)
    for i in range(out.shape[0]):
        upsample_row(grid, f, r0 + i, v, k)
        o, q, g = out[i], orig[i], gain[i]
        for j in range(wid):
            if (g[j] == one) & (k[j] == zero):
                o[3 * j], o[3 * j + 1], o[3 * j + 2] = q[3 * j], q[3 * j + 1], q[3 * j + 2]


@exact_kernel
def _times_plus_rows(out, gain, plus, add):  # type: ignore[no-untyped-def]
    """Rows (3W) of ``out`` × ``gain`` (rows of W), then + ``plus`` with ``add``."""
    for i in range(out.shape[0]):
        o, g = out[i], gain[i]
        for j in range(g.shape[0]):
            gj = g[j]
            o[3 * j] = o[3 * j] * gj
            o[3 * j + 1] = o[3 * j + 1] * gj
            o[3 * j + 2] = o[3 * j + 2] * gj
        if add:
            q = plus[i]
            for m in range(o.shape[0]):
                o[m] = o[m] + q[m]


@exact_kernel
def _minus_rows(out, x):  # type: ignore[no-untyped-def]
    for i in range(out.shape[0]):
        o, q = out[i], x[i]
        for m in range(o.shape[0]):
            o[m] = o[m] - q[m]
