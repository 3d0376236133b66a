"""The shipped Apparent Relief Maps and the painting template (Fig. 1a's domain)."""

from __future__ import annotations

import math
import pathlib
from collections.abc import Callable

import cv2
import numpy as np
from numpy.typing import NDArray

from ops.relief._common import (
    _ARM_DIR,
    F32,
    PLANE_RADIUS,
    REGION_ANGLES,
    SHIPPED_ARM_SIZE,
    SHIPPED_ARMS,
)
from ops.relief.arm import arm_coords, s_to_uv, uv_to_texel
from ops.relief.shape import _polar, descriptor_colors

__all__ = ["SHIPPED_ARM_VALUES", "arm_template", "make_arm", "shipped_arm_path"]

# -- shipped ARMs and the template -----------------------------------------------------------------


def _smoothstep(e0: float, e1: float, x: NDArray[np.floating]) -> F32:
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return np.asarray(t * t * (3.0 - 2.0 * t), np.float32)


def _arm_convex_black_concave_white(rho: F32, t: F32, feat: F32) -> F32:
    conv = np.clip(1.6 * np.cos(np.radians(t)), -1.0, 1.0)
    return np.asarray(0.5 - 0.5 * conv * feat, np.float32)


def _arm_planar_filtered(rho: F32, t: F32, feat: F32) -> F32:
    return feat


def _arm_saddles_only(rho: F32, t: F32, feat: F32) -> F32:
    return np.asarray(feat * (1.0 - _smoothstep(15.0, 30.0, np.abs(t - 90.0))), np.float32)


def _arm_caps_and_cups(rho: F32, t: F32, feat: F32) -> F32:
    ends = np.minimum(t, 180.0 - t)
    return np.asarray(feat * (1.0 - _smoothstep(15.0, 30.0, ends)), np.float32)


def _arm_convex_only(rho: F32, t: F32, feat: F32) -> F32:
    return np.asarray(feat * (1.0 - _smoothstep(60.0, 75.0, t)), np.float32)


_ARM_MAKERS: dict[str, Callable[[F32, F32, F32], F32]] = {
    "convex_black_concave_white": _arm_convex_black_concave_white,
    "planar_filtered": _arm_planar_filtered,
    "saddles_only": _arm_saddles_only,
    "caps_and_cups": _arm_caps_and_cups,
    "convex_only": _arm_convex_only,
}

#: The value each shipped ARM holds at the centre of each region (|S| = 1 on the region's angle,
#: S = 0 for the plane); what tests and documentation rely on.
SHIPPED_ARM_VALUES: dict[str, dict[str, float]] = {
    "convex_black_concave_white": {
        "plane": 0.5,
        "cap": 0.0,
        "convex": 0.0,
        "saddle": 0.5,
        "concave": 1.0,
        "cup": 1.0,
    },
    "planar_filtered": {
        "plane": 0.0,
        "cap": 1.0,
        "convex": 1.0,
        "saddle": 1.0,
        "concave": 1.0,
        "cup": 1.0,
    },
    "saddles_only": {
        "plane": 0.0,
        "cap": 0.0,
        "convex": 0.0,
        "saddle": 1.0,
        "concave": 0.0,
        "cup": 0.0,
    },
    "caps_and_cups": {
        "plane": 0.0,
        "cap": 1.0,
        "convex": 0.0,
        "saddle": 0.0,
        "concave": 0.0,
        "cup": 1.0,
    },
    "convex_only": {
        "plane": 0.0,
        "cap": 1.0,
        "convex": 1.0,
        "saddle": 0.0,
        "concave": 0.0,
        "cup": 0.0,
    },
}


def make_arm(name: str, size: int = SHIPPED_ARM_SIZE) -> F32:
    """Generate a shipped ARM (size x size float32 in [0, 1]); the PNGs in ``ops/data/arm`` are
    these, quantised to 8 bits (``python -m bench.make_arms`` rewrites them).

    Features (|S| > 0.3) vs planes (|S| < 0.2) fade smoothly; angular boundaries are soft over
    15° so the bilinear lookup does not alias. Values at each region's centre
    (:data:`SHIPPED_ARM_VALUES`):

    - ``convex_black_concave_white`` (Fig. 1d): caps/convex 0, cups/concave 1, saddles and
      planes 0.5, i.e. ``0.5 − 0.5 · clip(1.6 cos t, −1, 1) · feature``;
    - ``planar_filtered`` (Fig. 1c): 0 on planes, 1 on every feature;
    - ``saddles_only``: 1 within 15° of the saddle direction, 0 elsewhere;
    - ``caps_and_cups``: 1 within 15° of the symmetry axis (caps and cups), 0 elsewhere;
    - ``convex_only`` (the mask of Fig. 2c): 1 on caps and convex regions (t < 60°), 0 on
      saddles, concave regions, cups and planes.
    """
    if name not in _ARM_MAKERS:
        raise ValueError(f"ARM name {name!r} is not one of {', '.join(SHIPPED_ARMS)}")
    grid = arm_coords(int(size))
    rho, t = _polar(grid)
    feat = _smoothstep(PLANE_RADIUS - 0.05, PLANE_RADIUS + 0.05, rho)
    return np.ascontiguousarray(np.clip(_ARM_MAKERS[name](rho, t, feat), 0.0, 1.0), np.float32)


