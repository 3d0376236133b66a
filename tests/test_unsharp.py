"""3D unsharp masking (Ritschel et al. 2008) and linear RGB <-> CIELAB (the baselines:
test_unsharp_baselines.py).

Scenes are built inline: fronto-parallel or slanted planes and a square in front of a plane,
seen through a perspective camera (pixel_size = depth / focal_px) unless stated otherwise.
"""

from __future__ import annotations

import numpy as np
import pytest

from ops.color import (
    auto_white,
    lab_phi_to_rgb,
    lab_to_rgb,
    luminance,
    resolve_white,
    rgb_to_lab,
    rgb_to_lab_phi,
)
from ops.unsharp import (
    plain_unsharp_mask,
    surface_blur,
    surface_blur_rows,
    surface_blurs,
    unsharp_lightness,
    unsharp_masking,
)
from tests import analytic
from tests.unsharp_scenes import FOCAL, grey, lightness, plane, square_scene

# ------------------------------------------------------------------------------------------------
# helpers


def _lab_ref(rgb: np.ndarray, white: float = 1.0) -> np.ndarray:
    """CIE 15 CIELAB in float64, straight from the definition (sRGB primaries, D65)."""
    m = np.array(
        [
            [0.4124564, 0.3575761, 0.1804375],
            [0.2126729, 0.7151522, 0.0721750],
            [0.0193339, 0.1191920, 0.9503041],
        ]
    )
    t = (rgb.astype(np.float64) / white) @ m.T / m.sum(axis=1)
    d = 6.0 / 29.0
    f = np.where(t > d**3, np.cbrt(t), t / (3 * d * d) + 4.0 / 29.0)
    return np.stack(
        [116 * f[..., 1] - 16, 500 * (f[..., 0] - f[..., 1]), 200 * (f[..., 1] - f[..., 2])], -1
    )


# ------------------------------------------------------------------------------------------------
# colour


def test_lab_matches_cie_definition_and_round_trips_hdr() -> None:
    rng = np.random.default_rng(1)
    rgb = (rng.random((64, 96, 3), dtype=np.float32) ** 3) * 6.0  # HDR, mostly dark
    rgb[0, :8] = [[0, 0, 0], [1, 1, 1], [4, 4, 4], [1e-4, 2e-4, 5e-5], [-0.01, 0.02, 0.0]] + [
        [20.0, 0.5, 0.1]
    ] * 3
    white = 2.0
    lab = rgb_to_lab(rgb, white)
    assert lab.dtype == np.float32
    assert np.abs(lab - _lab_ref(rgb, white)).max() < 2e-3
    # above the white level L* > 100, not clipped (OpenCV's COLOR_LRGB2Lab clips to 100)
    assert lab[0, 2, 0] == pytest.approx(_lab_ref(rgb[0:1, 2:3], white)[0, 0, 0], abs=1e-3)
    assert lab[0, 2, 0] > 120.0
    back = lab_to_rgb(lab, white)
    # relative to the pixel's magnitude, with a floor of 1e-4 of the white level (black)
    scale = np.maximum(np.abs(rgb).max(axis=2, keepdims=True), 1e-4 * white)
    assert (np.abs(back - rgb) / scale).max() < 1e-4


def test_lab_without_dark_values_takes_the_same_values() -> None:
    # nothing below the CIE knee (t > (6/29)³): the pure cube-root path
    rng = np.random.default_rng(4)
    rgb = 0.05 + rng.random((32, 48, 3), dtype=np.float32) * 5.0
    lab = rgb_to_lab(rgb, 1.0)
    assert np.abs(lab - _lab_ref(rgb)).max() < 2e-3
    back = lab_to_rgb(lab, 1.0)
    assert (np.abs(back - rgb) / rgb.max(axis=2, keepdims=True)).max() < 1e-4


