"""Compile Depict's kernels before the first frame needs them (``depict warmup``).

The per-pixel kernels of ``ops/`` are compiled by Numba on first use and cached on disk (beside
the code, or in ``NUMBA_CACHE_DIR`` when that is set), so the first frame a new installation
processes waits for the compiler (tens of seconds); every later process only loads them. A
container image or a farm node's provisioning runs ``depict warmup`` once: it renders the bundled
example mesh small, in both renderer-lobe and G-buffer-only forms, and runs every operator of
the registry on it with its default parameters, plus the frame-size variants the kernels
specialise on (an odd size, a float coverage mask) and the lobes the example lacks (transmission).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from gbuffer.render import auto_camera, load_mesh, render
from ops.curvature import isotropic, mean_curvature_layers, principal_curvatures
from ops.shading import parse_light, shade_directions
from service import pipeline
from service.registry import operators

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "spot.obj"


def warm(mesh: Path = EXAMPLE, size: tuple[int, int] = (96, 72)) -> dict[str, float]:
    """Run every operator once on a small render of ``mesh``; seconds per operator."""
    loaded = load_mesh(mesh)
    width, height = size
    frame = render(loaded, width, height, camera=auto_camera(loaded, width=width, height=height))
    bare = frame.copy()
    for name in list(bare.buffers):
        if name not in ("normal", "depth", "albedo", "beauty"):
            bare.buffers.pop(name)
    times: dict[str, float] = {}
    for name in operators():
        t0 = time.perf_counter()
        for source in (frame, bare):
            try:
                pipeline.run(source, [{"op": name}], debug_layers=True)
            except ValueError:  # an operator this form of frame cannot feed (a missing buffer)
                pass
        times[name] = time.perf_counter() - t0
    t0 = time.perf_counter()
    normal, depth = frame.buffers["normal"], frame.buffers["depth"]
    odd = (slice(0, height - 1), slice(0, width - 1))
    for mask in (None, np.isfinite(depth[odd]).astype(np.float32)):
        isotropic(principal_curvatures(normal[odd], depth[odd], mask))
    for part in (odd, (slice(None), slice(None))):  # a working grid: exact and rounded sizes
        isotropic(principal_curvatures(normal[part], depth[part], scale=0.1))
    mean_curvature_layers(principal_curvatures(normal, depth, scale=0.1))  # their one pass
    times["curvature variants"] = time.perf_counter() - t0
    t0 = time.perf_counter()  # a path-traced frame's transmission lobe (glass), as LLA shades it
    view = np.array([0.0, 0.0, 1.0], np.float32)
    shade_directions(normal, view, frame.positions(), [parse_light("0,0,-1")], transmission=True)
    times["shading variants"] = time.perf_counter() - t0
    return times
