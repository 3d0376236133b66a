"""The fixed sweep of light directions used to compare depictions (Mestres et al. 2021, §7).

Local Light Alignment scores every technique on "a set of images rendered with 21 different
lighting directions, numbered as in the inset figure" of §7 (Figs. 12-13). The inset itself is
not in the text; what the text says is that #1 is a well-lit direction, #7 is grazing (one side
of the object goes entirely dark) and that the scores drop "when the original light is positioned
away from the camera" (masking, around #7 and #21). Depict's sweep follows that description and is
fixed so that scores are comparable between runs:

- #1 is frontal, ℓ = (0, 0, 1) (towards the camera).
- #2-#21 are four arcs of five directions each, at azimuths φ = 0° (light from the right),
  90° (from above), 180° (from the left) and 270° (from below), in that order; on each arc the
  angle to the view axis is θ = 30°, 60°, 90° (grazing: in the image plane), 120° and 150°
  (behind the object). #4, #9, #14, #19 are grazing; #6, #11, #16, #21 are the furthest behind.

ℓ = (sin θ cos φ, sin θ sin φ, cos θ) in OpenGL camera space (+x right, +y up, +z towards the
camera), pointing from the surface towards the light, unit length.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["ARC_AZIMUTHS_DEG", "ARC_THETAS_DEG", "N_DIRECTIONS", "comparison_directions"]

#: Angles to the view axis on each arc, degrees.
ARC_THETAS_DEG: tuple[float, ...] = (30.0, 60.0, 90.0, 120.0, 150.0)
#: Azimuths of the arcs, degrees (0 = from the right, 90 = from above).
ARC_AZIMUTHS_DEG: tuple[float, ...] = (0.0, 90.0, 180.0, 270.0)
#: Number of directions of the paper's comparison.
N_DIRECTIONS = 1 + len(ARC_THETAS_DEG) * len(ARC_AZIMUTHS_DEG)


def _sweep() -> NDArray[np.float64]:
    theta = [0.0]
    phi = [0.0]
    for az in ARC_AZIMUTHS_DEG:
        for th in ARC_THETAS_DEG:
            theta.append(th)
            phi.append(az)
    t = np.radians(np.asarray(theta))
    p = np.radians(np.asarray(phi))
    dirs = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=1)
    dirs[np.abs(dirs) < 1e-15] = 0.0  # exact zeros instead of 6e-17
    return np.asarray(dirs / np.linalg.norm(dirs, axis=1, keepdims=True))


_DIRECTIONS = _sweep()


def comparison_directions(n: int = N_DIRECTIONS) -> NDArray[np.float32]:
    """The first ``n`` directions of the fixed 21-direction comparison sweep (LLA §7, Fig. 13).

    Parameters
    ----------
    n : int
        How many directions, 1..21 (the sweep is fixed; ``n`` < 21 takes its first ``n``).

    Returns
    -------
    (n, 3) float32
        Unit light directions in camera space (towards the light); row k is direction #k+1.
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 1 <= n <= N_DIRECTIONS:
        raise ValueError(f"n must be an integer in [1, {N_DIRECTIONS}], got {n!r}")
    return _DIRECTIONS[: int(n)].astype(np.float32)
