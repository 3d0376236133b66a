"""Local Light Alignment (LLA Eq. 1, §4-6) on analytic G-buffers."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

import ops.pyramid.depth
from ops import shading
from ops.filtering import NormalPyramid, multiscale_normals, normal_pyramid
from ops.light_alignment import (
    align_components,
    align_light,
    align_lights,
    align_scale,
    rotate_towards,
    w_gamma,
)
from ops.light_alignment._stages import _guide_soa, _Work
from tests import analytic
from tests.test_filtering import bumpy_dome


def unit(v: tuple[float, float, float]) -> np.ndarray:
    a = np.asarray(v, np.float64)
    return (a / np.linalg.norm(a)).astype(np.float32)


def lambert(n: np.ndarray, light: np.ndarray) -> np.ndarray:
    return np.clip((n * light).sum(axis=-1), 0.0, None)


def constant_fields(vectors: list[np.ndarray], shape: tuple[int, int] = (4, 5)) -> list[np.ndarray]:
    return [np.broadcast_to(unit(tuple(v)), (*shape, 3)).copy() for v in vectors]


def angle(a: np.ndarray, b: np.ndarray) -> float:
    return math.acos(float(np.clip(np.dot(a, b) / np.linalg.norm(a) / np.linalg.norm(b), -1, 1)))


# -- W_γ ------------------------------------------------------------------------------------


def test_w_gamma_properties() -> None:
    lam = np.linspace(0.0, 1.0, 101, dtype=np.float32)
    np.testing.assert_allclose(w_gamma(lam, 0.0), lam, atol=1e-6)  # W_0 is the identity
    for gamma in (0.5, 1.0, 3.0, 8.0):
        w = w_gamma(lam, gamma)
        assert w[0] == 0.0
        assert w[-1] == pytest.approx(1.0, abs=1e-6)
        assert np.all(np.diff(w) > 0.0)  # strictly increasing
        assert np.all((w >= 0.0) & (w <= 1.0))
    # a larger γ narrows the transition: W rises faster
    assert np.all(w_gamma(lam[1:-1], 4.0) > w_gamma(lam[1:-1], 2.0))
    assert float(w_gamma(0.5, 3.0)) == pytest.approx(0.5 / (math.exp(-3.0) * 0.5 + 0.5), rel=1e-6)


def test_w_gamma_rejects_bad_gamma() -> None:
    with pytest.raises(ValueError, match="gamma"):
        w_gamma(0.5, -1.0)
    with pytest.raises(ValueError, match="gamma"):
        w_gamma(0.5, float("inf"))


# -- Eq. 1 on one scale, against a float64 reference -----------------------------------------


@pytest.mark.parametrize("sigma", [0.3, 1.0])
@pytest.mark.parametrize("gamma", [0.0, 3.0])
def test_lit_side_rotates_towards_the_normal(sigma: float, gamma: float) -> None:
    alpha, beta = math.radians(30.0), math.radians(50.0)
    n1 = unit((math.sin(alpha), 0.0, math.cos(alpha)))
    z = unit((0.0, 0.0, 1.0))
    light = unit((math.sin(beta), 0.0, math.cos(beta)))  # same side as n1: ℓ̄·x > 0
    out = align_light(light, constant_fields([n1, z]), [sigma], gamma=gamma)
    lam = 1.0 * math.sin(alpha)  # λ1 = 1 (ℓ̄ along x), λ2 = |n̄| = sin α
    theta = sigma * float(w_gamma(lam, gamma)) * angle(light, n1)
    ref = rotate_towards(light, n1, theta)
    np.testing.assert_allclose(out[0, 0], ref, atol=3e-4)  # cv2.phase: ~1e-4 rad


@pytest.mark.parametrize("sigma", [0.4, 1.0])
def test_other_side_rotates_towards_the_tangent(sigma: float) -> None:
    alpha, beta = math.radians(30.0), math.radians(20.0)
    n1 = unit((math.sin(alpha), 0.0, math.cos(alpha)))
    z = unit((0.0, 0.0, 1.0))
    light = unit((-math.sin(beta), 0.0, math.cos(beta)))  # ℓ̄·x < 0
    out = align_light(light, constant_fields([n1, z]), [sigma], gamma=3.0)
    tangent = np.array([-math.cos(alpha), 0.0, math.sin(alpha)])  # ⟂ n1, in (x, z), towards z
    theta = sigma * float(w_gamma(math.sin(alpha), 3.0)) * angle(light, tangent)
    ref = rotate_towards(light, tangent, theta)
    np.testing.assert_allclose(out[0, 0], ref, atol=3e-4)  # cv2.phase: ~1e-4 rad
    if sigma == 1.0:  # σ = 1, W ≈ 1: the light grazes the surface
        assert abs(float(out[0, 0] @ n1)) < 0.05
    assert float(out[0, 0] @ n1) < float(light @ n1)  # darker than before


def test_lambda1_uses_the_projected_angle() -> None:
    alpha = math.radians(40.0)
    n1 = unit((math.sin(alpha), 0.0, math.cos(alpha)))
    z = unit((0.0, 0.0, 1.0))
    light = unit((0.5, 0.5, 0.70710678))  # ℓ̄ at 45° from x: λ1 = 1 − 2(π/4)/π = 0.5
    out = align_light(light, constant_fields([n1, z]), [1.0], gamma=0.0)
    theta = float(w_gamma(0.5 * math.sin(alpha), 0.0)) * angle(light, n1)
    np.testing.assert_allclose(out[0, 0], rotate_towards(light, n1, theta), atol=3e-4)


def test_light_along_the_base_normal_or_no_feature_is_unchanged() -> None:
    n1 = unit((0.4, 0.1, 0.9))
    z = unit((0.0, 0.0, 1.0))
    out = align_light(z, constant_fields([n1, z]), [1.0])  # ℓ̄ = 0: λ1 = 0
    np.testing.assert_allclose(out, np.broadcast_to(z, out.shape), atol=1e-6)
    flat = constant_fields([z, z])  # n_i = n_{i+1}: λ2 = 0
    light = unit((0.3, -0.5, 0.8))
    np.testing.assert_allclose(align_light(light, flat, [1.0]), np.broadcast_to(light, (4, 5, 3)))


def test_scales_apply_from_coarse_to_fine() -> None:
    """ℓ_S = ℓ, ℓ_i = R_i ℓ_{i+1}: two one-scale calls chained give the two-scale result."""
    n = [unit((0.5, 0.1, 0.85)), unit((0.2, -0.2, 0.95)), unit((0.0, 0.0, 1.0))]
    light = unit((-0.3, 0.6, 0.75))
    f = constant_fields(n)
    both = align_light(light, f, [0.7, 0.5])
    coarse = align_light(light, [f[1], f[2]], [0.5])
    chained = align_components(coarse, [f[0], f[1]], {"diffuse": [0.7]})["diffuse"]
    np.testing.assert_allclose(both, chained, atol=1e-5)


def test_rotate_towards_keeps_length_and_reaches_the_guide() -> None:
    rng = np.random.default_rng(7)
    ell = rng.normal(size=(500, 3))
    ell /= np.linalg.norm(ell, axis=1, keepdims=True)
    g = rng.normal(size=(500, 3))
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    omega = np.arccos(np.clip(np.sum(ell * g, axis=1), -1.0, 1.0))
    onto = rotate_towards(ell, g, omega)
    np.testing.assert_allclose(np.linalg.norm(onto, axis=1), 1.0, atol=1e-6)
    np.testing.assert_allclose(onto, g, atol=1e-5)  # θ = Ω: onto g
    half = rotate_towards(ell, g, omega / 2)  # halfway: the bisector
    np.testing.assert_allclose(np.sum(half * ell, axis=1), np.cos(omega / 2), atol=1e-5)
    np.testing.assert_allclose(np.sum(half * g, axis=1), np.cos(omega / 2), atol=1e-5)


def test_the_fused_kernel_is_eq1_as_written() -> None:
    """One scale of the compiled Eq. 1 (align_light on two fields) against
    :func:`ops.light_alignment.align_scale`, the paper's formula in float64 NumPy, on every
    pixel of a bumpy dome (fine normals over their smoothed base) for lights all around."""
    s = bumpy_dome(96, 128)
    fine = s.normal
    base = np.asarray(shading.normalize(cv2.GaussianBlur(fine, (0, 0), 6.0)), np.float32)
    cov = s.mask & (np.linalg.norm(base, axis=2) > 0.5)
    for light in ((-0.4, 0.6, 0.7), (0.8, 0.1, 0.6), (0.0, -0.3, 0.95)):
        ell = unit(light)
        for sigma, gamma in ((1.0, 3.0), (0.4, 0.0)):
            fused = align_light(ell, [fine, base], [sigma], gamma=gamma, mask=cov)
            written = align_scale(np.broadcast_to(ell, fine.shape), fine, base, sigma, gamma)
            err = np.linalg.norm(fused - written, axis=2)[cov]
            # float32 rounding of nearly parallel fields moves a few pixels (module docstring)
            assert np.median(err) < 1e-6 and np.percentile(err, 99) < 1e-4 and err.max() < 5e-3
            turned = np.linalg.norm(written - ell, axis=2)[cov]
            assert turned.max() > 0.1  # the case turns the light


# -- on images ------------------------------------------------------------------------------


def test_zero_sigmas_leave_the_light_unchanged() -> None:
    s = bumpy_dome(64, 96)
    pyr = normal_pyramid(s.normal, s.depth, s.mask, scales=5, base=0.02)
    light = unit((0.3, 0.5, 0.8))
    view = np.array([0.0, 0.0, 1.0], np.float32)
    comps = {"diffuse": [0.0] * 4, "specular": [0.0] * 4, "transmission": [0.0] * 4}
    for normals in (pyr, pyr.full_list()):
        out = align_components(light, normals, comps, view=view)
        for g in comps:
            np.testing.assert_allclose(out[g], np.broadcast_to(light, out[g].shape), atol=1e-6)


BASE = 0.15  # σ_1 ≈ 19 px at 128 px: ~4x the ridge's half-width


def tent_on_plane(size: int = 128) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A ridge (two 35° flanks, half-width 0.04 image heights) on a plane facing the camera —
    the "Lambertian feature on a plane" of LLA §4 / Fig. 2. The coarse scale (``BASE``) sees
    a plane: the frame's z stays within ~1° of the view axis on the flanks. Returns normal,
    depth, left and right flank masks (away from the crest and foot)."""
    u, _ = analytic.pixel_coords(size, size)
    slope = math.radians(35.0)
    half = 0.04
    on = np.abs(u) < half
    nx = np.where(on & (u > 0), math.sin(slope), np.where(on & (u < 0), -math.sin(slope), 0.0))
    nz = np.where(on, math.cos(slope), 1.0)
    normal = np.stack([nx, np.zeros_like(nx), nz], axis=-1).astype(np.float32)
    height = np.where(on, (half - np.abs(u)) * math.tan(slope), 0.0) * 2.0  # scene units
    depth = (10.0 - height).astype(np.float32)
    left = (u < -0.01) & (u > -half + 0.01)
    right = (u > 0.01) & (u < half - 0.01)
    return normal, depth, left, right


