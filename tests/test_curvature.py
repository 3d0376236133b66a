"""View-centred curvature (ops.curvature, Radiance Scaling §4) on analytic G-buffers."""

from __future__ import annotations

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


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.corrcoef(a.ravel(), b.ravel())[0, 1])


# -- signs ---------------------------------------------------------------------------------------


def test_sphere_is_convex_everywhere() -> None:
    s = analytic.sphere(128)
    c = s.curvature()
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
    c = s.curvature()
    inner = s.interior(0.03)
    assert (c.k1[inner] < 0).all() and (c.k2[inner] < 0).all()
    assert (isotropic(c)[inner] < -0.2).all()


def test_saddle_has_opposite_principal_curvatures() -> None:
    s = analytic.saddle(128)
    c = s.curvature()
    inner = s.interior(0.03)
    assert (c.k1[inner] > 0).all() and (c.k2[inner] < 0).all()
    # Mean curvature vanishes at the centre; convex along y there (k1 direction vertical).
    h, w = s.shape
    centre = (slice(h // 2 - 2, h // 2 + 2), slice(w // 2 - 2, w // 2 + 2))
    assert np.abs(isotropic(c)[centre]).max() < 0.01
    assert (np.abs(c.dir_y[centre]) > 0.99).all()


def test_cylinder_is_curved_across_its_axis_only() -> None:
    s = analytic.cylinder(128)
    c = s.curvature()
    inner = s.interior(0.03)
    np.testing.assert_allclose(c.k1[inner], 4.0, rtol=0.02)  # ortho_height / R = 2 / 0.5
    assert np.abs(c.k2[inner]).max() < 0.05
    # Direction of k1: horizontal (camera x).
    assert (np.abs(c.dir_x[inner]) > 0.999).all()
    assert np.abs(c.dir_y[inner]).max() < 0.05


@pytest.mark.parametrize(("tx", "ty"), [(0.0, 0.0), (40.0, 0.0), (25.0, -35.0)])
def test_plane_has_no_curvature(tx: float, ty: float) -> None:
    s = analytic.plane(128, tilt_x_deg=tx, tilt_y_deg=ty)
    c = s.curvature()
    assert np.abs(c.k1).max() < 1e-3 and np.abs(c.k2).max() < 1e-3
    assert np.abs(isotropic(c)).max() < 1e-3
    assert c.weight.min() > 0.99  # nothing to fade on an unbroken plane


# -- magnitudes ----------------------------------------------------------------------------------


@pytest.mark.parametrize("foreshortening", [0.0, 1.0])
def test_curvature_scales_as_inverse_radius(foreshortening: float) -> None:
    """κ·R / ortho_height = 1: at f = 0 on every interior pixel, at f = 1 where n_z ≈ 1."""
    for radius in (0.25, 0.4, 0.7):
        s = analytic.sphere(240, radius=radius)
        c = s.curvature(foreshortening=foreshortening)
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
    c = s.curvature()
    sel = s.interior(0.04)
    tol = 0.02 * np.abs(s.k1[sel]).max()
    assert np.abs(c.k1[sel] - s.k1[sel]).max() < tol
    assert np.abs(c.k2[sel] - s.k2[sel]).max() < tol


def test_foreshortening_follows_its_reference() -> None:
    """f = 1: the Hessian of depth, which grows towards the silhouette (sphere: R²/h³ radially)."""
    s = analytic.sphere(160, radius=0.7)
    c = s.curvature(foreshortening=1.0)
    k1, k2, _, _ = s.reference(1.0)
    sel = s.interior(0.05)
    np.testing.assert_allclose(c.k1[sel], k1[sel], rtol=0.03)
    np.testing.assert_allclose(c.k2[sel], k2[sel], rtol=0.03)
    assert k1[sel].max() > 1.5 * k1[sel].min()  # the reference really does vary


def test_coarse_working_grid_matches_reference() -> None:
    """A scale large enough to compute on a downsampled grid (σ = 6 px) still gives κ = h / R."""
    s = analytic.sphere(400, radius=0.6)
    c = s.curvature(scale=0.015)
    assert c.__dict__["_coarse"].k1.shape[0] < s.shape[0]  # a coarser working grid ran
    sel = s.interior(0.08)
    np.testing.assert_allclose(c.k1[sel], s.k1[sel], rtol=0.02)
    np.testing.assert_allclose(c.k2[sel], s.k2[sel], rtol=0.02)
    cyl = analytic.cylinder(400)
    cc = cyl.curvature(scale=0.015)
    sel = cyl.interior(0.08)
    assert (np.abs(cc.dir_x[sel]) > 0.99).all()


# -- discontinuities ------------------------------------------------------------------------------


@pytest.mark.parametrize("scale", [0.003, 0.012])
def test_no_curvature_across_depth_jump(scale: float) -> None:
    s = analytic.two_spheres(200)
    c = s.curvature(scale=scale)
    hmap = isotropic(c)
    assert s.ring(hmap) < 0.02
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
    hmap = isotropic(s.curvature(scale=0.012, depth_jump=10.0))
    assert s.ring(hmap) > 0.1


def test_background_and_silhouettes_are_zero() -> None:
    s = analytic.sphere(128)
    c = s.curvature()
    hmap = isotropic(c)
    assert (hmap[~s.mask] == 0).all() and (c.weight[~s.mask] == 0).all()
    assert s.ring(hmap) < 0.02  # no bright rim at the silhouette
    # Garbage (NaN) normals on the background change nothing.
    n = s.normal.copy()
    n[~s.mask] = np.nan
    c2 = principal_curvatures(n, s.depth, s.mask)
    np.testing.assert_array_equal(isotropic(c2), hmap)


def test_float_mask_and_depth_only_coverage() -> None:
    s = analytic.sphere(128)
    ref = isotropic(s.curvature())
    by_depth = isotropic(principal_curvatures(s.normal, s.depth))
    by_alpha = isotropic(principal_curvatures(s.normal, s.depth, s.mask.astype(np.float32)))
    np.testing.assert_array_equal(by_depth, ref)
    np.testing.assert_array_equal(by_alpha, ref)


# -- resolution independence ---------------------------------------------------------------------


@pytest.mark.parametrize("scale", [0.008, 0.012])
def test_same_look_at_two_resolutions(scale: float) -> None:
    """Built analytically at 256 and 512 px (σ >= 2 px at 256; the 512 frame runs on a coarser
    working grid), the mapped curvature agrees once the 512 one is box-downsampled."""
    lo = analytic.two_spheres(256)
    hi = analytic.two_spheres(512)
    h_lo = isotropic(lo.curvature(scale=scale))
    h_hi = isotropic(hi.curvature(scale=scale))
    down = cv2.resize(h_hi, (256, 256), interpolation=cv2.INTER_AREA)
    sel = lo.mask
    assert _corr(h_lo[sel], down[sel]) >= 0.98
    inner = lo.interior(0.08)
    np.testing.assert_allclose(down[inner], h_lo[inner], atol=0.01)


def test_image_height_makes_tiles_match_the_full_frame() -> None:
    s = analytic.sphere(200, radius=0.6)
    full = s.curvature()
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
    c = s.curvature()
    inner = s.interior(0.05)
    for gain in (0.05, 0.1, 0.5):
        np.testing.assert_allclose(isotropic(c, gain)[inner], np.tanh(gain * 8.0), atol=2e-3)
    # The default maps a sphere spanning half the image to tanh(8 s), well inside tanh's range.
    np.testing.assert_allclose(isotropic(c)[inner], np.tanh(DEFAULT_GAIN * 8.0), atol=2e-3)
    assert 0.15 < float(np.median(isotropic(c)[inner])) < 0.5


def test_lazy_fields_match_and_stay_consistent() -> None:
    s = analytic.two_spheres(400)
    c = s.curvature(scale=0.012)
    assert c.__dict__["_coarse"].k1.shape[0] < s.shape[0]
    h_coarse = isotropic(c)  # mapped on the working grid
    k1, k2, w = c.k1, c.k2, c.weight
    direct = Curvature(k1.copy(), k2.copy(), c.dir_x.copy(), c.dir_y.copy(), w.copy())
    h_full = isotropic(direct)
    assert np.abs(h_full - h_coarse).max() < 0.05
    assert _corr(h_full[s.mask], h_coarse[s.mask]) > 0.999
    # So is the anisotropic mapping of a constant light.
    lazy = s.curvature(scale=0.012)
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
    c = s.curvature()
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
    c = s.curvature()
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
    fused = mean_curvature_layers(s.curvature(scale=scale), 0.2)
    c = s.curvature(scale=scale)
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
    c = s.curvature()
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
        strips = s.curvature(scale=scale, foreshortening=0.5)
        monkeypatch.setattr(oc, "_STRIP_ROWS", 100_000)
        whole = s.curvature(scale=scale, foreshortening=0.5)
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
