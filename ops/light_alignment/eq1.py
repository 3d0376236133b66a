"""Eq. 1 of Local Light Alignment (Mestres et al., EG 2021, §4) as the paper writes it, in NumPy.

For one scale i with the fine field a = a_i and the base field z = a_{i+1} (unit vectors)::

    x = normalize(a − z (a·z)),   y = x × z
    g = a                      if ℓ̄·x ≥ 0   (the lit side)
        R(y, −π/2) a           otherwise    (the tangent (z − (a·z) a) / |ā|)
    ℓ' = R(ℓ × g, θ) ℓ,   θ = σ W_γ(λ1 λ2) ∠(ℓ, g)
    W_γ(λ) = λ / (e^{−γ}(1 − λ) + λ),   λ1 = 1 − 2∠(ℓ̄, ḡ)/π,   λ2 = |ā|

(ℓ̄, ḡ, ā: projections on the (x, y) plane). :func:`align_scale` is this for the diffuse guide
(g from the normals); :func:`ops.light_alignment.align_light` runs it scale by scale, fused
into one compiled pass per strip row (:mod:`ops.light_alignment._kernels`), and the tests
compare the two.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from ops.checks import LLA_GAMMA
from ops.filtering import F32
from ops.light_alignment._common import DEFAULT_GAMMA

__all__ = ["align_scale", "rotate_towards", "w_gamma"]


def w_gamma(lam: np.ndarray | float, gamma: float = DEFAULT_GAMMA) -> np.ndarray:
    """Confidence weighting W_γ(λ) = λ / (e^{−γ}(1 − λ) + λ) (Mestres et al. 2021, §4).

    Maps [0, 1] onto [0, 1] monotonically with W(0) = 0 and W(1) = 1; W_0 is the identity and a
    larger γ narrows the transition between the bright and the dark side of features.

    Parameters
    ----------
    lam : confidence λ = λ1 λ2 in [0, 1] (array or scalar; clipped to [0, 1]).
    gamma : γ in :data:`ops.checks.LLA_GAMMA` (the paper uses 3).
    """
    gamma = LLA_GAMMA.check(gamma, "gamma")
    lam_a = np.clip(np.asarray(lam, np.float32), 0.0, 1.0)
    e = np.float32(math.exp(-gamma))
    return np.asarray(lam_a / (e + lam_a * (np.float32(1.0) - e)), np.float32)


def rotate_towards(light: ArrayLike, guide: ArrayLike, theta: ArrayLike) -> F32:
    """R(ℓ × g, θ) ℓ of Eq. 1: the unit vector ℓ turned by θ towards g, in their plane.

    Rodrigues' formula with the unit axis u = (ℓ × g)/|ℓ × g| (u ⊥ ℓ, so its last term
    vanishes): R(u, θ) ℓ = ℓ cos θ + (u × ℓ) sin θ. Where ℓ ∥ g there is no plane and ℓ is
    returned. Arrays broadcast over leading axes; the last one is (x, y, z).

    >>> rotate_towards([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], np.pi / 2).astype(float).round(6).tolist()
    [0.0, 1.0, 0.0]
    >>> rotate_towards([1.0, 0.0, 0.0], [0.0, 0.0, 1.0], np.pi / 6).astype(float).round(6).tolist()
    [0.866025, 0.0, 0.5]
    """
    ell = np.asarray(light, np.float64)
    axis = np.cross(ell, np.asarray(guide, np.float64))
    size = np.linalg.norm(axis, axis=-1, keepdims=True)
    u = np.divide(axis, size, out=np.zeros_like(axis), where=size > 0)
    t = np.asarray(theta, np.float64)[..., None]
    return (ell * np.cos(t) + np.cross(u, ell) * np.sin(t)).astype(np.float32)


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.sum(a * b, axis=-1, keepdims=True)


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """∠(a, b) of unit vectors, (..., 1)."""
    return np.arccos(np.clip(_dot(a, b), -1.0, 1.0))


def align_scale(
    light: ArrayLike,
    fine: ArrayLike,
    base: ArrayLike,
    sigma: float,
    gamma: float = DEFAULT_GAMMA,
) -> F32:
    """One scale of Eq. 1 with the diffuse guide: ℓ' = R(ℓ × g, σ W_γ(λ1 λ2) ∠(ℓ, g)) ℓ.

    ``fine`` is a_i and ``base`` a_{i+1} (unit normals, (..., 3)); ``light`` ℓ (unit, towards
    the light). Written as the paper writes it (module docstring), in float64.

    A ridge's side facing away from the light turns its light towards the tangent: with the
    base normal z, a fine normal tilted to +x and the light from −x, the light is rotated
    towards the fine normal's tangent (z − (a·z) a)/|ā|, away from +x:

    >>> a = np.array([np.sin(0.5), 0.0, np.cos(0.5)])
    >>> out = align_scale([-0.6, 0.0, 0.8], a, [0.0, 0.0, 1.0], sigma=1.0, gamma=0.0)
    >>> bool(out[0] < -0.6), round(float(np.linalg.norm(out)), 6)
    (True, 1.0)
    """
    ell = np.asarray(light, np.float64)
    a = np.asarray(fine, np.float64)
    z = np.asarray(base, np.float64)
    a_bar = a - z * _dot(a, z)  # a's projection on the (x, y) plane
    lam2 = np.linalg.norm(a_bar, axis=-1, keepdims=True)  # λ2 = |ā|
    x = np.divide(a_bar, lam2, out=np.zeros_like(a_bar), where=lam2 > 0)
    y = np.cross(x, z)
    lx, ly = _dot(ell, x), _dot(ell, y)
    tangent = np.divide(z - a * _dot(a, z), lam2, out=np.zeros_like(a), where=lam2 > 0)
    g = np.where(lx > 0, a, tangent)  # ℓ̄·x = 0: λ1 = 0, θ = 0 either way
    lam1 = (2.0 / np.pi) * np.arctan2(np.abs(lx), np.abs(ly))  # 1 − 2∠(ℓ̄, ḡ)/π, ḡ = ±x
    weight = w_gamma(lam1 * lam2, gamma).astype(np.float64)
    theta = sigma * weight * _angle(ell, g)
    return rotate_towards(ell, g, theta[..., 0])
