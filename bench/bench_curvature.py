"""Benchmark: view-centred curvature (RS §4) and radiance scaling of lobes (RS Eq. 2/4) at 1080p.

Run: ``.venv/bin/python -m bench.bench_curvature``. Targets (ratios to the copy unit):
``principal_curvatures + isotropic`` <= 4x, ``principal_curvatures + scale_lobes`` (3 lobes) <= 8x.
The frame is analytic (tests/analytic.py): two overlapping spheres (a depth jump) on a background,
with lobes made from a Lambert and a Phong term so the scaling sees real lighting variation. A
second frame, a sphere over a receding ground plane in perspective, times the depth-jump test
where many pixels are candidates (a slanted surface) and few are occlusions. The spheres cover
19 % of the first frame, and both operators skip work where nothing is covered or κ = 0: the
``fully covered`` rows put a wavy wall behind them, so every pixel is covered and curved (the
worst case for both).

The ``floor`` rows time the memory traffic alone, on the same row strips and threads: one compiled
pass that reads each input once and writes each output once (normal, depth and mask in, κ out;
three lobes and three lights in, the beauty out: κ comes from the working grid, a quarter of a
plane), with a sum as the only arithmetic. They
show what the memory costs any implementation of the operation on this machine.
"""

from __future__ import annotations

import cv2
import numpy as np

from bench.common import HD, Report
from ops.curvature import isotropic, isotropic_field, principal_curvatures
from ops.jit import kernel
from ops.parallel import run_strips
from ops.radiance_scaling import scale_lobes
from tests.analytic import two_spheres

#: normal, depth, mask, lobes, lights
_Frame = tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, np.ndarray], dict[str, np.ndarray]]


def _frame(covered: bool = False) -> _Frame:
    """The two spheres on background (19 % of the pixels covered) or, ``covered``, in front of a
    wavy wall that fills the rest of the frame, so that every pixel is covered and curved."""
    h, w = HD
    s = two_spheres(h, width=w)
    normal, depth, mask = s.normal, s.depth, s.mask
    if covered:
        v, u = np.mgrid[0:h, 0:w].astype(np.float32) / np.float32(h) * np.float32(2.0 * np.pi)
        amp, freq = 0.02, 6.0  # the wall's height 0.02·sin(6u)·sin(6v), in image heights
        gx = amp * freq * np.cos(freq * u) * np.sin(freq * v) / (2.0 * np.pi)
        gy = amp * freq * np.sin(freq * u) * np.cos(freq * v) / (2.0 * np.pi)
        wall = np.stack([-gx, gy, np.ones_like(gx)], axis=-1)
        wall /= np.linalg.norm(wall, axis=-1, keepdims=True)
        far = float(depth[mask].max()) * 2.0
        normal = np.where(mask[..., None], normal, wall).astype(np.float32)
        depth = np.where(mask, depth, np.float32(far)).astype(np.float32)
        mask = np.ones_like(mask)
    n = normal
    n = s.normal
    ell = np.array([0.4, 0.5, 0.77], np.float32)
    ell /= np.linalg.norm(ell)
    ndl = np.clip(n @ ell, 0.0, None).astype(np.float32)
    hv = ell + np.array([0, 0, 1], np.float32)
    hv /= np.linalg.norm(hv)
    spec = (np.clip(n @ hv, 0.0, None) ** 40).astype(np.float32)
    amb = (0.5 + 0.5 * n[..., 2]).astype(np.float32) * mask
    lights = {
        "ambient": np.repeat(amb[..., None], 3, axis=2),
        "diffuse": np.repeat(ndl[..., None], 3, axis=2),
        "specular": np.repeat(spec[..., None], 3, axis=2),
    }
    colour = {"ambient": (0.1, 0.1, 0.12), "diffuse": (0.8, 0.5, 0.3), "specular": (1, 1, 1)}
    lobes = {k: (v * np.array(colour[k], np.float32)).astype(np.float32) for k, v in lights.items()}
    return normal, depth, mask, lobes, lights


def main() -> None:
    normal, depth, mask, lobes, lights = _frame()
    rep = Report(f"curvature + radiance scaling (cv2 threads: {cv2.getNumThreads()})")
    rep.time("principal_curvatures", lambda: principal_curvatures(normal, depth, mask), repeat=15)
    rep.time(
        "  floor: normal, depth, mask in; κ out", lambda: _curvature_floor(normal, depth, mask)
    )
    g_normal, g_depth, g_mask = _receding_frame()
    rep.time(
        "principal_curvatures (receding ground + sphere)",
        lambda: principal_curvatures(g_normal, g_depth, g_mask),
        repeat=15,
    )
    curv = principal_curvatures(normal, depth, mask)
    rep.time("  materialise k1, k2, dir, weight", lambda: _materialise(normal, depth, mask))
    kappa = isotropic_field(curv)  # as the operator passes it: the working grid, upsampled per row
    whites = {"ambient": 1.0, "diffuse": 1.0, "specular": 1.0}
    rep.time(
        "scale_lobes (3 lobes, pinned whites)",
        lambda: scale_lobes(lobes, lights, kappa, 0.5, 3.0, whites, with_sigmas=False),
        repeat=15,
    )
    rep.time("  floor: lobes, lights in; beauty out", lambda: _lobes_floor(lobes, lights))
    _time_targets(rep, "", (normal, depth, mask, lobes, lights))
    _time_targets(rep, " (fully covered)", _frame(covered=True))
    rep.time(
        "scale_lobes (3 lobes, white='auto')",
        lambda: scale_lobes(lobes, lights, kappa, 0.5, 3.0, "auto", mask=mask, with_sigmas=False),
    )


