"""Averages over the covered pixels only (normalised convolution)."""

from __future__ import annotations

import functools
from collections.abc import Sequence

import cv2
import numpy as np
from numpy.typing import NDArray

from ops.color import row_strips
from ops.jit import kernel

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
    ``G_σ * c`` (the denominator) is taken once for all of them, bit for bit as one by one.

    Around each Gaussian (OpenCV's) one compiled pass on row strips: before it, the values
    with 0 off the covered pixels and where not finite; after it, the division by ``G_σ * c``
    and the values kept where too little of the Gaussian's weight is covered."""
    srcs = [np.ascontiguousarray(v, dtype=np.float32) for v in values]
    if sigma_px <= 0.0:
        return srcs
    m = np.ascontiguousarray(mask)
    if m.dtype == np.bool_:
        m = m.view(np.uint8)
    h, w = int(m.shape[0]), int(m.shape[1])
    cov = np.empty((h, w), np.uint8)  # 0/1: covered
    row_strips(h, w, lambda r: _covered_rows(m[r], cov[r]))
    if cv2.countNonZero(cov) == cov.size:  # G_σ * c is 1 (to rounding): a plain Gaussian
        return [_blur(_weighted(src, None), sigma_px) for src in srcs]
    den = _blur(cov.astype(np.float32), sigma_px)
    keep = np.empty((h, w), np.uint8)  # 1: the value kept (uncovered, or too little weight)
    least = np.float32(_MIN_WEIGHT)
    row_strips(h, w, lambda r: _inverse_rows(cov[r], den[r], least, keep[r]))
    outs = []
    for src in srcs:
        out = _blur(_weighted(src, cov), sigma_px)
        c = 1 if src.ndim == 2 else src.shape[2]
        flat = (src.shape[0], src.shape[1] * c)
        o, v = out.reshape(flat), src.reshape(flat)
        row_strips(h, w, functools.partial(_divide, o, v, den, keep, c))
        outs.append(out)
    return outs


def _weighted(src: F32, cov: np.ndarray | None) -> F32:
    """``src`` with 0 where it is not finite and (``cov`` given) off the covered pixels; ``src``
    itself when nothing changes."""
    c = 1 if src.ndim == 2 else src.shape[2]
    flat = src.reshape(src.shape[0], src.shape[1] * c)
    # all finite and nothing masked: ``src`` itself (a sum that overflows takes the long way)
    if cov is None and bool(np.isfinite(src.sum(dtype=np.float32))):
        return src
    out = np.empty_like(src)
    dst = out.reshape(flat.shape)
    none = np.zeros((0, 0), np.uint8)
    row_strips(
        src.shape[0],
        src.shape[1],
        lambda r: _weighted_rows(flat[r], none if cov is None else cov[r], c, dst[r]),
    )
    return out


def _divide(out: F32, src: F32, inv: F32, keep: np.ndarray, c: int, r: slice) -> None:
    _divide_rows(out[r], src[r], inv[r], keep[r], c)


def _blur(src: F32, sigma_px: float) -> F32:
    return np.asarray(cv2.GaussianBlur(src, (0, 0), sigma_px), np.float32)


@kernel
def _covered_rows(mask, out):  # type: ignore[no-untyped-def]
    """out = 1 where ``mask`` > 0 (bool masks as their bytes), else 0."""
    for i in range(out.shape[0]):
        for j in range(out.shape[1]):
            out[i, j] = mask[i, j] > 0


@kernel
def _inverse_rows(cov, den, least, keep):  # type: ignore[no-untyped-def]
    """keep = uncovered or ``den`` ≤ ``least``; elsewhere ``den`` becomes 1 / ``den``."""
    one = np.float32(1.0)
    for i in range(den.shape[0]):
        for j in range(den.shape[1]):
            d = den[i, j]
            k = (cov[i, j] == 0) | (d <= least)
            keep[i, j] = k
            den[i, j] = d if k else one / d


@kernel
def _weighted_rows(src, cov, c, out):  # type: ignore[no-untyped-def]
    """out = ``src`` where finite (and, with ``cov`` rows, covered), else 0; ``c`` channels
    (one: a loop over the pixels alone, which vectorises)."""
    zero = np.float32(0.0)
    big = np.float32(np.inf)
    masked = cov.shape[0] > 0
    for i in range(out.shape[0]):
        s, o = src[i], out[i]
        if not masked:
            for j in range(o.shape[0]):
                o[j] = s[j] if abs(s[j]) < big else zero
        elif c == 1:
            m = cov[i]
            for j in range(o.shape[0]):
                o[j] = s[j] if (abs(s[j]) < big) & (m[j] != 0) else zero
        else:
            m = cov[i]
            for j in range(o.shape[0]):
                o[j] = s[j] if (abs(s[j]) < big) & (m[j // c] != 0) else zero


@kernel
def _divide_rows(out, src, inv, keep, c):  # type: ignore[no-untyped-def]
    """out = ``src`` where ``keep``, else ``out`` · ``inv`` (1 / G_σ * c); ``c`` channels
    (one: a loop over the pixels alone, which vectorises)."""
    for i in range(out.shape[0]):
        o, s, q, kp = out[i], src[i], inv[i], keep[i]
        if c == 1:
            for j in range(o.shape[0]):
                o[j] = s[j] if kp[j] else o[j] * q[j]
        else:
            for j in range(o.shape[0]):
                p = j // c
                o[j] = s[j] if kp[p] else o[j] * q[p]
