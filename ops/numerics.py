"""Vectorisable float32 numerics that the compiled kernels of ``ops/`` share.

Numba does not vectorise calls to libm here (no SVML), so a kernel that needs a transcendental
function in its inner loop calls one of these instead: polynomials with branch-free range
reduction that LLVM inlines and vectorises with the caller's loop. Each states its domain and
its error; the tests compare them with NumPy's float64 functions.

* :func:`expf`: e^x (Cephes), within 2 ulp;
* :func:`exp_neg`: e^{−u} for u ≥ 0, 2e-7 absolute, for range weights near 1;
* :func:`atan2_upper`: atan2(y, x) for y ≥ 0, ~1e-7 rad;
* :func:`sincos_upper`: (sin θ, cos θ) for θ ∈ [0, π], ~1e-8;
* :func:`dot3_row`: a row of interleaved triples dotted with constant weights (luminance);
* :func:`finite_quotient`: a plane divided by a number where finite, inf elsewhere (pixel
  sizes from depth), on row strips;
* :func:`clip_new_negatives`: the values an operation made negative set to 0 (the others bit
  for bit), on row strips;
* :func:`past_and_not_finite`: whether some value of a plane is past a bound, and whether some
  is not finite, in one pass on row strips (a frame's normals);
* :func:`fill_triples`: rows of interleaved triples set to one triple, on row strips;
* :func:`put_points`: values at scattered pixels written into a window of planes (a strip's
  sparse upsampled values), without Python's lock, where NumPy's fancy indexing holds it.

Constants are ``np.float32``: a Python float would promote a kernel's arithmetic to float64.
"""

from __future__ import annotations

import math

import numpy as np
from llvmlite import ir
from numba import types
from numba.extending import intrinsic

from ops.jit import exact_kernel, inline_kernel, kernel
from ops.parallel import run_strips, strip_rows

__all__ = [
    "EXPF_MAX",
    "atan2_upper",
    "clip_new_negatives",
    "dot3_row",
    "exp_neg",
    "expf",
    "finite_quotient",
    "magnitude",
    "new_values",
    "put_points",
    "sincos_upper",
]

_F0, _F1 = np.float32(0.0), np.float32(1.0)
_TINY = np.float32(1e-12)


@intrinsic
def _float32_from_bits(typingctx, bits):
    """The float32 whose IEEE-754 bit pattern is the int32 ``bits`` (a bit cast, no conversion)."""
    sig = types.float32(types.int32)

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.FloatType())

    return sig, codegen


# Cephes expf (S. L. Moshier, "Methods and Programs for Mathematical Functions", 1989): ln 2 in
# two parts for the reduction, and the degree-6 minimax polynomial of e^r on |r| <= ln(2)/2.
_LOG2E = np.float32(1.44269504088896341)
_LN2_HI, _LN2_LO = np.float32(0.693359375), np.float32(-2.12194440e-4)
_EXPF_P = tuple(
    np.float32(c)
    for c in (1.9875691500e-4, 1.3981999507e-3, 8.3334519073e-3, 4.1665795894e-2, 1.6666665459e-1)
)
_EXPF_P5 = np.float32(5.0000001201e-1)
#: Arguments of :func:`expf` are clamped to ± this (e^±87 stays a normal float32).
EXPF_MAX = np.float32(87.0)


@inline_kernel
def expf(x):
    """e^x in float32 for |x| <= :data:`EXPF_MAX` (clamped there), within 2 ulp of the exact
    value, vectorisable (no library call): x = n ln 2 + r, e^r from Cephes' polynomial and 2^n
    from its bits. NaN must be handled by the caller (it gives an undefined value)."""
    one = np.float32(1.0)
    x = min(max(x, -EXPF_MAX), EXPF_MAX)
    z = np.floor(x * _LOG2E + np.float32(0.5))
    r = x - z * _LN2_HI - z * _LN2_LO
    p = _EXPF_P[0]
    for c in _EXPF_P[1:]:
        p = p * r + c
    y = (p * r + _EXPF_P5) * (r * r) + r + one
    return y * _float32_from_bits((np.int32(z) + np.int32(127)) << np.int32(23))  # type: ignore[call-arg]


# e^{-u} of the range kernel: u clamped here (e^-64 ≈ 1.6e-28 counts as 0), halved this many
# times before the polynomial (see exp_neg).
_EXP_U_MAX = np.float32(64.0)
_EXP_SQUARINGS = 5
_EXP_SCALE = np.float32(1.0 / (1 << _EXP_SQUARINGS))
_E2, _E3, _E4, _E5 = (np.float32((-1.0) ** n / math.factorial(n)) for n in (2, 3, 4, 5))


