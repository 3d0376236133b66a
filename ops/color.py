"""Linear scene-referred RGB <-> CIELAB, float32, vectorised, HDR-safe.

Depict's radiance is linear RGB with Rec.709 / sRGB primaries and a D65 white (DESIGN.md). CIELAB
is taken relative to a *white level*: a linear value equal to ``white`` in all three channels maps
to L* = 100, a* = b* = 0. Values above the white level are not clipped: CIELAB's
f(t) = t^(1/3) extends above 1, so L* > 100 and the round trip stays exact for HDR radiance.

Why not ``cv2.cvtColor``: OpenCV's float ``COLOR_RGB2Lab`` applies the sRGB transfer curve, and
both it and the linear ``COLOR_LRGB2Lab`` clip the input to [0, 1] (RGB (4, 4, 4) comes back as
L* = 100 instead of 168.1; checked with OpenCV 5.0), and use a cube-root table with errors of
about 0.02 in L*. Here the matrix is ``cv2.transform`` and the cube root ``np.cbrt`` (correctly
rounded to 1 ulp, 3-4x faster than ``cv2.pow(x, 1/3)``), with the CIE linear segment below
(6/29)^3 written in closed form (no branches, no masks):

    f(t)    = cbrt(max(t, δ³)) + min(t − δ³, 0) / (3δ²),       δ = 6/29
    f⁻¹(u)  = max(u, δ)³ + 3δ² · min(u − δ, 0)

(for t ≥ δ³ the second term is 0; below, cbrt(δ³) + (t − δ³)/(3δ²) = t/(3δ²) + 4/29, CIE's
linear segment). Negative linear values (out of gamut) follow the linear segment, so they too
round-trip.

The conversions work through row strips of about 128k pixels (a strip's 3-channel float32
temporaries stay in cache between the steps; smaller strips cost more in per-call overhead than
they gain), spread over ``cv2.getNumThreads()`` threads (OpenCV and NumPy release the GIL;
``cv2.setNumThreads(1)`` makes them sequential). For 3D unsharp masking
(Ritschel et al. 2008, §4), :func:`lightness` gives L* alone and :func:`scale_lab` the colour
whose (L*, a*, b*) are scaled by a per-pixel k, in one pass each, without ever storing a*, b*.

References
----------
CIE 15:2004 Colorimetry, §8.2.1 (CIELAB); IEC 61966-2-1 (sRGB primaries, D65).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Literal

import cv2
import numpy as np

from ops.checks import PERCENTILE, WHITE
from ops.colorspace import REC709_RGB_TO_XYZ, REC709_Y
from ops.jit import kernel
from ops.numerics import dot3_row
from ops.opencv import written
from ops.parallel import run_strips, strip_rows

_cv: Any = cv2  # OpenCV's stubs reject scalar operands (cv2.max(a, 0.0))

__all__ = [
    "REC709_Y",
    "RGB_TO_XYZ",
    "auto_white",
    "check_in_place",
    "lab_phi_to_rgb",
    "lab_to_rgb",
    "lightness",
    "lightness_rows",
    "luminance",
    "luminance_of_sum",
    "luminance_of_sum_rows",
    "resolve_white",
    "rgb_to_lab",
    "rgb_to_lab_phi",
    "row_strips",
    "scale_lab",
]

#: Linear Rec.709/sRGB (D65) to CIE XYZ (IEC 61966-2-1), column vectors: the default space.
#: Another working space passes its own matrix (``rgb_to_xyz``, :mod:`ops.colorspace`).
RGB_TO_XYZ = REC709_RGB_TO_XYZ
_LUMA_ROWS = 64  # rows per strip of luminance()

_DELTA = 6.0 / 29.0
_DELTA3 = _DELTA**3
_SLOPE = 1.0 / (3.0 * _DELTA * _DELTA)  # d f / d t on the linear segment

# φ = f − 4/29 -> (L*, a*, b*) and back (linear, no offset).
_PHI_TO_LAB = np.array(
    [[0.0, 116.0, 0.0], [500.0, -500.0, 0.0], [0.0, 200.0, -200.0]], dtype=np.float32
)
_LAB_TO_PHI = np.linalg.inv(_PHI_TO_LAB.astype(np.float64)).astype(np.float32)
_C0 = 4.0 / 29.0  # f(0): φ = f − 4/29
_KNEE_PHI = _DELTA - _C0  # φ at the knee t = δ³ (2/29)
_116 = np.float32(116.0)

White = float | Literal["auto"]
#: What a per-strip ``k`` of :func:`scale_lab` returns: (k, keep) or (k, keep, columns).
KRows = tuple[np.ndarray, np.ndarray | None] | tuple[np.ndarray, np.ndarray | None, slice]


def row_strips(h: int, w: int, fn: Callable[[slice], None], step: int | None = None) -> None:
    """``fn(rows)`` on strips of ``step`` rows (default: about
    :data:`ops.parallel.STRIP_PIXELS` pixels of a ``w``-wide image) covering ``h`` rows, on
    every core (:func:`ops.parallel.run_strips`); ``fn`` must only write its own rows."""
    rows = step if step is not None else strip_rows(w)
    run_strips(h, lambda a, b: fn(slice(a, b)), rows)


def _phi_inplace(t: np.ndarray) -> None:
    """t -> φ = f(t) − 4/29 in place (a 2-D float32 array or view)."""
    if _cv.minMaxLoc(t)[0] > _DELTA3:  # nothing on the linear segment: φ = cbrt(t) − 4/29
        np.cbrt(t, out=t)
        _cv.subtract(t, _C0, dst=t)
        return
    lo = _cv.min(t, _DELTA3)
    _cv.max(t, _DELTA3, dst=t)
    np.cbrt(t, out=t)
    _cv.addWeighted(t, 1.0, lo, _SLOPE, -_DELTA, dst=t)


def _unphi_inplace(u: np.ndarray) -> None:
    """φ -> t = f⁻¹(φ + 4/29) in place (a 2-D float32 array or view)."""
    if _cv.minMaxLoc(u)[0] >= _KNEE_PHI:  # nothing on the linear segment: t = (φ + 4/29)³
        _cv.add(u, _C0, dst=u)
        _cv.pow(u, 3, dst=u)
        return
    lo = _cv.min(u, _KNEE_PHI)
    _cv.max(u, _KNEE_PHI, dst=u)
    _cv.add(u, _C0, dst=u)
    _cv.pow(u, 3, dst=u)
    s = 3.0 * _DELTA * _DELTA
    _cv.addWeighted(u, 1.0, lo, s, -s * _KNEE_PHI, dst=u)


def _to_t(white: float, rgb_to_xyz: np.ndarray) -> np.ndarray:
    """linear RGB -> t = (X/Xn, Y/Yn, Z/Zn) of rgb / white (3×3 float32); (Xn, Yn, Zn) is the
    space's white, XYZ of RGB (1, 1, 1)."""
    m = np.asarray(rgb_to_xyz, np.float64)
    return (m / (m.sum(axis=1)[:, None] * white)).astype(np.float32)