@pytest.mark.parametrize("use_pyramid", [True, False])
def test_ridge_lit_from_above_gets_a_bright_and_a_dark_side(use_pyramid: bool) -> None:
    normal, depth, left, right = tent_on_plane()
    pyr = normal_pyramid(normal, depth, None, scales=3, base=BASE)
    normals = pyr if use_pyramid else pyr.full_list()
    # from above the ridge, 1.5° off its bisector (exactly on it, the mirror symmetry of Eq. 1
    # keeps both sides alike: see test_symmetric_light_gives_a_symmetric_result)
    light = unit((math.sin(math.radians(1.5)), 0.0, math.cos(math.radians(1.5))))
    before = lambert(normal, light)
    assert abs(before[right].mean() - before[left].mean()) < 0.05  # (nearly) the same
    out = align_light(light, normals, [1.0, 0.0], gamma=3.0)
    after = lambert(normal, out)
    assert after[right].mean() > 0.95  # the lit side faces the light
    assert after[left].mean() < 0.1  # the other side is grazed


def test_symmetric_light_gives_a_symmetric_result() -> None:
    s = analytic.ridge(64, width=96)
    light = unit((0.0, 0.3, 1.0))  # in the ridge's plane of symmetry x = 0
    out = align_light(light, normal_pyramid(s.normal, s.depth, s.mask, scales=4), [0.8] * 3)
    mirrored = out[:, ::-1] * np.array([-1.0, 1.0, 1.0], np.float32)
    np.testing.assert_allclose(out, mirrored, atol=2e-3)
    assert np.degrees(np.arccos(np.clip(out @ light, -1, 1))).max() > 5.0  # it did rotate


