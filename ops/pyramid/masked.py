"""Averages over the covered pixels only (normalised convolution)."""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

__all__ = ["masked_gaussian"]

F32 = NDArray[np.float32]

#: Share of the Gaussian's weight on covered pixels below which a pixel keeps its value.
_MIN_WEIGHT = 1e-4


def masked_gaussian(values: np.ndarray, mask: np.ndarray, sigma_px: float) -> F32:
    """``G_σ * (values · c) / G_σ * c`` over the covered pixels ``c = mask > 0``: the values
    averaged at ``sigma_px`` pixels without mixing in the background (uncovered pixels keep
    their value; non-finite values count as 0). ``values`` is (H, W, 3) or (H, W);
    ``sigma_px`` ≤ 0 returns them unchanged."""
    src = np.ascontiguousarray(values, dtype=np.float32)
    if sigma_px <= 0.0:
        return src
    covered = np.asarray(mask) > 0
    finite = bool(np.isfinite(src.sum(dtype=np.float32)))  # (an overflow: take the long way)
    weighted = src if finite else np.where(np.isfinite(src), src, np.float32(0.0))
    if covered.all():  # G_σ * c is 1 (to rounding): a plain Gaussian
        return np.asarray(cv2.GaussianBlur(weighted, (0, 0), sigma_px), np.float32)
    cov = covered.astype(np.float32)
    weighted = cv2.copyTo(weighted, covered.view(np.uint8))  # 0 off the covered pixels
    out = np.asarray(cv2.GaussianBlur(weighted, (0, 0), sigma_px), np.float32)
    den = np.asarray(cv2.GaussianBlur(cov, (0, 0), sigma_px), np.float32)
    keep = ~covered | (den <= _MIN_WEIGHT)
    np.divide(1.0, den, out=den, where=~keep)
    out *= den[..., None] if src.ndim == 3 else den
    return np.asarray(cv2.copyTo(src, keep.view(np.uint8), out), np.float32)