def _from_t(white: float, rgb_to_xyz: np.ndarray) -> np.ndarray:
    """t -> linear RGB (3×3 float32), the inverse of :func:`_to_t`."""
    m = np.asarray(rgb_to_xyz, np.float64)
    return (np.linalg.inv(m) * (m.sum(axis=1)[None, :] * white)).astype(np.float32)


def _check_rgb(rgb: np.ndarray, name: str) -> np.ndarray:
    arr = np.asarray(rgb)
    if arr.ndim != 3 or arr.shape[2] != 3:
        raise ValueError(f"{name} must have shape (H, W, 3), got {arr.shape}")
    return np.ascontiguousarray(arr, dtype=np.float32)


def check_in_place(x: np.ndarray, shape: tuple[int, int], who: str) -> None:
    """Refuse (ValueError) an array that ``who`` cannot change in place as an (H, W, 3) float32
    one: another shape or type, or not C-contiguous (a reshape of it would be a copy)."""
    if x.shape != (*shape, 3) or x.dtype != np.float32 or not x.flags.c_contiguous:
        raise ValueError(
            f"{who} changes C-contiguous float32 ({shape[0]}, {shape[1]}, 3) arrays in place; "
            f"got {x.dtype} {x.shape}{'' if x.flags.c_contiguous else ' (not contiguous)'}"
        )


