"""Lights (directional and point), their text syntax, and their directions and irradiance on
fields of positions."""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from ops.shading.vectors import Vec3, _outer, dot, normalize

__all__ = [
    "LIGHT_SYNTAX",
    "Light",
    "light_irradiance",
    "light_vectors",
    "need_positions",
    "parse_light",
]


#: The largest magnitude of a light's numbers: shading is float32, and a colour times an
#: intensity, or a point light's squared distance, must stay finite there (1e308 gave NaN).
LIGHT_MAX = 1e15


def _vec3(value: Sequence[float] | np.ndarray, name: str) -> Vec3:
    arr = np.asarray(value, dtype=np.float64).reshape(-1)
    if arr.shape != (3,) or not np.all(np.abs(arr) <= LIGHT_MAX):
        raise ValueError(
            f"{name} must be 3 finite numbers of magnitude at most {LIGHT_MAX:g}, got {value!r}"
        )
    return (float(arr[0]), float(arr[1]), float(arr[2]))


@dataclass(frozen=True)
class Light:
    """A light in camera space.

    Attributes
    ----------
    kind : "directional" or "point"
    vector : direction **towards** the light (directional; normalised on construction) or the
        light's position (point), camera space.
    color : linear RGB, each >= 0.
    intensity : >= 0. A directional light gives irradiance ``color * intensity``; a point light
        ``color * intensity / d²`` at distance d (inverse-square falloff).
    """

    kind: Literal["directional", "point"]
    vector: Vec3
    color: Vec3 = (1.0, 1.0, 1.0)
    intensity: float = 1.0

    def __post_init__(self) -> None:
        if self.kind not in ("directional", "point"):
            raise ValueError(f"light kind must be 'directional' or 'point', got {self.kind!r}")
        vec = _vec3(self.vector, "light vector")
        if self.kind == "directional":
            norm = math.sqrt(sum(c * c for c in vec))
            if norm < 1e-12:
                raise ValueError("light vector of a directional light must not be (0, 0, 0)")
            vec = (vec[0] / norm, vec[1] / norm, vec[2] / norm)
        object.__setattr__(self, "vector", vec)
        color = _vec3(self.color, "light color")
        if min(color) < 0.0:
            raise ValueError(f"light color must be >= 0 in each channel, got {color}")
        object.__setattr__(self, "color", color)
        if not 0.0 <= self.intensity <= LIGHT_MAX:
            raise ValueError(
                f"light intensity must be finite, >= 0 and at most {LIGHT_MAX:g}, "
                f"got {self.intensity}"
            )
        object.__setattr__(self, "intensity", float(self.intensity))


_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_TRIPLE = rf"\s*({_NUM})\s*,\s*({_NUM})\s*,\s*({_NUM})\s*"
_LIGHT_RE = re.compile(
    rf"^\s*(?:(dir|directional|point)\s*:)?{_TRIPLE}(?:@{_TRIPLE})?(?:\*\s*({_NUM}))?\s*$",
    re.IGNORECASE,
)
LIGHT_SYNTAX = "[dir:|point:]X,Y,Z[@R,G,B][*INTENSITY]"


def parse_light(text: str) -> Light:
    """Parse a light from a CLI string ``[dir:|point:]X,Y,Z[@R,G,B][*INTENSITY]``.

    ``X,Y,Z`` is the direction towards the light (``dir:``, the default) or the light position
    (``point:``), camera space. ``@R,G,B`` sets the linear colour, ``*I`` the intensity.
    Examples: ``"-1,1,1"``, ``"dir:0,0,1*0.5"``, ``"point:0,2,1@1,0.9,0.8*4"``.

    Raises
    ------
    ValueError
        When the text does not follow the syntax, or the values are out of range.
    """
    match = _LIGHT_RE.match(text) if isinstance(text, str) else None
    if match is None:
        raise ValueError(
            f"light {text!r} is not of the form {LIGHT_SYNTAX} "
            "(e.g. '-1,1,1', 'point:0,2,1@1,0.9,0.8*4')"
        )
    groups = match.groups()
    kind: Literal["directional", "point"] = (
        "point" if (groups[0] or "").lower() == "point" else "directional"
    )
    vector = (float(groups[1]), float(groups[2]), float(groups[3]))
    color = (1.0, 1.0, 1.0)
    if groups[4] is not None:
        color = (float(groups[4]), float(groups[5]), float(groups[6]))
    intensity = 1.0 if groups[7] is None else float(groups[7])
    try:
        return Light(kind=kind, vector=vector, color=color, intensity=intensity)
    except ValueError as exc:
        raise ValueError(f"light {text!r}: {exc}") from None


# -- lights on fields -------------------------------------------------------------------------


def need_positions(position: np.ndarray | None) -> np.ndarray:
    """``position`` (H, W, 3) as float32, for point lights: ValueError when it is None."""
    if position is None:
        raise ValueError("point lights need the surface positions (position is None)")
    return np.asarray(position, np.float32)


def light_direction(light: Light, position: np.ndarray | None) -> np.ndarray:
    """The direction towards ``light``: a directional light's (3,) vector, a point light's
    (H, W, 3) field from ``position`` (:func:`light_vectors`; ValueError without positions)."""
    if light.kind == "directional":
        return np.asarray(light.vector, np.float32)
    return light_vectors(light, need_positions(position))


def light_vectors(light: Light, position: np.ndarray) -> np.ndarray:
    """(H, W, 3) unit directions from each surface point towards ``light`` (camera space)."""
    position = np.asarray(position, np.float32)
    if light.kind == "directional":
        out = np.empty((*position.shape[:2], 3), np.float32)
        out[...] = light.vector
        return out
    return normalize(np.asarray(light.vector, np.float32) - position)


def light_irradiance(light: Light, position: np.ndarray) -> np.ndarray:
    """Irradiance ``color * intensity`` of ``light`` at each point, broadcastable to (H, W, 3).

    A directional light gives a (3,) vector; a point light (H, W, 3) with inverse-square falloff
    ``color * intensity / d²`` (d clamped at 1e-6).
    """
    rgb = np.asarray(light.color, np.float32) * np.float32(light.intensity)
    if light.kind == "directional":
        return rgb
    offset = np.asarray(light.vector, np.float32) - np.asarray(position, np.float32)
    d2 = np.maximum(dot(offset, offset), np.float32(1e-12))
    return _outer(1.0 / d2, rgb)