def shipped_arm_path(name: str) -> pathlib.Path:
    """Path of a shipped ARM PNG (8-bit grey, ``ops/data/arm/<name>.png``); see
    :data:`SHIPPED_ARMS`. Read it with the frame I/O and pass it through :func:`arm_from_image`."""
    if name not in SHIPPED_ARMS:
        raise ValueError(f"ARM name {name!r} is not one of {', '.join(SHIPPED_ARMS)}")
    return _ARM_DIR / f"{name}.png"


def arm_template(size: int = 256) -> F32:
    """The descriptor domain in the Fig. 1a colour code, for an artist to paint an ARM on.

    (size, size, 3) float32 RGB in [0, 1], laid out as ARMs are indexed (κ1 to the right, κ2
    upwards, plane at the centre). Marked: the κ1 and κ2 axes, the symmetry axis κ1 = κ2, the
    unit circle (|S| = 1), the plane disc (|S| = PLANE_RADIUS), the region boundaries, and region
    labels. The half above the symmetry axis (κ2 > κ1) is never looked up: it is shown dimmed
    (mirrored colours) and labelled "unused".
    """
    n = int(size)
    if not 64 <= n <= 4096:
        raise ValueError(f"size={size!r} is outside the allowed range [64, 4096]")
    grid = arm_coords(n)
    col = descriptor_colors(grid)
    s1, s2 = grid[:, :, 0], grid[:, :, 1]
    rho = np.hypot(s1, s2)
    grey = np.float32(0.62)
    unused = (s2 > s1)[:, :, None]
    col = np.where(unused, 0.45 * col + 0.55 * grey, col)
    col = np.where((rho > 1.0)[:, :, None], 0.35 * col + 0.65 * np.float32(0.9), col)
    img = np.ascontiguousarray(np.clip(col * 255.0 + 0.5, 0, 255).astype(np.uint8))

    def px(a: float, b: float) -> tuple[int, int]:
        x, y = uv_to_texel(*s_to_uv(a, b), (n, n))
        return round(x), round(y)

    ink = (40, 40, 40)
    thin = max(1, n // 256)
    aa = cv2.LINE_AA
    c = px(0.0, 0.0)
    rad_px = round((n - 1) / 2)
    cv2.line(img, px(-1.0, 0.0), px(1.0, 0.0), ink, thin, aa)  # κ2 = 0 (the κ1 axis)
    cv2.line(img, px(0.0, -1.0), px(0.0, 1.0), ink, thin, aa)  # κ1 = 0 (the κ2 axis)
    cv2.line(img, px(-1.0, -1.0), px(1.0, 1.0), (90, 90, 90), thin, aa)  # symmetry axis
    cv2.circle(img, c, rad_px, ink, thin, aa)
    cv2.circle(img, c, round(PLANE_RADIUS * (n - 1) / 2), ink, thin, aa)
    for deg in (22.5, 67.5, 112.5, 157.5):  # region boundaries in the reached half
        th = math.radians(45.0 - deg)
        a, b = math.cos(th), math.sin(th)
        cv2.line(img, px(PLANE_RADIUS * a, PLANE_RADIUS * b), px(a, b), (110, 110, 110), thin, aa)
    font = cv2.FONT_HERSHEY_SIMPLEX
    scale = n / 640.0
    # Labels at 0.68 of the radius on each region's angle, nudged off the axis lines.
    nudge = {"convex": -9.0, "concave": 9.0}
    labels = [(k, 0.68, a + nudge.get(k, 0.0)) for k, a in REGION_ANGLES.items()]
    for text, r, deg in [*labels, ("plane", 0.13, -45.0), ("unused", 0.62, 135.0)]:
        th = math.radians(deg)
        (tw, tht), _ = cv2.getTextSize(text, font, scale, thin)
        x, y = px(r * math.cos(th), r * math.sin(th))
        cv2.putText(img, text, (x - tw // 2, y + tht // 2), font, scale, ink, thin, aa)
    for text, org in (
        ("k1", (n - round(0.09 * n), c[1] - round(0.02 * n))),
        ("k2", (c[0] + round(0.02 * n), round(0.06 * n))),
    ):
        cv2.putText(img, text, org, font, scale, ink, thin, aa)
    return np.asarray(img.astype(np.float32) / 255.0, np.float32)