def _flat(a: np.ndarray) -> np.ndarray:
    """A single-channel (H, W*C) view, so that cv2 scalar ops apply to every channel."""
    return a.reshape(a.shape[0], -1)


def luminance(rgb: np.ndarray, weights: tuple[float, float, float] = REC709_Y) -> np.ndarray:
    """Relative luminance Y = w_R R + w_G G + w_B B of linear RGB, by default Rec. 709's
    Y = 0.2126 R + 0.7152 G + 0.0722 B (:data:`REC709_Y`).

    ``rgb`` has shape (..., 3); the result has the leading shape, float32 (the weights are
    rounded to float32, the sum is taken in float32).

    >>> luminance(np.array([[1.0, 1.0, 1.0], [2.0, 0.0, 0.0]])).tolist() == [
    ...     np.float32(0.2126) + np.float32(0.7152) + np.float32(0.0722), np.float32(0.4252)]
    True
    """
    arr = np.ascontiguousarray(rgb, dtype=np.float32)
    if arr.ndim == 0 or arr.shape[-1] != 3:
        raise ValueError(f"rgb must have shape (..., 3), got {arr.shape}")
    if arr.size == 0:
        return np.zeros(arr.shape[:-1], np.float32)
    grid = arr.reshape(-1, arr.shape[-2] if arr.ndim > 1 else 1, 3)  # (rows, width, 3)
    w0, w1, w2 = (np.float32(w) for w in weights)
    out = np.empty(grid.shape[:2], np.float32)
    run_strips(
        grid.shape[0],
        lambda r0, r1: _luma_rows(grid[r0:r1], w0, w1, w2, out[r0:r1]),
        _LUMA_ROWS,
    )
    return out.reshape(arr.shape[:-1])


def luminance_of_sum(
    rgbs: Sequence[np.ndarray], weights: tuple[float, float, float] = REC709_Y
) -> np.ndarray:
    """``luminance(total(rgbs))`` of (H, W, 3) arrays, bit for bit (the sum taken in order in
    float32), by strips of rows: the RGB sum is never formed at full size."""
    arrays = [_check_rgb(x, f"rgbs[{i}]") for i, x in enumerate(rgbs)]
    h, w = arrays[0].shape[:2]
    out = np.empty((h, w), np.float32)
    row_strips(h, w, lambda r: luminance_of_sum_rows([x[r] for x in arrays], weights, out[r]))
    return out


def luminance_of_sum_rows(
    rows: Sequence[np.ndarray], weights: tuple[float, float, float], out: np.ndarray
) -> None:
    """Rows of :func:`luminance_of_sum`: ``out`` (rows, W) = the luminance of the sum of float32
    RGB rows ((rows, W, 3) or flat (rows, 3W)), taken in order in float32; one compiled pass,
    each row summed in a scratch row."""
    flat = tuple(np.ascontiguousarray(x, np.float32).reshape(x.shape[0], -1) for x in rows)
    w0, w1, w2 = (np.float32(x) for x in weights)
    _luma_of_sum_rows(flat, w0, w1, w2, np.empty(flat[0].shape[1], np.float32), out)


@kernel
def _luma_of_sum_rows(rows, w0, w1, w2, acc, out):  # type: ignore[no-untyped-def]
    for i in range(out.shape[0]):
        first = rows[0][i]
        for m in range(acc.shape[0]):
            acc[m] = first[m]
        for t in range(1, len(rows)):
            row = rows[t][i]
            for m in range(acc.shape[0]):
                acc[m] += row[m]
        dot3_row(acc, w0, w1, w2, out[i])


@kernel
def _luma_rows(rgb, w0, w1, w2, out):  # type: ignore[no-untyped-def]
    wid = out.shape[1]
    for i in range(out.shape[0]):
        dot3_row(rgb[i].reshape(3 * wid), w0, w1, w2, out[i])