@kernel
def exp_neg(u):
    """e^{−u} for u ≥ 0, vectorisable (no exp call), within 2e-7 absolute (0 for u ≥ 64):
    e^{−u} = (e^{−t})^32 with t = min(u, 64)/32 ∈ [0, 2] and e^{−t} ≈ 1 + q, q the degree-5
    Taylor polynomial less 1; the 5 squarings are done on q, (1 + q)² = 1 + q (q + 2), so that
    weights near 1 keep their relative precision."""
    t = min(u, _EXP_U_MAX) * _EXP_SCALE
    q = ((((_E5 * t + _E4) * t + _E3) * t + _E2) * t - _F1) * t
    for _ in range(_EXP_SQUARINGS):
        q = q * (q + np.float32(2.0))
    return q + _F1


_PI_F = np.float32(math.pi)
_HALF_PI_F = np.float32(math.pi / 2.0)
# atan(t) ≈ t P(t²) on [0, 1]: minimax, error 4e-8 rad (1.3e-7 evaluated in float32)
_AT0 = np.float32(0.9999993356019542)
_AT1 = np.float32(-0.33329860818634105)
_AT2 = np.float32(0.19946565712599593)
_AT3 = np.float32(-0.13908628858035077)
_AT4 = np.float32(0.09642193828012686)
_AT5 = np.float32(-0.05591226181184129)
_AT6 = np.float32(0.021862903744628806)
_AT7 = np.float32(-0.004054550244039307)
# sin(u) ≈ u S(u²), cos(u) ≈ C(u²) on [−π/2, π/2]: minimax, errors 3e-9 and 2e-10
_S0 = np.float32(0.9999999765894195)
_S1 = np.float32(-0.16666647634345014)
_S2 = np.float32(0.008332899818385985)
_S3 = np.float32(-0.00019800897458455147)
_S4 = np.float32(2.5904878875604442e-06)
_C0 = np.float32(0.9999999997806464)
_C1 = np.float32(-0.4999999935846119)
_C2 = np.float32(0.04166663625765576)
_C3 = np.float32(-0.001388836139486635)
_C4 = np.float32(2.4760161070974673e-05)
_C5 = np.float32(-2.6051490159550994e-07)


@kernel
def atan2_upper(y, x):
    """atan2(y, x) ∈ [0, π] for y ≥ 0 (0 at the origin), vectorisable: octant reduction by
    selects and the minimax polynomial of atan on [0, 1]."""
    ax = abs(x)
    big = y > ax
    hi = y if big else ax
    lo = ax if big else y
    hi = hi if hi > _TINY else _TINY
    t = lo / hi
    z = t * t
    p = _AT6 + z * _AT7
    p = _AT5 + z * p
    p = _AT4 + z * p
    p = _AT3 + z * p
    p = _AT2 + z * p
    p = _AT1 + z * p
    p = _AT0 + z * p
    r = t * p
    r = _HALF_PI_F - r if big else r
    return _PI_F - r if x < _F0 else r


@kernel
def sincos_upper(theta):
    """(sin θ, cos θ) for θ ∈ [0, π] (minimax polynomials on [0, π/2], by sin(π − θ) = sin θ,
    cos(π − θ) = −cos θ)."""
    big = theta > _HALF_PI_F
    u = _PI_F - theta if big else theta
    z = u * u
    s = _S3 + z * _S4
    s = _S2 + z * s
    s = _S1 + z * s
    s = _S0 + z * s
    s = u * s
    c = _C4 + z * _C5
    c = _C3 + z * c
    c = _C2 + z * c
    c = _C1 + z * c
    c = _C0 + z * c
    return s, (-c if big else c)


@inline_kernel
def dot3_row(rgb, w0, w1, w2, out):
    """out[j] = (w0, w1, w2) · triple j of the flat interleaved row ``rgb`` (3 · len(out))."""
    for j in range(out.shape[0]):
        out[j] = w0 * rgb[3 * j] + w1 * rgb[3 * j + 1] + w2 * rgb[3 * j + 2]


