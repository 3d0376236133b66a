"""Local Light Alignment at 1920x1080: multi-scale normals + aligned lights + a relit shade.

The frame: a bumpy dome (features at two sizes) in front of a second, partly hidden dome (a
depth jump) on background, perspective view vectors, one directional light. Timed:

- ``normal_pyramid``: the depth-guided multi-scale normals (LLA §5), S = 6;
- ``align_components``: diffuse + specular aligned directions (LLA Eq. 1, §6) from the pyramid;
- a Lambert + Blinn-Phong shade with the aligned directions (``ops.shading``), emulating the
  relit output;
- the whole chain at S = 4, 6 and 8 (the cost should be nearly flat in S).

Target: the chain (pyramid + both guides + shade) at S = 6 ≤ 50x the copy unit.

Run: ``.venv/bin/python -m bench.bench_light_alignment``
"""

from __future__ import annotations

import numpy as np

from bench.common import HD, Report
from ops import shading
from ops.filtering import multiscale_normals, normal_pyramid
from ops.light_alignment import align_components

TARGET = 50.0


def scene(shape: tuple[int, int] = HD) -> dict[str, np.ndarray]:
    """Perspective G-buffer of two bumpy domes (camera space, OpenGL conventions)."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    u = (xx + 0.5 - w / 2) / h  # image-height units, +x right
    v = (h / 2 - yy - 0.5) / h  # +y up
    tan_half = np.float32(np.tan(np.radians(20.0)))  # 40° vertical field of view
    ray = np.stack([2 * u * tan_half, 2 * v * tan_half, -np.ones_like(u)], axis=-1)

    def dome(cx: float, cy: float, radius: float, dist: float, seed: int):
        x = (u - cx) / radius
        y = (v - cy) / radius
        r2 = x * x + y * y
        cover = r2 < 0.97**2
        base = np.sqrt(np.maximum(1.0 - r2, 1e-6))
        a1, f1, a2, f2 = 0.02, 12.0 + seed, 0.004, 60.0 + 3 * seed
        z = base + a1 * np.sin(f1 * x) * np.sin(f1 * y) + a2 * np.sin(f2 * x + 1) * np.sin(f2 * y)
        zx = -x / base + a1 * f1 * np.cos(f1 * x) * np.sin(f1 * y)
        zx += a2 * f2 * np.cos(f2 * x + 1) * np.sin(f2 * y)
        zy = -y / base + a1 * f1 * np.sin(f1 * x) * np.cos(f1 * y)
        zy += a2 * f2 * np.sin(f2 * x + 1) * np.cos(f2 * y)
        n = np.stack([-zx, -zy, np.ones_like(z)], axis=-1)
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
        depth = dist - 0.35 * z  # planar depth, scene units
        return cover, n.astype(np.float32), depth.astype(np.float32)

    c1, n1, d1 = dome(-0.15, -0.02, 0.42, 5.0, 0)
    c2, n2, d2 = dome(0.45, 0.12, 0.38, 6.5, 1)
    front = c1 & (~c2 | (d1 <= d2))
    mask = c1 | c2
    normal = np.where(front[..., None], n1, n2)
    depth = np.where(front, d1, d2)
    normal[~mask] = 0.0
    depth[~mask] = np.inf
    position = ray * np.where(mask, depth, 0.0)[..., None]
    view = -ray / np.linalg.norm(ray, axis=-1, keepdims=True)
    return {
        "normal": np.ascontiguousarray(normal, np.float32),
        "depth": np.ascontiguousarray(depth, np.float32),
        "mask": mask,
        "position": position.astype(np.float32),
        "view": np.ascontiguousarray(view, np.float32),
    }


def main() -> None:
    g = scene()
    normal, depth, mask, view = g["normal"], g["depth"], g["mask"], g["view"]
    light = np.array([0.6, 0.55, 0.58], np.float32)
    light /= np.linalg.norm(light)

    def sigmas(scales: int) -> dict[str, list[float]]:
        return {
            "diffuse": [0.5, 0.4, 0.4, 0.6, 0.7, 0.7, 0.7][: scales - 1],
            "specular": [0.7, 0.5, 0.3, 0.2, 0.2, 0.2, 0.2][: scales - 1],
        }

    def chain(scales: int) -> np.ndarray:
        pyr = normal_pyramid(normal, depth, mask, scales=scales)
        aligned = align_components(light, pyr, sigmas(scales), view=view)
        return shade(aligned)

    def shade(aligned: dict[str, np.ndarray]) -> np.ndarray:
        diffuse = shading.lambert(normal, aligned["diffuse"])
        return diffuse + shading.blinn_phong(normal, aligned["specular"], view, 32.0)

    rep = Report("Local Light Alignment (LLA §4-6)")
    pyr6 = normal_pyramid(normal, depth, mask, scales=6)
    aligned6 = align_components(light, pyr6, sigmas(6), view=view)
    rep.time("normal_pyramid, S=6", lambda: normal_pyramid(normal, depth, mask, scales=6))
    rep.time(
        "align diffuse+specular from the pyramid, S=6",
        lambda: align_components(light, pyr6, sigmas(6), view=view),
    )
    rep.time("shade Lambert + Blinn-Phong (ops.shading)", lambda: shade(aligned6))
    rep.time("chain S=6: pyramid + 2 guides + shade", lambda: chain(6), target_ratio=TARGET)
    for scales in (4, 8):
        rep.time(f"chain S={scales}", lambda s=scales: chain(s))
    rep.time(
        "multiscale_normals, S=6 (full-res list)",
        lambda: multiscale_normals(normal, depth, mask, scales=6),
        repeat=3,
    )


if __name__ == "__main__":
    main()