def auto_white(
    rgb: np.ndarray,
    mask: np.ndarray | None = None,
    percentile: float = 99.0,
    weights: tuple[float, float, float] = REC709_Y,
) -> float:
    """White level for CIELAB: the ``percentile`` of luminance (``weights``: the working space's)
    over covered pixels.

    Computed on a strided subsample (every 4th row and column, at least 64k pixels kept where the
    image has them) for speed; a 99th percentile moves by well under 1 % from that. Pixels with
    ``mask <= 0`` or non-finite luminance are ignored. Returns 1.0 when nothing usable is left
    (an all-black or empty frame), so black stays black instead of dividing by zero.

    A sequence should pin the white level (pass a number to the operators) so that it does not
    flicker from frame to frame (DESIGN.md).
    """
    percentile = PERCENTILE.check(percentile, "percentile")
    arr = _check_rgb(rgb, "rgb")
    h, w = arr.shape[:2]
    step = 4 if h * w >= 16 * 65536 else 1
    sub = np.ascontiguousarray(arr[::step, ::step])
    y = luminance(sub, weights)
    ok = np.isfinite(y) & (y > 0.0)
    if mask is not None:
        m = np.asarray(mask)
        if m.shape != (h, w):
            raise ValueError(f"mask must have shape {(h, w)}, got {m.shape}")
        ok &= m[::step, ::step] > 0
    vals = y[ok]
    if vals.size == 0:
        return 1.0
    white = float(np.percentile(vals, percentile))
    return white if white > 0.0 and np.isfinite(white) else 1.0


def resolve_white(
    white: White,
    rgb: np.ndarray,
    mask: np.ndarray | None = None,
    weights: tuple[float, float, float] = REC709_Y,
) -> float:
    """``white`` as a number: ``"auto"`` -> :func:`auto_white` (luminance with the working
    space's ``weights``), a number -> itself (checked)."""
    if isinstance(white, str):
        if white != "auto":
            raise ValueError(f"white must be 'auto' or a number > 0, got {white!r}")
        return auto_white(rgb, mask, weights=weights)
    return WHITE.check(white, "white")


def rgb_to_lab_phi(
    rgb: np.ndarray, white: float = 1.0, rgb_to_xyz: np.ndarray = RGB_TO_XYZ
) -> np.ndarray:
    """Linear RGB -> centred CIELAB cube-root coordinates φ = f(t) − 4/29, (H, W, 3) float32.

    With t = (X/Xn, Y/Yn, Z/Zn) of ``rgb / white``, φ = (f(t_x), f(t_y), f(t_z)) − 4/29, so that

        L* = 116 φ_y,   a* = 500 (φ_x − φ_y),   b* = 200 (φ_y − φ_z).

    CIELAB is linear in φ without offset, so scaling (L*, a*, b*) by a common factor k (what
    3D unsharp masking does to keep saturation, Ritschel et al. 2008 §4) is scaling φ by k.
    Computed as φ = cbrt(max(t, δ³)) + min(t, δ³)/(3δ²) − δ (the CIE linear segment below δ³).
    """
    arr = _check_rgb(rgb, "rgb")
    m = _to_t(WHITE.check(white, "white"), rgb_to_xyz)
    h, w = arr.shape[:2]
    out = np.empty_like(arr)

    def strip(r: slice) -> None:
        t = _cv.transform(arr[r], m, dst=out[r])
        written(t, out[r])
        _phi_inplace(_flat(out[r]))

    row_strips(h, w, strip)
    return out


def lab_phi_to_rgb(
    phi: np.ndarray,
    white: float = 1.0,
    out: np.ndarray | None = None,
    rgb_to_xyz: np.ndarray = RGB_TO_XYZ,
) -> np.ndarray:
    """Centred cube-root coordinates φ (see :func:`rgb_to_lab_phi`) -> linear RGB, float32.

    f = φ + 4/29; t = f³ for f > 6/29, 3 (6/29)² (f − 4/29) below;
    rgb = white · M⁻¹ · ((Xn, Yn, Zn) ∘ t). ``phi`` is not modified. ``out``: an (H, W, 3)
    float32 array (or view) to write the result into; the result is returned either way.
    """
    arr = _check_rgb(phi, "phi")
    m_inv = _from_t(WHITE.check(white, "white"), rgb_to_xyz)
    h, w = arr.shape[:2]
    res = np.empty_like(arr) if out is None else out

    def strip(r: slice) -> None:
        cube = arr[r].copy()
        _unphi_inplace(_flat(cube))
        written(_cv.transform(cube, m_inv, dst=res[r]), res[r])

    row_strips(h, w, strip)
    return res


