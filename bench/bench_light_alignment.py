"""Local Light Alignment at 1920x1080: multi-scale normals + aligned lights + the relit shade.

The frame: a bumpy dome (features at two sizes) in front of a second, partly hidden dome (a
depth jump) on background, perspective view vectors, one directional light. Timed:

- ``normal_pyramid``: the depth-guided multi-scale normals (LLA §5), S = 6;
- ``align_lights``: diffuse + specular aligned directions (LLA Eq. 1, §6) from the pyramid;
- ``shade_directions``: Lambert + Blinn-Phong with the aligned directions (the relight);
- the chain: exactly what the ``light_alignment`` operator (service/operators/light_alignment.py)
  computes for one directional light with diffuse + specular guides, Lambert + Blinn-Phong,
  given the frame's normals, depth, coverage, view vectors and positions — at S = 4, 6 and 8
  (the cost should be nearly flat in S);
- the whole operator through ``service.pipeline.run`` on a canonical frame (adds the frame's
  view vectors and positions, the frame copy and the relit lobes and beauty).

Target: the chain at S = 6 ≤ 50x the copy unit.

Run: ``.venv/bin/python -m bench.bench_light_alignment``
"""

from __future__ import annotations

import numpy as np

from bench.common import HD, Report
from gbuffer.camera import Camera
from gbuffer.frame import Frame
from ops.filtering import multiscale_normals, normal_pyramid
from ops.light_alignment import align_lights
from ops.shading import Light, shade_directions
from service import pipeline

TARGET = 50.0
FOV_Y_DEG = 40.0
LIGHT = (0.6, 0.55, 0.58)


def scene(shape: tuple[int, int] = HD) -> dict[str, np.ndarray]:
    """Perspective G-buffer of two bumpy domes (camera space, OpenGL conventions)."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    u = (xx + 0.5 - w / 2) / h  # image-height units, +x right
    v = (h / 2 - yy - 0.5) / h  # +y up
    tan_half = np.float32(np.tan(np.radians(FOV_Y_DEG / 2)))
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


def sigmas(scales: int) -> dict[str, list[float]]:
    """σ_1 … σ_{S−1} of the diffuse and specular components, finest first."""
    return {
        "diffuse": [0.5, 0.4, 0.4, 0.6, 0.7, 0.7, 0.7][: scales - 1],
        "specular": [0.7, 0.5, 0.3, 0.2, 0.2, 0.2, 0.2][: scales - 1],
    }


def main() -> None:
    g = scene()
    normal, depth, view, position = g["normal"], g["depth"], g["view"], g["position"]
    mask = np.isfinite(depth).astype(np.float32)  # Frame.mask: coverage from the depth
    lights = [Light(kind="directional", vector=LIGHT)]

    # what apply_light_alignment does (relight form, defaults: γ = 3, §5 filtering, Lambert +
    # Blinn-Phong s = 32, no transmission), given the frame's view vectors and positions
    def pyramid(scales: int):
        return normal_pyramid(normal, depth, mask, scales=scales)

    def align(pyr, scales: int) -> dict[str, list[np.ndarray]]:
        return align_lights(lights, pyr, position, view, sigmas(scales), mask=mask)

    def shade(aligned: dict[str, list[np.ndarray]]) -> dict[str, np.ndarray]:
        directions = {c: list(v) for c, v in aligned.items()}
        return shade_directions(normal, view, position, lights, directions)

    def chain(scales: int) -> dict[str, np.ndarray]:
        return shade(align(pyramid(scales), scales))

    frame = Frame(buffers={"normal": normal, "depth": depth}, camera=Camera(fov_y_deg=FOV_Y_DEG))
    sig6 = sigmas(6)
    step = {
        "op": "light_alignment",
        "params": {
            "sigmas": sig6["diffuse"],
            "specular_sigmas": sig6["specular"],
            "lights": [",".join(str(c) for c in LIGHT)],
            "form": "relight",
        },
    }

    rep = Report("Local Light Alignment (LLA §4-6)")
    pyr6 = pyramid(6)
    aligned6 = align(pyr6, 6)
    rep.time("normal_pyramid, S=6", lambda: pyramid(6))
    rep.time("align_lights diffuse+specular, S=6", lambda: align(pyr6, 6))
    rep.time("shade_directions Lambert + Blinn-Phong", lambda: shade(aligned6))
    rep.time("chain S=6: pyramid + 2 guides + relight", lambda: chain(6), target_ratio=TARGET)
    for scales in (4, 8):
        rep.time(f"chain S={scales}", lambda s=scales: chain(s))
    rep.time("pipeline.run light_alignment, S=6", lambda: pipeline.run(frame, [step]))
    rep.time(
        "multiscale_normals, S=6 (full-res list)",
        lambda: multiscale_normals(normal, depth, mask, scales=6),
        repeat=3,
    )


if __name__ == "__main__":
    main()
