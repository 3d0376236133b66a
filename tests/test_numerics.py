"""The shared kernel numerics (ops/numerics.py): each polynomial within its stated error of
NumPy's float64 function over its whole domain; the compiled passes bit for bit as NumPy."""

from __future__ import annotations

import numpy as np
import pytest

from ops.jit import kernel
from ops.numerics import (
    EXPF_MAX,
    atan2_upper,
    clip_new_negatives,
    dot3_row,
    exp_neg,
    expf,
    finite_quotient,
    magnitude,
    new_values,
    sincos_upper,
)


@kernel
def _exp_all(x, out):  # type: ignore[no-untyped-def]
    for j in range(x.shape[0]):
        out[j] = expf(x[j])


def _ulps(got: np.ndarray, x: np.ndarray) -> np.ndarray:
    exact = np.exp(x.astype(np.float64))
    return np.abs(got - exact) / np.spacing(exact.astype(np.float32))


def test_expf_is_within_two_ulp_over_its_range() -> None:
    x = np.concatenate(
        [
            np.linspace(-EXPF_MAX, EXPF_MAX, 1_000_001, dtype=np.float32),
            np.linspace(-1.0, 1.0, 200_001, dtype=np.float32),
            np.float32([1e-7, -1e-7, 1e-30, -1e-30]),
        ]
    )
    got = np.empty_like(x)
    _exp_all(x, got)
    assert _ulps(got, x).max() <= 2.0


def test_expf_is_exact_at_zero_and_clamps_outside_its_range() -> None:
    x = np.float32([0.0, -0.0, 100.0, np.inf, -100.0, -np.inf])
    got = np.empty_like(x)
    _exp_all(x, got)
    assert got[0] == 1.0 and got[1] == 1.0
    top = np.float32(np.exp(np.float64(EXPF_MAX)))
    bottom = np.float32(np.exp(-np.float64(EXPF_MAX)))
    np.testing.assert_allclose(got[2:4], top, rtol=3e-7)
    np.testing.assert_allclose(got[4:], bottom, rtol=3e-7)
    assert np.isfinite(got).all()


@kernel
def _apply_exp_neg(u, out):  # type: ignore[no-untyped-def]
    for j in range(u.shape[0]):
        out[j] = exp_neg(u[j])


@kernel
def _apply_atan2(y, x, out):  # type: ignore[no-untyped-def]
    for j in range(y.shape[0]):
        out[j] = atan2_upper(y[j], x[j])


@kernel
def _apply_sincos(theta, s, c):  # type: ignore[no-untyped-def]
    for j in range(theta.shape[0]):
        s[j], c[j] = sincos_upper(theta[j])


def test_exp_neg_is_within_2e7_and_zero_far_out() -> None:
    u = np.concatenate([np.linspace(0.0, 70.0, 700_001, dtype=np.float32), np.float32([1e9])])
    got = np.empty_like(u)
    _apply_exp_neg(u, got)
    assert np.abs(got - np.exp(-u.astype(np.float64))).max() <= 2e-7
    assert got[0] == 1.0 and got[-1] < 1e-27


def test_atan2_upper_is_within_4e7_rad_on_the_upper_half_plane() -> None:
    rng = np.random.default_rng(1)
    y = np.abs(rng.normal(size=200_000)).astype(np.float32)
    x = rng.normal(size=200_000).astype(np.float32)
    y[:3], x[:3] = 0.0, np.float32([1.0, -1.0, 0.0])  # the axis both ways and the origin
    got = np.empty_like(y)
    _apply_atan2(y, x, got)
    exact = np.arctan2(y.astype(np.float64), x.astype(np.float64))
    assert np.abs(got - exact).max() <= 4e-7  # 1.5 float32 ulp at π
    assert got[0] == 0.0 and abs(got[1] - np.pi) < 1e-6 and got[2] == 0.0


def test_sincos_upper_is_within_2e7_on_zero_to_pi() -> None:
    theta = np.linspace(0.0, np.pi, 400_001, dtype=np.float32)
    s, c = np.empty_like(theta), np.empty_like(theta)
    _apply_sincos(theta, s, c)
    t64 = theta.astype(np.float64)
    assert np.abs(s - np.sin(t64)).max() <= 2e-7
    assert np.abs(c - np.cos(t64)).max() <= 2e-7


def test_dot3_row_weighs_interleaved_triples() -> None:
    rgb = np.arange(12, dtype=np.float32)
    out = np.empty(4, np.float32)
    dot3_row(rgb, np.float32(1.0), np.float32(10.0), np.float32(100.0), out)
    np.testing.assert_array_equal(out, [210.0, 543.0, 876.0, 1209.0])


