"""The scaling function σ of Radiance Scaling (Vergne et al., TVCG 2011, §4, Eq. 2).

:func:`scaling_function` is Eq. 2 as the paper prints it (with κ' = −κ, below), in float64
NumPy; :func:`sigma` evaluates the same function in float32 without cancellation (the form the
operators use); the renderer-lobe kernel (:mod:`ops.radiance_scaling._kernels`) fuses that form
into one pass over the lobes. The tests compare all three.

Sign of κ. Eq. 2 is printed with ``e^{γκ}``. Evaluated with κ > 0 on convexities (the convention
the paper states for κ, and Depict's), that would *darken* intensities above α on convex features,
the opposite of the paper's own text ("For convex features, reflected lighting intensities above
α are brightened and those below α are darkened") and of the authors' shaders (MeshLab's Radiance
Scaling plugin evaluates it with ``exp(-β)`` / ``exp(gamma*(-k))`` of a convex-positive κ). The
printed sign goes with the paper's ``H = ∇(-(n_x, n_y)/n_z)``, negative on bumps in a camera
space whose +z points at the viewer. Depict keeps κ > 0 on convexities (``ops.curvature``) and
evaluates Eq. 2 with ``e^{-γκ}``, so convexities brighten what is above α, as the text says.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import ArrayLike

from ops.checks import ALPHA, GAMMA
from ops.radiance_scaling._common import _MAX_EXP

__all__ = ["scaling_function", "sigma"]


def _clip01(x: np.ndarray) -> np.ndarray:
    """Clip to [0, 1] in place (+inf -> 1, NaN -> 0)."""
    cv2.patchNaNs(x, 0.0)
    np.clip(x, np.float32(0.0), np.float32(1.0), out=x)
    return x


def _exp_term(kappa: np.ndarray, gamma: float) -> np.ndarray:
    """e^{-γκ} for κ clipped to [-1, 1] (float32, 2-D; NaN κ counts as 0)."""
    arg = np.multiply(kappa, np.float32(-gamma), dtype=np.float32)
    cv2.patchNaNs(arg, 0.0)
    lim = np.float32(min(gamma, _MAX_EXP))
    np.clip(arg, -lim, lim, out=arg)
    return np.asarray(cv2.exp(arg, dst=arg), np.float32)


def _sigma_from(
    expk: np.ndarray,
    delta: np.ndarray,
    alpha: float,
    *,
    scratch: np.ndarray | None = None,
    consume: bool = False,
    out: np.ndarray | None = None,
) -> np.ndarray:
    """Eq. 2 from E = e^{-γκ} and δ in [0, 1] (both (H, W) float32), in the cancellation-free
    form σ = (P·E + Q) / (P + Q·E), P = α(1 - δ), Q = (1 - α)δ.

    ``scratch`` is an optional buffer like ``delta``; with ``consume`` ``delta`` is overwritten;
    ``out`` receives σ.
    (NumPy for the scalar operations: cv2 is slower with Python scalars.)
    """
    # Coefficients rounded to float32 each way, so that swapping α and 1 - α swaps them exactly
    # and, at δ = α, α(1 - δ) and (1 - α)δ round alike (σ = 1).
    p = np.subtract(np.float32(1.0), delta, out=scratch, dtype=np.float32)
    np.multiply(p, np.float32(alpha), out=p)
    q = np.multiply(delta, np.float32(1.0 - alpha), out=delta if consume else None)
    num = cv2.multiply(p, expk, dst=out)
    cv2.add(num, q, dst=num)
    cv2.accumulateProduct(q, expk, p)  # p <- P + Q·E (the denominator)
    return np.asarray(cv2.divide(num, p, dst=num), np.float32)


def _as_2d(x: np.ndarray) -> np.ndarray:
    if x.ndim == 2:
        return np.ascontiguousarray(x)
    return np.ascontiguousarray(x).reshape(1, -1) if x.size else x.reshape(1, 0)


def sigma(kappa: ArrayLike, delta: ArrayLike, alpha: float, gamma: float) -> np.ndarray:
    """Scaling function σ_{α,γ}(κ, δ) of Radiance Scaling (TVCG 2011, §4, Eq. 2)::

        σ_{α,γ}(κ, δ) = (α e^{γκ'} + δ(1 − α(1 + e^{γκ'}))) / (α + δ(e^{γκ'} − α(1 + e^{γκ'})))

    with κ' = −κ (κ > 0 on convexities, see the module docstring), evaluated as
    ``(P·E + Q) / (P + Q·E)`` with E = e^{−γκ}, P = α(1 − δ), Q = (1 − α)δ (the same function,
    without cancellation). Properties: σ = 1 where κ = 0 or δ = α; σ(κ, δ)·σ(−κ, δ) = 1;
    σ_α(κ, 1 − δ) = 1 / σ_{1−α}(κ, δ); monotonic in δ (increasing for κ > 0: on convexities δ > α
    is brightened, δ < α darkened; decreasing for κ < 0); σ(κ, 0) = e^{−γκ}, σ(κ, 1) = e^{γκ};
    γ = 0 gives σ ≡ 1.

    Parameters
    ----------
    kappa : array or float
        Mapped curvature, clipped to [-1, 1].
    delta : array or float
        Reflectance mapping δ, clipped to [0, 1] (NaN counts as 0).
    alpha : float
        Scaling-invariant point α in (0, 1).
    gamma : float
        Scaling magnitude γ in [0, 1e4] (γκ is clipped to ±80).

    Returns
    -------
    float32 array of the broadcast shape of ``kappa`` and ``delta``.
    """
    a = ALPHA.check(alpha, "alpha")
    g = GAMMA.check(gamma, "gamma")
    k, d = np.broadcast_arrays(np.asarray(kappa, np.float32), np.asarray(delta, np.float32))
    shape = k.shape
    k2 = _as_2d(k)
    d2 = _clip01(_as_2d(d).copy())
    out = _sigma_from(_exp_term(k2, g), d2, a)
    return out.reshape(shape)


def scaling_function(kappa: ArrayLike, delta: ArrayLike, alpha: float, gamma: float) -> np.ndarray:
    """Eq. 2 of Radiance Scaling as printed, with κ' = −κ (module docstring)::

        σ_{α,γ}(κ, δ) = (α e^{γκ'} + δ(1 − α(1 + e^{γκ'}))) / (α + δ(e^{γκ'} − α(1 + e^{γκ'})))

    in float64, for κ in [−1, 1], δ in [0, 1], α in (0, 1), γ ≥ 0. :func:`sigma` is the
    same function in float32.

    >>> float(scaling_function(0.0, 0.3, 0.5, 3.0))  # flat: unchanged
    1.0
    >>> float(scaling_function(0.7, 0.5, 0.5, 3.0))  # δ = α: unchanged at any curvature
    1.0
    >>> round(float(scaling_function(1.0, 0.9, 0.5, 1.0)), 4)  # convex, bright: brightened
    2.1731
    >>> round(float(scaling_function(1.0, 0.1, 0.5, 1.0)), 4)  # convex, dark: darkened
    0.4602
    """
    e = np.exp(np.float64(gamma) * -np.asarray(kappa, np.float64))  # e^{γκ'}
    d = np.asarray(delta, np.float64)
    a = ALPHA.check(alpha, "alpha")
    GAMMA.check(gamma, "gamma")
    return (a * e + d * (1.0 - a * (1.0 + e))) / (a + d * (e - a * (1.0 + e)))
