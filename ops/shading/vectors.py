"""Vector helpers on per-pixel fields: dot products, normalisation, reflection and refraction."""

from __future__ import annotations

import cv2
import numpy as np

from ops.checks import IOR

__all__ = ["Vec3", "dot", "normalize", "reflect", "refract"]

Vec3 = tuple[float, float, float]
_EPS = np.float32(1e-12)
_ONES = np.ones((1, 3), np.float32)


# -- vector helpers ---------------------------------------------------------------------------


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per-pixel dot product of two (H, W, 3) fields, or of a field and a (3,) vector -> (H, W).

    Uses ``cv2.transform`` (a 3-channel reduction), ≈10x faster than ``(a * b).sum(axis=2)``.
    If both are (3,) vectors the result is a 0-d array.
    """
    a = np.asarray(a, np.float32)
    b = np.asarray(b, np.float32)
    if a.ndim == 1:
        a, b = b, a
    if a.ndim == 1:
        return np.asarray(np.dot(a, b), np.float32)
    a = np.ascontiguousarray(a)
    if b.ndim == 1:
        out = cv2.transform(a, b.reshape(1, 3))
    else:
        out = cv2.transform(cv2.multiply(a, np.ascontiguousarray(b, np.float32)), _ONES)
    return np.asarray(out, np.float32).reshape(a.shape[:2])


def normalize(v: np.ndarray) -> np.ndarray:
    """Unit vectors along ``v`` (..., 3); zero vectors give (0, 0, 0)."""
    v = np.asarray(v, np.float32)
    if v.ndim == 1:
        norm = float(np.linalg.norm(v))
        return (v / norm).astype(np.float32) if norm > 1e-12 else np.zeros(3, np.float32)
    len2 = dot(v, v)
    inv = np.zeros_like(len2)
    np.divide(1.0, np.sqrt(len2), out=inv, where=len2 > 1e-24)
    return np.asarray(v * inv[..., None], np.float32)


def _field(v: np.ndarray, like: np.ndarray) -> np.ndarray:
    """``v`` as an (H, W, 3) float32 field shaped like ``like`` (broadcasting a (3,) vector)."""
    v = np.asarray(v, np.float32)
    if v.ndim == 1:
        return np.broadcast_to(v, (*like.shape[:2], 3))
    return v


def reflect(v: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Mirror ``v`` about ``n``: r = 2(n·v)n − v (both pointing away from the surface).

    ``reflect(l, n)`` is the mirror direction of the light (Phong); ``reflect(v, n)`` the
    reflected view direction (environment lookups, Radiance Scaling §5.4).
    """
    n = np.asarray(n, np.float32)
    v = _field(v, n)
    return np.asarray(2.0 * dot(n, v)[..., None] * n - v, np.float32)


def refract(v: np.ndarray, n: np.ndarray, ior: float) -> np.ndarray:
    """Refracted direction of the view ray entering a medium of index ``ior`` (Snell's law).

    ``v`` points from the surface towards the eye; the eye ray travels along −v and continues
    into the surface along t = η(−v) + (η cosθ_i − √k) n with η = 1/ior, cosθ_i = n·v,
    k = 1 − η²(1 − cos²θ_i). Total internal reflection (k < 0, possible when ior < 1) gives 0.
    """
    IOR.check(ior, "ior")
    n = np.asarray(n, np.float32)
    v = _field(v, n)
    eta = np.float32(1.0 / ior)
    cos_i = dot(n, v)
    k = 1.0 - eta * eta * (1.0 - cos_i * cos_i)
    root = np.sqrt(np.maximum(k, 0.0))
    t = -eta * v + (eta * cos_i - root)[..., None] * n
    t[k < 0.0] = 0.0
    return np.asarray(t, np.float32)


def _pos_pow(x: np.ndarray, p: float) -> np.ndarray:
    """max(x, 0) ** p with cv2.pow (≈10x faster than np.power on float32)."""
    x = np.maximum(x, np.float32(0.0))
    return np.asarray(cv2.pow(x, float(p)), np.float32).reshape(x.shape)


def _dots(
    n: np.ndarray,
    l: np.ndarray,  # noqa: E741
    v: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(n·l, n·v, l·v): every lobe below is a function of these three scalar fields."""
    n = np.asarray(n, np.float32)
    nl = dot(n, l)
    nv = dot(n, v)
    lv = dot(l, v)
    if lv.ndim == 0:
        lv = np.full(nl.shape, lv, np.float32)
    return nl, nv, lv


def _half_cosines(nl: np.ndarray, nv: np.ndarray, lv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n·h, v·h) for h = (l + v)/|l + v|: n·h = (n·l + n·v)/|l + v|, v·h = |l + v|/2.

    |l + v| = √(2 + 2 l·v); where l = −v (no half vector) both are 0.
    """
    length = np.sqrt(np.maximum(2.0 + 2.0 * lv, 0.0))
    inv = np.zeros_like(length)
    np.divide(1.0, length, out=inv, where=length > 1e-6)
    return np.asarray((nl + nv) * inv, np.float32), np.asarray(0.5 * length, np.float32)


def _outer(s: np.ndarray, rgb: np.ndarray) -> np.ndarray:
    """(H, W) × (3,) -> (H, W, 3) by cv2.merge of scaled planes (≈5x faster than broadcasting)."""
    s = np.asarray(s, np.float32)
    planes = [s * np.float32(c) for c in np.asarray(rgb, np.float32)]
    return np.asarray(cv2.merge(planes), np.float32).reshape((*s.shape, 3))


def _dot_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """:func:`dot` (the same rounding) of (h, w, 3) fields that may be row-strided views, or
    of a field and a (3,) vector, without copying them."""
    if a.ndim == 1:
        a, b = b, a
    if a.ndim == 1:
        return np.asarray(np.dot(a, b), np.float32)
    if b.ndim == 1:
        out = cv2.transform(a, b.reshape(1, 3))
    else:
        out = cv2.transform(cv2.multiply(a, b), _ONES)
    return np.asarray(out, np.float32).reshape(a.shape[:2])