@pytest.mark.parametrize("shape", [(1, 1), (37, 53), (300, 7)])
def test_finite_quotient_is_numpys_where_and_division(shape: tuple[int, int]) -> None:
    rng = np.random.default_rng(3)
    a = (rng.random(shape) * 50.0).astype(np.float32)
    a.ravel()[::5] = np.inf
    a.ravel()[1::7] = -np.inf
    a.ravel()[2::11] = np.nan
    a.ravel()[3::13] = 0.0
    for divisor in (1.0, 1234.5678, 3e-3):
        want = np.where(np.isfinite(a), a, np.inf) / np.float32(divisor)
        got = finite_quotient(a, divisor)
        assert got.dtype == np.float32 and np.array_equal(got, want)
    view = a[:, ::2]  # a view with a row stride is read as it is
    assert np.array_equal(
        finite_quotient(view, 7.0), np.where(np.isfinite(view), view, np.inf) / np.float32(7.0)
    )


def _at_offset(a: np.ndarray, floats: int) -> np.ndarray:
    """A copy of ``a`` starting ``floats`` float32 after a 64-byte boundary."""
    buf = np.empty(a.size + 32, np.float32)
    start = (-buf.ctypes.data % 64) // 4 + floats
    out = buf[start : start + a.size].reshape(a.shape)
    out[...] = a
    return out


@pytest.mark.parametrize("shape", [(270, 480), (7, 5), (3,)])
def test_magnitude_is_numpys_squares_sum_and_root_wherever_the_planes_lie(
    shape: tuple[int, ...],
) -> None:
    rng = np.random.default_rng(4)
    x, y, z = (rng.standard_normal(shape).astype(np.float32) * 1e-3 for _ in range(3))
    two, three = np.sqrt(x * x + y * y), np.sqrt(x * x + y * y + z * z)
    for floats in range(16):  # every alignment of the inputs (and so of the work) in a cache line
        xs, ys, zs = (_at_offset(a, floats) for a in (x, y, z))
        got2, got3 = magnitude(xs, ys), magnitude(xs, ys, zs)
        assert got2.dtype == np.float32 and got2.shape == shape
        np.testing.assert_array_equal(got2, two)
        np.testing.assert_array_equal(got3, three)


def test_magnitude_refuses_planes_that_do_not_match() -> None:
    with pytest.raises(ValueError, match="one shape"):
        magnitude(np.zeros((2, 3), np.float32), np.zeros((3, 2), np.float32))
    with pytest.raises(ValueError, match="two or three"):
        magnitude(np.zeros((2, 3), np.float32))


@pytest.mark.parametrize("shape", [(), (0,), (0, 4), (4, 0), (3, 0, 2)])
def test_magnitude_keeps_empty_and_scalar_shapes(shape: tuple[int, ...]) -> None:
    x, y = np.full(shape, 3.0, np.float32), np.full(shape, 4.0, np.float32)
    got = magnitude(x, y)
    assert got.shape == shape and got.dtype == np.float32
    np.testing.assert_array_equal(got, np.full(shape, 5.0, np.float32))


@pytest.mark.parametrize("shape", [(37, 53, 3), (300, 700), (1, 1, 3)])
def test_clip_new_negatives_is_the_where_of_numpy(shape: tuple[int, ...]) -> None:
    """0 where the result is below 0 and not what it was, the rest bit for bit (negative values
    left as they were, NaN, -inf made by the operation alike: -inf is clipped, NaN is not)."""
    rng = np.random.default_rng(5)
    before = rng.normal(size=shape).astype(np.float32)
    after = before + rng.normal(scale=0.5, size=shape).astype(np.float32)
    after.flat[::7] = before.flat[::7]  # left as they were, some of them negative
    after.flat[3::11] = np.nan
    after.flat[5::13] = -np.inf
    want = np.where((after < 0) & (after != before), np.float32(0.0), after)
    kept = after.copy()
    got = clip_new_negatives(after, before)
    np.testing.assert_array_equal(got, want)
    np.testing.assert_array_equal(after, kept)  # a new array: the operation's own is not changed
    assert got is not after and got.dtype == np.float32
    clean = np.abs(after)
    assert clip_new_negatives(clean, before) is clean  # nothing to clip: the same array
    assert clip_new_negatives(after, before, in_place=True) is after  # clipped where it is
    np.testing.assert_array_equal(after, want)


@pytest.mark.parametrize("shape", [(37, 53, 3), (300, 700), (1, 1, 3), (0, 4)])
def test_new_values_counts_as_numpy_does(shape: tuple[int, ...]) -> None:
    """Values made negative (below 0, not what they were), and values made NaN or ±inf where
    they were finite (NaN, inf or -inf left as they were do not count)."""
    rng = np.random.default_rng(6)
    before = rng.normal(size=shape).astype(np.float32)
    before.flat[1::17] = np.inf
    after = before + rng.normal(scale=0.5, size=shape).astype(np.float32)
    after.flat[::7] = before.flat[::7]
    after.flat[3::11] = np.nan
    after.flat[5::13] = -np.inf
    negatives = np.count_nonzero((after < 0) & (after != before))
    not_finite = np.count_nonzero(~np.isfinite(after) & np.isfinite(before))
    assert new_values(after, before) == (negatives, not_finite)
    assert after.size < 100 or not_finite > 0


def test_clip_new_negatives_refuses_arrays_that_do_not_match() -> None:
    with pytest.raises(ValueError, match="same shape"):
        clip_new_negatives(np.zeros((4, 5, 3), np.float32), np.zeros((4, 5), np.float32))