def finite_quotient(a: np.ndarray, divisor: float) -> np.ndarray:
    """``a / divisor`` (float32, ``divisor`` > 0 rounded to float32) where ``a`` is finite, inf
    elsewhere: ``np.where(np.isfinite(a), a, np.inf) / np.float32(divisor)`` in one compiled
    pass over row strips of the (H, W) plane ``a`` (e.g. pixel sizes, depth / focal length)."""
    src = np.ascontiguousarray(a, np.float32)
    out = np.empty_like(src)
    d = np.float32(divisor)
    flat_in, flat_out = src.reshape(src.shape[0], -1), out.reshape(src.shape[0], -1)
    run_strips(
        src.shape[0],
        lambda r0, r1: _finite_quotient_rows(flat_in[r0:r1], d, flat_out[r0:r1]),
        strip_rows(flat_in.shape[1]),
    )
    return out


@exact_kernel
def _finite_quotient_rows(a, d, out):
    inf = np.float32(np.inf)
    for i in range(out.shape[0]):
        for j in range(out.shape[1]):
            x = a[i, j]
            out[i, j] = (x if abs(x) < inf else inf) / d


def magnitude(*planes: np.ndarray) -> np.ndarray:
    """√(x² + y² [+ z²]) per element of two or three planes of one shape (float32): each square,
    sum and root rounded on its own (as NumPy rounds them), in one compiled pass over row
    strips. Every element gets the same value wherever the arrays lie in memory, which
    ``cv2.magnitude`` does not give: its vectorised loop rounds some elements differently
    depending on the alignment of the array it allocates for the result, so a frame's result
    could change from one run to the next."""
    if len(planes) not in (2, 3):
        raise ValueError(f"magnitude takes two or three planes, got {len(planes)}")
    shapes = [np.shape(a) for a in planes]
    shape = shapes[0]
    if any(other != shape for other in shapes):
        raise ValueError(f"magnitude needs planes of one shape, got {shapes}")
    out = np.empty(shape, np.float32)
    if out.size == 0:
        return out
    lead = shape[0] if len(shape) > 1 else 1  # (rows of the strips; one for 0-d and 1-d)
    ins = [np.ascontiguousarray(a, np.float32).reshape(lead, -1) for a in planes]
    rows = [*ins, out.reshape(lead, -1)]
    z = rows[2] if len(ins) == 3 else rows[0][:0]
    run_strips(
        rows[0].shape[0],
        lambda r0, r1: _magnitude_rows(rows[0][r0:r1], rows[1][r0:r1], z[r0:r1], rows[-1][r0:r1]),
        strip_rows(rows[0].shape[1]),
    )
    return out


@exact_kernel
def _magnitude_rows(x, y, z, out):
    """out = √(x² + y² + z²), z left out where it has no rows."""
    with_z = z.shape[0] > 0
    for i in range(out.shape[0]):
        for j in range(out.shape[1]):
            s = x[i, j] * x[i, j] + y[i, j] * y[i, j]
            if with_z:
                s += z[i, j] * z[i, j]
            out[i, j] = np.sqrt(s)


@kernel
def put_points(stack, ys, xs, vals, i0, i1, origin, width):
    """stack[ch, ys[n] − r0, xs[n] − x0 + c] = vals[n, ch] for the points i0 ≤ n < i1 with
    0 ≤ xs[n] − x0 < ``width``, ``origin`` = (r0, x0, c): values at pixels (ys, xs) of an image
    written into (channels, rows, columns) planes that hold its rows from r0 and its columns
    from x0 at column c (for one plane, ``plane[None]`` and ``vals[:, None]``)."""
    r0, x0, c = origin
    for n in range(i0, i1):
        xx = xs[n] - x0
        if xx >= 0 and xx < width:
            yy = ys[n] - r0
            for ch in range(stack.shape[0]):
                stack[ch, yy, xx + c] = vals[n, ch]


