"""Shading styles driven by the ARM value r (§3, Figs. 1c-d and 2): cel, counter shading, X-Toon
and masking another operator's result."""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence

import cv2
import numpy as np
from numpy.typing import NDArray

from ops.checks import FRACTION
from ops.parallel import run_strips, strip_rows
from ops.relief._common import _STRIP_ROWS, F32, _check_same, _check_unit_image, _f32, _f32_rows
from ops.relief._kernels import _counter_rows, _toon_coords
from ops.relief.arm import _lookup, _prepare, _Texture
from ops.relief.shipped import _smoothstep

__all__ = ["cel", "counter_shading", "default_toon", "masked", "xtoon"]

# -- styles (Figs. 1c-d, 2) ------------------------------------------------------------------------


def cel(r: NDArray[np.generic]) -> F32:
    """Cel shading (Apparent Relief §2, Figs. 1c-d): the relief value itself, I = r."""
    return np.asarray(np.clip(_f32(r, "r", (2, 3)), 0.0, 1.0), np.float32)


_NO_ROWS = np.empty((0, 0), np.float32)  # the operand a kernel does not read


def _lit(
    ndotl: NDArray[np.generic] | None,
    normal: NDArray[np.generic] | None,
    light: NDArray[np.generic] | Sequence[float] | None,
    shape: tuple[int, ...],
) -> Callable[[int, int], tuple[F32, F32, F32, bool]]:
    """The n·ℓ operands of :func:`_ndotl_row` on rows [r0, r1): ``(normal rows (rows, 3W),
    n·ℓ rows (rows, W), light (3,), from_normal)``, views of an (H, W) ``ndotl`` or of the
    (H, W, 3) ``normal`` field (rows may be strided: a crop is read in place) with a
    directional ``light`` (3,)."""
    if ndotl is not None:
        if normal is not None or light is not None:
            raise ValueError("give either ndotl or normal and light, not both")
        nl = _f32_rows(ndotl, "ndotl", (2,))
        _check_same(nl, "ndotl", shape)
        none = np.zeros(3, np.float32)

        def given(r0: int, r1: int) -> tuple[F32, F32, F32, bool]:
            return _NO_ROWS, nl[r0:r1], none, False

        return given
    if normal is None or light is None:
        raise ValueError("n·ℓ is needed: give ndotl, or normal and light")
    n = _f32_rows(normal, "normal", (3,))
    if n.shape[2] != 3:
        raise ValueError(f"normal must have shape (H, W, 3), got {n.shape}")
    _check_same(n, "normal", shape)
    vec = np.asarray(light, np.float32)
    if vec.shape != (3,) or not np.isfinite(vec).all():
        raise ValueError(f"light must be a finite (3,) direction, got {vec!r}")
    vec = np.ascontiguousarray(vec)
    width = n.shape[1]

    def rows(r0: int, r1: int) -> tuple[F32, F32, F32, bool]:
        return n[r0:r1].reshape(r1 - r0, 3 * width), _NO_ROWS, vec, True

    return rows


def counter_shading(
    r: NDArray[np.generic],
    ndotl: NDArray[np.generic] | None = None,
    threshold: float = 0.5,
    *,
    normal: NDArray[np.generic] | None = None,
    light: NDArray[np.generic] | Sequence[float] | None = None,
) -> F32:
    """Counter shading (Apparent Relief §2, Fig. 2b)::

        I = (1 − r) n·ℓ + r (1 − n·ℓ) = n·ℓ + r (1 − 2 n·ℓ),   output 1 where I > threshold, else 0

    Parameters
    ----------
    r : (H, W) relief value in [0, 1] (:func:`arm_lookup`), used as the contrast.
    ndotl : (H, W) n·ℓ, clamped to [0, 1] (back-facing light counts as 0).
    threshold : in [0, 1] (the paper's 0.5).
    normal, light : instead of ``ndotl``, the (H, W, 3) normals and a directional light (3,),
        unit length, camera space: n·ℓ is then computed in the same pass (no (H, W) n·ℓ
        written), with the result of ``counter_shading(r, ops.shading.dot(normal, light))`` up
        to float rounding (a pixel whose I is within rounding of the threshold may differ).

    Returns
    -------
    (H, W) float32, exactly 0 or 1.

    Notes
    -----
    One compiled pass (:func:`ops.jit.kernel`) per row strip, on both cores: n·ℓ, I and the
    threshold per row, the row in L1; (H, W) r and (H, W, 3) normals read once, the result
    written once.
    """
    rr = _f32_rows(r, "r", (2,))
    lit = _lit(ndotl, normal, light, rr.shape)
    thr = FRACTION.check(threshold, "threshold")
    out = np.empty(rr.shape, np.float32)
    t = np.float32(thr)

    def strip(r0: int, r1: int) -> None:
        _counter_rows(rr[r0:r1], *lit(r0, r1), t, out[r0:r1])

    run_strips(rr.shape[0], strip, strip_rows(rr.shape[1]))
    return out


