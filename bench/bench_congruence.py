"""Benchmark: congruence score (LLA Eq. 2) and the comparison baselines at 1920x1080.

Run: ``.venv/bin/python -m bench.bench_congruence``. Target: the score at ≤ 15x the copy unit.
The machine is shared: the medians are over many repeats, and only the ratios to the copy unit
measured in the same run are comparable between runs.
"""

from __future__ import annotations

import numpy as np

from bench.common import HD, Report
from ops.congruence import congruence
from ops.directions import comparison_directions
from ops.shading import lambert


def scene(shape: tuple[int, int] = HD) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A bumpy sphere over background: (normal, depth, mask), orthographic, float32."""
    h, w = shape
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    u = (x - w / 2) / (0.45 * h)
    v = -(y - h / 2) / (0.45 * h)
    r2 = u * u + v * v
    mask = r2 < 1.0
    z = np.sqrt(np.clip(1.0 - r2, 0.0, 1.0))
    bump = 0.02 * np.sin(25 * u) * np.sin(25 * v)
    height = z + bump
    gy, gx = np.gradient(height * (0.45 * h))
    normal = np.dstack([-gx, gy, np.ones_like(gx)])
    normal /= np.linalg.norm(normal, axis=2, keepdims=True)
    normal = (normal * mask[..., None]).astype(np.float32)
    depth = np.where(mask, 5.0 - height, np.inf).astype(np.float32)
    return normal, depth, mask


def main() -> None:
    report = Report("congruence (LLA Eq. 2) and baselines")
    normal, depth, mask = scene()
    light = comparison_directions()[2]
    img = np.repeat(lambert(normal, light)[..., None], 3, axis=2).astype(np.float32)

    report.time("congruence score (RGB image)", lambda: congruence(img, depth).score, 21, 15.0)
    report.time(
        "congruence score + full-res maps",
        lambda: congruence(img, depth).score_map,
        repeat=9,
    )
    res = congruence(img, depth)
    print(f"  score = {res.score:.3f}, analysis level {res.analysis_shape}")

    # The baselines (no targets: they are references for the comparison, not operators).
    try:
        from ops.baselines import exaggerated_shading, light_warping
    except ImportError as exc:  # ops.curvature not there yet
        print(f"  baselines skipped: {exc}")
        return
    report.time(
        "exaggerated shading (5 scales)",
        lambda: exaggerated_shading(normal, depth, mask, light),
        repeat=7,
    )
    report.time("light warping", lambda: light_warping(normal, depth, mask, light), repeat=5)


if __name__ == "__main__":
    main()