@pytest.mark.parametrize("guide", ["diffuse", "specular", "transmission"])
def test_aligned_directions_are_unit_and_background_keeps_the_light(guide: str) -> None:
    s = analytic.two_spheres(64, width=80)
    light = unit((-0.4, 0.6, 0.7))
    view = np.array([0.0, 0.0, 1.0], np.float32)
    out = align_light(
        light,
        normal_pyramid(s.normal, s.depth, s.mask, scales=5),
        [0.6] * 4,
        guide=guide,
        view=view,
    )
    assert out.dtype == np.float32 and out.shape == s.normal.shape
    np.testing.assert_allclose(np.linalg.norm(out, axis=-1), 1.0, atol=1e-5)
    np.testing.assert_allclose(out[~s.mask], np.broadcast_to(light, out[~s.mask].shape), atol=1e-6)
    assert np.any(np.abs(out[s.mask] - light) > 0.05)


def test_no_bleeding_of_the_back_object_into_the_front_one() -> None:
    two = analytic.two_spheres(96, width=128)
    front = two.segment == 0
    n_alone = np.where(front[..., None], two.normal, 0.0).astype(np.float32)
    d_alone = np.where(front, two.depth, np.inf).astype(np.float32)
    light = unit((0.5, 0.4, 0.75))
    kw = {"scales": 5, "base": 0.03}
    both = align_light(light, normal_pyramid(two.normal, two.depth, two.mask, **kw), [0.7] * 4)
    alone = align_light(light, normal_pyramid(n_alone, d_alone, front, **kw), [0.7] * 4)
    err = np.degrees(np.arccos(np.clip((both[front] * alone[front]).sum(-1), -1, 1)))
    assert err.max() < 0.5


