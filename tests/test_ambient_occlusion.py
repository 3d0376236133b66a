"""Screen-space ambient occlusion (ops.ambient_occlusion.ssao) on analytic depth buffers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ops.ambient_occlusion import ssao

H, W = 96, 128


def ortho_grid(pixel_size: float) -> tuple[np.ndarray, np.ndarray]:
    """Camera-space x, y of pixel centres of an orthographic camera centred on the image."""
    x = (np.arange(W) + 0.5 - W / 2) * pixel_size
    y = -(np.arange(H) + 0.5 - H / 2) * pixel_size
    return np.meshgrid(x, y)


def heightfield(depth: np.ndarray, pixel_size: float) -> np.ndarray:
    """Normals of an orthographic depth map z = -depth(x, y), by central differences."""
    dz_dx = -np.gradient(depth, pixel_size, axis=1)
    dz_dy = np.gradient(depth, pixel_size, axis=0)  # rows grow downwards: d/dy = -d/drow
    n = np.stack([-dz_dx, -dz_dy, np.ones_like(depth)], axis=2)
    return (n / np.linalg.norm(n, axis=2, keepdims=True)).astype(np.float32)


def perspective_plane(focal: float, normal: np.ndarray, point: np.ndarray) -> np.ndarray:
    """Planar depth of the plane (normal, point) through each pixel centre's ray."""
    x = (np.arange(W) + 0.5 - W / 2) / focal
    y = -(np.arange(H) + 0.5 - H / 2) / focal
    gx, gy = np.meshgrid(x, y)
    rays = np.stack([gx, gy, -np.ones_like(gx)], axis=2)  # P = depth * ray
    depth = float(normal @ point) / (rays @ normal)
    return depth.astype(np.float32)


def test_plane_is_unoccluded_orthographic_and_perspective() -> None:
    ps = 0.02
    x, y = ortho_grid(ps)
    depth = (5.0 + 0.3 * x - 0.2 * y).astype(np.float32)  # a tilted plane
    ao = ssao(depth, heightfield(depth, ps), radius=0.3, pixel_size=ps)
    assert ao.dtype == np.float32 and ao.shape == (H, W)
    assert ao.min() > 0.99

    n = np.array([0.3, -0.4, 0.866])
    n /= np.linalg.norm(n)
    focal = 100.0
    depth = perspective_plane(focal, n, np.array([0.0, 0.0, -4.0]))
    normal = np.broadcast_to(n.astype(np.float32), (H, W, 3))
    ao = ssao(depth, normal, radius=0.5, focal_px=focal)
    assert ao.min() > 0.99


