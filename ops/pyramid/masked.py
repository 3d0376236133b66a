"""Averages over the covered pixels only (normalised convolution)."""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
from numpy.typing import NDArray

__all__ = ["masked_gaussian", "masked_gaussians"]

F32 = NDArray[np.float32]

#: Share of the Gaussian's weight on covered pixels below which a pixel keeps its value.
_MIN_WEIGHT = 1e-4


def masked_gaussian(values: np.ndarray, mask: np.ndarray, sigma_px: float) -> F32:
    """``G_σ * (values · c) / G_σ * c`` over the covered pixels ``c = mask > 0``: the values
    averaged at ``sigma_px`` pixels without mixing in the background (uncovered pixels keep
    their value; non-finite values count as 0). ``values`` is (H, W, 3) or (H, W);
    ``sigma_px`` ≤ 0 returns them unchanged."""
    return masked_gaussians([values], mask, sigma_px)[0]


def masked_gaussians(values: Sequence[np.ndarray], mask: np.ndarray, sigma_px: float) -> list[F32]:
    """:func:`masked_gaussian` of each of ``values`` over one ``mask``: the coverage's Gaussian
    ``G_σ * c`` (the denominator) is taken once for all of them, bit for bit as one by one."""
    srcs = [np.ascontiguousarray(v, dtype=np.float32) for v in values]
    if sigma_px <= 0.0:
        return srcs
    covered = np.asarray(mask) > 0
    if covered.all():  # G_σ * c is 1 (to rounding): a plain Gaussian
        return [_blurred(src, covered, sigma_px) for src in srcs]
    den = np.asarray(cv2.GaussianBlur(covered.astype(np.float32), (0, 0), sigma_px), np.float32)
    keep = ~covered | (den <= _MIN_WEIGHT)
    np.divide(1.0, den, out=den, where=~keep)  # (1 / G_σ * c where it is used)
    outs = []
    for src in srcs:
        out = _blurred(src, covered, sigma_px, zero_outside=True)
        out *= den[..., None] if src.ndim == 3 else den
        outs.append(np.asarray(cv2.copyTo(src, keep.view(np.uint8), out), np.float32))
    return outs


def _blurred(src: F32, covered: np.ndarray, sigma_px: float, zero_outside: bool = False) -> F32:
    """``G_σ * src`` with non-finite values as 0 (and, with ``zero_outside``, the uncovered
    pixels as 0)."""
    finite = bool(np.isfinite(src.sum(dtype=np.float32)))  # (an overflow: take the long way)
    weighted = src if finite else np.where(np.isfinite(src), src, np.float32(0.0))
    if zero_outside:
        weighted = cv2.copyTo(weighted, covered.view(np.uint8))  # 0 off the covered pixels
    return np.asarray(cv2.GaussianBlur(weighted, (0, 0), sigma_px), np.float32)