def lightness(
    rgb: np.ndarray,
    white: float = 1.0,
    out: np.ndarray | None = None,
    rgb_to_xyz: np.ndarray = RGB_TO_XYZ,
) -> np.ndarray:
    """CIELAB lightness L* = 116 f(Y/Yn) − 16 of linear RGB relative to ``white``, (H, W) float32.

    The L* channel of :func:`rgb_to_lab` without a*, b* (one 1×3 transform and one cube root per
    pixel). No clipping: values above ``white`` give L* > 100. ``out``: an (H, W) float32 array
    (or view) to write into; the result is returned either way.
    """
    arr = _check_rgb(rgb, "rgb")
    kernel = lightness_rows(white, rgb_to_xyz)
    h, w = arr.shape[:2]
    if out is None:
        out = np.empty((h, w), np.float32)
    elif out.shape != (h, w) or out.dtype != np.float32:
        raise ValueError(f"out must be float32 of shape {(h, w)}, got {out.dtype} {out.shape}")
    res = out

    def strip(r: slice) -> None:
        y = res[r]
        if not y.flags.c_contiguous:  # work in a contiguous strip
            y = np.empty(y.shape, np.float32)
        kernel(arr[r], y)
        written(y, res, r)

    row_strips(h, w, strip)
    return res


def lightness_rows(
    white: float = 1.0, rgb_to_xyz: np.ndarray = RGB_TO_XYZ
) -> Callable[[np.ndarray, np.ndarray], None]:
    """The strip kernel of :func:`lightness` for ``white``: ``fn(rgb, out)`` writes L* of
    ``rgb`` ((n, W, 3) float32 whose rows are contiguous) into ``out`` ((n, W) float32,
    C-contiguous), unchecked, in the calling thread: for a caller's own pass over strips, in
    which the dozen calls of :func:`lightness`'s checks per strip would add up."""
    m = _to_t(WHITE.check(white, "white"), rgb_to_xyz)[1:2]

    def fn(rgb: np.ndarray, out: np.ndarray) -> None:
        written(_cv.transform(rgb, m, dst=out), out)
        _phi_inplace(out)
        np.multiply(out, _116, out=out)  # (exact: OpenCV would multiply in double, slower)

    return fn


def scale_lab(
    rgb: np.ndarray,
    k: np.ndarray | Callable[[slice], KRows],
    white: float = 1.0,
    *,
    keep: np.ndarray | None = None,
    out: np.ndarray | None = None,
    rgb_to_xyz: np.ndarray = RGB_TO_XYZ,
) -> np.ndarray:
    """Linear RGB whose CIELAB coordinates are those of ``rgb`` times ``k``: (k L*, k a*, k b*).

    3D unsharp masking (Ritschel et al. 2008, §4) replaces L* by U(L*) and scales a*, b* by
    k = U(L*)/L*, keeping the hue angle and the saturation √(a*² + b*²)/L*. CIELAB is linear in
    the centred cube-root coordinates φ (:func:`rgb_to_lab_phi`), so this is
    ``lab_phi_to_rgb(k · rgb_to_lab_phi(rgb))``, done strip by strip without storing φ.

    Parameters
    ----------
    rgb : (H, W, 3) float32 linear RGB
    k : (H, W) float32, or a function of a row slice returning (k, keep) or (k, keep, cols)
        Per-pixel factor (≥ 0 keeps the colour physical). A function is called once per strip
        (from several threads at once): it lets the caller form k (and keep) while the strip
        is in cache; its keep (uint8 or None) replaces ``keep``. With ``cols`` (a slice of
        columns), k and keep cover those columns only and the strip's other columns are
        returned as ``rgb``, bit for bit (nothing there to change: not converted at all).
    white : float
        White level of the CIELAB coordinates (> 0).
    keep : (H, W) uint8 or None
        Where non-zero, ``rgb`` is returned bit for bit.
    out : (H, W, 3) float32 array (or view) or None
        Where to write the result; it is returned either way.
    """
    arr = _check_rgb(rgb, "rgb")
    w = WHITE.check(white, "white")
    hh, ww = arr.shape[:2]
    if callable(k):
        k_of = k
    else:
        kk = _rows_of(k, (hh, ww), np.float32, "k")
        kp_all = None if keep is None else _rows_of(keep, (hh, ww), np.uint8, "keep")

        def k_of(r: slice) -> KRows:
            return kk[r], None if kp_all is None else kp_all[r]

    m, m_inv = _to_t(w, rgb_to_xyz), _from_t(w, rgb_to_xyz)
    res = np.empty_like(arr) if out is None else out

    def strip(r: slice) -> None:
        got = k_of(r)
        kr, kp = got[0], got[1]
        c = got[2] if len(got) > 2 else slice(0, ww)
        if c.start > 0:
            res[r, : c.start] = arr[r, : c.start]
        if c.stop < ww:
            res[r, c.stop :] = arr[r, c.stop :]
        if c.stop <= c.start:
            return
        src, dst = arr[r, c], res[r, c]
        t = _cv.transform(src, m)
        _phi_inplace(_flat(t))
        _cv.multiply(t, _cv.merge([kr, kr, kr]), dst=t)
        _unphi_inplace(_flat(t))
        written(_cv.transform(t, m_inv, dst=dst), dst)
        if kp is not None and _cv.countNonZero(kp):
            written(_cv.copyTo(src, kp, dst), dst)

    row_strips(hh, ww, strip)
    return res


