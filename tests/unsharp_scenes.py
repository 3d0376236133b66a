"""Scenes of the unsharp masking tests: fronto-parallel planes and a square in front of a plane,
seen through a perspective camera (pixel_size = depth / focal_px), and their CIELAB lightness."""

from __future__ import annotations

import numpy as np

from ops.color import rgb_to_lab

FOCAL = 400.0  # pixels


def plane(h: int, w: int, z: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    depth = np.full((h, w), z, np.float32)
    normal = np.zeros((h, w, 3), np.float32)
    normal[..., 2] = 1.0
    mask = np.ones((h, w), bool)
    return depth, normal, mask, depth / np.float32(FOCAL)


def grey(lum: np.ndarray) -> np.ndarray:
    return np.repeat(lum[..., None], 3, axis=2).astype(np.float32)


def lightness(rgb: np.ndarray) -> np.ndarray:
    return rgb_to_lab(rgb, 1.0)[..., 0]


def square_scene(
    h: int = 160, w: int = 160
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A bright square at depth 2 in front of a darker plane at depth 4 (all covered)."""
    depth, normal, mask, _ = plane(h, w, 4.0)
    beauty = np.full((h, w, 3), 0.15, np.float32)
    fg = np.zeros((h, w), bool)
    fg[50:110, 50:110] = True
    depth[fg] = 2.0
    beauty[fg] = 0.7
    return beauty, depth, normal, mask, depth / np.float32(FOCAL), fg
