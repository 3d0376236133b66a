"""Baselines of the LLA comparison: Lambert, Exaggerated Shading, Light Warping (approximation)."""

from __future__ import annotations

import numpy as np
import pytest

from ops.baselines import (
    exaggerated_shading,
    lambert_image,
    light_warping,
    smoothed_normals,
    warp_light,
)
from ops.congruence import congruence
from ops.curvature import isotropic, principal_curvatures
from ops.directions import comparison_directions
from tests import analytic

OBLIQUE = np.array([0.7, 0.0, 0.7], np.float32) / np.float32(np.sqrt(0.98))


def bumpy_sphere(h: int = 160, w: int = 200, amp: float = 0.02, freq: float = 25.0):
    """Sphere with a sinusoidal relief (normal, depth, mask), orthographic."""
    y, x = np.mgrid[0:h, 0:w].astype(np.float64) + 0.5
    s = 0.45 * h
    u, v = (x - w / 2) / s, -(y - h / 2) / s
    mask = u * u + v * v < 1.0
    z = np.sqrt(np.clip(1.0 - u * u - v * v, 0.0, 1.0)) + amp * np.sin(freq * u) * np.sin(freq * v)
    dz_drow, dz_dx = np.gradient(z * s)
    normal = np.dstack([-dz_dx, dz_drow, np.ones_like(z)])  # -dz/dy = +dz/drow (y up)
    normal /= np.linalg.norm(normal, axis=2, keepdims=True)
    normal = (normal * mask[..., None]).astype(np.float32)
    depth = np.where(mask, 5.0 - z, np.inf).astype(np.float32)
    return normal, depth, mask


# -- Lambert --------------------------------------------------------------------------------------


def test_lambert_image_matches_n_dot_l_and_albedo() -> None:
    s = analytic.sphere(64, 0.8)
    img = lambert_image(s.normal, s.mask, OBLIQUE)
    expected = np.clip(s.normal @ OBLIQUE, 0, None)
    np.testing.assert_allclose(img[s.mask], expected[s.mask], atol=1e-6)
    assert np.all(img[~s.mask] == 0.0)
    half = lambert_image(s.normal, s.mask, OBLIQUE * 3.0, albedo=0.5)  # light is normalised
    np.testing.assert_allclose(half, 0.5 * img, atol=1e-6)
    with pytest.raises(ValueError, match="albedo"):
        lambert_image(s.normal, s.mask, OBLIQUE, albedo=np.ones((3, 3)))


# -- Exaggerated Shading -------------------------------------------------------------------------


def test_smoothed_normals_are_unit_and_do_not_bleed() -> None:
    s = analytic.sphere(96, 0.6)
    levels = smoothed_normals(s.normal, s.mask, (0.02, 0.08))
    for lv in levels:
        norm = np.linalg.norm(lv, axis=2)
        np.testing.assert_allclose(norm[s.mask], 1.0, atol=1e-4)
        assert np.all(lv[~s.mask] == 0.0)
    # at the silhouette the smoothed normal still points outwards (no background pulled in)
    row = 48
    edge = np.nonzero(s.mask[row])[0][-1]
    assert levels[1][row, edge, 0] > 0.6
    # coarser = smoother: closer to the sphere's mean normal
    c = (48, 48 + 20)
    assert abs(levels[1][c][0]) < abs(s.normal[c][0])


def test_exaggerated_shading_range_and_difference_from_lambert() -> None:
    normal, depth, mask = bumpy_sphere()
    img = exaggerated_shading(normal, depth, mask, OBLIQUE)
    assert img.dtype == np.float32 and img.shape == depth.shape
    assert np.all(np.isfinite(img))
    assert img.min() >= 0.0 and img.max() <= 1.0
    assert np.all(img[~mask] == 0.0)
    lam = lambert_image(normal, mask, OBLIQUE)
    assert np.abs(img - lam)[mask].mean() > 0.05


def test_exaggerated_shading_reveals_detail_where_lambert_is_black() -> None:
    """RBD06's clamped half-Lambertian keeps every part of the shape visible (LLA §7): with
    the light behind the object, most of the Lambertian image is 0, the exaggerated one is not,
    shows the relief there, and is more congruent with the shape."""
    normal, depth, mask = bumpy_sphere()
    light = comparison_directions()[5]  # 150° from the view axis, from the right
    lam = lambert_image(normal, mask, light)
    img = exaggerated_shading(normal, depth, mask, light)
    dark = mask & (lam == 0.0)
    assert dark.sum() > 0.5 * mask.sum()
    assert img[dark].min() > 0.1
    assert img[dark].std() > 0.05  # the relief is visible in the unlit part
    assert congruence(img, depth).score > congruence(lam, depth).score + 0.05


def test_exaggerated_shading_weights_and_contrast() -> None:
    normal, depth, mask = bumpy_sphere()
    a = exaggerated_shading(normal, depth, mask, OBLIQUE)
    # more contrast saturates the detail terms: the image spreads out
    b = exaggerated_shading(normal, depth, mask, OBLIQUE, contrast=50.0)
    assert b[mask].std() > a[mask].std()
    # the ambient term shifts the image
    c = exaggerated_shading(normal, depth, mask, OBLIQUE, ambient=0.4)
    assert c[mask].mean() == pytest.approx(a[mask].mean() - 0.1, abs=0.01)
    # favouring coarse scales makes the base term dominate: smoother, closer to half-Lambert
    coarse = exaggerated_shading(normal, depth, mask, OBLIQUE, weight_exponent=4.0)
    half_lambert = 0.5 + 0.5 * np.clip(normal @ OBLIQUE, -1, 1)
    assert np.abs(coarse - half_lambert)[mask].mean() < np.abs(a - half_lambert)[mask].mean()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"scales": ()}, "scales"),
        ({"scales": (0.02, 0.01)}, "scales"),
        ({"scales": (0.0, 0.01)}, "scales"),
        ({"contrast": 0.0}, "contrast"),
        ({"ambient": 1.5}, "ambient"),
        ({"weight_exponent": 9.0}, "weight_exponent"),
    ],
)
def test_exaggerated_shading_bad_parameters(kwargs: dict, match: str) -> None:
    s = analytic.sphere(32, 0.8)
    with pytest.raises(ValueError, match=match):
        exaggerated_shading(s.normal, s.depth, s.mask, OBLIQUE, **kwargs)


