"""The shading and shape flows: covered planes at the gradient level, structure-tensor products
on strips of rows, and each flow's strength and doubled-angle direction."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import cv2
import numpy as np
from numpy.typing import NDArray

from ops.congruence._common import _LUMA, _REL_FLOOR, F32
from ops.numerics import magnitude
from ops.parallel import run_strips


def _f32(x: object) -> F32:
    """An OpenCV result as a float32 array (no copy)."""
    return np.asarray(x, np.float32)


def _half_angle(c: F32, s: F32, insidef: F32) -> F32:
    """Unit (cos θ, sin θ) from a doubled-angle vector ∝ (cos 2θ, sin 2θ); 0 where undefined."""
    mag, ang = cv2.cartToPolar(c, s)
    okf = cv2.multiply((mag > 1e-6).astype(np.float32), insidef)
    vx, vy = cv2.polarToCart(okf, ang * np.float32(0.5))
    return np.asarray(cv2.merge([vx, vy]), np.float32)


# Strip heights, in rows of the level a pass writes: the full-resolution pass (gradient-level
# rows) and the gradient pass (gradient-level rows, rounded to a multiple of the integration
# factor). Strips keep each pass's working set in the CPU cache and run on parallel threads.
_ROWS_COVER = 48
_ROWS_GRAD = 136

_ONES3 = np.ones((3, 3), np.uint8)


def _covered_level(
    img: F32 | None,
    dep: F32,
    mask: NDArray[np.generic] | None,
    f: int,
    size: tuple[int, int],
    normal: F32 | None = None,
    weights: F32 = _LUMA,
    geometry: bool = True,
) -> list[F32]:
    """Covered luminance (when ``img`` is given), then with ``geometry`` the covered depth and
    coverage (then, with ``normal``, the covered n_x, n_y, n_z), area-downsampled by ``f`` to
    ``size``.

    Coverage is finite positive depth (and mask > 0.5); the other planes are 0 where it is 0
    (a NaN depth stays NaN). When ``f`` divides the image this runs on strips of rows (an
    integer area resize only mixes rows of one strip, so the result is the same as one pass).
    """
    h, w = dep.shape
    ws, hs = size
    strips = f == 1 or (w == ws * f and h == hs * f)
    with_lum = img is not None
    n_geo = 0 if not geometry else 2 if normal is None else 5
    n_out = int(with_lum) + n_geo
    out = [np.empty((hs, ws), np.float32) for _ in range(n_out)]
    msk = None if mask is None else np.asarray(mask)

    def strip(a: int, b: int) -> None:
        r0, r1 = (a * f, b * f) if strips else (0, h)
        if f == 1:
            planes = [o[a:b] for o in out]
        else:
            planes = [np.empty((r1 - r0, w), np.float32) for _ in range(n_out)]
        own = planes[int(with_lum) :] if geometry else []
        depc = own[0] if geometry else np.empty((r1 - r0, w), np.float32)
        covf = own[1] if geometry else np.empty((r1 - r0, w), np.float32)
        cv2.threshold(dep[r0:r1], 1e30, 0, cv2.THRESH_TOZERO_INV, dst=depc)  # +inf -> 0
        cv2.threshold(depc, 0, 1, cv2.THRESH_BINARY, dst=covf)  # > 0 -> 1
        if msk is not None:
            cv2.multiply(covf, (msk[r0:r1] > 0.5).astype(np.float32), dst=covf)
        if geometry:
            cv2.multiply(depc, covf, dst=depc)
        if img is not None:
            lum = planes[0]
            if img.ndim == 3:
                cv2.transform(img[r0:r1], weights, dst=lum)
                cv2.multiply(lum, covf, dst=lum)
            else:
                cv2.multiply(img[r0:r1], covf, dst=lum)
        if geometry and normal is not None:
            for c, dst in enumerate(own[2:]):
                cv2.multiply(np.ascontiguousarray(normal[r0:r1, :, c]), covf, dst=dst)
                cv2.patchNaNs(dst, 0.0)  # uncovered normals may be NaN (NaN * 0 = NaN)
        if f > 1:
            rows = slice(a, b) if strips else slice(0, hs)
            for src, o in zip(planes, out, strict=True):
                cv2.resize(src, (ws, o[rows].shape[0]), dst=o[rows], interpolation=cv2.INTER_AREA)

    run_strips(hs, strip, _ROWS_COVER if strips else hs)
    return out


def _sobel(x: F32, rows: slice) -> tuple[F32, F32]:
    """Sobel derivatives per level pixel (x right, rows down) of ``x``, on ``rows``."""
    return (
        _f32(cv2.Sobel(x, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)[rows]),
        _f32(cv2.Sobel(x, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)[rows]),
    )


def _whole_strips(level: tuple[int, int], f: int, size: tuple[int, int]) -> bool:
    """Whether a level of (h, w) pixels reduces to ``size`` by whole blocks of ``f``: its
    passes then run on strips of rows (else on the whole level at once)."""
    (h, w), (ws, hs) = level, size
    return f == 1 or (w == ws * f and h == hs * f)


def _grad_strips(
    level: tuple[int, int],
    sigma: float,
    f: int,
    size: tuple[int, int],
    strip: Callable[[int, int, int, int], None],
) -> None:
    """``strip(a, b, lo, hi)`` over strips [a, b) of the gradient level's rows (``level``: its
    (h, w)), with a halo [lo, hi) covering the blur of ``sigma`` and the 3×3 stencils when
    the level reduces by whole blocks (each kept row is then the same as in one pass over the
    whole level)."""
    h = level[0]
    halo = int(4.0 * sigma) + 4  # > Gaussian radius (≈ 4σ) + the Sobel / erosion row

    def run(a: int, b: int) -> None:
        strip(a, b, max(0, a - halo), min(h, b + halo))

    run_strips(h, run, max(1, _ROWS_GRAD // f) * f if _whole_strips(level, f, size) else h)


def _reduced(
    prods: Sequence[np.ndarray], out: list[F32], f: int, rows: tuple[int, int] | None
) -> None:
    """Rows [a, b) = ``rows`` of the gradient level's ``prods`` (None: all of them)
    area-downsampled by ``f`` into ``out``."""
    hs, ws = out[0].shape
    orows = slice(0, hs) if rows is None else slice(rows[0] // f, rows[1] // f)
    for p, o in zip(prods, out, strict=True):
        if f > 1:
            cv2.resize(p, (ws, o[orows].shape[0]), dst=o[orows], interpolation=cv2.INTER_AREA)
        else:
            o[orows] = p


def _shape_products(
    planes: list[F32], sigma: float, jump: float, f: int, size: tuple[int, int]
) -> tuple[list[F32], F32, F32]:
    """Gradient-level pass over the geometry planes of :func:`_covered_level` (depth, coverage
    and, when given, n_x, n_y, n_z): blur them by ``sigma``, normalise by the coverage, take
    Sobel gradients of the shape signal (the log depth, or each normal component) where the
    whole stencil is covered and the log depth steps by at most ``jump``, and return the shape's
    structure-tensor products [sxx, sxy, syy, valid] area-downsampled by ``f`` to ``size`` (summed
    over the normal's components); and, at the gradient level, 1 / the blurred coverage and the
    valid gradients (:func:`_shading_products` takes them).

    Runs on strips of rows with a halo (:func:`_grad_strips`), which gives the same result as
    one pass over the whole level.
    """
    cov = planes[1]
    h, w = cov.shape
    ws, hs = size
    out = [np.empty((hs, ws), np.float32) for _ in range(4)]
    inv_all = np.empty((h, w), np.float32)
    valid = np.empty((h, w), np.float32)

    def strip(a: int, b: int, lo: int, hi: int) -> None:
        chans = [x[lo:hi] for x in planes]
        if sigma >= 0.3:
            chans = [_f32(cv2.GaussianBlur(x, (0, 0), sigma)) for x in chans]
        dep1, c1 = chans[:2]
        # 1 / coverage; where the coverage is <= 1e-6 this is 1e6 instead of 0, which only
        # changes values no kept gradient reads (those need coverage > 0.999) and keeps them
        # finite
        inv = cv2.divide(1.0, np.maximum(c1, np.float32(1e-6)))
        logd1 = _f32(cv2.log(np.maximum(cv2.multiply(dep1, inv), np.float32(1e-30))))
        # kept where the whole stencil is covered and the log depth does not jump; computed on
        # the strip, used on [a, b)
        rows = slice(a - lo, b - lo)
        dx, dy = _sobel(logd1, rows)
        full = cv2.erode(cv2.threshold(c1, 0.999, 1, cv2.THRESH_BINARY)[1], _ONES3)[rows]
        steep = cv2.max(np.abs(dx), np.abs(dy))
        vf = cv2.multiply(cv2.threshold(steep, jump, 1, cv2.THRESH_BINARY_INV)[1], full)
        shape = [(dx, dy)]
        if len(chans) > 2:  # the normal's components
            shape = [_sobel(_f32(cv2.multiply(n, inv)), rows) for n in chans[2:]]
        sxx, sxy, syy = (np.zeros_like(vf) for _ in range(3))
        for sx, sy in shape:
            gx, gy = cv2.multiply(sx, vf), cv2.multiply(sy, vf)
            cv2.accumulateSquare(gx, sxx)
            cv2.accumulateProduct(gx, gy, sxy)
            cv2.accumulateSquare(gy, syy)
        inv_all[a:b] = inv[rows]
        valid[a:b] = vf
        # xy products in image (row-down) convention; the sign is flipped to y-up later
        _reduced((sxx, sxy, syy, vf), out, f, (a, b) if by_strips else None)

    by_strips = _whole_strips((h, w), f, size)
    _grad_strips((h, w), sigma, f, size, strip)
    return out, inv_all, valid


def _shading_products(
    lum: F32, inv: F32, valid: F32, sigma: float, f: int, size: tuple[int, int]
) -> list[F32]:
    """The shading's structure-tensor products [lxx, lxy, lyy] of the covered luminance ``lum``
    at the gradient level, as :func:`_shape_products` takes the shape's: blurred by ``sigma``,
    normalised by the coverage (``inv``), its Sobel gradients kept where ``valid``,
    area-downsampled by ``f`` to ``size``. The same strips and halo, the same result as one
    pass."""
    ws, hs = size
    out = [np.empty((hs, ws), np.float32) for _ in range(3)]

    def strip(a: int, b: int, lo: int, hi: int) -> None:
        lum1 = _f32(cv2.GaussianBlur(lum[lo:hi], (0, 0), sigma)) if sigma >= 0.3 else lum[lo:hi]
        lx, ly = _sobel(_f32(cv2.multiply(lum1, inv[lo:hi])), slice(a - lo, b - lo))
        vf = valid[a:b]
        lx, ly = _f32(cv2.multiply(lx, vf)), _f32(cv2.multiply(ly, vf))
        _reduced((lx * lx, lx * ly, ly * ly), out, f, (a, b) if by_strips else None)

    level = (lum.shape[0], lum.shape[1])
    by_strips = _whole_strips(level, f, size)
    _grad_strips(level, sigma, f, size, strip)
    return out


#: The analysis-level maps a :class:`CongruenceResult` upsamples on demand.
_LOW_MAPS = (
    "score",
    "e_shading",
    "e_shape",
    "weight",
    "cos2_shading",
    "sin2_shading",
    "cos2_shape",
    "sin2_shape",
)


def _reach(sigma: float) -> int:
    """An upper bound of the radius of OpenCV's float Gaussian kernel for ``sigma`` (its size
    is round(8σ + 1) | 1)."""
    return int(4.0 * sigma) + 1


def _window(
    cov: F32, f: int, size: tuple[int, int], margin: int
) -> tuple[tuple[int, int, int, int], tuple[int, int, int, int]] | None:
    """Rows and columns (y0, y1, x0, x1) of the level ``cov`` that hold its covered pixels plus
    ``margin``, aligned to the factor ``f`` of the next level, and the same window at the next
    level (of ``size``); the whole level when ``f`` does not divide it; None when nothing is
    covered.

    The first column is a multiple of 16 at both levels and the window extends 16 columns
    further on the right, so that OpenCV's vectorised filters process every column that is
    not 0 with the same lanes as on the whole level (a bit-identical result).
    """
    h, w = cov.shape
    ws, hs = size
    bx, by, bw, bh = cv2.boundingRect((cov > 0).view(np.uint8))
    if bw == 0 or bh == 0:
        return None
    if f > 1 and (w != ws * f or h != hs * f):
        return (0, h, 0, w), (0, hs, 0, ws)
    y0 = max(0, by - margin) // f
    x0 = max(0, bx - margin) // (16 * f) * 16
    y1 = min(hs, -(-(by + bh + margin) // f))
    x1 = min(ws, -(-(bx + bw + margin) // f) + 16)
    return (y0 * f, y1 * f, x0 * f, x1 * f), (y0, y1, x0, x1)


def _percentile(vals: F32, q: float) -> float:
    """``np.percentile(vals, q)`` (linear method), bit for bit, with one partial sort of ``vals``
    in place (numpy's partitions at four ranks and copies the array first)."""
    if type(q) not in (int, float):  # numpy scalars interpolate in their own precision
        return float(np.percentile(vals, q))
    n = vals.size
    virtual = (n - 1) * (q / 100.0)
    k = min(int(np.floor(virtual)), n - 1)
    gamma = virtual - k
    vals.partition(k)
    a = vals[k]
    b = vals[k + 1 :].min() if k + 1 < n else a
    d = b - a
    return float(b - d * (1.0 - gamma) if gamma >= 0.5 else a + d * gamma)


def _flow(
    txx: F32,
    txy: F32,
    tyy: F32,
    invw: F32,
    inside: NDArray[np.bool_],
    outside: NDArray[np.bool_],
    ref: float,
    q: float,
    norm: float | None = None,
    counted: NDArray[np.bool_] | None = None,
) -> tuple[F32, F32, F32, NDArray[np.bool_], float]:
    """Normalised strength, doubled-angle direction (cos 2θ, sin 2θ), definedness and the
    strength mapped to 1 (``norm``, else the ``q``-th percentile over the ``counted`` pixels,
    by default the ``inside`` ones) of one integrated structure tensor (row-down xy products; y
    flipped to up here)."""
    jxx = np.multiply(txx, invw)
    jyy = np.multiply(tyy, invw)
    e = np.add(jxx, jyy)
    e *= 0.5  # mean eigenvalue (≥ 0: the tensor is a positive blur of squares)
    a = np.subtract(jxx, jyy, out=jxx)
    b = np.asarray(cv2.multiply(txy, invw, scale=-2.0))  # 2 jxy, y up
    floor = _REL_FLOOR * ref * ref
    mag = magnitude(a, b)
    defined = mag > e * np.float32(1e-6)
    defined &= e > floor
    defined &= inside
    if norm is None:
        vals = e[inside if counted is None else counted]
        p = _percentile(vals, q) if vals.size else 0.0
    else:
        p = float(norm)
    p = max(p, floor)
    if p > 0:
        en = np.multiply(e, np.float32(1.0 / p), out=e)
        np.minimum(en, np.float32(1.0), out=en)
    else:
        en = np.multiply(e, 0, out=e)
    en[outside] = 0.0
    inv_mag = np.divide(1.0, mag, out=np.zeros_like(mag), where=defined)
    return en, np.multiply(a, inv_mag, out=a), np.multiply(b, inv_mag, out=b), defined, p


def _brightness(lum: F32, cov: F32) -> float:
    """The scale of the image's brightness for the noise floor: the 99.9th percentile of the
    covered pixels' |luminance| (the maximum would let one firefly or sun glint, thousands of
    times brighter than the rest, push every real gradient under the floor)."""
    full = cov > 0.5
    if not full.any():
        lmin, lmax = cv2.minMaxLoc(lum)[:2]
        return max(abs(lmin), abs(lmax)) / max(float(cv2.minMaxLoc(cov)[1]), 1e-6)
    return float(np.percentile(np.abs(lum[full] / cov[full]), 99.9))