def default_toon(width: int = 256, height: int = 64) -> F32:
    """A default X-Toon texture (Barla et al. 2006) for :func:`xtoon`: (height, width, 3) RGB.

    Column = tone n·ℓ (0 left → 1 right), row = relief r (1 at the top row, 0 at the bottom row).
    At r = 0 (features not selected) a soft, low-contrast warm gradient; at r = 1 crisp three-tone
    cel shading (dark / mid / light with narrow smooth steps), interpolated in between, so the
    selected features stand out in full contrast.
    """
    if not (2 <= width <= 4096 and 2 <= height <= 4096):
        raise ValueError(f"toon size must be in [2, 4096] per side, got {width}x{height}")
    tone = np.linspace(0.0, 1.0, width, dtype=np.float32)[None, :]
    rel = np.linspace(1.0, 0.0, height, dtype=np.float32)[:, None]
    soft = 0.55 + 0.35 * tone
    steps = 0.18 + 0.42 * _smoothstep(0.27, 0.33, tone) + 0.4 * _smoothstep(0.67, 0.73, tone)
    val = soft + rel * (steps - soft)
    tint = np.array([1.0, 0.85, 0.68], np.float32)
    return np.ascontiguousarray(np.clip(val[:, :, None] * tint, 0.0, 1.0), dtype=np.float32)


_DEFAULT_TOON_SIZE = (64, 256)  # (h, w) of default_toon()


@functools.cache
def _default_toon_texture() -> _Texture:
    """:func:`default_toon` prepared for the lookup, once (read-only arrays)."""
    tex = _prepare(default_toon(_DEFAULT_TOON_SIZE[1], _DEFAULT_TOON_SIZE[0]))
    for plane in tex.planes:
        plane.setflags(write=False)
    return tex


def xtoon(
    r: NDArray[np.generic],
    ndotl: NDArray[np.generic] | None = None,
    toon: NDArray[np.generic] | None = None,
    *,
    normal: NDArray[np.generic] | None = None,
    light: NDArray[np.generic] | Sequence[float] | None = None,
) -> F32:
    """X-Toon shading with the relief as the detail axis (Apparent Relief §2, Fig. 2a; Barla,
    Thollot & Markosian, "X-Toon: an extended toon shader", NPAR 2006)::

        I = T(n·ℓ, r),  column x = n·ℓ · (w − 1),  row y = (1 − r) · (h − 1)

    Parameters
    ----------
    r : (H, W) relief value in [0, 1].
    ndotl : (H, W) n·ℓ, clamped to [0, 1].
    toon : (h, w) or (h, w, C <= 4) texture in [0, 1], tone left → right, r = 1 on the top row;
        default :func:`default_toon`.
    normal, light : instead of ``ndotl``, the (H, W, 3) normals and a directional light (3,):
        n·ℓ is computed in the same pass as the lookup, with the result of
        ``xtoon(r, ops.shading.dot(normal, light), toon)`` up to float rounding.

    Returns
    -------
    (H, W, C) float32 (or (H, W) for a one-channel texture), bilinear lookup.

    Notes
    -----
    Strip by strip on both cores, so no full-size map is written: the texture coordinates in one
    compiled pass (:func:`ops.jit.kernel`: n·ℓ, x and y per row, r clamped to [0, 1]), then the
    bilinear lookup (one cv2.remap of the RGBA texture: its SIMD gathers beat a compiled scalar
    lookup, which LLVM does not vectorise here).
    """
    rr = _f32_rows(r, "r", (2,))
    if toon is None:
        tex, (h, w) = _default_toon_texture(), _DEFAULT_TOON_SIZE
    else:
        img = _check_unit_image(toon, "toon")
        if img.ndim == 3 and img.shape[2] == 1:
            img = img[:, :, 0]
        tex, (h, w) = _prepare(img), img.shape[:2]
    sx, sy = np.float32(w - 1), np.float32(h - 1)
    lit = _lit(ndotl, normal, light, rr.shape)
    out = np.empty(rr.shape if tex.chans == 1 else (*rr.shape, tex.chans), np.float32)

    def strip(r0: int, r1: int) -> None:
        mx = np.empty((r1 - r0, rr.shape[1]), np.float32)
        my = np.empty_like(mx)
        _toon_coords(rr[r0:r1], *lit(r0, r1), sx, sy, mx, my)
        _lookup(tex, mx, my, dst=out[r0:r1])

    run_strips(rr.shape[0], strip, _STRIP_ROWS)
    return out


def masked(r: NDArray[np.generic], base: NDArray[np.generic], effect: NDArray[np.generic]) -> F32:
    """The relief as a mask on another operator's result (Apparent Relief §2, Fig. 2c: exaggerated
    shading only on the features the ARM selects)::

        I = base · (1 − r) + effect · r

    ``base`` and ``effect``: (H, W) or (H, W, C) of the same shape; r: (H, W) in [0, 1].
    Returns float32 of ``base``'s shape.
    """
    rr = np.clip(_f32(r, "r", (2,)), 0.0, 1.0)
    b = _f32(base, "base", (2, 3))
    e = _f32(effect, "effect", (2, 3))
    if e.shape != b.shape:
        raise ValueError(f"effect must have the shape of base {b.shape}, got {e.shape}")
    _check_same(b, "base", rr.shape)
    diff = cv2.subtract(e, b)
    if b.ndim == 2:
        cv2.multiply(diff, rr, dst=diff)
    else:
        diff = diff.reshape(b.shape)  # cv2 drops a trailing channel axis of 1
        np.multiply(diff, rr[:, :, None], out=diff)
    return np.asarray(cv2.add(b, diff).reshape(b.shape), np.float32)