def test_pyramid_path_matches_the_full_resolution_path() -> None:
    s = bumpy_dome(128, 160)
    pyr = normal_pyramid(s.normal, s.depth, s.mask, scales=6, base=0.01)
    light = unit((0.6, 0.5, 0.6))
    sig = [0.5, 0.4, 0.6, 0.7, 0.8]
    fast = lambert(s.normal, align_light(light, pyr, sig))[s.mask]
    full = lambert(s.normal, align_light(light, pyr.full_list(), sig))[s.mask]
    assert np.corrcoef(fast, full)[0, 1] > 0.99
    orig = lambert(s.normal, light)[s.mask]
    assert np.corrcoef(full, orig)[0, 1] < 0.97  # the alignment did change the shading


def test_same_frame_at_two_resolutions_matches() -> None:
    lo, hi = bumpy_dome(96, 128), bumpy_dome(192, 256)
    light = unit((0.6, 0.5, 0.6))
    sig = [0.6, 0.5, 0.5, 0.7]
    shaded = []
    for s in (lo, hi):
        pyr = normal_pyramid(s.normal, s.depth, s.mask, scales=5, base=0.012)
        shaded.append(lambert(s.normal, align_light(light, pyr, sig)))
    down = shaded[1].reshape(96, 2, 128, 2).mean(axis=(1, 3))
    inner = lo.mask & (np.hypot(2 * lo.u, 2 * lo.v) < 0.8)
    assert np.corrcoef(down[inner], shaded[0][inner])[0, 1] >= 0.98