def _rows_of(a: np.ndarray, shape: tuple[int, int], dtype: type, name: str) -> np.ndarray:
    """``a`` checked to be an (H, W) array of the given dtype."""
    arr = np.asarray(a)
    if arr.shape != shape or arr.dtype != dtype:
        want = f"{np.dtype(dtype)} of shape {shape}"
        raise ValueError(f"{name} must be {want}, got {arr.dtype} {arr.shape}")
    return arr


def rgb_to_lab(
    rgb: np.ndarray, white: float = 1.0, rgb_to_xyz: np.ndarray = RGB_TO_XYZ
) -> np.ndarray:
    """Linear RGB (Rec.709 primaries, D65) -> CIELAB relative to the white level ``white``.

    X, Y, Z = M · rgb / white, each divided by the D65 white (Xn, Yn, Zn);
    L* = 116 f(Y/Yn) − 16, a* = 500 (f(X/Xn) − f(Y/Yn)), b* = 200 (f(Y/Yn) − f(Z/Zn)),
    f(t) = t^(1/3) for t > (6/29)³, t / (3 (6/29)²) + 4/29 below (CIE 15:2004 §8.2.1).
    No clipping: linear values above ``white`` give L* > 100.

    Parameters
    ----------
    rgb : (H, W, 3) float32
        Linear scene-referred radiance.
    white : float
        Linear value that maps to L* = 100 (> 0).

    Returns
    -------
    (H, W, 3) float32 ``(L*, a*, b*)``.
    """
    return _cv.transform(rgb_to_lab_phi(rgb, white, rgb_to_xyz), _PHI_TO_LAB)


def lab_to_rgb(
    lab: np.ndarray, white: float = 1.0, rgb_to_xyz: np.ndarray = RGB_TO_XYZ
) -> np.ndarray:
    """CIELAB relative to the white level ``white`` -> linear RGB; inverse of :func:`rgb_to_lab`.

    f_y = (L* + 16)/116, f_x = f_y + a*/500, f_z = f_y − b*/200;
    t = f³ above 6/29, 3 (6/29)² (f − 4/29) below; rgb = white · M⁻¹ · (Xn, Yn, Zn) ∘ t.

    Parameters
    ----------
    lab : (H, W, 3) float32
    white : float
        The white level the Lab values are relative to (> 0).

    Returns
    -------
    (H, W, 3) float32 linear RGB.
    """
    arr = _check_rgb(lab, "lab")
    return lab_phi_to_rgb(_cv.transform(arr, _LAB_TO_PHI), white, rgb_to_xyz=rgb_to_xyz)
