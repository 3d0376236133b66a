"""The result of :func:`ops.curvature.principal_curvatures`: per-pixel principal curvatures,
direction and reliability, held on the working grid and upsampled lazily."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from ops.curvature import _common
from ops.jit import inline_kernel, kernel
from ops.parallel import run_strips
from ops.pyramid.upsample import Upsampled

#: cv2 for calls with Python scalars or None where its stubs only list arrays (Scalar arguments,
#: default kernels); same module, untyped.
_cv: Any = cv2

__all__ = ["Curvature"]


@dataclass(init=False)
class Curvature:
    """Principal view-centred curvatures (RS §4) per unit of image height.

    Attributes
    ----------
    k1, k2 : (H, W) float32
        Principal curvatures, k1 >= k2, > 0 on convexities; per unit image height.
    dir_x, dir_y : (H, W) float32
        Unit direction of k1 in camera x (right) / y (up); defined up to sign (dir_y >= 0).
    weight : (H, W) float32
        Reliability in [0, 1]: 0 on background and near depth discontinuities, 1 inside.

    Notes
    -----
    :func:`principal_curvatures` may compute on a coarser working grid; the full-resolution
    fields are then interpolated on first access (k1, k2, weight bilinearly; the direction from
    the bilinearly interpolated doubled-angle vector) and cached, so consumers that only need
    :func:`isotropic` never pay for them. Constructing ``Curvature(k1, k2, dir_x, dir_y, weight)``
    directly works as for any dataclass.
    """

    k1: np.ndarray
    k2: np.ndarray
    dir_x: np.ndarray
    dir_y: np.ndarray
    weight: np.ndarray

    def __init__(
        self,
        k1: np.ndarray,
        k2: np.ndarray,
        dir_x: np.ndarray,
        dir_y: np.ndarray,
        weight: np.ndarray,
    ) -> None:
        self.k1, self.k2, self.dir_x, self.dir_y, self.weight = k1, k2, dir_x, dir_y, weight

    @classmethod
    def _lazy(cls, coarse: _Coarse) -> Curvature:
        obj = cls.__new__(cls)
        obj.__dict__["_coarse"] = coarse
        return obj

    def __getattr__(self, name: str) -> np.ndarray:
        # Only reached for attributes not yet set: the lazily interpolated fields.
        coarse = self.__dict__.get("_coarse")
        if coarse is None or name not in _FIELDS:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        if name in ("dir_x", "dir_y"):
            self.dir_x, self.dir_y = coarse.directions()
        else:
            setattr(self, name, coarse.upsample(getattr(coarse, name)))
        value: np.ndarray = self.__dict__[name]
        return value

    def view(self) -> Curvature:
        """This curvature for another reader: the same working-grid data with nothing
        interpolated yet. A reader that interpolates a field (and may edit it) makes the
        readers after it take the full-resolution path, which rounds differently: a result kept
        between runs (:mod:`service.memo`) hands each run a view, so that each reads the same
        numbers whatever ran before. One constructed at full resolution is its own."""
        coarse: _Coarse | None = self.__dict__.get("_coarse")
        return self if coarse is None else Curvature._lazy(coarse)

    def _coarse_for(self, *names: str) -> _Coarse | None:
        """The working-grid data, if none of ``names`` was materialised (and so maybe edited)."""
        coarse: _Coarse | None = self.__dict__.get("_coarse")
        if coarse is None or any(n in self.__dict__ for n in names):
            return None
        return coarse


_FIELDS = ("k1", "k2", "dir_x", "dir_y", "weight")


@dataclass
class _Coarse:
    """Working-grid results and the full size (H, W) they are interpolated to.

    The symmetrised Hessian H = ∇q = [[a, b], [b, c]] is kept as its trace a + c (all
    :func:`isotropic` needs), d = (a - c)/2 and b, as
    :func:`ops.curvature._hessian._trace_rows` computes them; the principal curvatures
    κ1,2 = trace/2 ± sqrt(d² + b²) are derived on first access.
    """

    trace: np.ndarray
    d: np.ndarray
    b: np.ndarray
    weight: np.ndarray
    size: tuple[int, int]

    @functools.cached_property
    def _principal(self) -> tuple[np.ndarray, np.ndarray]:
        """(κ1, κ2) in one compiled pass (:func:`_principal_rows`)."""
        k1, k2 = np.empty_like(self.trace), np.empty_like(self.trace)
        args = (self.trace, self.d, self.b, k1, k2)
        run_strips(
            k1.shape[0],
            lambda r0, r1: _principal_rows(*(a[r0:r1] for a in args)),
            _common._STRIP_ROWS,
        )
        return k1, k2

    @property
    def k1(self) -> np.ndarray:
        return self._principal[0]

    @property
    def k2(self) -> np.ndarray:
        return self._principal[1]

    def upsample(self, img: np.ndarray) -> np.ndarray:
        return np.asarray(Upsampled(img, self.size))

    def directions(self) -> tuple[np.ndarray, np.ndarray]:
        """Direction of k1 from the interpolated (d, b): θ = ½·atan2(b, d) in [0, π), so that
        dir_y >= 0 (:func:`_half_angle_rows`)."""
        d, b = self.upsample(self.d), self.upsample(self.b)
        dx, dy = np.empty_like(d), np.empty_like(d)
        run_strips(
            d.shape[0],
            lambda r0, r1: _half_angle_rows(d[r0:r1], b[r0:r1], dx[r0:r1], dy[r0:r1]),
            _common._STRIP_ROWS,
        )
        return dx, dy


@kernel
def _principal_rows(trace, d, b, k1, k2):  # type: ignore[no-untyped-def]
    """κ1 = trace/2 + r and κ2 = κ1 − 2r, r = sqrt(d² + b²), on rows."""
    half, two = np.float32(0.5), np.float32(2.0)
    for i in range(k1.shape[0]):
        for j in range(k1.shape[1]):
            r = np.sqrt(d[i, j] * d[i, j] + b[i, j] * b[i, j])
            k1[i, j] = trace[i, j] * half + r
            k2[i, j] = k1[i, j] - two * r


@kernel
def _half_angle_rows(d, b, dx, dy):  # type: ignore[no-untyped-def]
    """Rows of :func:`half_angle_row`."""
    for i in range(d.shape[0]):
        half_angle_row(d[i], b[i], dx[i], dy[i])


@inline_kernel
def half_angle_row(dr, br, xr, yr):  # type: ignore[no-untyped-def]
    """(cos θ, sin θ) of θ = ½·atan2(b, d) taken in [0, π), on a row, without trigonometry:
    with c = cos 2θ = d / r and s = sin 2θ = b / r (r = |(d, b)|; c = 1 where r = 0), the larger
    of cos θ, sin θ from the half-angle formula (√((1 ± c)/2)) and the other from
    s = 2 sin θ cos θ, which keeps both accurate; θ < 0 is turned by π (the direction of a
    line)."""
    zero, one, half = np.float32(0.0), np.float32(1.0), np.float32(0.5)
    for j in range(dr.shape[0]):
        r = np.sqrt(dr[j] * dr[j] + br[j] * br[j])
        inv = one / r if r > zero else zero
        c = dr[j] * inv if r > zero else one
        s = br[j] * inv
        big = np.sqrt(max((one + abs(c)) * half, half))  # cos θ (c >= 0) or sin θ (c < 0)
        small = abs(s) / (big + big)
        neg = s < zero
        xr[j] = (-big if neg else big) if c >= zero else (-small if neg else small)
        yr[j] = small if c >= zero else big
