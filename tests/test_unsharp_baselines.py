"""The baselines of 3D unsharp masking: the plain 2-D unsharp mask and the depth-buffer unsharp
mask (Luft et al. 2006)."""

from __future__ import annotations

import numpy as np
import pytest

from ops.unsharp import depth_unsharp_masking, plain_unsharp_mask
from tests.unsharp_scenes import grey, lightness, plane, square_scene

# ------------------------------------------------------------------------------------------------
# baselines


def test_plain_unsharp_mask_sharpens_across_everything() -> None:
    beauty, *_ = square_scene()
    out = plain_unsharp_mask(beauty, sigma=0.03, amount=1.0, white=1.0)
    c = lightness(out) - lightness(beauty)
    assert c[80, 48] < -3.0 and c[80, 51] > 3.0
    np.testing.assert_allclose(
        plain_unsharp_mask(beauty, sigma=0.03, amount=0.0, white=1.0), beauty, rtol=1e-5
    )
    with pytest.raises(ValueError, match="sigma"):
        plain_unsharp_mask(beauty, sigma=0.0, amount=1.0)
    with pytest.raises(ValueError, match="amount"):
        plain_unsharp_mask(beauty, sigma=0.01, amount=float("inf"))


def test_depth_unsharp_masking_darkens_behind_silhouettes_only() -> None:
    beauty, depth, _, mask, _, fg = square_scene()
    out = depth_unsharp_masking(beauty, depth, mask, amount=1.0, sigma=0.03, white=1.0)
    c = lightness(out) - lightness(beauty)
    ring = np.zeros_like(fg)
    ring[46:114, 46:114] = True
    ring &= ~fg
    assert c[ring].max() < -1.0  # the plane just behind the square darkens (ΔD < 0)
    assert np.abs(c[fg]).max() < 1e-3  # darken mode: nearer side untouched (ΔD > 0 there)
    assert np.abs(c[:10, :10]).max() < 1e-3  # far from the silhouette: ΔD = 0
    both = depth_unsharp_masking(
        beauty, depth, mask, amount=1.0, sigma=0.03, mode="both", white=1.0
    )
    cb = lightness(both) - lightness(beauty)
    assert cb[fg].max() > 1.0  # "both" brightens the nearer side
    # a flat plane is left unchanged, fronto-parallel or slanted (ΔD = G∗D − D = 0)
    h, w = 96, 128
    pd, _, pm, _ = plane(h, w, 3.0)
    flat_img = grey(np.full((h, w), 0.3, np.float32))
    np.testing.assert_allclose(
        depth_unsharp_masking(flat_img, pd, pm, amount=2.0, sigma=0.05, white=1.0),
        flat_img,
        rtol=1e-4,
    )
    slanted = (3.0 + 0.02 * np.arange(h, dtype=np.float32)[:, None] + 0 * pd).astype(np.float32)
    res = depth_unsharp_masking(
        flat_img, slanted, pm, amount=2.0, sigma=0.05, mode="both", white=1.0
    )
    # G∗D − D = 0 on a linear ramp, away from the image's top and bottom rows (replicated border)
    np.testing.assert_allclose(res[16:-16], flat_img[16:-16], rtol=1e-3)
    # background (mask 0) pixels are returned unchanged
    m2 = fg.copy()
    d2 = np.where(fg, depth, np.inf).astype(np.float32)
    out2 = depth_unsharp_masking(beauty, d2, m2, amount=1.0, sigma=0.03, white=1.0)
    assert np.array_equal(out2[~fg], beauty[~fg])
    with pytest.raises(ValueError, match="mode"):
        depth_unsharp_masking(beauty, depth, mask, mode="lighten")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="sigma"):
        depth_unsharp_masking(beauty, depth, mask, sigma=2.0)


def test_depth_unsharp_masking_leaves_the_far_edge_of_a_floor_alone() -> None:
    """A floor receding to the top of the frame, with sky above it: its far edge borders the
    background, which lies beyond it, so the blur pulls the edge back and darkening (ΔD < 0)
    must not appear there (it did when the background took the farthest surface's depth)."""
    h, w = 96, 128
    rows = np.arange(h, dtype=np.float32)[:, None]
    floor = np.broadcast_to(10.0 - 0.06 * rows, (h, w)).astype(np.float32)  # far at the top
    sky = rows < 24
    depth = np.where(sky, np.inf, floor).astype(np.float32)
    mask = ~np.broadcast_to(sky, (h, w))
    img = grey(np.full((h, w), 0.3, np.float32))
    out = depth_unsharp_masking(img, depth, mask, amount=2.0, sigma=0.05, white=1.0)
    change = lightness(out) - lightness(img)
    assert np.abs(change[24:-16]).max() < 1e-2  # the whole floor, its far edge included