def test_lab_phi_is_linear_in_lab() -> None:
    rng = np.random.default_rng(2)
    rgb = rng.random((16, 16, 3), dtype=np.float32) * 3.0
    phi = rgb_to_lab_phi(rgb, 1.5)
    lab = rgb_to_lab(rgb, 1.5)
    np.testing.assert_allclose(116 * phi[..., 1], lab[..., 0], atol=2e-4)
    np.testing.assert_allclose(500 * (phi[..., 0] - phi[..., 1]), lab[..., 1], atol=2e-4)
    np.testing.assert_allclose(200 * (phi[..., 1] - phi[..., 2]), lab[..., 2], atol=2e-4)
    np.testing.assert_allclose(lab_phi_to_rgb(phi, 1.5), rgb, rtol=1e-4, atol=1e-6)


def test_white_level_auto_and_pinned() -> None:
    rgb = np.zeros((40, 50, 3), np.float32)
    rgb[:, :25] = 0.5
    rgb[:, 25:] = 8.0  # only this half is covered
    mask = np.zeros((40, 50), bool)
    mask[:, 25:] = True
    assert auto_white(rgb, mask) == pytest.approx(8.0, rel=1e-5)
    assert resolve_white("auto", rgb, ~mask) == pytest.approx(0.5, rel=1e-5)
    assert resolve_white(3.0, rgb) == 3.0
    assert auto_white(np.zeros((8, 8, 3), np.float32)) == 1.0
    np.testing.assert_allclose(luminance(rgb)[0, 0], 0.5, rtol=1e-5)
    with pytest.raises(ValueError, match="white"):
        resolve_white(-1.0, rgb)
    with pytest.raises(ValueError, match="white"):
        resolve_white("bright", rgb)  # type: ignore[arg-type]


# ------------------------------------------------------------------------------------------------
# 3D unsharp masking


