"""Averages over the covered pixels only (normalised convolution)."""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

__all__ = ["masked_gaussian"]

F32 = NDArray[np.float32]


def masked_gaussian(values: np.ndarray, mask: np.ndarray, sigma_px: float) -> F32:
    """``G_σ * (values · c) / G_σ * c`` over the covered pixels ``c = mask > 0``: the values
    averaged at ``sigma_px`` pixels without mixing in the background (uncovered pixels keep
    their value; non-finite values count as 0). ``values`` is (H, W, 3) or (H, W);
    ``sigma_px`` ≤ 0 returns them unchanged."""
    src = np.ascontiguousarray(values, dtype=np.float32)
    if sigma_px <= 0.0:
        return src
    cov = (np.asarray(mask) > 0).astype(np.float32)
    weighted = src * (cov[..., None] if src.ndim == 3 else cov)
    np.nan_to_num(weighted, copy=False, nan=0.0, posinf=0.0, neginf=0.0)
    num = np.asarray(cv2.GaussianBlur(weighted, (0, 0), sigma_px), np.float32)
    den = np.asarray(cv2.GaussianBlur(cov, (0, 0), sigma_px), np.float32)
    inv = np.divide(1.0, den, out=np.zeros_like(den), where=den > 1e-4)
    out = num * (inv[..., None] if src.ndim == 3 else inv)
    keep = (cov == 0) | (den <= 1e-4)
    if src.ndim == 3:
        keep = keep[..., None]
    return np.where(keep, src, out).astype(np.float32, copy=False)