def test_specular_guide_moves_highlights_and_matches_shading_formulas() -> None:
    normal, depth, left, right = tent_on_plane()
    view = np.array([0.0, 0.0, 1.0], np.float32)
    light = unit((0.05, 0.0, 1.0))
    pyr = normal_pyramid(normal, depth, None, scales=3, base=BASE)
    spec = align_light(light, pyr, [1.0, 0.0], guide="specular", view=view)
    before = shading.blinn_phong(normal, light, view, 20.0)
    after = shading.blinn_phong(normal, spec, view, 20.0)
    assert abs(before[right].mean() - before[left].mean()) < 0.05
    assert after[right].mean() > 0.9 and after[left].mean() < 0.05  # highlight on one flank
    # the structure-of-arrays guides are ops.shading's reflect / refract
    rng = np.random.default_rng(1)
    n = rng.normal(size=(6, 7, 3)).astype(np.float32)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    v = rng.normal(size=(6, 7, 3)).astype(np.float32)
    v[..., 2] = np.abs(v[..., 2]) + 0.2
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    ws = _Work((6, 7))
    soa = lambda a: tuple(np.ascontiguousarray(a[..., c]) for c in range(3))  # noqa: E731
    for guide, ior, ref in (
        ("specular", 1.5, shading.reflect(v, n)),
        ("transmission", 1.33, shading.refract(v, n, 1.33)),
        ("transmission", 0.7, shading.refract(v, n, 0.7)),  # with total internal reflection
    ):
        got = _guide_soa(guide, soa(n), soa(v), ior, ws.vec("o"), ws)
        np.testing.assert_allclose(np.stack(got, axis=-1), ref, atol=1e-5)


def test_transmission_guide_uses_the_refracted_view() -> None:
    normal, depth, left, right = tent_on_plane()
    view = np.array([0.0, 0.0, 1.0], np.float32)
    light = unit((0.03, 0.0, -1.0))  # behind the surface
    pyr = normal_pyramid(normal, depth, None, scales=3, base=BASE)
    out = align_light(light, pyr, [1.0, 0.0], guide="transmission", view=view, ior=1.5)
    before = shading.transmission(normal, light, view, ior=1.5, exponent=8.0)
    after = shading.transmission(normal, out, view, ior=1.5, exponent=8.0)
    assert abs(before[right].mean() - before[left].mean()) < 0.1
    assert abs(after[right].mean() - after[left].mean()) > 0.9
    other = align_light(light, pyr, [1.0, 0.0], guide="transmission", view=view, ior=1.1)
    assert np.abs(other - out).max() > 1e-3  # the index of refraction matters


# -- several lights ---------------------------------------------------------------------------


def test_align_lights_handles_directional_and_point_lights() -> None:
    s = analytic.sphere(48, radius=0.7)
    u, v = analytic.pixel_coords(48, 48)
    position = np.stack([2 * u, 2 * v, -s.depth], axis=-1).astype(np.float32)
    position[~s.mask] = 0.0
    view = np.array([0.0, 0.0, 1.0], np.float32)
    pyr = normal_pyramid(s.normal, s.depth, s.mask, scales=4)
    lights = [
        shading.Light("directional", (1.0, 1.0, 1.0)),
        shading.Light("point", (2.0, 1.0, -8.0)),
    ]
    comps = {"diffuse": [0.5] * 3, "specular": [0.3] * 3}
    out = align_lights(lights, pyr, position, view, comps)
    assert set(out) == {"diffuse", "specular"} and all(len(x) == 2 for x in out.values())
    np.testing.assert_allclose(
        out["diffuse"][0], align_light(np.array([1, 1, 1], np.float32), pyr, [0.5] * 3), atol=1e-4
    )
    point_dirs = shading.light_vectors(lights[1], position)
    for g in comps:
        got = out[g][1]
        np.testing.assert_allclose(np.linalg.norm(got, axis=-1), 1.0, atol=1e-5)
        np.testing.assert_allclose(got[~s.mask], point_dirs[~s.mask], atol=1e-6)
        rot = np.degrees(np.arccos(np.clip((got * point_dirs).sum(-1), -1, 1)))[s.mask]
        assert 0.5 < rot.mean() < 60.0


