"""Benchmark: 3D unsharp masking (Ritschel et al. 2008) and its baselines at 1920x1080.

Run: ``.venv/bin/python -m bench.bench_unsharp``. Target: ``unsharp_masking`` with typical
parameters at ≤ 30x the copy unit; ``depth_unsharp_masking`` likewise.

The scene is analytic: a textured ground plane seen at a grazing angle (depth 2.5 … 60 scene
units, background beyond) with three spheres standing on it, perspective camera with a 40°
vertical field of view. "Typical" is σ = 0.08 scene units (σ_px from 2 px at the far end of the
ground to 43 px at the bottom edge, up to 4 % of the image height).

The target row takes the median of 11 runs (the machines these run on are shared and noisy).
The "part" rows time the colour conversions on their own: what ``unsharp_masking`` uses (L* alone
on the way in, φ' = k φ on the way out) and the full φ round trip of ``ops.color``.
"""

from __future__ import annotations

import math

import numpy as np

from bench.common import HD, Report
from ops.color import lab_phi_to_rgb, lightness, rgb_to_lab_phi, scale_lab
from ops.unsharp import depth_unsharp_masking, plain_unsharp_mask, unsharp_masking


def scene(
    shape: tuple[int, int] = HD,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(beauty, depth, normal, mask, pixel_size), float32, OpenGL camera space."""
    h, w = shape
    f = 0.5 * h / math.tan(math.radians(20.0))
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    rays = np.dstack([(x + 0.5 - w / 2) / f, (h / 2 - y - 0.5) / f, -np.ones_like(x)])
    rays /= np.linalg.norm(rays, axis=2, keepdims=True)
    t_best = np.full((h, w), np.inf)
    normal = np.zeros((h, w, 3))
    albedo = np.zeros((h, w))
    # ground plane y = -1, up to 60 units away
    tg = np.where(rays[..., 1] < -1e-3, -1.0 / np.minimum(rays[..., 1], -1e-3), np.inf)
    tg[tg * -rays[..., 2] > 60.0] = np.inf
    hit = np.isfinite(tg)
    t_best[hit] = tg[hit]
    normal[hit] = [0.0, 1.0, 0.0]
    p = rays * tg[..., None]
    with np.errstate(invalid="ignore"):
        checker = (np.floor(p[..., 0]) + np.floor(p[..., 2])) % 2
    albedo[hit] = (0.25 + 0.5 * checker)[hit]
    for cx, cz, r, a in ((-1.2, -5.0, 0.8, 0.7), (0.9, -7.0, 1.0, 0.5), (2.5, -12.0, 1.0, 0.8)):
        c = np.array([cx, -1.0 + r, cz])
        b = rays @ c
        disc = b * b - (c @ c - r * r)
        ts = np.where(disc > 0, b - np.sqrt(np.maximum(disc, 0.0)), np.inf)
        closer = ts < t_best
        t_best[closer] = ts[closer]
        n = (rays * ts[..., None] - c) / r
        normal[closer] = n[closer]
        albedo[closer] = a
    mask = np.isfinite(t_best)
    light = np.array([0.4, 0.8, 0.45])
    light /= np.linalg.norm(light)
    shade = 0.15 + 0.85 * np.clip(normal @ light, 0.0, None)
    tint = np.array([1.0, 0.85, 0.7])
    beauty = (albedo * shade)[..., None] * tint * 1.5  # HDR: above 1 in the light
    beauty[~mask] = 0.0
    depth = np.where(mask, -(rays[..., 2] * t_best), np.inf)
    pixel_size = depth / f
    return (
        beauty.astype(np.float32),
        depth.astype(np.float32),
        normal.astype(np.float32),
        mask,
        pixel_size.astype(np.float32),
    )


def main() -> None:
    report = Report("unsharp masking (3D USM §4-5, Luft 2006, plain 2-D)")
    beauty, depth, normal, mask, ps = scene()
    kw = dict(pixel_size=ps, white=2.0)
    report.time(
        "unsharp_masking (σ=0.08, adaptive)",
        lambda: unsharp_masking(beauty, depth, normal, mask, sigma_scene=0.08, **kw),
        repeat=11,
        target_ratio=30.0,
    )
    report.time(
        "unsharp_masking (σ=0.08, adaptive=False)",
        lambda: unsharp_masking(
            beauty, depth, normal, mask, sigma_scene=0.08, adaptive=False, **kw
        ),
        repeat=7,
    )
    report.time(
        "unsharp_masking (σ=0.03: σ_px 1-16, half-res level)",
        lambda: unsharp_masking(beauty, depth, normal, mask, sigma_scene=0.03, **kw),
        repeat=5,
    )
    report.time(
        "unsharp_masking (σ=0.08, normal_sigma=None)",
        lambda: unsharp_masking(
            beauty, depth, normal, mask, sigma_scene=0.08, normal_sigma=None, **kw
        ),
        repeat=5,
    )
    report.time(
        "depth_unsharp_masking (σ=0.02 H)",
        lambda: depth_unsharp_masking(beauty, depth, mask, sigma=0.02, white=2.0),
        repeat=7,
        target_ratio=30.0,
    )
    report.time(
        "plain_unsharp_mask (σ=0.02 H)",
        lambda: plain_unsharp_mask(beauty, 0.02, 1.0, white=2.0),
        repeat=7,
    )
    phi = rgb_to_lab_phi(beauty, 2.0)
    k = np.random.default_rng(0).uniform(0.8, 1.25, mask.shape).astype(np.float32)
    report.time("  part: linear RGB -> L* (lightness)", lambda: lightness(beauty, 2.0), 9)
    report.time("  part: (L*, a*, b*) x k -> linear RGB", lambda: scale_lab(beauty, k, 2.0), 9)
    report.time("  part: linear RGB -> CIELAB (φ)", lambda: rgb_to_lab_phi(beauty, 2.0), 9)
    report.time("  part: CIELAB (φ) -> linear RGB", lambda: lab_phi_to_rgb(phi, 2.0), 9)


if __name__ == "__main__":
    main()
