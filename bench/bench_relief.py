"""Benchmark: Apparent Relief (descriptor + ARM lookup + style) at 1920x1080.

Run: ``.venv/bin/python -m bench.bench_relief``. Target (issue 8): descriptor + lookup + style,
curvature included as the operator runs it, <= 10x the copy unit. The operator's path is
``principal_curvatures(scale=ops.relief.DEFAULT_SCALE)`` -> ``relief`` (descriptor and lookup
fused on the curvature's working grid) -> a style, which computes n·l itself from the normals and
a directional light in the same pass (``normal=``, ``light=``). Each part is also timed alone,
the styles also from a precomputed n·l, the totals again at ``ops.curvature.DEFAULT_SCALE``, the
full-resolution variants for reference, and the whole operator through ``service.pipeline.run``
(curvature, relief with the full-resolution S layers, style, composite over the beauty).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from bench.bench_congruence import scene
from bench.common import Report
from gbuffer.frame import Frame
from ops.curvature import DEFAULT_SCALE as CURVATURE_SCALE
from ops.curvature import Curvature, principal_curvatures
from ops.relief import (
    DEFAULT_SCALE,
    Descriptor,
    arm_lookup,
    cel,
    counter_shading,
    default_toon,
    descriptor,
    descriptor_colors,
    make_arm,
    masked,
    relief,
    xtoon,
)
from ops.shading import dot
from service import pipeline

TARGET = 10.0


@dataclass(frozen=True)
class ReliefScene:
    """The benchmark's G-buffer, light, ARM and toon texture, and what the parts are timed from:
    the curvature at the relief's scale, its descriptor, the relief values and n·l."""

    normal: NDArray[np.float32]
    depth: NDArray[np.float32]
    mask: NDArray[np.float32]
    light: NDArray[np.float32]
    arm: NDArray[np.float32]
    toon: NDArray[np.float32]
    curv: Curvature
    desc: Descriptor
    r: NDArray[np.float32]
    ndotl: NDArray[np.float32]


def relief_scene() -> ReliefScene:
    normal, depth, mask = scene()
    light = np.array([0.4, 0.5, 0.77], np.float32)
    light /= np.linalg.norm(light)
    arm = make_arm("convex_black_concave_white")
    toon = default_toon()
    curv = principal_curvatures(normal, depth, mask, scale=DEFAULT_SCALE)
    desc = descriptor(curv)
    r = relief(curv, arm).r
    ndotl = dot(normal, light)
    return ReliefScene(normal, depth, mask, light, arm, toon, curv, desc, r, ndotl)


def time_parts(report: Report, sc: ReliefScene) -> None:
    """Each part alone: curvature, relief variants, descriptor, lookup, n·l and the styles."""
    base = sc.ndotl.copy()
    effect = np.clip(1.0 - sc.ndotl, 0.0, 1.0)
    print("-- parts")
    for scale in (DEFAULT_SCALE, CURVATURE_SCALE):
        report.time(
            f"curvature, scale {scale}",
            lambda scale=scale: principal_curvatures(sc.normal, sc.depth, sc.mask, scale=scale),
            9,
        )
    report.time("relief: descriptor + lookup, auto norm", lambda: relief(sc.curv, sc.arm), 9)
    report.time(
        "relief: descriptor + lookup, pinned norm",
        lambda: relief(sc.curv, sc.arm, curvedness_norm=sc.desc.norm),
        9,
    )
    report.time(
        "relief + full-res S planes (the operator's)",
        lambda: relief(sc.curv, sc.arm, with_descriptor=True),
        9,
    )
    report.time(
        "relief, full_resolution lookup", lambda: relief(sc.curv, sc.arm, full_resolution=True)
    )
    report.time("descriptor (full-res S, auto norm)", lambda: descriptor(sc.curv), 9)
    report.time("arm_lookup(S) (full res)", lambda: arm_lookup(sc.desc.s, sc.arm), 9)
    report.time("descriptor_colors (visualisation)", lambda: descriptor_colors(sc.desc.s), 5)
    report.time("n.l (ops.shading.dot)", lambda: dot(sc.normal, sc.light), 9)
    time_styles(report, sc, base, effect)