def test_align_lights_is_each_light_aligned_alone() -> None:
    # three lights aligned in one pass over each level's strips (the fields, the view and the
    # joint bilateral taps made once for all) come out bit for bit as each light aligned alone
    # on a pyramid of its own, and so on full-resolution fields; a sphere before a wall (depth
    # jumps: joint bilateral upsampling) with a per-pixel view for the specular and
    # transmission guides, directional and point lights mixed
    s = analytic.sphere(160, radius=0.7)
    depth = np.where(s.mask, s.depth, np.float32(s.depth[s.mask].max() + 2.0)).astype(np.float32)
    normal = np.where(s.mask[..., None], s.normal, np.float32([0.0, 0.0, 1.0])).astype(np.float32)
    u, v = analytic.pixel_coords(160, 160)
    position = np.stack([2 * u, 2 * v, -depth], axis=-1).astype(np.float32)
    view = -position / np.linalg.norm(position, axis=-1, keepdims=True)
    view = view.astype(np.float32)
    lights = [
        shading.Light("directional", (1.0, 1.0, 1.0)),
        shading.Light("point", (2.0, 1.0, -8.0)),
        shading.Light("directional", (-0.5, 0.2, 1.0)),
    ]
    comps = {"diffuse": [0.5] * 4, "specular": [0.3] * 4, "transmission": [0.4] * 4}

    def pyramid() -> NormalPyramid:
        return normal_pyramid(normal, depth, None, scales=5)

    used, fresh = pyramid().geometry, pyramid().geometry
    planes = [np.ascontiguousarray(normal[::2, ::2, c]) for c in range(3)]
    used.up_sparse([q[::2, ::2] for q in planes], 2, 1)
    got, want = used.up_sparse(planes, 1, 0), fresh.up_sparse(planes, 1, 0)
    assert got[0].size and all(np.array_equal(a, b) for a, b in zip(got, want, strict=True))
    fields = pyramid().full_list()
    for normals in (pyramid, lambda: fields):
        out = align_lights(lights, normals(), position, view, comps)
        for i, light in enumerate(lights):
            ldir = light.vector if light.kind == "directional" else None
            alone = align_components(
                shading.light_vectors(light, position) if ldir is None else np.asarray(ldir),
                normals(),
                comps,
                view=view,
            )
            for g in comps:
                assert np.array_equal(out[g][i], alone[g]), (i, g)
        assert not np.array_equal(out["diffuse"][0], out["diffuse"][2])


# -- parameters -----------------------------------------------------------------------------


def test_bad_parameters_raise() -> None:
    f = constant_fields([unit((0.3, 0, 1)), unit((0, 0, 1))])
    light = unit((0.2, 0.3, 0.9))
    with pytest.raises(ValueError, match="sigmas"):
        align_light(light, f, [0.5, 0.5])
    with pytest.raises(ValueError, match="sigmas"):
        align_light(light, f, [1.5])
    with pytest.raises(ValueError, match="gamma"):
        align_light(light, f, [0.5], gamma=-1.0)
    with pytest.raises(ValueError, match="guide"):
        align_light(light, f, [0.5], guide="glossy")
    with pytest.raises(ValueError, match="view"):
        align_light(light, f, [0.5], guide="specular")
    with pytest.raises(ValueError, match="ior"):
        align_light(light, f, [0.5], guide="transmission", view=light, ior=0.0)
    with pytest.raises(ValueError, match="light_dir"):
        align_light(np.zeros(3, np.float32), f, [0.5])
    with pytest.raises(ValueError, match="light_dir"):
        align_light(np.zeros((2, 2, 3), np.float32), f, [0.5])
    with pytest.raises(ValueError, match="normals"):
        align_light(light, f[:1], [])


