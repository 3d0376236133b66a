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

import numpy as np

from bench.bench_congruence import scene
from bench.common import Report
from gbuffer.frame import Frame
from ops.curvature import DEFAULT_SCALE as CURVATURE_SCALE
from ops.curvature import principal_curvatures
from ops.relief import (
    DEFAULT_SCALE,
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


def main() -> None:
    report = Report("apparent relief (Vergne et al. 2008)")
    normal, depth, mask = scene()
    light = np.array([0.4, 0.5, 0.77], np.float32)
    light /= np.linalg.norm(light)
    arm = make_arm("convex_black_concave_white")
    toon = default_toon()

    curv = principal_curvatures(normal, depth, mask, scale=DEFAULT_SCALE)
    desc = descriptor(curv)
    r = relief(curv, arm).r
    ndotl = dot(normal, light)
    base = ndotl.copy()
    effect = np.clip(1.0 - ndotl, 0.0, 1.0)
    print(
        f"  scale {DEFAULT_SCALE} (relief default); auto L_norm = {desc.norm:.3f} per image height"
    )

    print("-- parts")
    for sc in (DEFAULT_SCALE, CURVATURE_SCALE):
        report.time(
            f"curvature, scale {sc}",
            lambda sc=sc: principal_curvatures(normal, depth, mask, scale=sc),
            9,
        )
    report.time("relief: descriptor + lookup, auto norm", lambda: relief(curv, arm), 9)
    report.time(
        "relief: descriptor + lookup, pinned norm",
        lambda: relief(curv, arm, curvedness_norm=desc.norm),
        9,
    )
    report.time(
        "relief + full-res S planes (the operator's)",
        lambda: relief(curv, arm, with_descriptor=True),
        9,
    )
    report.time("relief, full_resolution lookup", lambda: relief(curv, arm, full_resolution=True))
    report.time("descriptor (full-res S, auto norm)", lambda: descriptor(curv), 9)
    report.time("arm_lookup(S) (full res)", lambda: arm_lookup(desc.s, arm), 9)
    report.time("descriptor_colors (visualisation)", lambda: descriptor_colors(desc.s), 5)
    report.time("n.l (ops.shading.dot)", lambda: dot(normal, light), 9)
    report.time("style: cel", lambda: cel(r), 9)
    report.time("style: counter shading, n.l given", lambda: counter_shading(r, ndotl), 9)
    report.time(
        "style: counter shading + n.l (fused)",
        lambda: counter_shading(r, normal=normal, light=light),
        9,
    )
    report.time("style: x-toon (RGB), n.l given", lambda: xtoon(r, ndotl, toon), 9)
    report.time(
        "style: x-toon (RGB) + n.l (fused)",
        lambda: xtoon(r, toon=toon, normal=normal, light=light),
        9,
    )
    report.time("style: masked (H, W)", lambda: masked(r, base, effect), 9)

    def total(style: str, scale: float = DEFAULT_SCALE, full: bool = False) -> object:
        c = principal_curvatures(normal, depth, mask, scale=scale)
        rr = relief(c, arm, full_resolution=full).r
        if style == "cel":
            return cel(rr)
        if style == "counter":
            return counter_shading(rr, normal=normal, light=light)
        return xtoon(rr, toon=toon, normal=normal, light=light)

    for sc in (DEFAULT_SCALE, CURVATURE_SCALE):
        print(f"-- operator at scale {sc}: curvature + descriptor + lookup + style (+ n.l)")
        for style in ("cel", "counter", "x-toon"):
            report.time(f"TOTAL {style}", lambda st=style, sc=sc: total(st, sc), 9, TARGET)
        report.time(
            "TOTAL counter, full_resolution lookup",
            lambda sc=sc: total("counter", sc, True),
            9,
            TARGET,
        )
    print("-- without the curvature (from a computed Curvature)")
    report.time("relief + cel", lambda: cel(relief(curv, arm).r), 9)
    report.time(
        "relief + counter shading (n.l fused)",
        lambda: counter_shading(relief(curv, arm).r, normal=normal, light=light),
        9,
    )
    report.time(
        "relief + x-toon (n.l fused)",
        lambda: xtoon(relief(curv, arm).r, toon=toon, normal=normal, light=light),
        9,
    )

    print("-- the operator: pipeline.run(frame, [apparent_relief]) on normal + depth + beauty")
    beauty = np.repeat(np.clip(ndotl, 0.0, 1.0)[..., None], 3, axis=2)
    frame = Frame(buffers={"normal": normal, "depth": depth, "beauty": beauty})
    for style in ("cel", "counter", "xtoon"):
        steps = [{"op": "apparent_relief", "params": {"style": style}}]
        report.time(
            f"pipeline.run apparent_relief, style {style}",
            lambda steps=steps: pipeline.run(frame, steps),
            9,
        )


if __name__ == "__main__":
    main()