def time_styles(
    report: Report, sc: ReliefScene, base: NDArray[np.float32], effect: NDArray[np.float32]
) -> None:
    """The styles on the computed relief values, from a given n·l and with n·l fused."""
    report.time("style: cel", lambda: cel(sc.r), 9)
    report.time("style: counter shading, n.l given", lambda: counter_shading(sc.r, sc.ndotl), 9)
    report.time(
        "style: counter shading + n.l (fused)",
        lambda: counter_shading(sc.r, normal=sc.normal, light=sc.light),
        9,
    )
    report.time("style: x-toon (RGB), n.l given", lambda: xtoon(sc.r, sc.ndotl, sc.toon), 9)
    report.time(
        "style: x-toon (RGB) + n.l (fused)",
        lambda: xtoon(sc.r, toon=sc.toon, normal=sc.normal, light=sc.light),
        9,
    )
    report.time("style: masked (H, W)", lambda: masked(sc.r, base, effect), 9)


def operator_total(
    sc: ReliefScene, style: str, scale: float = DEFAULT_SCALE, full: bool = False
) -> object:
    """The operator's work from the G-buffer: curvature, relief and a style (n·l fused)."""
    c = principal_curvatures(sc.normal, sc.depth, sc.mask, scale=scale)
    rr = relief(c, sc.arm, full_resolution=full).r
    if style == "cel":
        return cel(rr)
    if style == "counter":
        return counter_shading(rr, normal=sc.normal, light=sc.light)
    return xtoon(rr, toon=sc.toon, normal=sc.normal, light=sc.light)


def time_totals(report: Report, sc: ReliefScene) -> None:
    """The operator's totals at both scales (against the target), then without the curvature."""
    for scale in (DEFAULT_SCALE, CURVATURE_SCALE):
        print(f"-- operator at scale {scale}: curvature + descriptor + lookup + style (+ n.l)")
        for style in ("cel", "counter", "x-toon"):
            report.time(
                f"TOTAL {style}",
                lambda st=style, scale=scale: operator_total(sc, st, scale),
                9,
                TARGET,
            )
        report.time(
            "TOTAL counter, full_resolution lookup",
            lambda scale=scale: operator_total(sc, "counter", scale, True),
            9,
            TARGET,
        )
    print("-- without the curvature (from a computed Curvature)")
    report.time("relief + cel", lambda: cel(relief(sc.curv, sc.arm).r), 9)
    report.time(
        "relief + counter shading (n.l fused)",
        lambda: counter_shading(relief(sc.curv, sc.arm).r, normal=sc.normal, light=sc.light),
        9,
    )
    report.time(
        "relief + x-toon (n.l fused)",
        lambda: xtoon(relief(sc.curv, sc.arm).r, toon=sc.toon, normal=sc.normal, light=sc.light),
        9,
    )


def time_pipeline(report: Report, sc: ReliefScene) -> None:
    """The whole operator through service.pipeline.run, composited over a Lambert beauty."""
    print("-- the operator: pipeline.run(frame, [apparent_relief]) on normal + depth + beauty")
    beauty = np.repeat(np.clip(sc.ndotl, 0.0, 1.0)[..., None], 3, axis=2)
    frame = Frame(buffers={"normal": sc.normal, "depth": sc.depth, "beauty": beauty})
    for style in ("cel", "counter", "xtoon"):
        steps = [{"op": "apparent_relief", "params": {"style": style}}]
        report.time(
            f"pipeline.run apparent_relief, style {style}",
            lambda steps=steps: pipeline.run(frame, steps),
            9,
        )


def main() -> None:
    report = Report("apparent relief (Vergne et al. 2008)")
    sc = relief_scene()
    norm = sc.desc.norm
    print(f"  scale {DEFAULT_SCALE} (relief default); auto L_norm = {norm:.3f} per image height")
    time_parts(report, sc)
    time_totals(report, sc)
    time_pipeline(report, sc)


if __name__ == "__main__":
    main()
