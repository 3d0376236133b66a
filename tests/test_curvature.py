"""View-centred curvature (ops.curvature, Radiance Scaling §4) on analytic G-buffers."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from ops.curvature import (
    DEFAULT_GAIN,
    Curvature,
    anisotropic,
    isotropic,
    mean_curvature_layers,
    principal_curvatures,
)
from tests import analytic


def _curv(scene: analytic.Scene, **kw: float) -> Curvature:
    return principal_curvatures(scene.normal, scene.depth, scene.mask, **kw)  # type: ignore[arg-type]


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.corrcoef(a.ravel(), b.ravel())[0, 1])


# -- signs ---------------------------------------------------------------------------------------


def test_sphere_is_convex_everywhere() -> None:
    s = analytic.sphere(128)
    c = _curv(s)
    inner = s.interior(0.03)
    assert (c.k1[inner] > 0).all() and (c.k2[inner] > 0).all()
    assert (isotropic(c)[inner] > 0.2).all()


def test_one_column_keeps_the_curvature_along_it() -> None:
    """A frame one pixel wide has no derivative across it: the trace is 0, κ1 = −κ2 = |(d, b)|
    from the derivatives along the column (as before d and b came out of the trace's pass)."""
    s = analytic.sphere(128)
    col = slice(60, 61)
    c = principal_curvatures(s.normal[:, col], s.depth[:, col], s.mask[:, col], scale=0.0)
    np.testing.assert_array_equal(c.k1, -c.k2)
    assert (c.k1 >= 0).all() and c.k1[s.mask[:, col]].max() > 1.0


def test_bowl_is_concave_everywhere() -> None:
    s = analytic.bowl(128)
    c = _curv(s)
    inner = s.interior(0.03)
    assert (c.k1[inner] < 0).all() and (c.k2[inner] < 0).all()
    assert (isotropic(c)[inner] < -0.2).all()


def test_saddle_has_opposite_principal_curvatures() -> None:
    s = analytic.saddle(128)
    c = _curv(s)
    inner = s.interior(0.03)
    assert (c.k1[inner] > 0).all() and (c.k2[inner] < 0).all()
    # Mean curvature vanishes at the centre; convex along y there (k1 direction vertical).
    h, w = s.shape
    centre = (slice(h // 2 - 2, h // 2 + 2), slice(w // 2 - 2, w // 2 + 2))
    assert np.abs(isotropic(c)[centre]).max() < 0.01
    assert (np.abs(c.dir_y[centre]) > 0.99).all()


def test_cylinder_is_curved_across_its_axis_only() -> None:
    s = analytic.cylinder(128)
    c = _curv(s)
    inner = s.interior(0.03)
    np.testing.assert_allclose(c.k1[inner], 4.0, rtol=0.02)  # ortho_height / R = 2 / 0.5
    assert np.abs(c.k2[inner]).max() < 0.05
    # Direction of k1: horizontal (camera x).
    assert (np.abs(c.dir_x[inner]) > 0.999).all()
    assert np.abs(c.dir_y[inner]).max() < 0.05


@pytest.mark.parametrize(("tx", "ty"), [(0.0, 0.0), (40.0, 0.0), (25.0, -35.0)])
def test_plane_has_no_curvature(tx: float, ty: float) -> None:
    s = analytic.plane(128, tilt_x_deg=tx, tilt_y_deg=ty)
    c = _curv(s)
    assert np.abs(c.k1).max() < 1e-3 and np.abs(c.k2).max() < 1e-3
    assert np.abs(isotropic(c)).max() < 1e-3
    assert c.weight.min() > 0.99  # nothing to fade on an unbroken plane


# -- magnitudes ----------------------------------------------------------------------------------


@pytest.mark.parametrize("foreshortening", [0.0, 1.0])
def test_curvature_scales_as_inverse_radius(foreshortening: float) -> None:
    """κ·R / ortho_height = 1: at f = 0 on every interior pixel, at f = 1 where n_z ≈ 1."""
    for radius in (0.25, 0.4, 0.7):
        s = analytic.sphere(240, radius=radius)
        c = _curv(s, foreshortening=foreshortening)
        if foreshortening == 0.0:
            sel = s.interior(0.03)
        else:  # the Hessian of depth grows as 1/n_z³ away from the centre
            sel = s.interior(0.03) & (s.normal[..., 2] > 0.99)
        assert sel.sum() > 20
        mean = 0.5 * (c.k1[sel] + c.k2[sel])
        np.testing.assert_allclose(mean * radius / s.ortho_height, 1.0, rtol=0.03)


@pytest.mark.parametrize(
    "make",
    [
        lambda: analytic.sphere(160, radius=0.6, centre=(0.2, -0.1)),
        lambda: analytic.bowl(160),
        lambda: analytic.saddle(160),
        lambda: analytic.perspective_sphere(160),
    ],
    ids=["sphere", "bowl", "saddle", "perspective"],
)
def test_matches_analytic_reference(make: object) -> None:
    s = make()  # type: ignore[operator]
    c = _curv(s)
    sel = s.interior(0.04)
    tol = 0.02 * np.abs(s.k1[sel]).max()
    assert np.abs(c.k1[sel] - s.k1[sel]).max() < tol
    assert np.abs(c.k2[sel] - s.k2[sel]).max() < tol


def test_foreshortening_follows_its_reference() -> None:
    """f = 1: the Hessian of depth, which grows towards the silhouette (sphere: R²/h³ radially)."""
    s = analytic.sphere(160, radius=0.7)
    c = _curv(s, foreshortening=1.0)
    k1, k2, _, _ = s.reference(1.0)
    sel = s.interior(0.05)
    np.testing.assert_allclose(c.k1[sel], k1[sel], rtol=0.03)
    np.testing.assert_allclose(c.k2[sel], k2[sel], rtol=0.03)
    assert k1[sel].max() > 1.5 * k1[sel].min()  # the reference really does vary


def test_coarse_working_grid_matches_reference() -> None:
    """A scale large enough to compute on a downsampled grid (σ = 6 px) still gives κ = h / R."""
    s = analytic.sphere(400, radius=0.6)
    c = _curv(s, scale=0.015)
    assert c.__dict__["_coarse"].k1.shape[0] < s.shape[0]  # a coarser working grid ran
    sel = s.interior(0.08)
    np.testing.assert_allclose(c.k1[sel], s.k1[sel], rtol=0.02)
    np.testing.assert_allclose(c.k2[sel], s.k2[sel], rtol=0.02)
    cyl = analytic.cylinder(400)
    cc = _curv(cyl, scale=0.015)
    sel = cyl.interior(0.08)
    assert (np.abs(cc.dir_x[sel]) > 0.99).all()


# -- discontinuities ------------------------------------------------------------------------------


def _ring(scene: analytic.Scene, h_map: np.ndarray) -> float:
    """Largest excess of |H| over the analytic |H| anywhere on the surfaces."""
    ref = np.tanh(DEFAULT_GAIN * (scene.k1 + scene.k2))
    ok = np.isfinite(ref)
    return float((np.abs(h_map) - np.abs(ref))[ok].max())


@pytest.mark.parametrize("scale", [0.003, 0.012])
def test_no_curvature_across_depth_jump(scale: float) -> None:
    s = analytic.two_spheres(200)
    c = _curv(s, scale=scale)
    hmap = isotropic(c)
    assert _ring(s, hmap) < 0.02
    # On the occlusion boundary itself (pixels whose 4-neighbourhood spans both spheres) the
    # weight, hence H, is 0.
    seg = s.segment
    edge = np.zeros_like(s.mask)
    edge[:, :-1] |= (seg[:, :-1] != seg[:, 1:]) & (seg[:, :-1] >= 0) & (seg[:, 1:] >= 0)
    edge[:-1, :] |= (seg[:-1, :] != seg[1:, :]) & (seg[:-1, :] >= 0) & (seg[1:, :] >= 0)
    assert edge.sum() > 20
    assert np.abs(hmap[edge]).max() < 1e-6
    assert c.weight[edge].max() < 1e-6
    # Away from it the spheres keep their curvature.
    inner = s.interior(0.06)
    assert c.weight[inner].min() > 0.99


def test_jump_detection_is_what_prevents_the_ring() -> None:
    """Control: with jump detection disabled the smoothing mixes the spheres and a ring shows."""
    s = analytic.two_spheres(200)
    hmap = isotropic(_curv(s, scale=0.012, depth_jump=10.0))
    assert _ring(s, hmap) > 0.1


def test_background_and_silhouettes_are_zero() -> None:
    s = analytic.sphere(128)
    c = _curv(s)
    hmap = isotropic(c)
    assert (hmap[~s.mask] == 0).all() and (c.weight[~s.mask] == 0).all()
    assert _ring(s, hmap) < 0.02  # no bright rim at the silhouette
    # Garbage (NaN) normals on the background change nothing.
    n = s.normal.copy()
    n[~s.mask] = np.nan
    c2 = principal_curvatures(n, s.depth, s.mask)
    np.testing.assert_array_equal(isotropic(c2), hmap)


def test_float_mask_and_depth_only_coverage() -> None:
    s = analytic.sphere(128)
    ref = isotropic(_curv(s))
    by_depth = isotropic(principal_curvatures(s.normal, s.depth))
    by_alpha = isotropic(principal_curvatures(s.normal, s.depth, s.mask.astype(np.float32)))
    np.testing.assert_array_equal(by_depth, ref)
    np.testing.assert_array_equal(by_alpha, ref)


# -- discontinuities at any resolution: occlusions, not slanted surfaces ---------------------------
#
# A slanted surface changes its depth by more per pixel the smaller the image: a per-pixel jump
# test alone cuts large parts of receding planes and of curved surfaces near their silhouettes
# out of the curvature at low resolution. Only occlusions (a surface behind another) may be cut.

_ROOT = Path(__file__).resolve().parents[1]
_BLENDER = _ROOT / "tests" / "fixtures" / "blender"

_Hit = tuple[np.ndarray, np.ndarray]  # (depth, normal) along each pixel's ray; inf: missed


def _rays(height: int, width: int, fov_y_deg: float) -> np.ndarray:
    """(H, W, 3) pinhole rays (u·t, v·t, -1): the point at planar depth s is s·ray."""
    u, v = analytic.pixel_coords(height, width)
    t = 2.0 * math.tan(math.radians(fov_y_deg) / 2.0)
    return np.stack([u * t, v * t, -np.ones_like(u)], axis=-1)


def _plane_hit(rays: np.ndarray, point: tuple[float, ...], normal: tuple[float, ...]) -> _Hit:
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    if n @ np.asarray(point, float) > 0:  # face the camera at the origin
        n = -n
    rn = rays @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(rn < 0, (n @ np.asarray(point, float)) / rn, np.inf)
    return s, np.broadcast_to(n, rays.shape).copy()


def _sphere_hit(rays: np.ndarray, centre: tuple[float, ...], radius: float) -> _Hit:
    c = np.asarray(centre, float)
    a = (rays * rays).sum(-1)
    b = rays @ c
    disc = b * b - a * (c @ c - radius * radius)
    s = np.where(disc > 0, (b - np.sqrt(np.maximum(disc, 0.0))) / a, np.inf)
    p = rays * np.where(np.isfinite(s), s, 0.0)[..., None]
    return s, (p - c) / radius


def _cylinder_hit(
    rays: np.ndarray, point: tuple[float, ...], axis: tuple[float, ...], radius: float
) -> _Hit:
    c = np.asarray(point, float)
    ax = np.asarray(axis, float) / np.linalg.norm(axis)
    rp = rays - (rays @ ax)[..., None] * ax
    cp = c - (c @ ax) * ax
    a = (rp * rp).sum(-1)
    b = rp @ cp
    disc = b * b - a * (cp @ cp - radius * radius)
    s = np.where(disc > 0, (b - np.sqrt(np.maximum(disc, 0.0))) / a, np.inf)
    q = rays * np.where(np.isfinite(s), s, 0.0)[..., None] - c
    return s, (q - (q @ ax)[..., None] * ax) / radius


def _perspective(
    *hits: _Hit, far: float = 60.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(normal, depth, mask, segment) of the nearest of ``hits`` closer than ``far``."""
    depth = np.full(hits[0][0].shape, np.inf)
    normal = np.zeros((*depth.shape, 3))
    seg = np.full(depth.shape, -1)
    for i, (s, n) in enumerate(hits):
        ok = (s > 0.1) & (s < far) & (s < depth)
        depth[ok], normal[ok], seg[ok] = s[ok], n[ok], i
    mask = seg >= 0
    return normal.astype(np.float32), depth.astype(np.float32), mask, seg


def _inside(seg: np.ndarray, px: int) -> np.ndarray:
    """Pixels at least ``px`` pixels (chessboard) from another segment, background or the edge."""
    k = np.ones((2 * px + 1, 2 * px + 1), np.uint8)
    out = np.zeros(seg.shape, bool)
    for i in np.unique(seg[seg >= 0]):
        out |= cv2.erode((seg == i).astype(np.uint8), k, borderType=cv2.BORDER_CONSTANT) > 0
    return out


def _boundary(seg: np.ndarray) -> np.ndarray:
    """Pixels whose 4-neighbourhood holds two different surfaces (not the background)."""
    edge = np.zeros(seg.shape, bool)
    across = (seg[:, :-1] != seg[:, 1:]) & (seg[:, :-1] >= 0) & (seg[:, 1:] >= 0)
    edge[:, :-1] |= across
    edge[:, 1:] |= across
    across = (seg[:-1] != seg[1:]) & (seg[:-1] >= 0) & (seg[1:] >= 0)
    edge[:-1] |= across
    edge[1:] |= across
    return edge


def _receding_plane(rays: np.ndarray) -> _Hit:
    """A ground-like plane seen at 15° at the image centre (its horizon inside the image)."""
    phi = math.radians(15.0)
    return _plane_hit(rays, (0.0, 0.0, -5.0), (0.0, math.cos(phi), math.sin(phi)))


@pytest.mark.parametrize("height", [60, 120, 480])
def test_receding_plane_in_perspective_keeps_its_weight(height: int) -> None:
    """Clipped at 6 times the centre's depth, the plane reaches to 5 % of the image height below
    its horizon, where its depth grows by ~17 % per pixel at 120 px high (by > 3 % over a band
    a quarter of the image high): no occlusion anywhere, so weight 1 and no curvature inside."""
    rays = _rays(height, height * 4 // 3, 50.0)
    normal, depth, mask, seg = _perspective(_receding_plane(rays), far=30.0)
    c = principal_curvatures(normal, depth, mask)
    inner = _inside(seg, 4)
    assert inner.sum() > 0.6 * mask.sum()
    assert c.weight[inner].min() > 0.99
    assert np.abs(isotropic(c)[inner]).max() < 1e-3
    # Only the border pixels (and those next to them, the weight's fade) are below 1.
    assert ((c.weight < 0.99) & mask).sum() <= 3 * (mask & ~_inside(seg, 1)).sum()


@pytest.mark.parametrize("height", [60, 120])
def test_grazing_orthographic_plane_keeps_its_weight(height: int) -> None:
    """Tilted by 88° (depth from 1.4 to 59 over the image): affine depth, no discontinuity."""
    s = analytic.plane(height, tilt_y_deg=88.0, distance=30.0)
    c = _curv(s)
    inner = s.interior(4.0 / height)
    assert inner.sum() > 0.7 * s.mask.sum()
    assert c.weight[inner].min() > 0.99
    assert np.abs(isotropic(c)[inner]).max() < 1e-3


@pytest.mark.parametrize("height", [60, 120, 240])
@pytest.mark.parametrize("shape", ["cylinder", "sphere"])
def test_receding_curved_surfaces_keep_their_weight(shape: str, height: int) -> None:
    """A cylinder running away from the camera and an off-centre sphere, near enough to fill much
    of the view: their depth grows fast near the silhouettes (convexly), which is no occlusion."""
    rays = _rays(height, height * 4 // 3, 50.0)
    if shape == "cylinder":
        hit = _cylinder_hit(rays, (0.0, -1.0, -4.0), (0.0, 0.25, -1.0), 0.6)
    else:
        hit = _sphere_hit(rays, (0.9, -0.3, -4.0), 1.2)
    normal, depth, mask, seg = _perspective(hit, far=40.0)
    c = principal_curvatures(normal, depth, mask)
    inner = _inside(seg, 4)
    assert inner.sum() > 100
    assert c.weight[inner].min() > 0.99
    assert (isotropic(c)[inner] > 0.0).all()  # convex everywhere


@pytest.mark.parametrize("height", [60, 120, 480])
def test_sphere_in_front_of_a_receding_plane(height: int) -> None:
    """The sphere's silhouette over the plane is an occlusion at every resolution (weight 0 on
    both sides, no curvature leaking onto the plane); the plane's slant is not."""
    rays = _rays(height, height * 4 // 3, 50.0)
    sph = _sphere_hit(rays, (0.6, 0.9, -4.5), 0.8)  # 0.2 above the plane
    normal, depth, mask, seg = _perspective(sph, _receding_plane(rays), far=30.0)
    c = principal_curvatures(normal, depth, mask)
    hmap = isotropic(c)
    edge = _boundary(seg)
    assert edge.sum() > 10
    assert c.weight[edge].max() == 0.0
    plane = seg == 1
    assert np.abs(hmap[plane]).max() < 1e-3  # nothing of the sphere on the plane
    inner = _inside(seg, max(6, height // 48))  # the band widens with σ (in pixels)
    assert c.weight[inner].min() > 0.99
    assert (hmap[inner & (seg == 0)] > 0.0).all()


@pytest.mark.parametrize("height", [64, 480])
def test_overlapping_spheres_are_cut_at_any_resolution(height: int) -> None:
    """Two overlapping spheres (orthographic, and a pair in perspective): no curvature across the
    occlusion, weight 0 on it, full weight away from it, at a low and a high resolution."""
    ortho = analytic.two_spheres(height)
    c = _curv(ortho)
    assert _ring(ortho, isotropic(c)) < 0.02
    rays = _rays(height, height, 40.0)
    near = _sphere_hit(rays, (-0.4, 0.0, -5.0), 0.8)
    far = _sphere_hit(rays, (0.6, 0.2, -6.5), 1.0)
    normal, depth, mask, seg = _perspective(near, far)
    scenes = [(c, ortho.segment), (principal_curvatures(normal, depth, mask), seg)]
    for curv, sg in scenes:
        hmap = isotropic(curv)
        edge = _boundary(sg)
        assert edge.sum() > 10
        assert np.abs(hmap[edge]).max() < 1e-6 and curv.weight[edge].max() < 1e-6
        assert curv.weight[_inside(sg, 6)].min() > 0.99
        assert (hmap[sg >= 0] >= 0.0).all()  # both convex up to the cut: nothing of the other


@pytest.fixture(scope="module")
def spot_frames() -> dict[int, tuple[np.ndarray, np.ndarray, np.ndarray, int]]:
    """spot.obj rendered 160x120 and 640x480 (normal, depth, mask, image height)."""
    pytest.importorskip("pyrender")
    from analysis.compare import frame_from_mesh

    out = {}
    for h in (120, 480):
        f = frame_from_mesh(_ROOT / "examples" / "spot.obj", h * 4 // 3, h, azimuth_deg=150.0)
        out[h] = (f.buffers["normal"], f.buffers["depth"], f.mask, f.image_height)
    return out


def _zero_and_band(
    frame: tuple[np.ndarray, np.ndarray, np.ndarray, int], px: int
) -> tuple[float, float, float]:
    """Shares of the covered pixels with weight 0, within ``px`` pixels of the background, and
    with weight 0 farther from it."""
    normal, depth, mask, img_h = frame
    cov = np.isfinite(depth) & (mask > 0.5)
    w = principal_curvatures(normal, depth, mask, image_height=img_h).weight
    k = np.ones((2 * px + 1, 2 * px + 1), np.uint8)
    band = cov & (cv2.erode(cov.astype(np.uint8), k, borderType=cv2.BORDER_REPLICATE) == 0)
    zero = (w == 0) & cov
    n = float(cov.sum())
    return zero.sum() / n, band.sum() / n, (zero & ~band).sum() / n


def test_mesh_render_loses_only_a_silhouette_band_at_low_resolution(
    spot_frames: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray, int]],
) -> None:
    """spot at 120 and 480 px high: the share of covered pixels with weight 0 grows at 120 px by
    no more than the share of a 3-pixel band along the silhouette does (the weight is 0 on
    bands of a few pixels at silhouettes and occlusions, which cover ~4x more of a 4x smaller
    image), and what is 0 beyond 2 pixels of the background (the occlusion bands) covers at most
    4x more. (A per-pixel jump test alone: 41 % vs 8 %, the band explaining 24 points.)"""
    f120, band120, _ = _zero_and_band(spot_frames[120], 3)
    f480, band480, _ = _zero_and_band(spot_frames[480], 3)
    assert f120 - f480 <= band120 - band480
    _, _, occ120 = _zero_and_band(spot_frames[120], 2)
    _, _, occ480 = _zero_and_band(spot_frames[480], 2)
    assert occ120 <= 4.0 * occ480


def test_blender_ground_plane_keeps_its_weight() -> None:
    """The Cycles fixture (160x120): the receding ground plane (its far half changes depth by
    ~1.6 % per pixel in log) keeps weight 1 away from the objects standing on it and from its
    far edge; the objects' silhouettes over it are still cut."""
    if not (_BLENDER / "cycles_multilayer.exr").is_file():
        pytest.skip("tests/fixtures/blender/cycles_multilayer.exr is absent (see its README)")
    from gbuffer.io import read

    frame = read(_BLENDER / "cycles_multilayer.exr", camera=_BLENDER / "camera.json")
    normal, depth, mask = frame.buffers["normal"], frame.buffers["depth"], frame.mask
    c = principal_curvatures(normal, depth, mask, image_height=frame.image_height)
    # The ground plane z = 0: facing the world's up axis, and on the plane (the cube's top is
    # parallel to it).
    cam = frame.camera
    assert cam is not None and cam.world_to_camera is not None
    up = (cam.world_to_camera[:3, :3] @ np.array([0.0, 0.0, 1.0])).astype(np.float32)
    height = frame.buffers["position"] @ up  # up · p: minus the camera's height on the plane
    ground = (normal @ up > 0.9999) & (mask > 0.999)
    ground &= np.abs(height - np.median(height[ground])) < 1e-2
    seg = np.where(ground, 0, np.where(mask > 0.5, 1, -1))
    inner = _inside(seg, 4) & ground
    assert inner.sum() > 0.5 * ground.sum()
    assert (c.weight[inner] > 0.99).mean() > 0.99
    far_half = inner & (depth > np.median(depth[ground]))
    assert far_half.sum() > 1000
    assert c.weight[far_half].min() > 0.99
    # Where an object stands in front of the plane (nearer by > 10 %), the plane is still cut.
    behind = np.zeros_like(ground)
    for shift in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        nd, ns = np.roll(depth, shift, (0, 1)), np.roll(seg, shift, (0, 1))
        behind |= ground & (ns == 1) & (nd < 0.9 * depth)
    behind[[0, -1]] = behind[:, [0, -1]] = False
    assert behind.sum() > 30
    assert c.weight[behind].max() == 0.0


# -- resolution independence ---------------------------------------------------------------------


@pytest.mark.parametrize("scale", [0.008, 0.012])
def test_same_look_at_two_resolutions(scale: float) -> None:
    """Built analytically at 256 and 512 px (σ >= 2 px at 256; the 512 frame runs on a coarser
    working grid), the mapped curvature agrees once the 512 one is box-downsampled."""
    lo = analytic.two_spheres(256)
    hi = analytic.two_spheres(512)
    h_lo = isotropic(_curv(lo, scale=scale))
    h_hi = isotropic(_curv(hi, scale=scale))
    down = cv2.resize(h_hi, (256, 256), interpolation=cv2.INTER_AREA)
    sel = lo.mask
    assert _corr(h_lo[sel], down[sel]) >= 0.98
    inner = lo.interior(0.08)
    np.testing.assert_allclose(down[inner], h_lo[inner], atol=0.01)


def test_image_height_makes_tiles_match_the_full_frame() -> None:
    s = analytic.sphere(200, radius=0.6)
    full = _curv(s)
    tile = (slice(40, 140), slice(60, 180))
    c = principal_curvatures(s.normal[tile], s.depth[tile], s.mask[tile], image_height=200)
    inner = s.interior(0.05)[tile]
    inner[:4] = inner[-4:] = False
    inner[:, :4] = inner[:, -4:] = False
    np.testing.assert_allclose(c.k1[inner], full.k1[tile][inner], rtol=1e-3)
    # Without image_height the tile's own height sets the unit: values shrink by 100 / 200.
    c_own = principal_curvatures(s.normal[tile], s.depth[tile], s.mask[tile])
    np.testing.assert_allclose(c_own.k1[inner], 0.5 * full.k1[tile][inner], rtol=1e-3)


# -- mappings --------------------------------------------------------------------------------------


def test_isotropic_is_tanh_of_gain_times_trace() -> None:
    s = analytic.sphere(128)
    c = _curv(s)
    inner = s.interior(0.05)
    for gain in (0.05, 0.1, 0.5):
        np.testing.assert_allclose(isotropic(c, gain)[inner], np.tanh(gain * 8.0), atol=2e-3)
    # The default maps a sphere spanning half the image to tanh(8 s), well inside tanh's range.
    np.testing.assert_allclose(isotropic(c)[inner], np.tanh(DEFAULT_GAIN * 8.0), atol=2e-3)
    assert 0.15 < float(np.median(isotropic(c)[inner])) < 0.5


def test_default_gain_does_not_saturate_a_real_mesh(
    spot_frames: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray, int]],
) -> None:
    """On a render of spot (ears, horns, snout: detail well under the image height) the default
    gain leaves most covered pixels in tanh's near-linear range, at both sizes; a gain of 0.1
    would put |κ| above 0.75 on about half of them."""
    for normal, depth, mask, _ in spot_frames.values():
        c = principal_curvatures(normal, depth, mask)
        reliable = c.weight > 0.5
        kappa = np.abs(isotropic(c)[reliable])
        assert 0.1 < float(np.median(kappa)) < 0.5
        assert float(np.mean(kappa > 0.75)) < 0.2
        assert float(np.mean(np.abs(isotropic(c, 0.1)[reliable]) > 0.75)) > 0.3


def test_lazy_fields_match_and_stay_consistent() -> None:
    s = analytic.two_spheres(400)
    c = _curv(s, scale=0.012)
    assert c.__dict__["_coarse"].k1.shape[0] < s.shape[0]
    h_coarse = isotropic(c)  # mapped on the working grid
    k1, k2, w = c.k1, c.k2, c.weight
    direct = Curvature(k1.copy(), k2.copy(), c.dir_x.copy(), c.dir_y.copy(), w.copy())
    h_full = isotropic(direct)
    assert np.abs(h_full - h_coarse).max() < 0.05
    assert _corr(h_full[s.mask], h_coarse[s.mask]) > 0.999
    # So is the anisotropic mapping of a constant light.
    lazy = _curv(s, scale=0.012)
    for ell, lam in (([1.0, 0.2, 0.3], 1.0), ([0.1, -1.0, 0.5], -0.6)):
        a_coarse = anisotropic(lazy, np.array(ell), 0.1, lam)
        a_full = anisotropic(direct, np.array(ell), 0.1, lam)
        assert _corr(a_coarse[s.mask], a_full[s.mask]) > 0.999
    assert "k1" not in lazy.__dict__  # still not materialised
    # Once materialised (and maybe edited), the fields are what isotropic uses.
    c.k1[...] = 0.0
    c.k2[...] = 0.0
    assert np.abs(isotropic(c)).max() == 0.0
    assert {f for f in ("k1", "k2", "dir_x", "dir_y", "weight")} <= set(c.__dict__)
    norm = np.hypot(c.dir_x, c.dir_y)
    np.testing.assert_allclose(norm, 1.0, atol=1e-4)


def test_anisotropic_blends_principal_and_mean_curvature() -> None:
    s = analytic.cylinder(128)
    c = _curv(s)
    inner = s.interior(0.05)
    g = 0.1
    k1 = float(np.median(c.k1[inner]))  # k2 ≈ 0
    iso = isotropic(c, g)
    # λ = 0: isotropic whatever the light.
    for ell in ([1, 0, 0], [0, 1, 0], [0.3, 0.4, 0.8]):
        np.testing.assert_allclose(anisotropic(c, np.array(ell), g, 0.0), iso, atol=1e-5)
    # λ = 1: (H + Δκ) for a light along u (here x), (H - Δκ) across it; λ = -1 the reverse.
    along = anisotropic(c, np.array([1.0, 0, 0]), g, 1.0)[inner]
    across = anisotropic(c, np.array([0, 1.0, 0]), g, 1.0)[inner]
    np.testing.assert_allclose(along, np.tanh(g * 2 * k1), atol=2e-3)
    np.testing.assert_allclose(across, 0.0, atol=2e-3)
    np.testing.assert_allclose(
        anisotropic(c, np.array([1.0, 0, 0]), g, -1.0)[inner], 0.0, atol=2e-3
    )
    # A light along the view axis only sees the isotropic part.
    np.testing.assert_allclose(anisotropic(c, np.array([0, 0, 1.0]), g, 1.0), iso, atol=1e-5)
    # A per-pixel light map gives the same as the constant light.
    lmap = np.broadcast_to(np.array([2.0, 0.0, 0.0], np.float32), (*s.shape, 3)).copy()
    np.testing.assert_allclose(
        anisotropic(c, lmap, g, 1.0), anisotropic(c, np.array([1.0, 0, 0]), g, 1.0), atol=1e-5
    )


def test_mean_curvature_layers() -> None:
    s = analytic.cylinder(96)
    c = _curv(s)
    layers = mean_curvature_layers(c, 0.2)
    assert set(layers) == {"H", "k1", "k2", "dir.X", "dir.Y"}
    for v in layers.values():
        assert v.shape == s.shape and v.dtype == np.float32
    # (isotropic now reads the materialised k1 + k2, which round differently from their trace)
    np.testing.assert_allclose(layers["H"], isotropic(c, 0.2), rtol=0, atol=1e-6)
    assert (layers["k1"][~s.mask] == 0).all()
    inner = s.interior(0.05)
    np.testing.assert_allclose(layers["k1"][inner], 4.0, rtol=0.02)


@pytest.mark.parametrize("scale", [0.02, 0.05])  # working grids 2x and 4x coarser
def test_mean_curvature_layers_from_the_working_grid_are_the_fields_read_one_by_one(
    scale: float,
) -> None:
    """The one-pass layers of a result still on its working grid hold what reading its fields
    one by one gives (H and the direction exactly, k·weight to an ulp), and no -0.0."""
    s = analytic.two_spheres(256)
    fused = mean_curvature_layers(_curv(s, scale=scale), 0.2)
    c = _curv(s, scale=scale)
    assert c.__dict__["_coarse"].d.shape[0] < s.shape[0]  # the one-pass path is the one tested
    h = isotropic(c, 0.2)
    c.weight  # noqa: B018 (read: the fields are materialised, the layers take the other path)
    fields = mean_curvature_layers(c, 0.2)
    assert fields.keys() == fused.keys()
    np.testing.assert_array_equal(fused["H"], h)
    for name in ("dir.X", "dir.Y"):
        np.testing.assert_array_equal(fused[name], fields[name])
    for name in ("k1", "k2"):
        np.testing.assert_allclose(fused[name], fields[name], rtol=1e-6, atol=1e-7)
        assert not (np.signbit(fused[name]) & (fused[name] == 0)).any()
    assert np.abs(fused["k1"]).max() > 1.0


# -- validation ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kw", "word"),
    [
        ({"scale": -0.1}, "scale"),
        ({"scale": 0.5}, "scale"),
        ({"foreshortening": 1.5}, "foreshortening"),
        ({"foreshortening": -0.1}, "foreshortening"),
        ({"depth_jump": 0.0}, "depth_jump"),
        ({"image_height": 0}, "image_height"),
    ],
)
def test_bad_parameters_raise(kw: dict[str, float], word: str) -> None:
    s = analytic.sphere(32)
    with pytest.raises(ValueError, match=word):
        principal_curvatures(s.normal, s.depth, s.mask, **kw)  # type: ignore[arg-type]


def test_bad_shapes_and_mapping_parameters_raise() -> None:
    s = analytic.sphere(32)
    with pytest.raises(ValueError, match="normal"):
        principal_curvatures(s.normal[..., :2], s.depth)
    with pytest.raises(ValueError, match="depth"):
        principal_curvatures(s.normal, s.depth[:-1])
    with pytest.raises(ValueError, match="mask"):
        principal_curvatures(s.normal, s.depth, s.mask[:, :-1])
    c = _curv(s)
    with pytest.raises(ValueError, match="gain"):
        isotropic(c, -1.0)
    with pytest.raises(ValueError, match="lam"):
        anisotropic(c, np.array([1.0, 0, 0]), 0.1, 2.0)
    with pytest.raises(ValueError, match="light_dir"):
        anisotropic(c, np.zeros(3), 0.1, 0.5)
    with pytest.raises(ValueError, match="light_dir"):
        anisotropic(c, np.ones((4, 4, 3)), 0.1, 0.5)


def test_row_strips_give_the_same_result_as_one_pass(monkeypatch: pytest.MonkeyPatch) -> None:
    import ops.curvature._common as oc

    s = analytic.two_spheres(300, width=260)
    for scale in (0.003, 0.012):
        monkeypatch.setattr(oc, "_STRIP_ROWS", 40)
        strips = _curv(s, scale=scale, foreshortening=0.5)
        monkeypatch.setattr(oc, "_STRIP_ROWS", 100_000)
        whole = _curv(s, scale=scale, foreshortening=0.5)
        np.testing.assert_array_equal(strips.weight, whole.weight)
        for name in ("k1", "k2"):
            a, b = getattr(strips, name), getattr(whole, name)
            np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-4)


@pytest.mark.parametrize("scale", [0.003, 0.012])
def test_cropping_to_the_covered_columns_changes_nothing(scale: float) -> None:
    """Each strip is computed only on the columns around its covered pixels. A covered line at
    both sides of the frame makes every strip full width: the spheres' curvature must not
    change, nor the zeros between them and the lines."""
    s = analytic.two_spheres(300, width=520)
    lined = [s.normal.copy(), s.depth.copy(), s.mask.copy()]
    for cols in (slice(0, 3), slice(-3, None)):
        lined[0][:, cols] = (0.0, 0.0, 1.0)
        lined[1][:, cols] = 5.0
        lined[2][:, cols] = True
    cropped = principal_curvatures(s.normal, s.depth, s.mask, scale=scale, foreshortening=0.5)
    full = principal_curvatures(*lined, scale=scale, foreshortening=0.5)
    inner = (slice(None), slice(40, -40))
    kappa = isotropic(cropped)
    assert (np.abs(kappa[inner]) > 0.01).mean() > 0.1
    np.testing.assert_array_equal(kappa[inner], isotropic(full)[inner])
    for name in ("weight", "dir_x", "dir_y"):
        np.testing.assert_array_equal(getattr(cropped, name)[inner], getattr(full, name)[inner])
    for name in ("k1", "k2"):  # within an ulp (vectorised and scalar tails round alike but for FMA)
        a, b = getattr(cropped, name)[inner], getattr(full, name)[inner]
        np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-6 * np.abs(b).max())
