"""Apparent Relief (Vergne et al., NPAR 2008): descriptor, ARM lookup, shipped ARMs, styles."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from ops import relief as R
from ops.curvature import principal_curvatures
from tests import analytic

SCALE = 0.01  # derivative scale relative to the image height
SIZE = 128


def curv_of(scene: analytic.Scene, scale: float = SCALE):
    return principal_curvatures(scene.normal, scene.depth, scene.mask, scale=scale)


def trough(size: int = SIZE) -> analytic.Scene:
    """A concave cylinder (a trough along camera y): the cylinder with n_x mirrored."""
    s = analytic.cylinder(size, radius=0.5)
    s.normal[..., 0] *= -1.0
    return s


SHAPES = {
    "sphere": lambda: analytic.sphere(SIZE, radius=0.5),
    "bowl": lambda: analytic.bowl(SIZE, radius=0.5),
    "saddle": lambda: analytic.saddle(SIZE, radius=1.0, extent=0.8),
    "cylinder": lambda: analytic.cylinder(SIZE, radius=0.5),
    "trough": trough,
    "plane": lambda: analytic.plane(SIZE, tilt_x_deg=20.0),
}
#: Region each analytic shape falls in (the plane is the centre).
REGION_OF = {
    "sphere": "cap",
    "bowl": "cup",
    "saddle": "saddle",
    "cylinder": "convex",
    "trough": "concave",
    "plane": "plane",
}


def interior_s(name: str, **kw: object) -> np.ndarray:
    scene = SHAPES[name]()
    desc = R.descriptor(curv_of(scene), **kw)  # type: ignore[arg-type]
    inner = (
        scene.interior(0.12)
        if name != "saddle"
        else scene.interior(0.12) & (np.hypot(scene.u, scene.v) < 0.1)
    )
    assert inner.sum() > 50
    return desc.s[inner]


# -- descriptor ------------------------------------------------------------------------------------


def test_sphere_is_on_the_cap_diagonal() -> None:
    s = interior_s("sphere")
    np.testing.assert_allclose(s[:, 0], s[:, 1], atol=1e-3)  # κ1 ≈ κ2
    assert (s[:, 0] > 0).all()
    np.testing.assert_allclose(np.hypot(s[:, 0], s[:, 1]), 1.0, atol=1e-3)  # auto norm = its L


def test_bowl_is_on_the_cup_diagonal() -> None:
    s = interior_s("bowl")
    np.testing.assert_allclose(s[:, 0], s[:, 1], atol=1e-3)
    assert (s[:, 0] < 0).all()
    np.testing.assert_allclose(s.mean(0), [-math.sqrt(0.5)] * 2, atol=1e-3)


def test_saddle_is_in_the_saddle_region() -> None:
    s = interior_s("saddle")
    assert (s[:, 0] > 0).all() and (s[:, 1] < 0).all()
    d = s / np.linalg.norm(s, axis=1, keepdims=True)
    np.testing.assert_allclose(
        d, np.tile([math.sqrt(0.5), -math.sqrt(0.5)], (len(d), 1)), atol=0.02
    )


def test_cylinder_and_trough_lie_on_the_axes() -> None:
    np.testing.assert_allclose(interior_s("cylinder").mean(0), [1.0, 0.0], atol=1e-3)
    np.testing.assert_allclose(interior_s("trough").mean(0), [0.0, -1.0], atol=1e-3)


def test_plane_is_the_centre() -> None:
    assert np.abs(interior_s("plane")).max() < 1e-3
    assert np.abs(interior_s("plane", curvedness_norm=1.0)).max() < 1e-4


@pytest.mark.parametrize("shape", ["sphere", "saddle", "trough"])
def test_fused_descriptor_is_the_papers_s_equals_d_times_l(shape: str) -> None:
    """The compiled descriptor gives :func:`ops.relief.relief_vector` (S = D · L as written)
    from the same curvatures, below the rim and on it."""
    curv = curv_of(SHAPES[shape](), scale=0.004)  # its working grid is the image's
    rims = []
    for norm in (0.1, 1.0, 5.0):
        got = R.descriptor(curv, curvedness_norm=norm).s
        want = R.relief_vector(curv.k1, curv.k2, norm, curv.weight)
        np.testing.assert_allclose(got, want, atol=2e-7)
        rims.append(float(np.hypot(want[..., 0], want[..., 1]).max()))
    assert rims[0] > 0.999 > rims[-1] > 0.0  # clamped to the rim, and below it


def test_pinned_norm_scales_the_length_and_auto_reports_it() -> None:
    scene = SHAPES["sphere"]()
    curv = curv_of(scene)
    auto = R.descriptor(curv)
    assert auto.norm == pytest.approx(4.0, rel=1e-3)  # L = κ = ortho_height / R = 4
    pinned = R.descriptor(curv, curvedness_norm=8.0)
    assert pinned.norm == 8.0
    inner = scene.interior(0.12)
    np.testing.assert_allclose(np.linalg.norm(pinned.s[inner], axis=1), 0.5, atol=1e-3)
    # Twice the curvedness norm on a flatter sphere: same S.
    big = analytic.sphere(SIZE, radius=1.0 / 1.5)  # κ = 3
    s3 = R.descriptor(curv_of(big), curvedness_norm=6.0).s[big.interior(0.12)]
    np.testing.assert_allclose(np.linalg.norm(s3, axis=1), 0.5, atol=1e-3)


def test_curvedness_above_the_norm_is_clamped_to_the_rim() -> None:
    scene = analytic.saddle(SIZE)  # L = 2 at the centre, less away from it
    s = R.descriptor(curv_of(scene), curvedness_norm=0.5).s[scene.interior(0.12)]
    np.testing.assert_allclose(np.linalg.norm(s, axis=1), 1.0, atol=1e-5)
    assert (s[:, 0] > 0).all() and (s[:, 1] < 0).all()  # the direction D is kept


def test_background_and_silhouettes_are_planar() -> None:
    scene = analytic.sphere(SIZE, radius=0.5)
    s = R.descriptor(curv_of(scene)).s
    assert s.shape == (SIZE, SIZE, 2) and s.dtype == np.float32
    assert np.all(s[~scene.mask] == 0.0)
    assert np.all(np.linalg.norm(s, axis=2) <= 1.0 + 1e-5)


def test_auto_norm_is_a_percentile_of_covered_pixels() -> None:
    a = analytic.sphere(SIZE, radius=0.5, centre=(-0.5, 0.0), width=2 * SIZE)  # κ = 4
    b = analytic.sphere(SIZE, radius=0.25, centre=(0.5, 0.0), width=2 * SIZE)  # κ = 8
    normal = np.where(a.mask[..., None], a.normal, b.normal)
    depth = np.where(a.mask, a.depth, b.depth)
    mask = a.mask | b.mask
    curv = principal_curvatures(normal, depth, mask, scale=SCALE)
    lo = R.descriptor(curv, percentile=40.0).norm  # sphere a covers ~80 % of the coverage
    hi = R.descriptor(curv, percentile=99.0).norm
    assert lo == pytest.approx(4.0, rel=0.02)
    assert hi == pytest.approx(8.0, rel=0.02)


def test_curvedness_is_koenderinks() -> None:
    scene = analytic.saddle(SIZE)
    curv = curv_of(scene)
    inner = scene.interior(0.12)
    expect = np.sqrt((curv.k1**2 + curv.k2**2) / 2) * curv.weight
    np.testing.assert_allclose(R.curvedness(curv)[inner], expect[inner], rtol=1e-5)


@pytest.mark.parametrize(
    ("name", "kw"),
    [("curvedness_norm", {"curvedness_norm": 0.0}), ("curvedness_norm", {"curvedness_norm": "x"})]
    + [("percentile", {"percentile": p}) for p in (0.0, 101.0)],
)
def test_bad_descriptor_parameters(name: str, kw: dict) -> None:
    curv = curv_of(analytic.sphere(32))
    with pytest.raises(ValueError, match=name):
        R.descriptor(curv, **kw)


# -- regions, colour code, template ----------------------------------------------------------------


def anchor(region: str, rho: float = 1.0) -> np.ndarray:
    """S at the centre of a region, as a (1, 1, 2) image."""
    if region == "plane":
        return np.zeros((1, 1, 2), np.float32)
    th = math.radians(R.REGION_ANGLES[region])
    return np.array([[[rho * math.cos(th), rho * math.sin(th)]]], np.float32)


@pytest.mark.parametrize("region", R.REGIONS)
def test_classify_and_shape_index_at_region_centres(region: str) -> None:
    s = anchor(region, 0.8)
    assert R.REGIONS[int(R.classify(s)[0, 0])] == region
    mirrored = np.ascontiguousarray(s[..., ::-1])
    assert R.REGIONS[int(R.classify(mirrored)[0, 0])] == region
    expect = {"plane": 0, "cap": 1, "convex": 0.5, "saddle": 0, "concave": -0.5, "cup": -1}
    assert float(R.shape_index(s)[0, 0]) == pytest.approx(expect[region], abs=1e-3)


@pytest.mark.parametrize("region", R.REGIONS)
def test_descriptor_colors_follow_fig_1a(region: str) -> None:
    col = R.descriptor_colors(anchor(region))[0, 0]
    np.testing.assert_allclose(col, R.REGION_COLORS[region], atol=1e-3)
    half = R.descriptor_colors(anchor(region, 0.5))[0, 0]
    np.testing.assert_allclose(half, 0.5 + 0.5 * np.array(R.REGION_COLORS[region]), atol=1e-3)


def test_descriptor_colors_on_analytic_shapes() -> None:
    for name in ("sphere", "bowl", "saddle"):
        scene = SHAPES[name]()
        col = R.descriptor_colors(R.descriptor(curv_of(scene)).s)
        assert col.shape == (SIZE, SIZE, 3) and col.dtype == np.float32
        centre = col[SIZE // 2, SIZE // 2]
        np.testing.assert_allclose(centre, R.REGION_COLORS[REGION_OF[name]], atol=0.03)


def test_arm_template() -> None:
    tpl = R.arm_template(256)
    assert tpl.shape == (256, 256, 3) and tpl.dtype == np.float32
    assert 0.0 <= tpl.min() and tpl.max() <= 1.0
    # Region colours where the lookup reads them (away from lines and labels).
    for _region, (x, y) in {
        "cap": (0.7, 0.59),
        "saddle": (0.55, -0.72),
        "cup": (-0.55, -0.7),
    }.items():
        col, row = R.uv_to_texel(*R.s_to_uv(x, y), tpl.shape)
        expect = R.descriptor_colors(np.array([[[x, y]]], np.float32))[0, 0]
        np.testing.assert_allclose(tpl[round(row), round(col)], expect, atol=0.02)
    # The unreached half (κ2 > κ1) is dimmed towards grey: less saturated than its mirror.
    col, row = R.uv_to_texel(*R.s_to_uv(-0.3, 0.8), tpl.shape)
    mcol, mrow = R.uv_to_texel(*R.s_to_uv(0.8, -0.3), tpl.shape)
    a, b = tpl[round(row), round(col)], tpl[round(mrow), round(mcol)]
    assert np.ptp(a) < 0.6 * np.ptp(b)
    with pytest.raises(ValueError, match="size"):
        R.arm_template(8)


# -- ARM lookup ------------------------------------------------------------------------------------


def painted_arm(size: tuple[int, int], values: dict[str, float]) -> np.ndarray:
    labels = R.classify(R.arm_coords(size))
    return np.array([values[n] for n in R.REGIONS], np.float32)[labels]


VALUES = {"plane": 0.1, "cap": 0.3, "convex": 0.45, "saddle": 0.6, "concave": 0.75, "cup": 0.9}


@pytest.mark.parametrize("arm_size", [(64, 64), (37, 51), (256, 256)])
@pytest.mark.parametrize("name", list(SHAPES))
def test_lookup_reads_the_painted_region(name: str, arm_size: tuple[int, int]) -> None:
    arm = painted_arm(arm_size, VALUES)
    scene = SHAPES[name]()
    curv = curv_of(scene)
    inner = scene.interior(0.12)
    if name == "saddle":
        inner &= np.hypot(scene.u, scene.v) < 0.2
    r = R.arm_lookup(R.descriptor(curv).s, arm)
    assert r.shape == (SIZE, SIZE) and r.dtype == np.float32
    np.testing.assert_allclose(r[inner], VALUES[REGION_OF[name]], atol=1e-5)
    fused = R.relief(curv, arm)
    np.testing.assert_allclose(fused.r[inner], VALUES[REGION_OF[name]], atol=1e-5)


def test_lookup_is_bilinear_and_oriented() -> None:
    rng = np.random.default_rng(1)
    s = rng.uniform(-0.7, 0.7, (20, 30, 2)).astype(np.float32)
    h, w = 33, 17
    ramp_u = np.tile(np.linspace(0, 1, w, dtype=np.float32), (h, 1))  # u left -> right
    ramp_v = np.tile(np.linspace(1, 0, h, dtype=np.float32)[:, None], (1, w))  # v = 1 on top
    np.testing.assert_allclose(R.arm_lookup(s, ramp_u), (s[..., 0] + 1) / 2, atol=1e-5)
    np.testing.assert_allclose(R.arm_lookup(s, ramp_v), (s[..., 1] + 1) / 2, atol=1e-5)
    rgb = np.dstack([ramp_u, ramp_v, 1 - ramp_u])
    out = R.arm_lookup(s, rgb)
    assert out.shape == (20, 30, 3)
    np.testing.assert_allclose(out[..., 2], 1 - (s[..., 0] + 1) / 2, atol=1e-5)


def test_fused_relief_matches_lookup_on_a_working_grid() -> None:
    scene = analytic.two_spheres(256)
    curv = principal_curvatures(scene.normal, scene.depth, scene.mask, scale=0.02)
    assert curv.__dict__.get("_coarse") is not None, "expected a coarse working grid"
    arm = R.make_arm("convex_black_concave_white")
    ref = R.arm_lookup(R.descriptor(curv).s, arm)
    for full in (False, True):
        got = R.relief(curv, arm, full_resolution=full)
        assert got.norm == pytest.approx(R.descriptor(curv).norm)
        assert np.abs(got.r - ref).mean() < 5e-3  # differences only where S varies fast:
        inner = scene.interior(0.06)  # at the silhouettes, where the weight fades
        np.testing.assert_allclose(got.r[inner], ref[inner], atol=2e-3)
        if full:
            np.testing.assert_allclose(got.r, ref, atol=1e-4)


def test_bad_arms_are_rejected() -> None:
    s = np.zeros((4, 4, 2), np.float32)
    with pytest.raises(ValueError, match="arm"):
        R.arm_lookup(s, np.full((8, 8), 1.5, np.float32))
    with pytest.raises(ValueError, match="arm"):
        R.arm_lookup(s, np.full((8, 8), np.nan, np.float32))
    with pytest.raises(ValueError, match="arm"):
        R.arm_lookup(s, np.zeros((1, 8), np.float32))
    with pytest.raises(ValueError, match="S"):
        R.arm_lookup(np.zeros((4, 4, 3), np.float32), np.zeros((8, 8), np.float32))


def test_arm_from_image() -> None:
    u8 = np.array([[0, 255], [128, 51]], np.uint8)
    np.testing.assert_allclose(R.arm_from_image(u8), u8 / 255.0, atol=1e-6)
    u16 = (u8.astype(np.uint16) * 257)[..., None]
    np.testing.assert_allclose(R.arm_from_image(u16), u8 / 255.0, atol=1e-6)
    rgba = np.dstack([u8, u8, u8, np.zeros_like(u8)])
    np.testing.assert_allclose(R.arm_from_image(rgba), u8 / 255.0, atol=1e-4)
    with pytest.raises(ValueError, match="ARM image"):
        R.arm_from_image(np.zeros((2, 2, 2), np.uint8))


# -- shipped ARMs ----------------------------------------------------------------------------------


@pytest.mark.parametrize("name", R.SHIPPED_ARMS)
def test_shipped_arm_file_matches_the_generator(name: str) -> None:
    path = R.shipped_arm_path(name)
    assert path.is_file(), f"{path} missing: run python -m bench.make_arms"
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert img.dtype == np.uint8 and img.shape == (R.SHIPPED_ARM_SIZE,) * 2
    arm = R.arm_from_image(img)
    np.testing.assert_allclose(arm, R.make_arm(name), atol=0.5 / 255 + 1e-6)


@pytest.mark.parametrize("name", R.SHIPPED_ARMS)
def test_shipped_arms_have_their_documented_region_values(name: str) -> None:
    arm = R.arm_from_image(cv2.imread(str(R.shipped_arm_path(name)), cv2.IMREAD_UNCHANGED))
    for region, value in R.SHIPPED_ARM_VALUES[name].items():
        for rho in (0.6, 1.0) if region != "plane" else (0.0, 0.1):
            got = float(R.arm_lookup(anchor(region, rho), arm)[0, 0])
            assert got == pytest.approx(value, abs=0.01), (region, rho)


def test_shipped_arm_on_shapes_fig_1d() -> None:
    """Convexities black, concavities white, saddles and planes grey."""
    arm = R.arm_from_image(cv2.imread(str(R.shipped_arm_path("convex_black_concave_white")), 0))
    expect = {"sphere": 0.0, "cylinder": 0.0, "bowl": 1.0, "trough": 1.0, "saddle": 0.5}
    expect["plane"] = 0.5
    for name, value in expect.items():
        scene = SHAPES[name]()
        inner = scene.interior(0.12)
        if name == "saddle":
            inner &= np.hypot(scene.u, scene.v) < 0.1
        r = R.relief(curv_of(scene), arm).r
        np.testing.assert_allclose(r[inner], value, atol=0.02, err_msg=name)


def test_unknown_arm_name() -> None:
    with pytest.raises(ValueError, match="saddles_only"):
        R.shipped_arm_path("nope")
    with pytest.raises(ValueError, match="ARM name"):
        R.make_arm("nope")


# -- level of detail -------------------------------------------------------------------------------


def bumpy_plane(height: int, period: float, slope: float = 0.2, supersample: int = 1):
    """Orthographic plane with relief h = A sin(2πu/P) sin(2πv/P) (u, v, P in image heights),
    rendered at ``height * supersample`` and area-averaged down to ``height`` (anti-aliasing)."""
    hs = height * supersample
    u, v = analytic.pixel_coords(hs, hs)
    k = 2 * math.pi / period
    amp = slope / k
    hu = amp * k * np.cos(k * u) * np.sin(k * v)
    hv = amp * k * np.sin(k * u) * np.cos(k * v)
    n = np.dstack([-hu, -hv, np.ones_like(u)])
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    depth = 10.0 - amp * np.sin(k * u) * np.sin(k * v)
    n32, d32 = n.astype(np.float32), depth.astype(np.float32)
    if supersample > 1:
        n32 = cv2.resize(n32, (height, height), interpolation=cv2.INTER_AREA)
        n32 /= np.linalg.norm(n32, axis=2, keepdims=True)
        d32 = cv2.resize(d32, (height, height), interpolation=cv2.INTER_AREA)
    return n32, d32


def mean_curvedness(normal: np.ndarray, depth: np.ndarray, scale: float) -> float:
    curv = principal_curvatures(normal, depth, None, scale=scale)
    h = depth.shape[0]
    m = h // 8
    return float(R.curvedness(curv)[m:-m, m:-m].mean())


def test_level_of_detail_fine_bump_disappears_when_downsampled() -> None:
    scale = 0.001  # the same relative derivative scale at both resolutions
    fine = 4.0 / 512  # a 4-pixel period at 512 px, 1 pixel at 128 px
    coarse = 0.25
    l_fine_512 = mean_curvedness(*bumpy_plane(512, fine), scale)
    l_fine_128 = mean_curvedness(*bumpy_plane(128, fine, supersample=4), scale)
    l_coarse_512 = mean_curvedness(*bumpy_plane(512, coarse), scale)
    l_coarse_128 = mean_curvedness(*bumpy_plane(128, coarse, supersample=4), scale)
    assert l_fine_512 > 20.0  # clearly visible at 512 px
    assert l_fine_128 < 0.05 * l_fine_512  # gone at 128 px
    assert l_coarse_128 == pytest.approx(l_coarse_512, rel=0.1)  # large shapes stay
    # A period that is not a whole number of 128-px pixels is not exactly averaged out, but its
    # aliased remainder is much flatter.
    odd = 6.0 / 512
    l_odd_512 = mean_curvedness(*bumpy_plane(512, odd), scale)
    assert mean_curvedness(*bumpy_plane(128, odd, supersample=4), scale) < 0.1 * l_odd_512
    # And in the descriptor, with a pinned norm: the fine relief leaves the plane region.
    curv = principal_curvatures(*bumpy_plane(128, fine, supersample=4), None, scale=scale)
    s = R.descriptor(curv, curvedness_norm=l_fine_512).s
    assert (R.classify(s)[16:-16, 16:-16] == 0).all()


# -- styles ----------------------------------------------------------------------------------------


def test_cel_is_r() -> None:
    r = np.random.default_rng(2).random((8, 9), dtype=np.float32)
    np.testing.assert_array_equal(R.cel(r), r)


def test_counter_shading_is_binary_and_follows_the_formula() -> None:
    rng = np.random.default_rng(3)
    r = rng.random((64, 64), dtype=np.float32)
    nl = rng.uniform(-0.3, 1.0, (64, 64)).astype(np.float32)
    out = R.counter_shading(r, nl)
    assert out.dtype == np.float32 and set(np.unique(out)) <= {0.0, 1.0}
    assert 0 < out.mean() < 1
    c = np.clip(nl, 0, 1)
    i = (1 - r) * c + r * (1 - c)
    decided = np.abs(i - 0.5) > 1e-5
    np.testing.assert_array_equal(out[decided], (i > 0.5)[decided].astype(np.float32))
    # r = 0: plain diffuse thresholded; r = 1: inverted.
    np.testing.assert_array_equal(R.counter_shading(np.zeros_like(r), nl), (c > 0.5) * 1.0)
    np.testing.assert_array_equal(R.counter_shading(np.ones_like(r), nl), (c < 0.5) * 1.0)
    with pytest.raises(ValueError, match="threshold"):
        R.counter_shading(r, nl, threshold=1.5)
    with pytest.raises(ValueError, match="ndotl"):
        R.counter_shading(r, nl[:10])


def test_xtoon_indexes_tone_and_relief() -> None:
    rng = np.random.default_rng(4)
    r = rng.random((16, 16), dtype=np.float32)
    nl = rng.random((16, 16), dtype=np.float32)
    h, w = 9, 21
    tone = np.tile(np.linspace(0, 1, w, dtype=np.float32), (h, 1))
    detail = np.tile(np.linspace(1, 0, h, dtype=np.float32)[:, None], (1, w))  # r = 1 on top
    out = R.xtoon(r, nl, np.dstack([tone, detail]))
    assert out.shape == (16, 16, 2)
    np.testing.assert_allclose(out[..., 0], nl, atol=1e-5)
    np.testing.assert_allclose(out[..., 1], r, atol=1e-5)
    default = R.xtoon(r, nl)
    assert default.shape == (16, 16, 3) and 0 <= default.min() and default.max() <= 1


def test_default_toon_selected_rows_have_more_contrast() -> None:
    toon = R.default_toon()
    assert toon.shape == (64, 256, 3) and toon.dtype == np.float32
    top, bottom = toon[0, :, 1], toon[-1, :, 1]  # r = 1, r = 0
    assert np.ptp(top) > 1.5 * np.ptp(bottom)
    assert len(np.unique(np.round(top[[10, 120, 250]], 3))) == 3  # three tones


def test_masked_blends_base_and_effect() -> None:
    rng = np.random.default_rng(5)
    base = rng.random((10, 12, 3), dtype=np.float32)
    effect = rng.random((10, 12, 3), dtype=np.float32)
    r = rng.random((10, 12), dtype=np.float32)
    out = R.masked(r, base, effect)
    np.testing.assert_allclose(out, base * (1 - r[..., None]) + effect * r[..., None], atol=1e-6)
    np.testing.assert_allclose(R.masked(np.zeros_like(r), base, effect), base, atol=1e-7)
    np.testing.assert_allclose(
        R.masked(np.ones_like(r), base[..., 0], effect[..., 0]), effect[..., 0]
    )
    with pytest.raises(ValueError, match="effect"):
        R.masked(r, base, effect[..., :2])


def test_masked_exaggerated_shading_only_on_convexities() -> None:
    """Fig. 2c: exaggerated shading where the ARM selects convex features, Lambert elsewhere."""
    from ops.baselines import exaggerated_shading, lambert_image

    scene = analytic.two_spheres(SIZE)
    bowl = analytic.bowl(SIZE, radius=0.3)
    # Left half: the spheres; right half: a bowl (concave).
    normal = scene.normal.copy()
    depth = scene.depth.copy()
    mask = scene.mask.copy()
    half = SIZE // 2
    normal[:, half:], depth[:, half:], mask[:, half:] = (
        bowl.normal[:, half:],
        bowl.depth[:, half:],
        bowl.mask[:, half:],
    )
    light = (0.5, 0.5, 0.7)
    base = lambert_image(normal, mask, light)
    effect = exaggerated_shading(normal, depth, mask, light)
    curv = principal_curvatures(normal, depth, mask, scale=SCALE)
    r = R.relief(curv, R.make_arm("convex_only")).r
    out = R.masked(r, base, effect)
    sel, unsel = r > 0.99, (r < 0.01) & mask
    assert sel.sum() > 100 and unsel.sum() > 100
    np.testing.assert_allclose(out[sel], effect[sel], atol=1e-5)
    np.testing.assert_allclose(out[unsel], base[unsel], atol=1e-5)


# -- pick and paint --------------------------------------------------------------------------------


def test_pick_returns_s_and_its_uv() -> None:
    scene = analytic.saddle(SIZE)
    s = R.descriptor(curv_of(scene)).s
    p = R.pick(s, SIZE // 2, SIZE // 2)
    assert (p.s1, p.s2) == (float(s[SIZE // 2, SIZE // 2, 0]), float(s[SIZE // 2, SIZE // 2, 1]))
    assert p.u == pytest.approx((p.s1 + 1) / 2) and p.v == pytest.approx((p.s2 + 1) / 2)
    assert p.u > 0.5 > p.v  # saddle: κ1 > 0 > κ2
    with pytest.raises(ValueError, match="x="):
        R.pick(s, SIZE, 0)
    with pytest.raises(ValueError, match="y="):
        R.pick(s, 0, -1)


def test_paint_around_a_picked_feature_selects_it() -> None:
    sph, bowl = SHAPES["sphere"](), SHAPES["bowl"]()
    s_sph = R.descriptor(curv_of(sph)).s
    s_bowl = R.descriptor(curv_of(bowl)).s
    p = R.pick(s_sph, SIZE // 2, SIZE // 2)
    arm = R.paint_arm(np.zeros((64, 64), np.float32), (p.s1, p.s2), 0.8, radius=0.2)
    inner = sph.interior(0.12)
    np.testing.assert_allclose(R.arm_lookup(s_sph, arm)[inner], 0.8, atol=1e-5)
    assert R.arm_lookup(s_bowl, arm)[bowl.interior(0.12)].max() == 0.0
    with pytest.raises(ValueError, match="radius"):
        R.paint_arm(arm, (0.0, 0.0), 1.0, radius=0.0)
