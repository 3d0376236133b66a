"""BRDF terms on per-pixel fields, each an (H, W) float32 already multiplied by n·l where the
model calls for it (see :mod:`ops.shading`)."""

from __future__ import annotations

import math
from typing import Literal

import cv2
import numpy as np

from ops.checks import EXPONENT, FRACTION, IOR, ROUGHNESS, SHININESS
from ops.shading.vectors import _EPS, _dots, _half_cosines, _pos_pow, dot

__all__ = [
    "ashikhmin_shirley",
    "blinn_phong",
    "ggx",
    "half_lambert",
    "lambert",
    "phong",
    "transmission",
]

# -- BRDF terms -------------------------------------------------------------------------------


def lambert(n: np.ndarray, l: np.ndarray) -> np.ndarray:  # noqa: E741
    """Lambertian term max(n·l, 0) (Lambert 1760; Radiance Scaling §5.1, diffuse ρ_d)."""
    return np.maximum(dot(n, l), np.float32(0.0))


def half_lambert(
    n: np.ndarray,
    l: np.ndarray,  # noqa: E741
    form: Literal["valve", "exaggerated"] = "valve",
) -> np.ndarray:
    """Half-Lambertian shading, which never goes to 0 on the unlit side.

    ``form="valve"``: ((n·l + 1) / 2)² (Valve's Half-Lambert, Mitchell et al., "Shading in
    Valve's Source Engine", SIGGRAPH 2006 course).
    ``form="exaggerated"``: ½ (1 + clamp(n·l, −1, 1)), the clamped half-Lambertian of
    Exaggerated Shading (Rusinkiewicz, Burns, DeCarlo, SIGGRAPH 2006, Eq. 1 per scale).
    """
    d = dot(n, l)
    if form == "valve":
        h = (d + 1.0) * 0.5
        return np.asarray(h * h, np.float32)
    if form == "exaggerated":
        return np.asarray(0.5 * (1.0 + np.clip(d, -1.0, 1.0)), np.float32)
    raise ValueError(f"half_lambert form must be 'valve' or 'exaggerated', got {form!r}")


def _blinn_phong(nl: np.ndarray, nv: np.ndarray, lv: np.ndarray, shininess: float) -> np.ndarray:
    nh, _ = _half_cosines(nl, nv, lv)
    term = _pos_pow(nh, shininess)
    term[nl <= 0.0] = 0.0
    return term


def blinn_phong(
    n: np.ndarray,
    l: np.ndarray,  # noqa: E741
    v: np.ndarray,
    shininess: float,
) -> np.ndarray:
    """Blinn-Phong specular term (n·h)^s with h = (l + v)/|l + v|, 0 where n·l ≤ 0.

    Blinn, "Models of light reflection for computer synthesized pictures", SIGGRAPH 1977.
    Unnormalised, in [0, 1], as Radiance Scaling §5.1 needs (δ_s = ρ_s).
    """
    SHININESS.check(shininess, "shininess")
    return _blinn_phong(*_dots(n, l, v), shininess)


def _phong(nl: np.ndarray, nv: np.ndarray, lv: np.ndarray, shininess: float) -> np.ndarray:
    term = _pos_pow(2.0 * nl * nv - lv, shininess)  # r·v with r = 2(n·l)n − l
    term[nl <= 0.0] = 0.0
    return term


def phong(
    n: np.ndarray,
    l: np.ndarray,  # noqa: E741
    v: np.ndarray,
    shininess: float,
) -> np.ndarray:
    """Phong specular term (r·v)^s with r = 2(n·l)n − l, 0 where n·l ≤ 0.

    Phong, "Illumination for computer generated pictures", CACM 1975; in [0, 1] (Radiance
    Scaling §5.1, δ_s = ρ_s).
    """
    SHININESS.check(shininess, "shininess")
    return _phong(*_dots(n, l, v), shininess)


