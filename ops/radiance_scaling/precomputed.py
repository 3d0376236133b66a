"""Radiance Scaling of precomputed radiance (§5.3): ambient occlusion with a prefiltered
environment, Lit Spheres (matcaps), mirror and refraction environments, and default images."""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from ops.color import REC709_Y, luminance
from ops.curvature import Curvature, isotropic
from ops.radiance_scaling.scenarios import Scaled
from ops.radiance_scaling.sigma import sigma
from ops.shading import (
    dot,
    normalize,
    reflect,
    refract,
)

__all__ = [
    "environment",
    "latlong_lookup",
    "lit_sphere",
    "precomputed_diffuse",
    "rotate_directions",
    "sh_irradiance",
    "sky_environment",
    "studio_matcap",
]

# -- precomputed radiance (§5.3) -----------------------------------------------------------------


def latlong_lookup(env: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Bilinear lookup of an equirectangular map (+y up, u = 0 at −z, increasing towards +x).

    ``directions`` are (H, W, 3) unit vectors in the map's frame; returns (H, W, C) float32.
    """
    x, y, z = directions[..., 0], directions[..., 1], directions[..., 2]
    h, w = env.shape[:2]
    phi = cv2.phase(-z, x)  # 0 at -z, pi/2 at +x, in [0, 2pi)
    u = phi * np.float32(w / (2.0 * np.pi)) + 0.5  # + 1: the wrapped column padded on the left
    v = np.arccos(np.clip(y, -1.0, 1.0)) * np.float32(h / np.pi) - 0.5
    # Wrap in longitude only: a border mode of WRAP in v would blend the top (+y) row with the
    # bottom (-y) row within half a texel of the poles. Pad one wrapped column on each side and
    # replicate the border rows instead.
    src = np.asarray(env, np.float32)
    src = np.ascontiguousarray(np.concatenate([src[:, -1:], src, src[:, :1]], axis=1))
    out = cv2.remap(
        src,
        u.astype(np.float32),
        v.astype(np.float32),
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_REPLICATE,
    )
    return out if out.ndim == 3 else out[..., None]


def rotate_directions(d: np.ndarray, camera_to_world: np.ndarray | None) -> np.ndarray:
    """(H, W, 3) directions rotated by the 3×3 ``camera_to_world`` (unchanged when ``None``)."""
    if camera_to_world is None:
        return d
    m = np.asarray(camera_to_world, np.float32)[:3, :3]
    return cv2.transform(np.ascontiguousarray(d, np.float32), m)


def sh_irradiance(env: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Irradiance / π of an equirectangular environment for unit ``directions`` (H, W, 3).

    Order-2 spherical harmonics (9 coefficients), Ramamoorthi & Hanrahan, "An efficient
    representation for irradiance environment maps", SIGGRAPH 2001, Eqs. 10-13. This is L̄(n) of
    §5.3.1 (the prefiltered environment), normalised so a constant environment L gives L.
    """
    h, w = env.shape[:2]
    v = (np.arange(h, dtype=np.float64) + 0.5) / h * np.pi
    u = (np.arange(w, dtype=np.float64) + 0.5) / w * 2.0 * np.pi
    st, ct = np.sin(v)[:, None], np.cos(v)[:, None]
    x, y, z = st * np.sin(u)[None, :], np.broadcast_to(ct, (h, w)), -st * np.cos(u)[None, :]
    basis = np.stack(
        [
            0.282095 * np.ones((h, w)),
            0.488603 * y,
            0.488603 * z,
            0.488603 * x,
            1.092548 * x * y,
            1.092548 * y * z,
            0.315392 * (3 * z * z - 1),
            1.092548 * x * z,
            0.546274 * (x * x - y * y),
        ]
    )  # (9, h, w)
    d_omega = (2 * np.pi / w) * (np.pi / h) * np.broadcast_to(st, (h, w))
    env3 = env.reshape(h, w, -1).astype(np.float64)
    coeff = np.einsum("khw,hwc->kc", basis * d_omega, env3)  # (9, C)
    a = np.array([np.pi, *(2 * np.pi / 3,) * 3, *(np.pi / 4,) * 5])
    coeff *= a[:, None] / np.pi
    dx, dy, dz = directions[..., 0], directions[..., 1], directions[..., 2]
    terms = [
        0.282095 * np.ones_like(dx),
        0.488603 * dy,
        0.488603 * dz,
        0.488603 * dx,
        1.092548 * dx * dy,
        1.092548 * dy * dz,
        0.315392 * (3 * dz * dz - 1),
        1.092548 * dx * dz,
        0.546274 * (dx * dx - dy * dy),
    ]
    out = np.zeros((*dx.shape, coeff.shape[1]), np.float32)
    for k, t in enumerate(terms):
        out += t[..., None].astype(np.float32) * coeff[k].astype(np.float32)
    return np.maximum(out, 0.0)


def precomputed_diffuse(
    normal: np.ndarray,
    curv: Curvature,
    *,
    ao: np.ndarray | None = None,
    irradiance: np.ndarray | None = None,
    albedo: np.ndarray | Sequence[float] = (1.0, 1.0, 1.0),
    alpha: float = 0.5,
    gamma: float = 1.0,
    gain: float = 1.0,
    white: float | None = None,
    weights: tuple[float, float, float] = REC709_Y,
) -> Scaled:
    """Radiance Scaling of precomputed diffuse radiance, §5.3.1 (Eq. 4 with ρ = ρ_d).

    L'(p→e) ≈ σ̄(p, e) ρ_d A(p) L̄(n), δ̄_d = L̄(n)/L̄*, with A the ambient occlusion and L̄ the
    prefiltered irradiance (``irradiance``, (H, W, 3): e.g. :func:`sh_irradiance` of an
    environment map at the world-space normals). L̄* is ``white`` or, by default, the maximum
    of L̄'s luminance. Without ``irradiance`` the environment is uniform (L̄ = 1, δ̄ = 1) and the
    result is the ambient occlusion scaled by σ(κ, 1): mean-curvature shading of AO (Fig. 8b).
    ``weights``: the luminance weights of the working space (here and in :func:`lit_sphere`,
    :func:`environment`).
    """
    shape = normal.shape[:2]
    covered = np.linalg.norm(normal, axis=2) > 0.5
    a = np.ones(shape, np.float32) if ao is None else ao.astype(np.float32)
    if irradiance is None:
        irr = np.ones((*shape, 3), np.float32)
        delta = np.ones(shape, np.float32)
    else:
        irr = irradiance.astype(np.float32)
        lum = luminance(irr, weights)
        peak = float(white) if white else float(lum.max()) or 1.0
        delta = np.clip(lum / np.float32(peak), 0.0, 1.0)
    s = sigma(isotropic(curv, gain), delta, alpha, gamma)
    alb = np.broadcast_to(np.asarray(albedo, np.float32), (*shape, 3))
    diffuse = alb * irr * (a * s)[..., None]
    diffuse[~covered] = 0.0
    return Scaled({"diffuse": diffuse}, {"diffuse": s})


def _rgb(image: np.ndarray) -> np.ndarray:
    """An (H, W) grey or (H, W, C ≥ 3) image as contiguous float32 (H, W, 3) RGB."""
    img = np.asarray(image, np.float32)
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[..., 0]
    if img.ndim == 2:
        return np.ascontiguousarray(np.repeat(img[..., None], 3, axis=2))
    if img.ndim != 3 or img.shape[2] < 3:
        raise ValueError(f"expected an (H, W) or (H, W, 3) image, got shape {img.shape}")
    return np.ascontiguousarray(img[..., :3])


def _scaled_lookup(
    radiance: np.ndarray,
    curv: Curvature,
    common: tuple[float, float, float],
    peak: float,
    weights: tuple[float, float, float],
) -> Scaled:
    alpha, gamma, gain = common
    delta = np.clip(luminance(radiance, weights) / np.float32(peak or 1.0), 0.0, 1.0)
    s = sigma(isotropic(curv, gain), delta, alpha, gamma)
    return Scaled({"specular": radiance * s[..., None]}, {"specular": s})


def lit_sphere(
    normal: np.ndarray,
    curv: Curvature,
    sphere: np.ndarray,
    *,
    alpha: float = 0.5,
    gamma: float = 1.0,
    gain: float = 1.0,
    weights: tuple[float, float, float] = REC709_Y,
) -> Scaled:
    """Radiance Scaling of a Lit Sphere / matcap, §5.3.1 (Sloan et al. 2001's Lit Sphere).

    The shading is the painted sphere looked up by the camera-space normal (u = ½ + ½ n_x,
    v = ½ − ½ n_y over the image of the sphere), L' = σ̄ L_ls(n) with δ̄ = L_ls(n)/L*_ls and L*_ls
    the brightest luminance of the sphere image.
    """
    h, w = sphere.shape[:2]
    u = ((0.5 + 0.5 * normal[..., 0]) * w - 0.5).astype(np.float32)
    v = ((0.5 - 0.5 * normal[..., 1]) * h - 0.5).astype(np.float32)
    src = _rgb(sphere)
    looked = cv2.remap(src, u, v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    looked[np.linalg.norm(normal, axis=2) < 0.5] = 0.0
    peak = float(luminance(src, weights).max())
    return _scaled_lookup(looked, curv, (alpha, gamma, gain), peak, weights)


def environment(
    normal: np.ndarray,
    view: np.ndarray,
    curv: Curvature,
    env: np.ndarray,
    *,
    mode: str = "mirror",
    ior: float = 1.5,
    camera_to_world: np.ndarray | None = None,
    alpha: float = 0.5,
    gamma: float = 1.0,
    gain: float = 1.0,
    weights: tuple[float, float, float] = REC709_Y,
) -> Scaled:
    """Radiance Scaling of a perfect mirror or refraction, §5.3.2.

    L'(p→e) = σ̄(p, e) L_env(r), δ̄_s = L_env(r)/L*_env, r the reflected (``mode="mirror"``) or
    refracted (``mode="refraction"``, one bounce, relative index ``ior``) view direction and
    L*_env the maximum luminance of the environment map.
    """
    if mode == "mirror":
        r = reflect(view, normal)
    elif mode == "refraction":
        r = refract(view, normal, ior)
    else:
        raise ValueError(f"mode={mode!r} must be 'mirror' or 'refraction'")
    env = _rgb(env)
    radiance = latlong_lookup(env, rotate_directions(normalize(r), camera_to_world))
    radiance[np.linalg.norm(normal, axis=2) < 0.5] = 0.0
    peak = float(luminance(env, weights).max())
    return _scaled_lookup(radiance, curv, (alpha, gamma, gain), peak, weights)


# -- default images for the lit-sphere and environment scenarios ---------------------------------


def studio_matcap(size: int = 256) -> np.ndarray:
    """A neutral clay Lit Sphere: Blinn-Phong shading of a sphere under a warm key light from the
    upper left and a cool rim from the right, (size, size, 3) linear RGB; black outside."""
    c = (np.arange(size, dtype=np.float32) + 0.5) / size * 2.0 - 1.0
    x, y = np.meshgrid(c, -c)
    r2 = x * x + y * y
    n = np.dstack([x, y, np.sqrt(np.clip(1.0 - r2, 0.0, 1.0))]).astype(np.float32)
    view = np.zeros_like(n)
    view[..., 2] = 1.0
    key = normalize(np.array([-0.5, 0.6, 0.65], np.float32))
    rim = normalize(np.array([0.9, 0.1, -0.3], np.float32))
    diffuse = np.clip(dot(n, np.broadcast_to(key, n.shape)), 0, 1)
    h = normalize(np.broadcast_to(key, n.shape) + view)
    spec = np.power(np.clip(dot(n, h), 0, 1), 40.0)
    back = np.clip(dot(n, np.broadcast_to(rim, n.shape)), 0, 1)
    out = (
        diffuse[..., None] * np.array([0.78, 0.72, 0.66], np.float32)
        + spec[..., None] * 0.5
        + back[..., None] * np.array([0.15, 0.2, 0.3], np.float32)
        + 0.06
    )
    out[r2 > 1.0] = 0.0
    return out.astype(np.float32)


def sky_environment(width: int = 256) -> np.ndarray:
    """A simple outdoor environment, (width/2, width, 3) equirectangular linear RGB: a blue sky
    brightening to the horizon, a darker ground, and a small bright sun high in front-left."""
    h = width // 2
    v = (np.arange(h, dtype=np.float32) + 0.5) / h  # 0 at +y
    elevation = (0.5 - v) * np.pi
    sky = (
        np.array([0.35, 0.5, 0.9], np.float32)
        + np.array([0.5, 0.4, 0.1], np.float32) * np.exp(-np.abs(elevation) * 3)[:, None]
    )
    ground = np.array([0.25, 0.22, 0.18], np.float32)
    col = np.where((elevation > 0)[:, None], sky, ground).astype(np.float32)
    env = np.repeat(col[:, None, :], width, axis=1)
    u = (np.arange(width, dtype=np.float32) + 0.5) / width * 2 * np.pi
    dirs = np.dstack(
        [
            np.cos(elevation)[:, None] * np.sin(u)[None, :],
            np.broadcast_to(np.sin(elevation)[:, None], (h, width)),
            -np.cos(elevation)[:, None] * np.cos(u)[None, :],
        ]
    ).astype(np.float32)
    sun = normalize(np.array([-0.4, 0.7, -0.6], np.float32))
    env += (np.power(np.clip(dot(dirs, np.broadcast_to(sun, dirs.shape)), 0, 1), 800.0) * 40.0)[
        ..., None
    ]
    return env.astype(np.float32)
