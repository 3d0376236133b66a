"""The compiled-kernel toolbox (ops/jit.py): the vectorisable float32 exp."""

from __future__ import annotations

import numpy as np

from ops.jit import EXPF_MAX, expf, kernel


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