def _time_targets(
    rep: Report,
    suffix: str,
    frame: _Frame,
) -> None:
    """The two rows with targets, curvature + isotropic κ and the whole chain, on ``frame``."""
    normal, depth, mask, lobes, lights = frame
    rep.time(
        "principal_curvatures + isotropic" + suffix,
        lambda: isotropic(principal_curvatures(normal, depth, mask)),
        repeat=21,
        target_ratio=4,
    )
    rep.time(
        "principal_curvatures + scale_lobes (3 lobes)" + suffix,
        lambda: _chain(normal, depth, mask, lobes, lights),
        repeat=21,
        target_ratio=8,
    )


def _chain(
    normal: np.ndarray,
    depth: np.ndarray,
    mask: np.ndarray,
    lobes: dict[str, np.ndarray],
    lights: dict[str, np.ndarray],
) -> np.ndarray:
    """Radiance Scaling of the lobes as the operator runs it: curvature, κ on its working grid,
    the three lobes scaled with pinned white levels."""
    kappa = isotropic_field(principal_curvatures(normal, depth, mask))
    return scale_lobes(lobes, lights, kappa, 0.5, 3.0, 1.0, with_sigmas=False)[0]


def _receding_frame() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A sphere floating over a ground plane seen at 15° (horizon in view, clipped at 6x the
    centre's depth), pinhole camera with a 50° vertical field of view: normal, depth, mask."""
    h, w = HD
    t = 2.0 * np.tan(np.radians(25.0))
    u = (np.arange(w) + 0.5 - w / 2.0) / h * t
    v = (h / 2.0 - np.arange(h) - 0.5) / h * t
    ray = np.stack(np.broadcast_arrays(u[None, :], v[:, None], -1.0), axis=-1)
    n_g = np.array([0.0, np.cos(np.radians(15.0)), np.sin(np.radians(15.0))])
    with np.errstate(divide="ignore", invalid="ignore"):
        d_g = np.where(ray @ n_g < 0, (n_g @ np.array([0.0, 0.0, -5.0])) / (ray @ n_g), np.inf)
    d_g[d_g > 30.0] = np.inf
    c, r = np.array([0.6, 0.9, -4.5]), 0.8
    a, b = (ray * ray).sum(-1), ray @ c
    disc = b * b - a * (c @ c - r * r)
    d_s = np.where(disc > 0, (b - np.sqrt(np.maximum(disc, 0.0))) / a, np.inf)
    sphere = d_s < d_g
    depth = np.where(sphere, d_s, d_g)
    p = ray * np.where(np.isfinite(depth), depth, 0.0)[..., None]
    normal = np.where(sphere[..., None], (p - c) / r, n_g)
    mask = np.isfinite(depth)
    normal[~mask] = 0.0
    return normal.astype(np.float32), depth.astype(np.float32), mask


_FLOOR_ROWS = 64


def _curvature_floor(normal: np.ndarray, depth: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Read normal, depth and mask once, write an (H, W) float32 image once."""
    hgt, wid = depth.shape
    out = np.empty((hgt, wid), np.float32)
    m8 = mask.view(np.uint8)
    run_strips(
        hgt,
        lambda r0, r1: _curvature_floor_rows(normal[r0:r1], depth[r0:r1], m8[r0:r1], out[r0:r1]),
        _FLOOR_ROWS,
    )
    return out


@kernel
def _curvature_floor_rows(normal, depth, m8, out):  # type: ignore[no-untyped-def]
    wid = out.shape[1]
    for i in range(out.shape[0]):
        n, d, m, o = normal[i].reshape(3 * wid), depth[i], m8[i], out[i]
        for j in range(wid):
            o[j] = n[3 * j] + n[3 * j + 1] + n[3 * j + 2] + d[j] + np.float32(m[j])


def _lobes_floor(lobes: dict[str, np.ndarray], lights: dict[str, np.ndarray]) -> np.ndarray:
    """Read each lobe and light once; write the beauty once."""
    planes = (*lobes.values(), *lights.values())
    beauty = np.empty_like(planes[0])
    run_strips(
        beauty.shape[0],
        lambda r0, r1: _lobes_floor_rows(tuple(p[r0:r1] for p in planes), beauty[r0:r1]),
        _FLOOR_ROWS,
    )
    return beauty


@kernel
def _lobes_floor_rows(planes, out):  # type: ignore[no-untyped-def]
    wid = out.shape[1]
    for i in range(out.shape[0]):
        acc = out[i].reshape(3 * wid)
        acc[:] = planes[0][i].reshape(3 * wid)
        for p in planes[1:]:
            row = p[i].reshape(3 * wid)
            for m in range(3 * wid):
                acc[m] += row[m]


def _materialise(normal: np.ndarray, depth: np.ndarray, mask: np.ndarray) -> None:
    c = principal_curvatures(normal, depth, mask)
    for name in ("k1", "k2", "dir_x", "weight"):
        getattr(c, name)


if __name__ == "__main__":
    main()