def new_values(after: np.ndarray, before: np.ndarray) -> tuple[int, int]:
    """How many values of ``after`` an operation made negative (below 0 where ``before``, the same
    shape, holds another value), and how many it made NaN or ±inf (where ``before`` is finite):
    one compiled read-only pass on row strips."""
    a, b = _rows_alike(after, before)
    rows = strip_rows(a.shape[1])
    found = np.zeros((-(-a.shape[0] // rows), 2), np.int64)

    def count(r0: int, r1: int) -> None:
        _new_values_rows(a[r0:r1], b[r0:r1], found[r0 // rows])

    run_strips(a.shape[0], count, rows)
    negatives, not_finite = found.sum(axis=0)
    return int(negatives), int(not_finite)


def clip_new_negatives(
    after: np.ndarray, before: np.ndarray, *, in_place: bool = False, counted: bool = False
) -> np.ndarray:
    """``after`` with the values an operation made negative set to 0: those below 0 where
    ``before`` (the same shape) holds another value. What it left as it was, negative or not,
    stays bit for bit, and NaN is left alone. ``after`` itself where nothing is to be clipped
    (:func:`new_values`' pass), else a new float32 array; with ``in_place``, ``after`` itself
    clipped where it is a C-contiguous float32 array. ``counted``: :func:`new_values` has
    found some already (its pass is not made again).

    A result rebuilt as Σ scaled lobes + (beauty − Σ lobes) goes below 0 where that rest is
    (a half-float beauty, a path tracer's noise) and the lobes are scaled towards 0."""
    a = np.ascontiguousarray(after, np.float32)
    if not counted and new_values(a, before)[0] == 0:
        return a
    out = a.copy() if a is after and not in_place else a
    flat_o, flat_b = _rows_alike(out, before)
    run_strips(
        flat_o.shape[0],
        lambda r0, r1: _clip_new_negatives_rows(flat_o[r0:r1], flat_b[r0:r1]),
        strip_rows(flat_o.shape[1]),
    )
    return out


def _rows_alike(after: np.ndarray, before: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Both as C-contiguous float32 rows (H, N) of one shape, else ValueError."""
    a = np.ascontiguousarray(after, np.float32)
    b = np.ascontiguousarray(before, np.float32)
    if a.shape != b.shape:
        raise ValueError(f"after {a.shape} and before {b.shape} must have the same shape")
    if a.size == 0:
        return a.reshape(0, 0), b.reshape(0, 0)
    return a.reshape(a.shape[0], -1), b.reshape(b.shape[0], -1)


@kernel
def _new_values_rows(a, b, out):
    """out[0] += values of rows ``a`` below 0 and unlike ``b``'s; out[1] += values of ``a`` NaN
    or ±inf where ``b``'s is finite."""
    zero = np.float32(0.0)
    big = np.float32(np.finfo(np.float32).max)
    negatives, not_finite = 0, 0
    for i in range(a.shape[0]):
        ra, rb = a[i], b[i]
        for j in range(ra.shape[0]):
            x, y = ra[j], rb[j]
            negatives += (x < zero) & (x != y)
            not_finite += (not abs(x) <= big) & (abs(y) <= big)
    out[0] += negatives
    out[1] += not_finite


@kernel
def _clip_new_negatives_rows(a, b):
    """Rows ``a`` with their values below 0 and unlike ``b``'s set to 0."""
    zero = np.float32(0.0)
    for i in range(a.shape[0]):
        ra, rb = a[i], b[i]
        for j in range(ra.shape[0]):
            if (ra[j] < zero) & (ra[j] != rb[j]):
                ra[j] = zero


def past_and_not_finite(rows: np.ndarray, bound: float) -> tuple[bool, bool]:
    """Whether some value of the float32 plane ``rows`` (H, N) has |x| > ``bound`` (±inf has,
    NaN has not), and whether some is NaN or ±inf: one compiled pass over row strips."""
    step = strip_rows(rows.shape[1])
    found = np.zeros((-(-rows.shape[0] // step), 2), np.bool_)
    most = np.float32(bound)
    run_strips(rows.shape[0], lambda a, b: _past_rows(rows[a:b], most, found[a // step]), step)
    return bool(found[:, 0].any()), bool(found[:, 1].any())


@kernel
def _past_rows(rows, most, out):
    big = np.float32(np.finfo(np.float32).max)
    past, bad = False, False
    for i in range(rows.shape[0]):
        r = rows[i]
        for j in range(r.shape[0]):
            a = abs(r[j])
            past |= a > most
            bad |= not (a <= big)
    out[0], out[1] = past, bad


def fill_triples(out: np.ndarray, value: tuple[float, float, float]) -> None:
    """Every pixel of the float32 (H, W, 3) C-contiguous ``out`` set to ``value``, by a compiled
    pass over row strips (a broadcast assignment of a triple is several times slower)."""
    hgt, wid = out.shape[:2]
    rows = out.reshape(hgt, 3 * wid)
    x, y, z = (np.float32(v) for v in value)
    run_strips(hgt, lambda a, b: _fill_rows(rows[a:b], x, y, z), strip_rows(wid))


@kernel
def _fill_rows(rows, x, y, z):
    for i in range(rows.shape[0]):
        r = rows[i]
        for j in range(r.shape[0] // 3):
            r[3 * j], r[3 * j + 1], r[3 * j + 2] = x, y, z