@pytest.mark.parametrize("with_normals", [True, False])
def test_step_edge_gets_cornsweet_profile(with_normals: bool) -> None:
    h, w = 96, 256
    depth, normal, mask, ps = plane(h, w, 3.0)
    lum = np.where(np.arange(w) < w // 2, 0.08, 0.3).astype(np.float32)
    beauty = grey(np.broadcast_to(lum, (h, w)))
    out = unsharp_masking(
        beauty,
        depth,
        normal if with_normals else None,
        mask,
        amount=1.5,
        sigma_scene=0.08,
        pixel_size=ps,
        white=1.0,
    )
    l0, l1 = lightness(beauty)[h // 2], lightness(out)[h // 2]
    c = l1 - l0
    e = w // 2
    assert c[e - 3 : e].max() < -3.0  # dark side darker next to the edge
    assert c[e : e + 3].min() > 3.0  # bright side brighter next to the edge
    # the overshoot decays away from the edge (σ = 0.08 scene units = 10.7 px here)
    assert abs(c[5]) < 0.05 * abs(c[e - 1]) and abs(c[-6]) < 0.05 * abs(c[e])
    assert np.all(np.diff(c[e : e + 60]) <= 1e-3)  # monotone decay: a Cornsweet profile
    assert np.all(np.diff(c[e - 60 : e]) <= 1e-3)
    # mean lightness over the region is kept (within a few %)
    assert abs(l1.mean() - l0.mean()) < 0.02 * l0.mean()


def test_hue_and_saturation_unchanged_on_coloured_ramp() -> None:
    h, w = 64, 192
    depth, normal, mask, ps = plane(h, w, 3.0)
    x = np.linspace(0.0, 1.0, w, dtype=np.float32)
    y = np.linspace(0.0, 1.0, h, dtype=np.float32)[:, None]
    beauty = np.stack(
        [0.05 + 0.6 * x**2 + 0 * y, 0.02 + 0.3 * x * (0.5 + y), 0.3 * (1 - x) + 0.05 * y], -1
    ).astype(np.float32)
    beauty[:, w // 2 :] *= 1.8  # a lightness step to enhance
    out = unsharp_masking(
        beauty, depth, normal, mask, amount=2.0, sigma_scene=0.05, pixel_size=ps, white=1.0
    )
    lab0, lab1 = _lab_ref(beauty), _lab_ref(out)
    assert np.abs(lab1[..., 0] - lab0[..., 0]).max() > 2.0  # it did enhance
    c0, c1 = np.hypot(lab0[..., 1], lab0[..., 2]), np.hypot(lab1[..., 1], lab1[..., 2])
    ok = c0 > 1.0
    dh = np.angle(
        np.exp(
            1j * (np.arctan2(lab1[..., 2], lab1[..., 1]) - np.arctan2(lab0[..., 2], lab0[..., 1]))
        )
    )
    assert np.abs(dh[ok]).max() < 1e-3
    s0, s1 = c0 / lab0[..., 0], c1 / lab1[..., 0]
    assert (np.abs(s1 - s0) / s0)[ok].max() < 1e-3


def _textured_square_scene() -> tuple[
    np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray
]:
    """The square scene with a lightness step on the square and one on the plane."""
    beauty, depth, normal, mask, ps, fg = square_scene()
    beauty[50:110, 80:110] = 0.35
    beauty[:, 130:] = 0.4
    return beauty, depth, normal, mask, ps, fg


def test_zero_gain_is_identity() -> None:
    beauty, depth, normal, mask, ps, _ = _textured_square_scene()
    kw = dict(sigma_scene=0.1, pixel_size=ps, white="auto")
    out0 = unsharp_masking(beauty, depth, normal, mask, amount=0.0, **kw)
    np.testing.assert_allclose(out0, beauty, rtol=1e-6, atol=0)
    gain = np.zeros(depth.shape, np.float32)
    outg = unsharp_masking(beauty, depth, normal, mask, amount=2.0, gain_map=gain, **kw)
    np.testing.assert_allclose(outg, beauty, rtol=1e-6, atol=0)
    # and a non-zero gain does change it (the test could fail)
    out1 = unsharp_masking(beauty, depth, normal, mask, amount=2.0, **kw)
    assert np.abs(out1 - beauty).max() > 0.05


def test_gain_map_scales_and_flips_the_contrast() -> None:
    beauty, depth, normal, mask, ps, _ = _textured_square_scene()
    kw = dict(amount=1.0, sigma_scene=0.1, pixel_size=ps, white=1.0, adaptive=False)
    gain = np.full(depth.shape, -1.0, np.float32)
    pos = lightness(unsharp_masking(beauty, depth, normal, mask, **kw)) - lightness(beauty)
    neg = lightness(unsharp_masking(beauty, depth, normal, mask, gain_map=gain, **kw))
    neg -= lightness(beauty)
    sel = np.abs(pos) > 0.5
    assert sel.sum() > 50
    np.testing.assert_allclose(neg[sel], -pos[sel], rtol=0.02, atol=0.05)


def test_no_halo_across_depth_discontinuity() -> None:
    beauty, depth, normal, mask, ps, fg = square_scene()
    out = unsharp_masking(
        beauty, depth, normal, mask, amount=2.0, sigma_scene=0.1, pixel_size=ps, white=1.0
    )
    plain = plain_unsharp_mask(beauty, sigma=0.05, amount=2.0, white=1.0)
    # background pixels within 6 px of the silhouette
    ring = np.zeros_like(fg)
    ring[44:116, 44:116] = True
    ring &= ~fg
    rel = np.abs(out[ring] - beauty[ring]) / beauty[ring]
    assert rel.max() < 1e-4  # the plane behind is untouched by the bright square
    assert (np.abs(plain[ring] - beauty[ring]) / beauty[ring]).max() > 0.1  # 2-D USM darkens it
    # the square itself still gets its Cornsweet rim against its own (flat) surface: none,
    # as it is uniform - and nothing leaks in from the darker plane either
    assert (np.abs(out[fg] - beauty[fg]) / beauty[fg]).max() < 1e-4


def test_halo_free_against_empty_background_and_nan_depth() -> None:
    beauty, depth, normal, mask, ps, fg = square_scene()
    mask = fg.copy()
    depth[~fg] = np.inf
    ps = np.where(fg, ps, np.nan).astype(np.float32)
    normal[~fg] = np.nan
    beauty[:] = 0.0
    beauty[50:110, 50:80] = 0.3  # a vertical step on the square
    beauty[50:110, 80:110] = 0.7
    out = unsharp_masking(
        beauty, depth, normal, mask, amount=2.0, sigma_scene=0.05, pixel_size=ps, white=1.0
    )
    assert np.all(np.isfinite(out))
    assert np.array_equal(out[~fg], beauty[~fg])  # background bit for bit
    c = lightness(out) - lightness(beauty)
    assert c[80, 80:83].min() > 2.0 and c[80, 77:80].max() < -2.0  # the step is enhanced
    # the signal is constant down each column of the square, so is the enhancement: the black
    # background above and below does not darken the square's rim
    cols = c[50:110, 52:108]
    assert np.abs(cols - cols[30]).max() < 0.05


@pytest.mark.parametrize(
    ("width", "z_front", "depth_sigma"), [(1, 3.6, 1.0), (3, 2.0, 1.0), (2, 3.9, 0.25)]
)
def test_no_halo_from_thin_object_in_front(width: int, z_front: float, depth_sigma: float) -> None:
    # a bright bar `width` pixels wide in front of a dark plane at depth 4; σ = 0.1, so the gap
    # is 4 σ (default depth_sigma keeps > ~3 σ apart) or 1 σ (depth_sigma = 0.25: > ~0.75 σ)
    h, w = 128, 192
    depth, normal, mask, _ = plane(h, w, 4.0)
    beauty = np.full((h, w, 3), 0.15, np.float32)
    bar = np.zeros((h, w), bool)
    bar[20:108, 90 : 90 + width] = True
    depth[bar] = z_front
    beauty[bar] = 0.8
    out = unsharp_masking(
        beauty,
        depth,
        normal,
        mask,
        amount=2.0,
        sigma_scene=0.1,
        pixel_size=depth / np.float32(FOCAL),
        white=1.0,
        depth_sigma=depth_sigma,
    )
    assert (np.abs(out[~bar] - beauty[~bar]) / 0.15).max() < 1e-4
    # while layers closer than that are smoothed together (the plane darkens next to the bar)
    if depth_sigma == 0.25:
        near = unsharp_masking(
            beauty,
            depth,
            normal,
            mask,
            amount=2.0,
            sigma_scene=0.1,
            pixel_size=depth / np.float32(FOCAL),
            white=1.0,
        )
        assert (np.abs(near[~bar] - beauty[~bar]) / 0.15).max() > 0.05


def test_grazing_ground_plane_stays_clean_around_a_floating_ball() -> None:
    # a uniform ground plane seen at grazing angles up to the horizon, and a bright ball floating
    # above it: the ground (constant radiance) must come out unchanged everywhere
    h, w = 120, 200
    f = 150.0
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    rays = np.dstack([(x + 0.5 - w / 2) / f, (h / 2 - y - 0.5) / f, -np.ones_like(x)])
    rays /= np.linalg.norm(rays, axis=2, keepdims=True)
    with np.errstate(divide="ignore"):
        t = np.where(rays[..., 1] < -1e-3, -1.0 / rays[..., 1], np.inf)
    t[t * -rays[..., 2] > 40.0] = np.inf
    normal = np.zeros((h, w, 3))
    normal[np.isfinite(t)] = [0.0, 1.0, 0.0]
    c, r = np.array([0.0, 0.2, -6.0]), 0.8  # 0.4 above the ground
    b = rays @ c
    disc = b * b - (c @ c - r * r)
    ts = np.where(disc > 0, b - np.sqrt(np.maximum(disc, 0.0)), np.inf)
    ball = ts < t
    t[ball] = ts[ball]
    normal[ball] = ((rays * ts[..., None] - c) / r)[ball]
    mask = np.isfinite(t)
    depth = np.where(mask, -rays[..., 2] * t, np.inf).astype(np.float32)
    beauty = np.where(ball[..., None], 0.9, 0.2).astype(np.float32) * np.ones(3, np.float32)
    beauty[~mask] = 0.0
    out = unsharp_masking(
        beauty,
        depth,
        normal.astype(np.float32),
        mask,
        amount=2.0,
        sigma_scene=0.1,
        pixel_size=(depth / np.float32(f)),
        white=1.0,
    )
    ground = mask & ~ball
    assert ground.sum() > 5000 and ball.sum() > 500
    assert (np.abs(out[ground] - beauty[ground]) / 0.2).max() < 1e-4
    assert np.array_equal(out[~mask], beauty[~mask])


def test_result_does_not_depend_on_empty_margins() -> None:
    # orthographic: shifting the picture inside a larger empty frame changes nothing
    beauty, depth, normal, mask, _, _ = _textured_square_scene()
    kw = dict(amount=1.5, sigma_scene=0.1, pixel_size=0.01, white=1.0)
    out = unsharp_masking(beauty, depth, normal, mask, **kw)
    pad = ((64, 32), (32, 96))
    big = unsharp_masking(
        np.pad(beauty, (*pad, (0, 0))),
        np.pad(depth, pad, constant_values=np.inf),
        np.pad(normal, (*pad, (0, 0))),
        np.pad(mask, pad),
        **kw,
    )
    np.testing.assert_allclose(big[64:-32, 32:-96], out, rtol=1e-5, atol=1e-7)
    assert not big[:64].any() and not big[:, -96:].any()


def test_same_gradient_same_width_at_two_distances() -> None:
    h, w = 64, 384
    widths = []
    for z in (2.0, 4.0):
        depth, normal, mask, ps = plane(h, w, z)
        x_scene = (np.arange(w) + 0.5 - w / 2) * z / FOCAL
        lum = 0.1 + 0.4 * (0.5 + 0.5 * np.tanh(x_scene / 0.02))
        beauty = grey(np.broadcast_to(lum, (h, w)))
        out = unsharp_masking(
            beauty,
            depth,
            normal,
            mask,
            amount=1.5,
            sigma_scene=0.05,
            pixel_size=ps,
            white=1.0,
            adaptive=False,
        )
        c = (lightness(out) - lightness(beauty))[h // 2]
        # width of the bright overshoot lobe, in scene units (pixels x pixel size)
        widths.append((c > 0.1 * c.max()).sum() * z / FOCAL)
    assert widths[0] > 0.05  # a real lobe, several pixels wide at both distances
    assert abs(widths[0] - widths[1]) < 0.2 * widths[0]


def test_surface_blur_sigma_is_in_scene_units_and_follows_surfaces() -> None:
    h, w = 128, 384
    depth, normal, mask, ps = plane(h, w, 4.0)
    xx = np.arange(w, dtype=np.float32)
    sig = np.broadcast_to(50 + 4e-4 * (xx - w / 2) ** 2, (h, w)).astype(np.float32)
    for sigma_px in (3.0, 6.0, 11.0, 16.0):
        out = surface_blur(
            sig, depth, normal, mask, sigma_scene=sigma_px * 4.0 / FOCAL, pixel_size=ps
        )
        # a Gaussian adds σ²/2 · L'' = σ² · 4e-4 to a parabola
        gain = (out - sig)[40:88, 100:284].mean()
        assert np.sqrt(gain / 4e-4) == pytest.approx(sigma_px, rel=0.05)
    const = np.full((h, w), 7.0, np.float32)
    np.testing.assert_allclose(
        surface_blur(const, depth, normal, mask, sigma_scene=0.1, pixel_size=ps), 7.0, rtol=1e-5
    )


@pytest.mark.parametrize("sigma_scene", [0.04, 0.3])
def test_surface_blurs_is_surface_blur_of_each_signal(sigma_scene: float) -> None:
    # a square in front of a plane, a band uncovered; σ_px 4 and 8 (0.04: the far plane fades
    # to the signal itself below level 1) or 30 and 60: two signals on one pyramid come out
    # bit for bit as each smoothed alone
    beauty, depth, normal, mask, ps, _ = square_scene()
    mask[:, :12] = False
    mask[40:44, 60:70] = False  # a hole inside the surface's bounding box
    first = beauty[..., 0] + np.float32(0.01) * np.arange(160, dtype=np.float32)
    second = np.random.default_rng(3).uniform(0.1, 1.0, first.shape).astype(np.float32)
    kw = dict(sigma_scene=sigma_scene, pixel_size=ps)
    both = surface_blurs([first, second], depth, normal, mask, **kw)
    for one, sig in zip(both, (first, second), strict=True):
        alone = surface_blur(sig, depth, normal, mask, **kw)
        assert np.array_equal(one, alone)
        assert not np.array_equal(one[mask], sig[mask])  # smoothed
        assert np.array_equal(one[~mask], sig[~mask])  # off the surface: the input
    assert not np.array_equal(both[0], both[1])


@pytest.mark.parametrize("sigma_scene", [0.04, 0.3])
def test_surface_blur_rows_by_any_strips_are_the_whole_image(sigma_scene: float) -> None:
    # the rows of the smoothed signals asked for by strips of 7 rows (crossing the bounding box
    # of the surface, the fade to the signal at σ 0.04 and the hole) or all at once: the same
    # numbers, and those of surface_blurs
    beauty, depth, normal, mask, ps, _ = square_scene()
    mask[:, :12] = False
    mask[:9] = False
    mask[40:44, 60:70] = False
    signals = [beauty[..., 0], beauty[..., 1] * np.float32(3.0)]
    kw = dict(sigma_scene=sigma_scene, pixel_size=ps)
    rows = surface_blur_rows(signals, depth, normal, mask, **kw)
    whole = rows(0, rows.shape[0])
    h = rows.shape[0]
    for k, ref in enumerate(surface_blurs(signals, depth, normal, mask, **kw)):
        assert np.array_equal(whole[k], ref)
        strips = np.concatenate([rows(r, min(h, r + 7))[k] for r in range(0, h, 7)])
        assert np.array_equal(strips, ref)
        assert not np.array_equal(ref[mask], signals[k][mask])


def test_orthographic_pixel_size_and_slanted_plane() -> None:
    h, w = 96, 192
    rows = np.arange(h, dtype=np.float32)[:, None]
    depth = np.broadcast_to(3.0 + 0.01 * rows, (h, w)).astype(np.float32)  # tilted 45°
    normal = np.zeros((h, w, 3), np.float32)
    normal[..., 1:] = [-np.sqrt(0.5), np.sqrt(0.5)]
    mask = np.ones((h, w), bool)
    lum = np.where(np.arange(w) < w // 2, 0.1, 0.4).astype(np.float32)
    beauty = grey(np.broadcast_to(lum, (h, w)))
    out = unsharp_masking(
        beauty, depth, normal, mask, amount=1.0, sigma_scene=0.05, pixel_size=0.01, white=1.0
    )
    c = lightness(out) - lightness(beauty)
    assert c[:, w // 2 - 1].max() < -2.0 and c[:, w // 2].min() > 2.0
    assert np.abs(c[:, :20]).max() < 0.1


def test_fused_unsharp_masking_is_eq1_on_the_surface_blur() -> None:
    """The strip-fused operator gives the lightness of Eq. 1 written plainly
    (:func:`unsharp_lightness`) with L_σ from :func:`surface_blur` of the same surfaces."""
    h, w = 96, 160
    depth, normal, mask, ps = plane(h, w, 3.0)
    beauty = grey(np.where(np.arange(w) < w // 2, 0.1, 0.4).astype(np.float32)[None, :] + 0 * ps)
    kw = dict(sigma_scene=0.05, pixel_size=ps)
    out = unsharp_masking(beauty, depth, normal, mask, amount=1.5, adaptive=False, white=1.0, **kw)
    lum = lightness(beauty).astype(np.float32)
    smooth = surface_blur(lum, depth, normal, mask, **kw)
    expect = unsharp_lightness(lum, smooth, 1.5)
    assert np.abs(lum - expect).max() > 5.0  # the case has contrast to add
    np.testing.assert_allclose(lightness(out), expect, atol=1e-3)


def test_adaptive_gain_raises_enhancement_on_texture() -> None:
    h, w = 128, 256
    depth, normal, mask, ps = plane(h, w, 3.0)
    rng = np.random.default_rng(3)
    lum = np.where(np.arange(w) < w // 2, 0.1, 0.4) + 0 * np.arange(h)[:, None]
    noise = rng.random((h, w)) < 0.5
    lum[: h // 2] = np.where(noise[: h // 2], 0.02, 0.9)  # black and white texture on top
    beauty = grey(lum.astype(np.float32))
    kw = dict(amount=1.5, sigma_scene=0.08, pixel_size=ps, white=1.0)
    plain = unsharp_masking(beauty, depth, normal, mask, adaptive=False, **kw)
    adapt = unsharp_masking(beauty, depth, normal, mask, adaptive=True, **kw)
    l0 = lightness(beauty)
    cp, ca = lightness(plain) - l0, lightness(adapt) - l0
    big = np.abs(cp) > 1.0
    ratio = np.where(big, ca / np.where(big, cp, 1.0), np.nan)
    assert np.nanmin(ratio) > 0.999  # λ_adapt ≥ λ
    assert np.nanmax(ratio) < np.sqrt(1.25) + 1e-3  # Var(S) ≤ 1/4 for S = L*/100 in [0, 1]
    r_tex = np.nanmean(ratio[8 : h // 2 - 8, 8:-8])
    r_flat = np.nanmean(ratio[h // 2 + 24 : -8])
    assert r_tex > 1.03 and r_flat < 1.01


def test_hdr_values_above_white_are_enhanced_not_clipped() -> None:
    h, w = 48, 160
    depth, normal, mask, ps = plane(h, w, 3.0)
    lum = np.where(np.arange(w) < w // 2, 2.0, 6.0).astype(np.float32)
    beauty = grey(np.broadcast_to(lum, (h, w)))
    out = unsharp_masking(
        beauty, depth, normal, mask, amount=1.0, sigma_scene=0.05, pixel_size=ps, white=1.0
    )
    assert out[h // 2, w // 2, 0] > 6.3 and out[h // 2, w // 2 - 1, 0] < 1.9
    np.testing.assert_allclose(out[:, :10], beauty[:, :10], rtol=1e-3)


def test_unsharp_masking_validates_parameters() -> None:
    beauty, depth, normal, mask, ps, _ = square_scene(32, 32)
    good = dict(sigma_scene=0.1, pixel_size=ps)
    for bad, name in [
        (dict(amount=float("nan")), "amount"),
        (dict(amount=50.0), "amount"),
        (dict(sigma_scene=0.0), "sigma_scene"),
        (dict(sigma_scene=-1.0), "sigma_scene"),
        (dict(variance_sigma=0.0), "variance_sigma"),
        (dict(depth_sigma=0.0), "depth_sigma"),
        (dict(normal_sigma=-1.0), "normal_sigma"),
        (dict(white=0.0), "white"),
        (dict(pixel_size=np.ones((3, 3), np.float32)), "pixel_size"),
        (dict(gain_map=np.full((32, 32), np.inf, np.float32)), "gain_map"),
    ]:
        kw = {**good, **bad}
        with pytest.raises(ValueError, match=name):
            unsharp_masking(beauty, depth, normal, mask, **kw)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="beauty"):
        unsharp_masking(beauty[..., 0], depth, normal, mask, **good)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="normal"):
        unsharp_masking(beauty, depth, normal[..., :2], mask, **good)  # type: ignore[arg-type]


@pytest.mark.parametrize("background", [(0.6, 0.0, 0.8), (5.0, -3.0, 0.0), "noise"])
def test_normals_off_the_surface_do_not_matter(background: tuple[float, ...] | str) -> None:
    """Normals where there is no surface may be anything: they were averaged into the cells at
    the surface's rim, and a unit background normal made every covered pixel NaN ("gain_map
    must be finite everywhere" from unsharp_masking, which was given no gain map)."""
    normal, depth, inside = analytic.small_cap()
    x = np.abs(normal[..., 0])  # (a pixel size that varies across the cap)
    ps = np.where(inside, 0.07 + 0.01 * x, np.inf).astype(np.float32)
    beauty = np.where(inside[..., None], 0.3 + 0.2 * normal[..., :1], 0.0).repeat(3, -1)
    other = normal.copy()
    rng = np.random.default_rng(1)
    other[~inside] = (
        rng.normal(0, 3, (int((~inside).sum()), 3)) if background == "noise" else background
    )
    mask = inside.astype(np.float32)
    args = {"sigma_scene": 0.05, "pixel_size": ps}
    results = []
    for n in (normal, other):
        n = n.astype(np.float32)
        blur = surface_blur(beauty[..., 0].astype(np.float32), depth, n, mask, **args)
        out = unsharp_masking(beauty.astype(np.float32), depth, n, mask, amount=2.0, **args)
        assert np.isfinite(blur).all() and np.isfinite(out).all()
        results.append((blur, out))
    for a, b in zip(*results, strict=True):
        assert np.array_equal(a, b)
