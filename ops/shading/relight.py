"""Renderer lobes recombined (radiance = light × colour) and relit by the ratio of two shadings."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ops.color import check_in_place, luminance_of_sum_rows
from ops.parallel import run_strips
from ops.shading._kernels import _gain_rows, _radiance_rows, _ratio_rows
from ops.shading.directions import _SHADE_ROWS, MadeShading, Shading, _flat_rows

__all__ = ["Relit", "apply_gain", "lobe_radiance", "ratio_relight"]


def lobe_radiance(
    lights: dict[str, np.ndarray], colors: dict[str, np.ndarray]
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Each lobe's radiance ``light_j × colour_j`` and the beauty ``Σ_j light_j × colour_j``.

    Parameters
    ----------
    lights : lobe -> (H, W, 3) light without colour (e.g. :func:`shade_directions`).
    colors : lobe -> (H, W, 3) or (3,) colour (albedo, specular colour).

    Returns
    -------
    (lobe -> (H, W, 3) float32 radiance, (H, W, 3) float32 beauty); one compiled pass per row
    strip, each light and colour read once, the beauty kept in cache.
    """
    names = list(lights)
    if not names:
        raise ValueError("lobe_radiance needs at least one lobe")
    hgt, wid = lights[names[0]].shape[:2]
    shape = (hgt, wid, 3)
    flat = {
        n: (
            _flat_rows(lights[n], shape, f"lights[{n!r}]")[0],
            _flat_rows(colors[n], shape, f"colors[{n!r}]", constant=True),
        )
        for n in names
    }
    radiance = {n: np.empty((hgt, wid, 3), np.float32) for n in names}
    beauty = np.empty((hgt, wid, 3), np.float32)
    rad = {n: r.reshape(hgt, 3 * wid) for n, r in radiance.items()}
    out = beauty.reshape(hgt, 3 * wid)

    def strip(r0: int, r1: int) -> None:
        for k, n in enumerate(names):
            lit, (col, const) = flat[n]
            rows = col if const else col[r0:r1]
            _radiance_rows(lit[r0:r1], rows, const, rad[n][r0:r1], out[r0:r1], k == 0)

    run_strips(hgt, strip, rows=_SHADE_ROWS)
    return radiance, beauty


class Relit(NamedTuple):
    """What :func:`ratio_relight` returns."""

    beauty: np.ndarray  # (H, W, 3) beauty'
    lobes: dict[str, np.ndarray]  # lobe -> (H, W, 3) lobe'
    lights: dict[str, np.ndarray]  # lobe -> (H, W, 3) light', for the lobes given a light
    # luminance of the lobes' sum before and after ((H, W) each), when asked (``weights``)
    y_before: np.ndarray | None = None
    y_after: np.ndarray | None = None


