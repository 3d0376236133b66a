"""The allowed range of every operator parameter, in one place.

The ops validate their arguments with these ranges (:meth:`Range.check`) and the service's
parameter models take their bounds from the same objects (``Field(1.0, **GAMMA.bounds)``), so a
value the HTTP schema or the command line accepts is one the maths accepts, and the other way
round. Ranges are closed unless marked open; every value must be finite.

>>> GAMMA.check(3.0, "gamma")
3.0
>>> str(ALPHA), ALPHA.bounds
('(0, 1)', {'gt': 0.0, 'lt': 1.0})
>>> LLA_GAMMA.check(60, "gamma")
Traceback (most recent call last):
...
ValueError: gamma=60 is outside the allowed range [0, 20]
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import SupportsFloat, TypedDict

__all__ = [
    "ALPHA",
    "AMBIENT",
    "ANISOTROPY",
    "CONTRAST",
    "CURVATURE_DEPTH_JUMP",
    "CURVATURE_GAIN",
    "CURVATURE_SCALE",
    "CURVEDNESS_NORM",
    "DEPTH_JUMP",
    "ES_SCALE",
    "EXPONENT",
    "FACTOR",
    "FINE_SCALE",
    "FRACTION",
    "GAMMA",
    "GRADIENT_SCALE",
    "INTEGRATION_SCALE",
    "IOR",
    "LIGHTING_SCALE",
    "LLA_BASE",
    "LLA_DEPTH_SIGMA",
    "LLA_GAMMA",
    "LLA_SIGMA",
    "PERCENTILE",
    "POSITIVE",
    "RATIO_FLOOR",
    "RATIO_MAX",
    "RELATIVE_SIGMA",
    "ROUGHNESS",
    "SCALES",
    "SHADING_NORM",
    "SHININESS",
    "TOON_LEVELS",
    "UNSHARP_AMOUNT",
    "UNSHARP_SIGMA",
    "WEIGHT",
    "WEIGHT_EXPONENT",
    "WHITE",
    "Bounds",
    "Range",
    "check_sequence",
    "holds_truth_value",
]


class Bounds(TypedDict, total=False):
    """Keyword bounds of a pydantic ``Field``."""

    ge: float
    gt: float
    le: float
    lt: float


@dataclass(frozen=True)
class Range:
    """A finite interval of allowed values: [lo, hi], ends open when marked so."""

    lo: float = -math.inf
    hi: float = math.inf
    lo_open: bool = False
    hi_open: bool = False

    def __str__(self) -> str:
        left = "(" if self.lo_open or math.isinf(self.lo) else "["
        right = ")" if self.hi_open or math.isinf(self.hi) else "]"
        return f"{left}{self.lo:g}, {self.hi:g}{right}"

    def __contains__(self, value: float) -> bool:
        v = float(value)
        above = v > self.lo if self.lo_open else v >= self.lo
        below = v < self.hi if self.hi_open else v <= self.hi
        return math.isfinite(v) and above and below

    def check(self, value: object, name: str) -> float:
        """``value`` as a float, or a ``ValueError`` naming ``name`` and the range."""
        try:
            if not isinstance(value, SupportsFloat):  # str, None, a list...
                raise TypeError
            v = float(value)
        except (TypeError, ValueError):  # also an array of more than one value
            raise ValueError(f"{name} must be a number, got {value!r}") from None
        if v not in self:
            raise ValueError(f"{name}={value!r} is outside the allowed range {self}")
        return v

    @property
    def bounds(self) -> Bounds:
        """The bounds as pydantic ``Field`` keywords (``ge``/``gt``, ``le``/``lt``)."""
        out = Bounds()
        if math.isfinite(self.lo):
            if self.lo_open:
                out["gt"] = self.lo
            else:
                out["ge"] = self.lo
        if math.isfinite(self.hi):
            if self.hi_open:
                out["lt"] = self.hi
            else:
                out["le"] = self.hi
        return out


def check_sequence(values: Sequence[float], rng: Range, name: str) -> list[float]:
    """Each value checked against ``rng`` (a bad one is named ``name``)."""
    return [rng.check(v, f"{name} values") for v in values]


#: The largest finite float32 and its smallest normal number (``numpy.finfo(numpy.float32)``'s
#: ``max`` and ``tiny``): numbers the operators and the EXR headers hold as float32.
FLOAT32_MAX = 3.4028234663852886e38
FLOAT32_TINY = 1.1754943508222875e-38

#: A fraction of something, end points included (f0, thresholds, foreshortening, ζ...).
FRACTION = Range(0.0, 1.0)
#: A percentile of a distribution.
PERCENTILE = Range(0.0, 100.0, lo_open=True)
#: A size or level that only has to be positive (scene units, pixels).
POSITIVE = Range(0.0, math.inf, lo_open=True)
#: A linear white level (the radiance mapped to 1): within float32's reach both ways (1e-45
#: overflowed its reciprocal; radiance past 1e18 is a hole, :mod:`gbuffer.holes`).
WHITE = Range(1e-30, 1e18)

# -- Radiance Scaling (Vergne et al. 2010) ----------------------------------------------------
#: α of Eq. 2: the scaling-invariant point, strictly inside (0, 1).
ALPHA = Range(0.0, 1.0, lo_open=True, hi_open=True)
#: γ of Eq. 2: the scaling magnitude (γκ saturates at ±80, so large values are safe).
GAMMA = Range(0.0, 10000.0)
#: λ of the anisotropic curvature mapping κ(ℓ) (§4).
ANISOTROPY = Range(-1.0, 1.0)
#: Bands of toon shading (§5.1).
TOON_LEVELS = Range(2, 64)

# -- curvature ----------------------------------------------------------------------------------
#: σ of the curvature's derivatives, relative to the image height (0: the finest differences).
CURVATURE_SCALE = Range(0.0, 0.1)
#: s of κ = tanh(s·(κ1 + κ2)): κ is per unit image height.
CURVATURE_GAIN = Range(0.0, 100.0, lo_open=True)
#: Relative depth jump |Δ log d| between samples of different surfaces.
CURVATURE_DEPTH_JUMP = Range(0.0, 10.0, lo_open=True)
#: L_norm of Apparent Relief's curvedness (per unit image height; below 1e-6 every curvature
#: saturates, and under float32's smallest normal numbers S became NaN).
CURVEDNESS_NORM = Range(1e-6, 1e6)

# -- Light Alignment (Vergne et al. 2009) ---------------------------------------------------------
#: γ of W_γ (Eq. 1).
LLA_GAMMA = Range(0.0, 20.0)
#: σ_i, how much of each scale transition is aligned (§5).
LLA_SIGMA = Range(0.0, 1.0)
#: Number of normal fields (scales) of the pyramid.
SCALES = Range(2, 12)
#: Finest spatial σ, relative to the image height.
LLA_BASE = Range(0.0, 1.0, lo_open=True)
#: Spatial σ growth per scale.
FACTOR = Range(1.0, 4.0)
#: Depth gap (log-depth, in σ) above which the filtering does not mix surfaces: from 1e-4, a
#: relative depth step of 0.01 % (0.5 / σ² past float32 below 1e-19 made every pixel NaN).
LLA_DEPTH_SIGMA = Range(1e-4, 10.0)

# -- shading -------------------------------------------------------------------------------------
#: Index of refraction.
IOR = Range(0.0, 10.0, lo_open=True)
#: Blinn-Phong / Phong exponent.
SHININESS = Range(0.0, 10000.0, lo_open=True)
#: Ashikhmin-Shirley and transmission lobe exponents.
EXPONENT = Range(0.0, 100000.0, lo_open=True)
#: GGX roughness.
ROUGHNESS = Range(0.0, 1.0, lo_open=True)
#: Ambient term of a shading (× AO when present).
AMBIENT = Range(0.0, 10.0)
#: A reflectance or light weight: albedo, k_s, the weight of a lobe.
WEIGHT = Range(0.0, 10.0)
#: ε of the ratio relighting (aligned + ε) / (original + ε), relative to the irradiance.
RATIO_FLOOR = Range(0.0, 10.0, lo_open=True)
#: The largest factor of the ratio relighting.
RATIO_MAX = Range(1.0, 1000.0)
#: σ of the low-frequency lighting an operator keeps, relative to the image height.
LIGHTING_SCALE = Range(0.0, 0.5, lo_open=True)

# -- 3D unsharp masking (Ritschel et al. 2008) ----------------------------------------------------
#: λ of Eq. 1 (negative: blur).
UNSHARP_AMOUNT = Range(-10.0, 10.0)
#: Depth and normal σ of the bilateral smoothing (in σ of the spatial kernel).
UNSHARP_SIGMA = Range(0.0, 100.0, lo_open=True)
#: σ of the smooth signal, relative to the image height (auto σ, depth unsharp masking).
RELATIVE_SIGMA = Range(0.0, 1.0, lo_open=True)
#: σ of the lightness the contrast is taken from, relative to the image height (0: the pixel).
FINE_SCALE = Range(0.0, 0.1)

# -- baselines ------------------------------------------------------------------------------------
#: Exaggerated Shading's smoothing σ of each scale, relative to the image height.
ES_SCALE = Range(0.0, 0.5, lo_open=True)
#: Exaggerated Shading's contrast a of clamp(a n·ℓ).
CONTRAST = Range(0.0, 100.0, lo_open=True)
#: Exaggerated Shading's k_i ∝ σ_i^exponent.
WEIGHT_EXPONENT = Range(-4.0, 4.0)

# -- congruence ------------------------------------------------------------------------------------
#: Gradient and integration scales, relative to the image height.
GRADIENT_SCALE = Range(0.0, 0.1, lo_open=True)
INTEGRATION_SCALE = Range(0.0, 0.25, lo_open=True)
#: Largest log-depth step still one surface.
DEPTH_JUMP = Range(0.0, 100.0, lo_open=True)
#: Shading strength mapped to 1.
SHADING_NORM = POSITIVE


def holds_truth_value(value: object) -> bool:
    """Whether ``value`` is a bool or a list or tuple holding one (where numbers are expected,
    Python and pydantic read true and false as 1 and 0)."""
    if isinstance(value, bool):
        return True
    return isinstance(value, list | tuple) and any(holds_truth_value(v) for v in value)
