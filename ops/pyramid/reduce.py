"""Reductions of a frame's planes: 2×2 and 2^k box averages, and a Gaussian of any width through
them (the building blocks the curvature, the surface pyramid of unsharp masking and its
baselines share)."""

from __future__ import annotations

import math
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

__all__ = ["box_downsample", "gaussian_blur", "halve"]

F32 = NDArray[np.float32]
_cv: Any = cv2  # OpenCV's stubs reject scalar operands (cv2.max(a, 0.0))


def box_downsample(img: np.ndarray, level: int, size: tuple[int, int]) -> np.ndarray:
    """Box average over 2^level x 2^level blocks (``size`` = (w, h) of the result).

    For exact halvings, bilinear resizing by 1/2 samples the middle of each 2x2 block, which is
    their average (and faster than INTER_AREA); other sizes use INTER_AREA.
    """
    h, w = img.shape[:2]
    k = 2**level
    if h % k or w % k:
        return cv2.resize(img, size, interpolation=cv2.INTER_AREA)
    for _ in range(level):
        h, w = h // 2, w // 2
        img = cv2.resize(img, (w, h), interpolation=cv2.INTER_LINEAR)
    return img


def halve(a: F32) -> F32:
    """2×2 area average (pads odd sizes with zeros: coverage-weighted fields stay exact).

    Multi-channel arrays go through INTER_LINEAR, which at a scale of exactly 1/2 samples the
    midpoint of each 2×2 block with weights ½, ½: the same average, 3× faster than OpenCV's
    INTER_AREA on three channels (one channel: INTER_AREA is the faster).
    """
    h, w = a.shape[:2]
    if h % 2 or w % 2:
        a = _cv.copyMakeBorder(a, 0, h % 2, 0, w % 2, _cv.BORDER_CONSTANT, value=0.0)
    interp = _cv.INTER_AREA if a.ndim == 2 else _cv.INTER_LINEAR
    return _cv.resize(a, (a.shape[1] // 2, a.shape[0] // 2), interpolation=interp)


def gaussian_blur(img: F32, sigma_px: float) -> F32:
    """Gaussian blur of ``img`` with σ = ``sigma_px`` (replicated border), float32.

    Wide blurs go through a pyramid: the image is area-downsampled by 2^m so that σ is at least
    2 pixels there, blurred with the remaining σ' = √(σ² − σ_box²) / 2^m, and upsampled
    bilinearly (the result is band-limited, so the interpolation error is far below the
    enhancement). Cost stays ≈ a few copies at any σ.
    """
    if sigma_px <= 0.0:
        return img.copy()
    h, w = img.shape[:2]
    m = 0
    while sigma_px / 2 ** (m + 1) >= 2.0 and min(h, w) // 2 ** (m + 1) >= 8:
        m += 1
    if m == 0:
        return _cv.GaussianBlur(img, (0, 0), sigma_px, borderType=_cv.BORDER_REPLICATE)
    f = 2**m
    hs, ws = -(-h // f), -(-w // f)
    pad = img
    if hs * f != h or ws * f != w:
        pad = _cv.copyMakeBorder(img, 0, hs * f - h, 0, ws * f - w, _cv.BORDER_REPLICATE)
    small = _cv.resize(pad, (ws, hs), interpolation=_cv.INTER_AREA)
    # the box of the area average has variance (f² − 1)/12 image pixels², the bilinear
    # upsampling about f²/6 more; take both out of the Gaussian applied at the small scale
    rest = max(sigma_px**2 - (f * f - 1) / 12.0 - f * f / 6.0, (0.5 * f) ** 2)
    small = _cv.GaussianBlur(small, (0, 0), math.sqrt(rest) / f, borderType=_cv.BORDER_REPLICATE)
    big = _cv.resize(small, (ws * f, hs * f), interpolation=_cv.INTER_LINEAR)
    return big if big.shape[:2] == (h, w) else np.ascontiguousarray(big[:h, :w])