# -- Light Warping --------------------------------------------------------------------------------


def test_light_warping_brightens_convex_and_darkens_concave() -> None:
    """Documented behaviour: the light a convex point sees is pulled towards the view direction,
    a concave point's pushed away; on a plane nothing changes."""
    bump = analytic.sphere(128, 0.6)
    bowl = analytic.bowl(128, 0.6)
    flat = analytic.plane(128, tilt_x_deg=20.0)
    c = 64
    for scene, sign in ((bump, 1.0), (bowl, -1.0)):
        lw = light_warping(scene.normal, scene.depth, scene.mask, OBLIQUE)
        lam = lambert_image(scene.normal, scene.mask, OBLIQUE)
        assert sign * (lw[c, c] - lam[c, c]) > 0.05
        assert np.all(np.isfinite(lw)) and lw.min() >= 0.0 and lw.max() <= 1.0
        assert np.all(lw[~scene.mask] == 0.0)
    lw = light_warping(flat.normal, flat.depth, flat.mask, OBLIQUE)
    np.testing.assert_allclose(lw, lambert_image(flat.normal, flat.mask, OBLIQUE), atol=1e-5)


def test_light_warping_strength_and_fixed_points() -> None:
    s = analytic.sphere(96, 0.6)
    lam = lambert_image(s.normal, s.mask, OBLIQUE)
    np.testing.assert_allclose(
        light_warping(s.normal, s.depth, s.mask, OBLIQUE, strength=0.0), lam, atol=1e-5
    )
    # frontal light: v is a fixed point of the warp
    front = light_warping(s.normal, s.depth, s.mask, (0, 0, 1), strength=3.0)
    np.testing.assert_allclose(front, lambert_image(s.normal, s.mask, (0, 0, 1)), atol=1e-5)
    # stronger warping moves the convex centre further from Lambert
    c = 48
    d1 = light_warping(s.normal, s.depth, s.mask, OBLIQUE, strength=0.5)[c, c] - lam[c, c]
    d2 = light_warping(s.normal, s.depth, s.mask, OBLIQUE, strength=2.0)[c, c] - lam[c, c]
    assert 0.0 < d1 < d2


def test_light_warping_uses_given_curvature_and_matches_warp_light() -> None:
    s = analytic.sphere(96, 0.6)
    kappa = isotropic(principal_curvatures(s.normal, s.depth, s.mask))
    a = light_warping(s.normal, s.depth, s.mask, OBLIQUE)
    b = light_warping(s.normal, s.depth, s.mask, OBLIQUE, curvature=kappa)
    np.testing.assert_allclose(a, b, atol=1e-5)
    # the general (per-pixel view) path gives the same image for a constant view field
    view = np.broadcast_to(np.float32([0, 0, 1]), s.normal.shape).copy()
    c = light_warping(s.normal, s.depth, s.mask, OBLIQUE, curvature=kappa, view=view)
    np.testing.assert_allclose(a, c, atol=1e-5)
    # warped lights are unit vectors at angle θ' to the view, tan(θ'/2) = e^{-ακ} tan(θ/2)
    lw = warp_light(OBLIQUE, kappa, 1.0)
    np.testing.assert_allclose(np.linalg.norm(lw, axis=2), 1.0, atol=1e-5)
    theta = np.arccos(np.clip(lw[..., 2], -1, 1))
    np.testing.assert_allclose(
        np.tan(theta / 2), np.exp(-kappa) * np.tan(np.pi / 8), rtol=1e-3, atol=1e-5
    )
    # a constant convex curvature everywhere: one warped light for the whole image
    const = light_warping(s.normal, s.depth, s.mask, OBLIQUE, curvature=np.full(s.shape, 0.5))
    lw0 = warp_light(OBLIQUE, np.full((1, 1), 0.5, np.float32), 1.0)[0, 0]
    np.testing.assert_allclose(const, lambert_image(s.normal, s.mask, lw0), atol=1e-5)


def test_light_warping_bad_parameters() -> None:
    s = analytic.sphere(32, 0.8)
    with pytest.raises(ValueError, match="strength"):
        light_warping(s.normal, s.depth, s.mask, OBLIQUE, strength=-1.0)
    with pytest.raises(ValueError, match="curvature"):
        light_warping(s.normal, s.depth, s.mask, OBLIQUE, curvature=np.zeros((3, 3)))
    with pytest.raises(ValueError, match="light_dir"):
        light_warping(s.normal, s.depth, s.mask, (0, 0, 0))
    with pytest.raises(ValueError, match="normal"):
        light_warping(s.normal[..., :2], s.depth, s.mask, OBLIQUE)
    with pytest.raises(ValueError, match="depth"):
        light_warping(s.normal, s.depth[:-1], s.mask, OBLIQUE)