def test_multiscale_normals_list_and_pyramid_agree_on_inputs() -> None:
    s = analytic.sphere(40)
    fields = multiscale_normals(s.normal, s.depth, s.mask, scales=3)
    light = unit((0.1, 0.2, 1.0))
    a = align_light(light, fields, [0.5, 0.5], mask=s.mask)
    b = align_light(light, fields, [0.5, 0.5])
    np.testing.assert_allclose(a, b, atol=1e-6)


@pytest.mark.parametrize("points", [8192, 97])  # points per task of the gathering
def test_edge_aware_upsampling_by_strips_is_the_whole_image_rule(
    points: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``DepthPyramid.up_rows`` of three unit fields at once, strip by strip (interior strips
    resize the fields stacked and take the compiled write of the sparse values; the top and
    bottom strips one field at a time), is the whole image's bilinear resize with the
    ``up_sparse`` values in place, bit for bit; and those values are the joint bilateral
    taps' normalised weighted sums (written out in NumPy), gathered in one task or in many on
    both cores. A sphere before a wall: depth jumps."""
    monkeypatch.setattr(ops.pyramid.depth, "_GATHER_POINTS", points)
    s = analytic.sphere(160, radius=0.7)
    depth = np.where(s.mask, s.depth, np.float32(s.depth[s.mask].max() + 2.0)).astype(np.float32)
    normal = np.where(s.mask[..., None], s.normal, np.float32([0.0, 0.0, 1.0])).astype(np.float32)
    geo = normal_pyramid(normal, depth, None, scales=5).geometry
    k = 2
    hk, wk = geo.shape(k)
    rng = np.random.default_rng(4)
    fields = [rng.standard_normal((hk, wk, 3)).astype(np.float32) for _ in range(3)]
    planes = [np.ascontiguousarray(f[..., c]) for f in fields for c in range(3)]
    ys, xs, vals = sparse = geo.up_sparse(planes, k, 0)
    assert ys.size > 100  # the sphere's outline
    _, _, idx, w = geo._sparse_taps(k, 0)
    for c0 in range(0, 9, 3):
        taps = np.stack([planes[c0 + c].reshape(-1)[idx] for c in range(3)], axis=-1)
        acc = np.zeros((ys.size, 3), np.float32)
        for t in range(idx.shape[0]):  # Σ_t in order, in float32, as the kernel
            acc += w[t][:, None] * taps[t]
        n2 = (acc * acc).sum(-1, dtype=np.float32)
        inv = np.where(n2 > 1e-20, 1.0 / np.sqrt(np.maximum(n2, 1e-30)), 0.0).astype(np.float32)
        # (the kernel fuses multiply-adds: the last bits may differ)
        np.testing.assert_allclose(vals[:, c0 : c0 + 3], acc * inv[:, None], atol=1e-6)
    h0, w0 = geo.shape(0)
    whole = [cv2.resize(p, (w0, h0), interpolation=cv2.INTER_LINEAR) for p in planes]
    for ref, col in zip(whole, vals.T, strict=True):
        ref[ys, xs] = col
    work = _Work((1, 1))
    for r0 in range(0, h0, 24):
        r1 = min(h0, r0 + 24)
        got = geo.up_rows(planes, k, (r0, r1), work.arr, sparse, cols=(5, w0 - 7))
        for g, ref in zip(got, whole, strict=True):
            np.testing.assert_array_equal(g, ref[r0:r1, 5 : w0 - 7])