def _fresnel_schlick(f0: float, cos_theta: np.ndarray) -> np.ndarray:
    """Schlick's approximation F = f0 + (1 − f0)(1 − cosθ)⁵ (Schlick 1994)."""
    m = np.clip(1.0 - cos_theta, 0.0, 1.0)
    m2 = m * m
    return np.asarray(f0 + (1.0 - f0) * (m2 * m2 * m), np.float32)


def _ggx(
    nl: np.ndarray, nv: np.ndarray, lv: np.ndarray, roughness: float | np.ndarray, f0: float
) -> np.ndarray:
    nh, vh = _half_cosines(nl, nv, lv)
    r2 = np.asarray(roughness, np.float32) ** 2
    a2 = r2 * r2
    nh = np.clip(nh, 0.0, 1.0)
    denom = nh * nh * (a2 - 1.0) + 1.0
    d = a2 / (np.float32(math.pi) * denom * denom)
    nlc = np.maximum(nl, np.float32(0.0))
    nvc = np.maximum(nv, np.float32(1e-6))
    g1l = 2.0 * nlc / (nlc + np.sqrt(a2 + (1.0 - a2) * nlc * nlc) + _EPS)
    g1v = 2.0 * nvc / (nvc + np.sqrt(a2 + (1.0 - a2) * nvc * nvc))
    out = np.float32(math.pi / 4.0) * d * g1l * g1v * _fresnel_schlick(f0, vh) / nvc
    out[(nl <= 0.0) | (nv <= 0.0)] = 0.0
    return np.asarray(out, np.float32)


def ggx(
    n: np.ndarray,
    l: np.ndarray,  # noqa: E741
    v: np.ndarray,
    roughness: float,
    f0: float = 0.04,
) -> np.ndarray:
    """Cook-Torrance specular with GGX distribution, Smith-GGX masking, Schlick Fresnel, × n·l.

    f = D G F / (4 (n·l)(n·v)), returned as π f (n·l) = π D G F / (4 n·v), with α = roughness²,
    D = α² / (π ((n·h)²(α² − 1) + 1)²) (Walter et al., EGSR 2007, Eq. 33),
    G = G₁(l) G₁(v), G₁(x) = 2 (n·x) / (n·x + √(α² + (1 − α²)(n·x)²)) (Walter et al. Eq. 34),
    F = Schlick(f0, v·h). 0 where n·l ≤ 0 or n·v ≤ 0. Finite and ≥ 0 for roughness in (0, 1].
    """
    ROUGHNESS.check(roughness, "roughness")
    FRACTION.check(f0, "f0")
    return _ggx(*_dots(n, l, v), roughness, f0)


def _ashikhmin_shirley(
    nl: np.ndarray, nv: np.ndarray, lv: np.ndarray, exponent: float, rs: float
) -> tuple[np.ndarray, np.ndarray]:
    nh, hl = _half_cosines(nl, nv, lv)  # h·l = h·v
    nlc = np.clip(nl, 0.0, 1.0)
    nvc = np.clip(nv, 0.0, 1.0)
    spec = np.float32((exponent + 1.0) / 8.0) * _pos_pow(nh, exponent) * _fresnel_schlick(rs, hl)
    spec *= nlc / (np.maximum(hl, 1e-6) * np.maximum(np.maximum(nlc, nvc), 1e-6))
    a = 1.0 - 0.5 * nlc
    b = 1.0 - 0.5 * nvc
    a2 = a * a
    b2 = b * b
    diff = np.float32(28.0 / 23.0 * (1.0 - rs)) * (1.0 - a2 * a2 * a) * (1.0 - b2 * b2 * b) * nlc
    bad = (nl <= 0.0) | (nv <= 0.0)
    spec[bad] = 0.0
    diff[bad] = 0.0
    return np.asarray(diff, np.float32), np.asarray(spec, np.float32)


