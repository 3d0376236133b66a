"""Mesh rendering at 1920×1080: the whole render, and its parts (the smooth surface, visibility +
exact geometry, SSAO, lobes), on the Stanford bunny (70k faces) from ../shared/models; and a coarse
mesh that is Loop-subdivided (examples/spot.obj, 5856 faces).

Run: ``.venv/bin/python -m bench.bench_render``
"""

from __future__ import annotations

import sys
from pathlib import Path

import trimesh

from bench.common import HD, Report
from gbuffer.render import (
    auto_camera,
    bounding_sphere,
    default_lights,
    load_mesh,
    render,
    shared_rasterizer,
)
from gbuffer.subdivision import refine
from gbuffer.surface import smooth_surface
from ops.ambient_occlusion import ssao
from ops.shading import shade_lobes

MESH = Path(__file__).resolve().parents[2] / "shared" / "models" / "stanford-bunny.obj"
COARSE = Path(__file__).resolve().parents[1] / "examples" / "spot.obj"


def main() -> int:
    if not MESH.is_file():
        print(f"skipped: {MESH} is absent (the shared test meshes are not checked out)")
        return 0
    h, w = HD
    mesh = load_mesh(MESH)
    camera = auto_camera(mesh, width=w, height=h)
    raster = shared_rasterizer()
    geo = raster.rasterize(mesh, camera, w, h)  # also creates the OSMesa context
    coverage = float(geo["coverage"].mean())
    radius = 0.2 * bounding_sphere(mesh)[1]
    focal = camera.focal_px(h)
    view = camera.view_vectors((h, w), (w, h))
    ao = ssao(geo["depth"], geo["normal"], radius=radius, focal_px=focal)

    report = Report(f"render: stanford-bunny, {len(mesh.faces)} faces, coverage {coverage:.0%}")
    report.time("render (all buffers + lobes + AO + outputs)", lambda: render(mesh, w, h), 5)
    report.time(
        "  rasterize (smooth surface, visibility + float64 geometry)",
        lambda: raster.rasterize(mesh, camera, w, h),
        5,
    )
    report.time(
        "    smooth_surface (weld, corner normals, crease test; cached per mesh)",
        lambda: smooth_surface(trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)),
    )
    report.time(
        "  ssao (8 directions x 4 steps)",
        lambda: ssao(geo["depth"], geo["normal"], radius=radius, focal_px=focal),
    )
    report.time(
        "  shade_lobes (2 lights, Blinn-Phong)",
        lambda: shade_lobes(
            geo["normal"], geo["position"], view, geo["albedo"], default_lights(), ao=ao
        ),
    )
    full = geo["normal"].copy()
    full[...] = (0.0, 0.0, 1.0)
    depth_full = geo["depth"].copy()
    depth_full[~(depth_full < float("inf"))] = float(geo["depth"][geo["coverage"] > 0].max())
    report.time(
        "  ssao on a fully covered frame (flat)",
        lambda: ssao(depth_full, full, radius=radius, focal_px=focal),
        5,
    )
    coarse = load_mesh(COARSE)
    surface = smooth_surface(coarse)
    report.time(
        f"render of {COARSE.name} ({len(coarse.faces)} faces, Loop-subdivided)",
        lambda: render(coarse, w, h),
        5,
    )
    report.time("  refine: one Loop level", lambda: refine(surface, 1))
    report.time("  refine: two Loop levels", lambda: refine(surface, 2))
    raster.delete()
    return 0


if __name__ == "__main__":
    sys.exit(main())
