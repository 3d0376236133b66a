"""The congruence score and its per-pixel maps (computed at the analysis level, upsampled on
first access)."""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import cv2
import numpy as np

from ops.congruence._common import F32
from ops.congruence._flow import _half_angle

__all__ = ["CongruenceResult"]


@dataclass
class CongruenceResult:
    """Result of :func:`congruence`.

    ``score`` is computed eagerly; the per-pixel maps are upsampled to the input resolution on
    first access (and cached), so a sweep that only needs scores does not pay for them. All maps
    are 0 outside the scored pixels (background, silhouette borders, depth discontinuities).

    Attributes
    ----------
    score : float
        Eq. 2, in [0, 1]; 0 when there is no shape flow at all.
    score_map : (H, W) float32
        Per-pixel score (1 − ⌊e_shape − e_shading⌋) |v_shape · v_shading| in [0, 1].
    shading_flow, shape_flow : (H, W, 2) float32
        Dominant eigenvectors (x right, y up: camera convention), unit length, sign arbitrary
        (an orientation); (0, 0) where the flow is undefined.
    shading_strength, shape_strength : (H, W) float32
        Normalised mean eigenvalues in [0, 1].
    weight : (H, W) float32
        Fraction of each pixel that is scored (1 inside, 0 on background).
    analysis_shape : (h, w)
        Resolution at which the score was evaluated.
    shading_norm : float
        The shading strength that was mapped to 1 (the ``shading_norm`` argument, or this
        image's percentile): pass it to score other renderings of the same frame on this scale.
    """

    score: float
    analysis_shape: tuple[int, int]
    shading_norm: float
    _out_shape: tuple[int, int] = field(repr=False)
    _low: dict[str, F32] = field(repr=False)

    def _up(self, arr: F32) -> F32:
        h, w = self._out_shape
        if arr.shape[:2] == (h, w):
            return arr
        return np.asarray(cv2.resize(arr, (w, h), interpolation=cv2.INTER_LINEAR), np.float32)

    @functools.cached_property
    def _maps(self) -> dict[str, F32]:
        low = self._low
        weight = self._up(low["weight"])
        insidef = (weight > 0.5).astype(np.float32)
        out: dict[str, F32] = {
            "weight": np.asarray(cv2.threshold(weight, 1e-3, 0, cv2.THRESH_TOZERO)[1], np.float32)
        }
        for name in ("score", "e_shading", "e_shape"):
            out[name] = np.asarray(cv2.multiply(self._up(low[name]), insidef), np.float32)
        for name in ("shading", "shape"):
            c = self._up(low[f"cos2_{name}"])
            s = self._up(low[f"sin2_{name}"])
            out[f"{name}_flow"] = _half_angle(c, s, insidef)
        return out

    @property
    def score_map(self) -> F32:
        return self._maps["score"]

    @property
    def shading_flow(self) -> F32:
        return self._maps["shading_flow"]

    @property
    def shape_flow(self) -> F32:
        return self._maps["shape_flow"]

    @property
    def shading_strength(self) -> F32:
        return self._maps["e_shading"]

    @property
    def shape_strength(self) -> F32:
        return self._maps["e_shape"]

    @property
    def weight(self) -> F32:
        return self._maps["weight"]