def test_inside_corner_is_darker_than_the_flat_part() -> None:
    """A 90° valley (two perpendicular planes, crease along y) seen from the front."""
    ps = 0.02
    x, _ = ortho_grid(ps)
    depth = (5.0 - np.abs(x)).astype(np.float32)  # the crease at x = 0 is farthest: concave
    normal = np.zeros((H, W, 3), np.float32)
    normal[..., 0] = -np.sign(x) / math.sqrt(2.0)
    normal[..., 2] = 1.0 / math.sqrt(2.0)
    ao = ssao(depth, normal, radius=0.3, pixel_size=ps)
    crease = ao[:, np.abs(x[0]) < 0.05]
    flat = ao[:, np.abs(x[0]) > 0.5]
    assert crease.mean() < 0.8
    assert flat.min() > 0.98
    assert crease.mean() < flat.mean() - 0.2
    # occlusion grows towards the crease
    profile = ao.mean(axis=0)[W // 2 :]
    assert profile[2] < profile[6] < profile[12] <= profile[20] + 1e-6

    # the same shape turned inside out (a ridge, convex) is not occluded
    ridge = (5.0 + np.abs(x)).astype(np.float32)
    normal_r = normal.copy()
    normal_r[..., 0] *= -1.0
    assert ssao(ridge, normal_r, radius=0.3, pixel_size=ps).min() > 0.98


def test_step_occludes_its_foot_within_the_radius_only() -> None:
    ps = 0.02
    x, _ = ortho_grid(ps)
    normal = np.zeros((H, W, 3), np.float32)
    normal[..., 2] = 1.0
    # a step 0.2 high (left part closer) with R = 0.4: its top occludes the foot
    depth = np.where(x < 0.0, 4.8, 5.0).astype(np.float32)
    col = ssao(depth, normal, radius=0.4, pixel_size=ps).mean(axis=0)
    assert col[(x[0] > 0.0) & (x[0] < 0.1)].mean() < 0.85  # at the foot of the step
    assert col[x[0] > 0.5].min() > 0.98  # farther than R from the step
    assert col[x[0] < -0.1].min() > 0.98  # the top of the step is not occluded
    # a step higher than R (a silhouette over a distant background) casts no halo
    deep = np.where(x < 0.0, 4.0, 5.0).astype(np.float32)
    assert ssao(deep, normal, radius=0.4, pixel_size=ps).min() > 0.98


def test_background_is_one_and_finite() -> None:
    ps = 0.02
    x, y = ortho_grid(ps)
    r2 = x**2 + y**2
    inside = r2 < 0.6**2
    zc = np.sqrt(np.maximum(0.6**2 - r2, 0.0))
    depth = np.where(inside, 5.0 - zc, np.inf).astype(np.float32)
    normal = np.zeros((H, W, 3), np.float32)
    normal[..., 0] = np.where(inside, x / 0.6, 0.0)
    normal[..., 1] = np.where(inside, y / 0.6, 0.0)
    normal[..., 2] = np.where(inside, zc / 0.6, 0.0)
    ao = ssao(depth, normal, radius=0.2, pixel_size=ps)
    assert np.all(np.isfinite(ao))
    assert np.all(ao[~inside] == 1.0)
    assert ao[inside].min() > 0.97  # a sphere is convex
    # an all-background image
    empty = ssao(np.full((8, 8), np.inf, np.float32), np.zeros((8, 8, 3), np.float32),
                 radius=1.0, focal_px=10.0)  # fmt: skip
    assert np.all(empty == 1.0)


def test_rotation_jitter_blur_and_threads_give_the_same_result() -> None:
    ps = 0.02
    x, _ = ortho_grid(ps)
    depth = (5.0 - np.abs(x)).astype(np.float32)
    normal = heightfield(depth, ps)
    one = ssao(depth, normal, radius=0.3, pixel_size=ps, threads=1)
    two = ssao(depth, normal, radius=0.3, pixel_size=ps, threads=2)
    np.testing.assert_array_equal(one, two)
    raw = ssao(depth, normal, radius=0.3, pixel_size=ps, blur=False)
    assert np.all((raw >= 0.0) & (raw <= 1.0))
    assert abs(float(raw.mean()) - float(one.mean())) < 0.01


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"radius": 0.0, "focal_px": 100.0}, "radius"),
        ({"radius": 1.0}, "exactly one"),
        ({"radius": 1.0, "focal_px": 100.0, "pixel_size": 0.1}, "exactly one"),
        ({"radius": 1.0, "focal_px": -1.0}, "focal_px"),
        ({"radius": 1.0, "pixel_size": 0.0}, "pixel_size"),
        ({"radius": 1.0, "focal_px": 100.0, "directions": 0}, "directions"),
        ({"radius": 1.0, "focal_px": 100.0, "steps": 33}, "steps"),
        ({"radius": 1.0, "focal_px": 100.0, "bias_deg": 60.0}, "bias_deg"),
    ],
)
def test_bad_parameters(kwargs: dict[str, float], match: str) -> None:
    depth = np.ones((8, 8), np.float32)
    normal = np.zeros((8, 8, 3), np.float32)
    with pytest.raises(ValueError, match=match):
        ssao(depth, normal, **kwargs)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="normal"):
        ssao(depth, normal[:4], radius=1.0, focal_px=10.0)