def ratio_relight(
    beauty: np.ndarray,
    lobes: dict[str, tuple[np.ndarray, np.ndarray | None]],
    original: dict[str, np.ndarray] | Shading,
    aligned: dict[str, np.ndarray] | Shading,
    eps: float,
    ratio_max: float,
    weights: tuple[float, float, float] | None = None,
) -> Relit:
    """Renderer lobes relit by a ratio of two shadings (Depict's ratio form of relighting)::

        ρ_j = clamp((aligned_j + ε) / (original_j + ε), 0, ratio_max),
        lobe_j' = ρ_j · lobe_j,   light_j' = ρ_j · light_j,
        beauty' = beauty + Σ_j (lobe_j' − lobe_j)

    so the renderer's own lighting, textures and indirect light are kept and only the change of
    the shading (e.g. Local Light Alignment's aligned lights, :func:`shade_directions`) is applied.

    Parameters
    ----------
    beauty : (H, W, 3) the beauty the lobes are part of.
    lobes : lobe -> ((H, W, 3) radiance, (H, W, 3) light without colour or None).
    original, aligned : lobe -> (H, W, 3) the two shadings of each lobe, or a :class:`Shading`
        (from :func:`ops.shading.shading`: made strip by strip in this pass where it can be).
    eps : ε > 0 keeps the ratio finite where the original shading is dark.
    ratio_max : the largest ratio.
    weights : luminance weights: also the luminance of Σ_j lobe_j and of Σ_j lobe_j', as
        :func:`ops.color.luminance_of_sum` makes them (bit for bit), in the same pass.

    Returns
    -------
    :class:`Relit`; one compiled pass per row strip, every input read once.
    """
    hgt, wid = beauty.shape[:2]
    shape = (hgt, wid, 3)

    def flat(a: np.ndarray, what: str) -> np.ndarray:
        return _flat_rows(a, shape, what)[0]

    base = flat(beauty, "beauty")
    names = list(lobes)
    ins = {
        n: (
            flat(lobes[n][0], f"lobes[{n!r}]"),
            None if lobes[n][1] is None else flat(lobes[n][1], f"light of {n!r}"),  # type: ignore[arg-type]
        )
        for n in names
    }
    shadings = [
        _shading(x, shape, what) for x, what in ((aligned, "aligned"), (original, "original"))
    ]
    out = np.empty(shape, np.float32)
    new = {n: np.empty(shape, np.float32) for n in names}
    new_light = {n: np.empty(shape, np.float32) for n in names if lobes[n][1] is not None}
    flat_new = {n: x.reshape(hgt, 3 * wid) for n, x in new.items()}
    flat_light = {n: x.reshape(hgt, 3 * wid) for n, x in new_light.items()}
    lum = (
        None
        if weights is None
        else (np.empty((hgt, wid), np.float32), np.empty((hgt, wid), np.float32))
    )
    acc = out.reshape(hgt, 3 * wid)
    e, rmax = np.float32(eps), np.float32(ratio_max)

    def strip(r0: int, r1: int) -> None:
        acc[r0:r1] = base[r0:r1]
        a, o = (s.rows(r0, r1) for s in shadings)
        for n in names:
            lobe, light = ins[n]
            _ratio_rows(
                lobe[r0:r1],
                lobe[r0:r0] if light is None else light[r0:r1],
                a[n],
                o[n],
                e,
                rmax,
                flat_new[n][r0:r1],
                flat_light[n][r0:r1] if light is not None else acc[r0:r0],
                acc[r0:r1],
            )
        if lum is not None:
            assert weights is not None
            luminance_of_sum_rows([ins[n][0][r0:r1] for n in names], weights, lum[0][r0:r1])
            luminance_of_sum_rows([flat_new[n][r0:r1] for n in names], weights, lum[1][r0:r1])

    run_strips(hgt, strip, rows=_RATIO_ROWS)
    return Relit(out, new, new_light, *(lum or (None, None)))


#: Rows per strip of :func:`ratio_relight` (its shadings' strips stay in the caches).
_RATIO_ROWS = 16


def _shading(x: dict[str, np.ndarray] | Shading, shape: tuple[int, int, int], what: str) -> Shading:
    """A shading given as arrays, checked (ValueError naming ``what``), or as it is."""
    made = x if isinstance(x, Shading) else MadeShading(x, what)
    if made.shape != shape[:2]:
        raise ValueError(f"{what} must have shape {shape}, got {(*made.shape, 3)}")
    return made


def apply_gain(
    beauty: np.ndarray, gain: np.ndarray, lobes: list[np.ndarray], lights: list[np.ndarray]
) -> None:
    """A per-pixel ``gain`` (H, W) applied in place to relit ``lobes`` and their ``lights``
    (C-contiguous float32 (H, W, 3) arrays, as the beauty; anything else is a ValueError), the
    ``beauty`` they are part of changed by as much:
    beauty += Σ_j (gain − 1) lobe_j (each lobe's change added as it is made). One compiled pass
    per array and row strip."""
    hgt, wid = gain.shape
    for x in (beauty, *lobes, *lights):
        check_in_place(x, (hgt, wid), "apply_gain")
    flat = [(x.reshape(hgt, 3 * wid), True) for x in lobes]
    flat += [(x.reshape(hgt, 3 * wid), False) for x in lights]
    out = beauty.reshape(hgt, 3 * wid)

    def strip(r0: int, r1: int) -> None:
        for x, add in flat:
            _gain_rows(x[r0:r1], gain[r0:r1], add, out[r0:r1])

    run_strips(hgt, strip, rows=_SHADE_ROWS)
