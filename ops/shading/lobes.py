"""Deferred shading of a G-buffer into lobes (ambient, diffuse, specular, transmission), each as
light × colour, with any number of lights."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import cv2
import numpy as np

from ops.checks import AMBIENT, IOR, SHININESS, WEIGHT
from ops.shading.brdf import _ashikhmin_shirley, _blinn_phong, _ggx, _phong, _transmission
from ops.shading.lights import Light, light_irradiance, light_vectors
from ops.shading.vectors import _outer, dot

__all__ = ["MODELS", "Model", "shade_lobes"]

Model = Literal["lambert", "blinn_phong", "phong", "ggx", "ashikhmin_shirley"]
MODELS: tuple[str, ...] = ("lambert", "blinn_phong", "phong", "ggx", "ashikhmin_shirley")


def _rgb(value: float | Sequence[float] | np.ndarray, name: str) -> np.ndarray:
    arr = np.asarray(value, np.float32)
    if arr.ndim == 0:
        arr = np.full(3, float(arr), np.float32)
    if arr.shape[-1:] != (3,) or not np.all(np.isfinite(arr)) or np.any(arr < 0):
        raise ValueError(f"{name} must be a finite value >= 0 or an RGB triple/field of them")
    return arr


def shade_lobes(
    normal: np.ndarray,
    position: np.ndarray,
    view: np.ndarray,
    albedo: float | Sequence[float] | np.ndarray,
    lights: Sequence[Light],
    *,
    ambient: float = 0.1,
    specular: float | Sequence[float] = 0.3,
    shininess: float = 32.0,
    ao: np.ndarray | None = None,
    model: str = "blinn_phong",
    transmission_weight: float = 0.0,
    ior: float = 1.5,
) -> dict[str, np.ndarray]:
    """Shade per-pixel geometry with several lights into canonical radiance lobes.

    Parameters
    ----------
    normal : (H, W, 3) camera-space unit normals; (0, 0, 0) marks pixels without a surface.
    position : (H, W, 3) camera-space positions (used by point lights).
    view : (H, W, 3) or (3,) unit directions towards the eye.
    albedo : diffuse colour: a scalar, an RGB triple or an (H, W, 3) field.
    lights : lights, camera space.
    ambient : ambient light level (times ``ao`` when given), >= 0.
    specular : specular colour (scalar or RGB), >= 0.
    shininess : Phong / Blinn-Phong exponent s > 0. ``"ggx"`` uses α = √(2/(s + 2)) (the usual
        Blinn-Phong ↔ Beckmann/GGX correspondence); ``"ashikhmin_shirley"`` uses e = s.
    ao : optional (H, W) ambient occlusion in [0, 1], multiplied into the ambient light.
    model : ``"lambert"`` (no specular), ``"blinn_phong"``, ``"phong"``, ``"ggx"`` or
        ``"ashikhmin_shirley"`` (its own diffuse term; both lobes via
        :func:`ashikhmin_shirley`). Lambert, Blinn-Phong and Phong use :func:`lambert`.
    transmission_weight : > 0 adds the ``transmission`` lobes (:func:`transmission`, colour
        ``albedo * transmission_weight``).
    ior : index of refraction of the transmission lobe.

    Returns
    -------
    dict of (H, W, 3) float32: ``"ambient"``, ``"diffuse"``, ``"specular"`` (radiance; plus
    ``"transmission"`` when asked) and for each lobe X ``"X.light"`` (light without colour,
    summed over the lights: Σ_i E_i term_i) and ``"X.color"`` (albedo for ambient / diffuse /
    transmission, the specular colour for specular), with X = X.color × X.light. Pixels whose
    normal is 0 are 0 in every output.

    Notes
    -----
    For ``"ggx"`` and ``"ashikhmin_shirley"``, whose Fresnel term needs a reflectance f0 at
    normal incidence, f0 = mean(specular) and the specular light is the term divided by f0, so
    that specular = colour × light holds with colour = ``specular``.
    """
    if model not in MODELS:
        raise ValueError(f"model must be one of {', '.join(MODELS)}; got {model!r}")
    AMBIENT.check(ambient, "ambient")
    SHININESS.check(shininess, "shininess")
    WEIGHT.check(transmission_weight, "transmission_weight")
    IOR.check(ior, "ior")
    normal = np.ascontiguousarray(normal, np.float32)
    if normal.ndim != 3 or normal.shape[2] != 3:
        raise ValueError(f"normal must be (H, W, 3), got shape {normal.shape}")
    shape = normal.shape[:2]
    mask = (dot(normal, normal) > 0.25).astype(np.float32)
    alb = _rgb(albedo, "albedo")
    if alb.ndim not in (1, 3) or (alb.ndim == 3 and alb.shape[:2] != shape):
        raise ValueError(f"albedo must be a scalar, an RGB triple or (H, W, 3); got {alb.shape}")
    spec_rgb = _rgb(specular, "specular")
    if spec_rgb.ndim != 1:
        raise ValueError("specular must be a scalar or an RGB triple")
    f0 = float(np.mean(spec_rgb))
    view_a = np.asarray(view, np.float32)
    pos: np.ndarray | None = None
    if any(light.kind == "point" for light in lights):
        pos = np.where(mask[..., None] > 0, np.asarray(position, np.float32), np.float32(0.0))
    nv = dot(normal, view_a)

    diff_light = np.zeros((*shape, 3), np.float32)
    spec_light = np.zeros((*shape, 3), np.float32)
    trans_light = np.zeros((*shape, 3), np.float32) if transmission_weight > 0.0 else None
    for light in lights:
        if light.kind == "directional":
            l_vec: np.ndarray = np.asarray(light.vector, np.float32)
            e = light_irradiance(light, normal)
        else:
            assert pos is not None
            l_vec = light_vectors(light, pos)
            e = light_irradiance(light, pos)
        nl = dot(normal, l_vec)
        lv = dot(l_vec, view_a)
        if lv.ndim == 0:
            lv = np.full(shape, lv, np.float32)
        d_term, s_term = _model_terms(model, nl, nv, lv, shininess, f0)
        _accumulate(diff_light, d_term, e)
        if s_term is not None:
            _accumulate(spec_light, s_term, e)
        if trans_light is not None:
            _accumulate(trans_light, _transmission(nl, nv, lv, ior, 16.0) * mask, e)

    amb = np.float32(ambient) * mask
    if ao is not None:
        amb *= np.asarray(ao, np.float32)
    amb_light = _outer(amb, np.ones(3, np.float32))
    if alb.ndim == 1:
        alb_f = _outer(mask, alb)
    else:
        alb_f = np.asarray(np.ascontiguousarray(alb) * mask[..., None], np.float32)
    spec_f = _outer(mask, spec_rgb)
    out: dict[str, np.ndarray] = {}
    parts: list[tuple[str, np.ndarray, np.ndarray]] = [
        ("ambient", amb_light, alb_f),
        ("diffuse", diff_light, alb_f),
        ("specular", spec_light, spec_f),
    ]
    if trans_light is not None:
        parts.append(("transmission", trans_light, alb_f * np.float32(transmission_weight)))
    for name, light_f, color in parts:
        out[f"{name}.light"] = light_f
        out[f"{name}.color"] = color
        out[name] = np.asarray(cv2.multiply(light_f, color), np.float32).reshape(light_f.shape)
    return out


def _model_terms(
    model: str, nl: np.ndarray, nv: np.ndarray, lv: np.ndarray, shininess: float, f0: float
) -> tuple[np.ndarray, np.ndarray | None]:
    """One light's diffuse and specular terms under ``model`` (see :func:`shade_lobes`) from
    n·ℓ, n·v and ℓ·v; the specular term None for ``"lambert"``, divided by f0 where the model's
    Fresnel term holds it."""
    if model == "ashikhmin_shirley":
        d_term, s_term = _ashikhmin_shirley(nl, nv, lv, shininess, min(f0, 1.0))
        s_term *= np.float32(1.0 / max(f0, 1e-4))
        return d_term, s_term
    d_term = np.maximum(nl, np.float32(0.0))
    if model == "blinn_phong":
        return d_term, _blinn_phong(nl, nv, lv, shininess)
    if model == "phong":
        return d_term, _phong(nl, nv, lv, shininess)
    if model == "ggx":
        rough = (2.0 / (shininess + 2.0)) ** 0.25
        s_term = _ggx(nl, nv, lv, rough, min(f0, 1.0))
        s_term *= np.float32(1.0 / max(f0, 1e-4))
        return d_term, s_term
    return d_term, None


def _accumulate(acc: np.ndarray, term: np.ndarray, irradiance: np.ndarray) -> None:
    """acc += term × irradiance, irradiance (3,) or (H, W, 3)."""
    if irradiance.ndim == 1:
        acc += _outer(term, irradiance)
    else:
        acc += term[..., None] * irradiance