def ashikhmin_shirley(
    n: np.ndarray,
    l: np.ndarray,  # noqa: E741
    v: np.ndarray,
    exponent: float = 100.0,
    rs: float = 0.05,
) -> tuple[np.ndarray, np.ndarray]:
    """Isotropic Ashikhmin-Shirley BRDF, diffuse and specular parts, each × π (n·l).

    Ashikhmin & Shirley, "An anisotropic Phong BRDF model", JGT 2000, Eqs. 4-5 with
    n_u = n_v = ``exponent`` (used by Radiance Scaling §5.2, Eq. 3):

    ρ_s = (e + 1)/(8π) (n·h)^e / ((h·l) max(n·l, n·v)) F(h·l),  F = Schlick(rs)
    ρ_d = 28/(23π) R_d (1 − R_s) (1 − (1 − n·l/2)⁵)(1 − (1 − n·v/2)⁵)

    Returns ``(diffuse, specular)``: π ρ_d (n·l) without the diffuse colour R_d, and π ρ_s (n·l).
    Both are 0 where n·l ≤ 0 or n·v ≤ 0. Neither is bounded by 1 (which is why RS maps them with
    δ_d = ℓ·n and δ_s = h·n instead).
    """
    EXPONENT.check(exponent, "exponent")
    FRACTION.check(rs, "rs")
    return _ashikhmin_shirley(*_dots(n, l, v), exponent, rs)


def _transmission(
    nl: np.ndarray, nv: np.ndarray, lv: np.ndarray, ior: float, exponent: float
) -> np.ndarray:
    eta = np.float32(1.0 / ior)
    k = 1.0 - eta * eta * (1.0 - nv * nv)
    root = np.sqrt(np.maximum(k, 0.0))
    tl = (eta * nv - root) * nl - eta * lv  # t·l with t = −ηv + (η n·v − √k) n
    term = _pos_pow(tl, exponent)
    term[k < 0.0] = 0.0
    return term


def transmission(
    n: np.ndarray,
    l: np.ndarray,  # noqa: E741
    v: np.ndarray,
    ior: float = 1.5,
    exponent: float = 16.0,
) -> np.ndarray:
    """A back-lighting lobe: light seen through the surface along the refracted view ray.

    t = refract(v, n, ior) is the eye ray's direction once it has entered the surface; assuming
    it leaves the object unbent (the one-bounce refraction approximation of Radiance Scaling
    §5.4, Fig. 9), light arrives to the eye from lights lying along t: the lobe is
    max(t·l, 0)^exponent, in [0, 1], nonzero only for lights behind the surface. Local Light
    Alignment §6 uses the same refracted vector t as the guide of transmission.
    """
    EXPONENT.check(exponent, "exponent")
    IOR.check(ior, "ior")
    return _transmission(*_dots(n, l, v), ior, exponent)


def _blinn_phong_rows(
    nl: np.ndarray, nv: np.ndarray, lv: np.ndarray, shininess: float
) -> np.ndarray:
    """:func:`_blinn_phong` with the same rounding, in fewer passes (``cv2.threshold`` for the
    clamps and the n·l > 0 test): (n·h)^s, n·h = (n·l + n·v)/|l + v|, |l + v| = √(2 + 2 l·v)."""
    length = np.multiply(lv, np.float32(2.0))
    length += np.float32(2.0)
    cv2.threshold(length, 0.0, 0.0, cv2.THRESH_TOZERO, length)
    cv2.sqrt(length, length)
    big = cv2.threshold(length, 1e-6, 1.0, cv2.THRESH_BINARY)[1]  # 1/|l + v| where > 1e-6
    inv = np.divide(np.float32(1.0), cv2.max(length, 1e-6))  # type: ignore[call-overload]
    inv *= big
    nh = np.add(nl, nv)
    nh *= inv
    cv2.threshold(nh, 0.0, 0.0, cv2.THRESH_TOZERO, nh)
    term = np.asarray(cv2.pow(nh, float(shininess)), np.float32)
    term *= cv2.threshold(nl, 0.0, 1.0, cv2.THRESH_BINARY)[1]  # 0 where n·l ≤ 0
    return term
