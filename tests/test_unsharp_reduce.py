"""The surface pyramid's selective reduction (``ops.unsharp._reduce``) against the chain of
OpenCV and NumPy calls it replaces, written out here: the same numbers, bit for bit, with the
2×2 averages summed in pairs, ((a + b) + (c + d)) / 4, as OpenCV's area resize sums them but
for the last columns of a row that its vector loop leaves (summed in order there: a rounding
apart, checked too)."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
import pytest

from ops.pyramid.reduce import halve
from ops.unsharp._reduce import (
    block_averages,
    block_weights,
    cell_average,
    cell_coverage,
    masked_rows,
    step_flags,
)

_cv: Any = cv2
BIG = 1.0e30
JUMP = 4.0


def _halve(a: np.ndarray) -> np.ndarray:
    """2×2 averages summed in pairs, odd sizes padded with zeros."""
    h, w = a.shape
    p = np.zeros((h + h % 2, w + w % 2), np.float32)
    p[:h, :w] = a
    return ((p[0::2, 0::2] + p[0::2, 1::2]) + (p[1::2, 0::2] + p[1::2, 1::2])) * np.float32(0.25)


def _reference(
    cov: np.ndarray, iz: np.ndarray, grad: tuple[np.ndarray, np.ndarray] | None, k: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each cell's weight, the next coverage and its inverse, as OpenCV and NumPy calls."""
    h, w = cov.shape
    hp, wp = h + h % 2, w + w % 2
    d = float(2**k)
    if grad is not None:
        alt = np.array([0.5 * d, -0.5 * d], np.float32)
        sc = np.ascontiguousarray(np.broadcast_to(np.tile(alt, (w + 1) // 2)[None, :w], (h, w)))
        sr = np.ascontiguousarray(np.broadcast_to(np.tile(alt, (h + 1) // 2)[:h, None], (h, w)))
        p = _cv.add(iz, _cv.multiply(grad[0], sc))
        _cv.add(p, _cv.multiply(grad[1], sr), dst=p)
    else:
        p = iz.copy()
    p[~(cov > 0.0)] = BIG
    if (hp, wp) != (h, w):
        p = _cv.copyMakeBorder(p, 0, hp - h, 0, wp - w, _cv.BORDER_CONSTANT, value=BIG)
    block = np.ones((2, 2), np.uint8)
    near = _cv.erode(p, block, anchor=(0, 0), borderType=_cv.BORDER_REPLICATE)[::2, ::2]
    half = np.float32(0.5 * JUMP * 2**k)
    near = near + np.float32(2.0) * half
    keep = _cv.resize(near, (wp, hp), interpolation=_cv.INTER_NEAREST)[:h, :w]
    np.subtract(keep, p[:h, :w], out=keep)
    np.divide(keep, half, out=keep)
    np.minimum(np.maximum(keep, np.float32(0.0), out=keep), np.float32(1.0), out=keep)
    sel = _cv.multiply(cov, keep)
    cov_next = _halve(sel)
    np.testing.assert_allclose(cov_next, halve(sel), rtol=1e-6, atol=1e-30)  # OpenCV's
    return sel, cov_next, np.divide(np.float32(1.0), _cv.max(cov_next, 1e-12))


def _level(shape: tuple[int, int], seed: int) -> tuple[np.ndarray, np.ndarray, tuple[Any, Any]]:
    """Coverage with empty and partial cells, a guide with steps between surfaces of a few
    cells (and slopes steep enough to straddle _JUMP), and slopes."""
    rng = np.random.default_rng(seed)
    cov = rng.choice(np.array([0.0, 0.25, 0.5, 1.0], np.float32), shape, p=[0.15, 0.1, 0.15, 0.6])
    rows, cols = np.indices(shape, dtype=np.float32)
    iz = (0.7 * cols + 40.0 * (rng.random(shape) < 0.2) + 3.0 * rng.random(shape)).astype(
        np.float32
    )
    iz[rows > shape[0] / 2] += np.float32(25.0)
    gx = rng.normal(0.0, 2.0, shape).astype(np.float32)
    gy = rng.normal(0.0, 2.0, shape).astype(np.float32)
    return cov.astype(np.float32), iz, (gx, gy)


# (401, 2001): several strips of block rows on the pool, an odd last row and column
@pytest.mark.parametrize("shape", [(64, 96), (65, 97), (33, 50), (1, 7), (401, 2001)])
@pytest.mark.parametrize("k", [1, 3])
@pytest.mark.parametrize("slopes", [True, False])
def test_block_weights_and_averages_are_the_opencv_chain(
    shape: tuple[int, int], k: int, slopes: bool
) -> None:
    cov, iz, grad = _level(shape, seed=shape[0] + k)
    g = grad if slopes else None
    sel, cov_next, inv = block_weights(cov, iz, g, k, JUMP, BIG)
    want = _reference(cov, iz, g, k)
    for got, ref in zip((sel, cov_next, inv), want, strict=True):
        assert got.shape == ref.shape and np.array_equal(got, ref)
    assert 0.0 < (sel < cov).mean() < 0.5  # some samples dropped behind a front, most kept
    fields = np.random.default_rng(k).normal(0.0, 1.0, (2, *shape)).astype(np.float32)
    fields[0, 0, 0] = np.float32(1e30)  # large values stay finite products of a weight
    for field, reduced in zip(fields, block_averages(list(fields), sel, inv), strict=True):
        assert np.array_equal(reduced, _cv.multiply(_halve(_cv.multiply(field, sel)), inv))


def _reference_flags(
    cov: np.ndarray, iz: np.ndarray, grad: tuple[np.ndarray, np.ndarray] | None, k: int, thr: float
) -> np.ndarray:
    """The blocks that are not one surface, as OpenCV calls on the replicated level."""
    rep, d = _cv.BORDER_REPLICATE, float(2**k)
    bad = _cv.copyMakeBorder(_cv.compare(cov, 0.0, _cv.CMP_LE), 1, 1, 1, 1, rep)
    bad = _cv.dilate(bad, np.ones((2, 2), np.uint8), anchor=(0, 0), borderType=rep)[:-1, :-1]
    z = _cv.copyMakeBorder(iz, 1, 1, 1, 1, rep)
    if grad is None:
        tl, tr, bl, br = z[:-1, :-1], z[:-1, 1:], z[1:, :-1], z[1:, 1:]
    else:
        gx, gy = (_cv.copyMakeBorder(g, 1, 1, 1, 1, rep) for g in grad)
        right, left = _cv.scaleAdd(gx, 0.5 * d, z), _cv.scaleAdd(gx, -0.5 * d, z)
        tl = _cv.scaleAdd(gy[:-1, :-1], 0.5 * d, right[:-1, :-1])
        tr = _cv.scaleAdd(gy[:-1, 1:], 0.5 * d, left[:-1, 1:])
        bl = _cv.scaleAdd(gy[1:, :-1], -0.5 * d, right[1:, :-1])
        br = _cv.scaleAdd(gy[1:, 1:], -0.5 * d, left[1:, 1:])
    hi = _cv.max(_cv.max(tl, tr), _cv.max(bl, br))
    lo = _cv.min(_cv.min(tl, tr), _cv.min(bl, br))
    step = _cv.compare(_cv.subtract(hi, lo), thr, _cv.CMP_GT)
    return np.minimum(_cv.bitwise_or(bad, step), 1)


@pytest.mark.parametrize("shape", [(64, 96), (65, 97), (1, 7), (5, 1)])
@pytest.mark.parametrize("k", [1, 3])
@pytest.mark.parametrize("slopes", [True, False])
def test_step_flags_are_the_opencv_chain(shape: tuple[int, int], k: int, slopes: bool) -> None:
    cov, iz, grad = _level(shape, seed=2 * shape[1] + k)
    g = grad if slopes else None
    thr = float(np.float32(2.0 * JUMP))
    got = step_flags(cov, iz, g, k, thr)
    want = _reference_flags(cov, iz, g, k, thr)
    assert got.shape == (shape[0] + 1, shape[1] + 1) and np.array_equal(got, want)
    if shape[0] > 8:
        assert got.min() == 0 and got.max() == 1  # one-surface blocks, and steps or holes


@pytest.mark.parametrize("shape", [(64, 96), (65, 97), (7, 1), (1, 5)])
def test_first_level_cells_are_the_opencv_chain(shape: tuple[int, int]) -> None:
    # the first level's coverage and averages of full-resolution rows: OpenCV's area halving
    # of the rows with 0 off the surface (squared for the variance), times the inverse coverage
    rng = np.random.default_rng(shape[1])
    valid = (rng.random(shape) > 0.3).astype(np.uint8)
    src = rng.normal(0.0, 1.0, shape).astype(np.float32)
    cells = ((shape[0] + 1) // 2, (shape[1] + 1) // 2)
    cov, inv = np.empty(cells, np.float32), np.empty(cells, np.float32)
    cell_coverage(valid, cov, inv)
    assert np.array_equal(cov, halve(valid.astype(np.float32)))
    assert np.array_equal(inv, np.divide(np.float32(1.0), _cv.max(cov, 1e-12)))
    masked = _cv.copyTo(src, valid)
    cases: list[tuple[np.ndarray | None, bool, np.ndarray]] = [
        (valid, False, _cv.multiply(halve(masked), inv)),
        (valid, True, _cv.multiply(halve(_cv.multiply(masked, masked)), inv)),
        (None, False, _cv.multiply(halve(src), inv)),
    ]
    for mask, square, want in cases:
        out = np.empty(cells, np.float32)
        cell_average(src, mask, inv, out, square=square)
        assert np.array_equal(out, want)
    wide = np.stack([src, src, src], axis=-1)
    rows = np.empty(shape, np.float32)
    masked_rows(wide[..., 0], valid, 1.0, rows)  # a view with a stride: copied first
    assert np.array_equal(rows, np.where(valid > 0, src, np.float32(1.0)))
