"""Bilinear upsampling by an integer factor (ops/pyramid/upsample.py) against cv2.resize."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from ops.pyramid.upsample import Upsampled


@pytest.mark.parametrize("factor", [1, 2, 3, 4, 8])
@pytest.mark.parametrize("grid_shape", [(1, 1), (1, 7), (5, 1), (9, 13), (40, 23)])
def test_rows_are_cv2_inter_linear(factor: int, grid_shape: tuple[int, int]) -> None:
    grid = np.random.default_rng(factor).uniform(-1, 1, grid_shape).astype(np.float32)
    size = (grid_shape[0] * factor, grid_shape[1] * factor)
    up = Upsampled(grid, size)
    assert up.factor == factor and up.shape == size
    expect = cv2.resize(grid, size[::-1], interpolation=cv2.INTER_LINEAR)
    np.testing.assert_allclose(np.asarray(up), expect, rtol=0, atol=3e-7)


def test_a_size_that_is_no_multiple_is_interpolated_once_by_cv2() -> None:
    grid = np.random.default_rng(1).random((10, 16), dtype=np.float32)
    for size in [(21, 32), (20, 33), (30, 32)]:  # rounded halves, and unequal factors
        up = Upsampled(grid, size)
        assert up.factor == 1 and up.grid.shape == size
        expect = cv2.resize(grid, size[::-1], interpolation=cv2.INTER_LINEAR)
        np.testing.assert_array_equal(np.asarray(up), expect)


def test_constant_and_zero_grids_stay_exact() -> None:
    """At a power-of-two factor the weights are exact binary fractions summing to 1: a constant
    stays that constant, and 0 (where κ = 0 must give σ = 1 exactly) stays 0."""
    for value in (0.0, 0.3, -1.0):
        up = np.asarray(Upsampled(np.full((6, 9), value, np.float32), (24, 36)))
        assert (up == np.float32(value)).all()


def test_rejects_a_grid_that_is_not_an_image() -> None:
    with pytest.raises(ValueError, match="grid must have shape"):
        Upsampled(np.zeros((2, 3, 3), np.float32), (4, 6))
