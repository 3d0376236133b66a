"""Radiance Scaling in the scenarios of RS §5 (ops.radiance_scaling) on analytic G-buffers.

The references are computed here, in float64 from the paper's formulas, not with the functions
under test: the unscaled shading of each scenario (Phong lobes, Ashikhmin-Shirley, AO × L̄,
Lit Sphere and environment lookups), the reflectance mapping δ of each lobe (§5.1-5.3), and the
direction of the effect (§4: on convexities intensities above α brighten, below α darken; the
reverse in concavities).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from ops import radiance_scaling as rs
from ops.curvature import Curvature, anisotropic, isotropic, principal_curvatures
from ops.radiance_scaling import sigma
from ops.shading import Light
from ops.shading import ashikhmin_shirley as as_brdf
from tests import analytic

SIZE = 64
GAIN = 0.1  # κ = tanh(0.8) ≈ 0.66 inside the analytic sphere and bowl: far from saturation
LIGHT_DIR = np.array([-0.5, 0.4, 0.77]) / np.linalg.norm([-0.5, 0.4, 0.77])
LIGHT = Light("directional", tuple(LIGHT_DIR))
ALBEDO = (0.9, 0.6, 0.3)
SHININESS = 8.0
REC709 = np.array([0.2126, 0.7152, 0.0722])

#: scenario -> the lobes it returns
SCENARIOS: dict[str, tuple[str, ...]] = {
    "phong": ("ambient", "diffuse", "specular"),
    "sub_lambert": ("ambient", "diffuse", "specular"),
    "ashikhmin_shirley": ("diffuse", "specular"),
    "precomputed_diffuse": ("diffuse",),
    "lit_sphere": ("specular",),
    "mirror": ("specular",),
    "refraction": ("specular",),
}


# -- inputs --------------------------------------------------------------------------------------


def texel_directions(h: int, w: int) -> np.ndarray:
    """Unit direction of each texel centre of an (h, w) equirectangular map, float64: +y up,
    u = 0 at -z, increasing towards +x (the convention of rs.latlong_lookup's docstring)."""
    theta = (np.arange(h) + 0.5) / h * np.pi
    phi = (np.arange(w) + 0.5) / w * 2.0 * np.pi
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    x = st * np.sin(phi)[None, :]
    y = np.broadcast_to(ct, (h, w))
    z = -st * np.cos(phi)[None, :]
    return np.stack([x, y, z], axis=-1)


@functools.cache
def smooth_env() -> np.ndarray:
    """An environment whose luminance spans [0.1, 1]: a tinted glow around one direction."""
    d = texel_directions(48, 96)
    glow = np.clip(d @ (np.array([0.3, 0.6, 0.74]) / np.linalg.norm([0.3, 0.6, 0.74])), 0, 1)
    env = 0.1 + 0.9 * glow[..., None] ** 2 * np.array([1.0, 0.9, 0.7])
    return env.astype(np.float32)


@functools.cache
def direction_env() -> np.ndarray:
    """Colour = 0.5 + 0.5·direction: a lookup returns the direction it looked along."""
    return (0.5 + 0.5 * texel_directions(64, 128)).astype(np.float32)


@functools.cache
def scene(name: str) -> tuple[analytic.Scene, Curvature]:
    builders: dict[str, Callable[[], analytic.Scene]] = {
        "sphere": lambda: analytic.sphere(SIZE),
        "bowl": lambda: analytic.bowl(SIZE),
        "plane": lambda: analytic.plane(48, tilt_x_deg=25.0, tilt_y_deg=-15.0),
        "saddle": lambda: analytic.saddle(SIZE),
        "two_spheres": lambda: analytic.two_spheres(SIZE),
    }
    s = builders[name]()
    return s, principal_curvatures(s.normal, s.depth, s.mask)


def view_of(s: analytic.Scene) -> np.ndarray:
    v = np.zeros_like(s.normal)
    v[..., 2] = 1.0  # orthographic: towards the eye everywhere
    return v


def position_of(s: analytic.Scene) -> np.ndarray:
    h, w = s.shape
    u, v = analytic.pixel_coords(h, w)
    d = np.where(s.mask, s.depth, 0.0)
    return np.dstack([u * 2.0, v * 2.0, -d]).astype(np.float32)


def ao_of(s: analytic.Scene) -> np.ndarray:
    return (0.4 + 0.6 * np.clip(s.normal[..., 2], 0, 1)).astype(np.float32)


def gammas(scenario: str, value: float, per_lobe: dict[str, float] | None = None) -> dict:
    lobes = SCENARIOS[scenario]
    per_lobe = per_lobe or {}
    if scenario in ("phong", "sub_lambert", "ashikhmin_shirley"):
        return {f"gamma_{lobe}": per_lobe.get(lobe, value) for lobe in lobes}
    return {"gamma": per_lobe.get(lobes[0], value)}


def run(
    scenario: str, s: analytic.Scene, curv: Curvature, lights: list[Light] | None = None, **kw: Any
) -> rs.Scaled:
    """One scenario of ops.radiance_scaling on an analytic scene (orthographic view)."""
    lights = [LIGHT] if lights is None else lights
    kw.setdefault("gain", GAIN)
    n, v = s.normal, view_of(s)
    if scenario in ("phong", "sub_lambert"):
        kw.setdefault("zeta", 0.5 if scenario == "sub_lambert" else 1.0)
        kw.setdefault("shininess", SHININESS)
        kw.setdefault("albedo", ALBEDO)
        return rs.phong(n, position_of(s), v, lights, curv, **kw)
    if scenario == "ashikhmin_shirley":
        return rs.ashikhmin_shirley(
            n, position_of(s), v, lights, curv, albedo=ALBEDO, exponent=20.0, **kw
        )
    if scenario == "precomputed_diffuse":
        irr = rs.sh_irradiance(smooth_env(), n)
        return rs.precomputed_diffuse(n, curv, ao=ao_of(s), irradiance=irr, albedo=ALBEDO, **kw)
    if scenario == "lit_sphere":
        return rs.lit_sphere(n, curv, rs.studio_matcap(64), **kw)
    return rs.environment(n, v, curv, smooth_env(), mode=scenario, **kw)


# -- independent references ----------------------------------------------------------------------


def lum(rgb: np.ndarray) -> np.ndarray:
    return np.asarray(rgb, np.float64) @ REC709


def phong_reference(
    s: analytic.Scene, zeta: float = 1.0, light: np.ndarray = LIGHT_DIR
) -> dict[str, np.ndarray]:
    """Unscaled Phong lobes of §5.1 (k_a = 0.1, k_s = 0.3, white light of intensity 1)."""
    n = s.normal.astype(np.float64)
    alb = np.array(ALBEDO)
    nl = np.clip(n @ light, 0.0, 1.0)
    r = 2.0 * n[..., 2:3] * n - np.array([0.0, 0.0, 1.0])  # r = 2(n·e)n - e, e = +z
    rho_s = np.clip(r @ light, 0.0, 1.0) ** SHININESS * (nl > 0)
    cov = s.mask[..., None]
    return {
        "ambient": np.where(cov, 0.1 * alb, 0.0),
        "diffuse": np.where(cov, alb * np.where(nl > 0, nl**zeta, 0.0)[..., None], 0.0),
        "specular": np.where(cov, 0.3 * rho_s[..., None] * np.ones(3), 0.0),
    }


def delta_reference(
    scenario: str, lobe: str, s: analytic.Scene, plain: dict[str, np.ndarray]
) -> np.ndarray:
    """δ of each lobe as §5 defines it, float64 (H, W)."""
    n = s.normal.astype(np.float64)
    nl = np.clip(n @ LIGHT_DIR, 0.0, 1.0)
    if scenario in ("phong", "sub_lambert"):
        if lobe == "ambient":
            return np.ones(s.shape)  # ρ_a = 1
        if lobe == "diffuse":
            return np.where(nl > 0, nl ** (0.5 if scenario == "sub_lambert" else 1.0), 0.0)
        r = 2.0 * n[..., 2:3] * n - np.array([0.0, 0.0, 1.0])
        return np.clip(r @ LIGHT_DIR, 0.0, 1.0) ** SHININESS * (nl > 0)
    if scenario == "ashikhmin_shirley":
        if lobe == "diffuse":
            return nl  # δ_d = ℓ·n
        h = LIGHT_DIR + np.array([0.0, 0.0, 1.0])
        return np.clip(n @ (h / np.linalg.norm(h)), 0.0, 1.0)  # δ_s = h·n
    if scenario == "precomputed_diffuse":
        y = lum(rs.sh_irradiance(smooth_env(), s.normal))
        return np.clip(y / y.max(), 0.0, 1.0)  # δ̄_d = L̄(n) / L̄*
    # Lit Sphere and environment: δ̄ = L(lookup) / max over the image
    image = rs.studio_matcap(64) if scenario == "lit_sphere" else smooth_env()
    return np.clip(lum(plain[lobe]) / lum(image).max(), 0.0, 1.0)


def flat_curvature(shape: tuple[int, int], k: float = 0.0) -> Curvature:
    """A curvature field of constant k1 = k2 = k (κ = tanh(2·k·gain)) and weight 1."""
    full = np.full(shape, k, np.float32)
    ones = np.ones(shape, np.float32)
    return Curvature(full, full.copy(), ones, np.zeros(shape, np.float32), ones)


# -- γ = 0, planes --------------------------------------------------------------------------------


@pytest.mark.parametrize("scenario", list(SCENARIOS))
def test_gamma_zero_gives_exactly_the_unscaled_shading(scenario: str) -> None:
    s, curv = scene("sphere")
    out = run(scenario, s, curv, **gammas(scenario, 0.0))
    assert set(out.lobes) == set(SCENARIOS[scenario]) == set(out.sigmas)
    for lobe in SCENARIOS[scenario]:
        assert (out.sigmas[lobe] == 1.0).all(), lobe
    # The unscaled shading, computed independently where the paper gives it in closed form.
    if scenario in ("phong", "sub_lambert"):
        ref = phong_reference(s, zeta=0.5 if scenario == "sub_lambert" else 1.0)
    elif scenario == "ashikhmin_shirley":
        ell = np.broadcast_to(LIGHT_DIR.astype(np.float32), s.normal.shape)
        rho_d, rho_s = as_brdf(s.normal, ell, view_of(s), exponent=20.0)
        ref = {
            "diffuse": np.array(ALBEDO) * rho_d[..., None],
            "specular": np.repeat(rho_s[..., None], 3, axis=2),
        }
    elif scenario == "precomputed_diffuse":
        irr = rs.sh_irradiance(smooth_env(), s.normal)
        ref = {
            "diffuse": np.where(s.mask[..., None], np.array(ALBEDO) * irr * ao_of(s)[..., None], 0)
        }
    else:  # lookups (tested texel by texel below): γ = 0 gives what κ = 0 gives at any γ
        no_curvature = run(scenario, s, flat_curvature(s.shape), **gammas(scenario, 5.0))
        ref = {"specular": no_curvature.lobes["specular"]}
    for lobe, expect in ref.items():
        np.testing.assert_allclose(out.lobes[lobe], expect, rtol=1e-5, atol=1e-6, err_msg=lobe)
    np.testing.assert_allclose(out.beauty, sum(ref.values()), rtol=1e-5, atol=1e-6)


def test_phong_under_a_rim_light() -> None:
    """A light from behind: no diffuse nor highlight where n·ℓ ≤ 0, though r·ℓ > 0 there."""
    s, curv = scene("sphere")
    rim = np.array([0.8, 0.0, -0.6])
    out = run("phong", s, curv, [Light("directional", tuple(rim))], **gammas("phong", 0.0))
    ref = phong_reference(s, light=rim)
    for lobe in SCENARIOS["phong"]:
        np.testing.assert_allclose(out.lobes[lobe], ref[lobe], rtol=1e-5, atol=1e-6, err_msg=lobe)
    n = s.normal.astype(np.float64)
    r = 2.0 * n[..., 2:3] * n - np.array([0.0, 0.0, 1.0])
    assert (s.mask & (n @ rim < 0) & (r @ rim > 0.5)).any()  # where a highlight must not be
    assert out.lobes["specular"].max() > 0.1


@pytest.mark.parametrize("scenario", list(SCENARIOS))
def test_a_plane_is_not_scaled(scenario: str) -> None:
    """κ = 0 on a plane: σ = 1 for any γ, the shading stays plain (RS §4, second property)."""
    s, curv = scene("plane")
    plain = run(scenario, s, curv, **gammas(scenario, 0.0))
    strong = run(scenario, s, curv, alpha=0.2, **gammas(scenario, 20.0))
    for lobe in SCENARIOS[scenario]:
        assert (strong.sigmas[lobe] == 1.0).all(), lobe
        np.testing.assert_array_equal(strong.lobes[lobe], plain.lobes[lobe], err_msg=lobe)
    # ...while the same γ does change the shading of a curved surface
    s, curv = scene("sphere")
    curved = run(scenario, s, curv, alpha=0.2, **gammas(scenario, 20.0))
    unscaled = run(scenario, s, curv, **gammas(scenario, 0.0))
    assert np.abs(curved.beauty - unscaled.beauty).max() > 0.05


# -- the effect of σ: direction (RS §4) and magnitude (δ of each scenario, §5) ---------------------


@pytest.mark.parametrize("shape", ["sphere", "bowl"])
@pytest.mark.parametrize("scenario", list(SCENARIOS))
def test_convexities_brighten_above_alpha_and_concavities_the_reverse(
    scenario: str, shape: str
) -> None:
    """'For convex features, reflected lighting intensities above α are brightened and those
    below α are darkened. For concave features, the opposite effect is obtained.' (RS §4)"""
    alpha = 0.5
    s, curv = scene(shape)
    plain = run(scenario, s, curv, **gammas(scenario, 0.0)).lobes
    scaled = run(scenario, s, curv, alpha=alpha, **gammas(scenario, 3.0)).lobes
    inner = s.interior(0.05)
    sign = 1.0 if shape == "sphere" else -1.0
    for lobe in SCENARIOS[scenario]:
        delta = delta_reference(scenario, lobe, s, plain)
        y0, y1 = lum(plain[lobe]), lum(scaled[lobe])
        lit = inner & (y0 > 1e-4)
        above = lit & (delta > alpha + 0.05)
        below = lit & (delta < alpha - 0.05)
        assert above.sum() + below.sum() > 50, lobe  # the test looks at enough pixels
        assert (sign * (y1[above] - y0[above]) > 0).all(), lobe
        assert (sign * (y1[below] - y0[below]) < 0).all(), lobe


@pytest.mark.parametrize("shape", ["sphere", "bowl"])
@pytest.mark.parametrize("scenario", list(SCENARIOS))
def test_each_lobe_is_scaled_by_sigma_of_its_own_delta_and_gamma(scenario: str, shape: str) -> None:
    """L'_j = σ_{α,γ_j}(κ, δ_j) L_j with δ_j the mapping §5 gives for the lobe (one light)."""
    s, curv = scene(shape)
    per_lobe = {"ambient": 1.0, "diffuse": 4.0, "specular": 2.0}
    plain = run(scenario, s, curv, **gammas(scenario, 0.0)).lobes
    out = run(scenario, s, curv, alpha=0.3, **gammas(scenario, 0.0, per_lobe))
    kappa = isotropic(curv, GAIN)
    assert np.abs(kappa[s.mask]).max() > 0.3
    for lobe in SCENARIOS[scenario]:
        delta = delta_reference(scenario, lobe, s, plain)
        expect_sigma = sigma(kappa, delta, 0.3, per_lobe[lobe])
        np.testing.assert_allclose(out.sigmas[lobe], expect_sigma, rtol=2e-4, err_msg=lobe)
        np.testing.assert_allclose(
            out.lobes[lobe], plain[lobe] * expect_sigma[..., None], rtol=2e-4, atol=1e-6
        )


@pytest.mark.parametrize("scenario", ["phong", "ashikhmin_shirley"])
def test_gamma_per_lobe(scenario: str) -> None:
    """γ_s = 0 leaves the specular lobe as it was while the diffuse lobe changes, and back."""
    s, curv = scene("sphere")
    plain = run(scenario, s, curv, **gammas(scenario, 0.0)).lobes
    only_diffuse = run(scenario, s, curv, **gammas(scenario, 3.0, {"specular": 0.0})).lobes
    only_specular = run(scenario, s, curv, **gammas(scenario, 3.0, {"diffuse": 0.0})).lobes
    np.testing.assert_array_equal(only_diffuse["specular"], plain["specular"])
    np.testing.assert_array_equal(only_specular["diffuse"], plain["diffuse"])
    assert np.abs(only_diffuse["diffuse"] - plain["diffuse"]).max() > 0.05
    assert np.abs(only_specular["specular"] - plain["specular"]).max() > 0.01


@pytest.mark.parametrize("scenario", ["phong", "ashikhmin_shirley"])
def test_anisotropic_mapping_scales_with_kappa_of_the_light(scenario: str) -> None:
    """λ ≠ 0: σ uses κ(p, ℓ) of §4 for the light, not the isotropic κ."""
    s, curv = scene("saddle")
    plain = run(scenario, s, curv, **gammas(scenario, 0.0)).lobes
    out = run(scenario, s, curv, lam=0.8, **gammas(scenario, 3.0))
    iso = run(scenario, s, curv, **gammas(scenario, 3.0))
    k_aniso = anisotropic(curv, LIGHT_DIR.astype(np.float32), GAIN, 0.8)
    delta = delta_reference(scenario, "diffuse", s, plain)
    np.testing.assert_allclose(out.sigmas["diffuse"], sigma(k_aniso, delta, 0.5, 3.0), rtol=2e-4)
    assert np.abs(out.lobes["diffuse"] - iso.lobes["diffuse"]).max() > 0.02


@pytest.mark.parametrize("scenario", ["phong", "ashikhmin_shirley"])
def test_lights_are_scaled_one_by_one_and_summed(scenario: str) -> None:
    """Eq. 1 / Eq. 3: Σ_i ρ(ℓ_i) σ(p, ℓ_i) L(ℓ_i); the ambient lobe is counted once."""
    s, curv = scene("two_spheres")
    second = Light("point", (1.5, 1.0, -7.0), color=(1.0, 0.5, 0.2), intensity=6.0)
    g = gammas(scenario, 3.0)
    both = run(scenario, s, curv, [LIGHT, second], **g)
    one, two = run(scenario, s, curv, [LIGHT], **g), run(scenario, s, curv, [second], **g)
    for lobe in ("diffuse", "specular"):
        np.testing.assert_allclose(
            both.lobes[lobe], one.lobes[lobe] + two.lobes[lobe], rtol=1e-5, atol=1e-6
        )
        np.testing.assert_allclose(
            both.sigmas[lobe], 0.5 * (one.sigmas[lobe] + two.sigmas[lobe]), rtol=1e-5
        )
    if scenario == "phong":
        np.testing.assert_array_equal(both.lobes["ambient"], one.lobes["ambient"])


# -- toon, sub-Lambertian -----------------------------------------------------------------------


def test_quantise() -> None:
    ramp = np.linspace(-0.5, 1.5, 2001, dtype=np.float32)
    for levels in (2, 3, 5):
        q = rs.quantise(ramp, levels)
        assert q.dtype == np.float32
        np.testing.assert_allclose(np.unique(q), np.arange(levels) / (levels - 1), rtol=1e-6)
        assert (np.diff(q) >= 0).all()
        assert q[ramp <= 0].max() == 0.0 and q[ramp >= 1].min() == 1.0
        # bands of equal width: a value in band b (b/levels ≤ x < (b+1)/levels) maps to b/(L-1)
        x = np.float32((1.5) / levels)
        assert rs.quantise(x, levels) == pytest.approx(1.0 / (levels - 1))


def test_toon_quantises_the_scaled_intensity() -> None:
    """Toon shading: 'quantize the scaled reflected intensity' (§5.1), levels bands exactly."""
    levels = 4
    white = {"albedo": (1.0, 1.0, 1.0), "ambient": 0.0, "specular": 0.0}
    counts = {}
    for shape in ("sphere", "bowl"):
        s, curv = scene(shape)
        inner = s.interior(0.05)
        for g in (0.0, 3.0):
            smooth = run("phong", s, curv, gamma_diffuse=g, **white).lobes["diffuse"]
            toon = run("phong", s, curv, gamma_diffuse=g, toon_levels=levels, **white)
            d = toon.lobes["diffuse"]
            np.testing.assert_allclose(
                np.unique(d[s.mask]), np.arange(levels) / (levels - 1), rtol=1e-6
            )
            np.testing.assert_array_equal(d, rs.quantise(smooth, levels))  # after scaling
            counts[shape, g] = int((d[..., 0][inner] == 1.0).sum())
    # the top band grows on the convex sphere and shrinks in the bowl
    assert counts["sphere", 3.0] > counts["sphere", 0.0] > counts["bowl", 3.0]
    s, curv = scene("sphere")
    for bad in (1, -2):
        with pytest.raises(ValueError, match="toon_levels"):
            run("phong", s, curv, toon_levels=bad)


def test_sub_lambertian() -> None:
    s, curv = scene("sphere")
    lambert = phong_reference(s)["diffuse"]
    for zeta in (1.0, 1.0 - 1e-6):  # ζ = 1 is Lambert (the power path agrees at the limit)
        for g in (0.0, 3.0):
            out = run("phong", s, curv, zeta=zeta, gamma_diffuse=g).lobes["diffuse"]
            if g == 0.0:
                np.testing.assert_allclose(out, lambert, rtol=1e-4, atol=1e-6)
            else:
                ref = run("phong", s, curv, gamma_diffuse=g).lobes["diffuse"]
                np.testing.assert_allclose(out, ref, rtol=1e-4, atol=1e-6)
    # ζ < 1 is brighter than Lambert where lit, and black where the light does not reach, even
    # at ζ = 0 ((n·ℓ)^0 is 1 only on the lit hemisphere)
    n_l = s.normal @ LIGHT_DIR.astype(np.float32)
    for zeta in (0.5, 0.0):
        out = run("phong", s, curv, zeta=zeta, gamma_diffuse=0.0).lobes["diffuse"]
        lit = s.mask & (n_l > 0.01) & (n_l < 0.99)
        assert (out[lit][:, 0] > lambert[lit][:, 0]).all()
        dark = s.mask & (n_l < -1e-3)
        assert dark.sum() > 20 and (out[dark] == 0).all()
    for bad in (-0.1, 1.5):
        with pytest.raises(ValueError, match="zeta"):
            run("phong", s, curv, zeta=bad)


# -- lookups: Lit Sphere, environment, prefiltered irradiance ------------------------------------


def test_lit_sphere_looks_up_the_texel_of_the_normal() -> None:
    """u = ½ + ½ n_x, v = ½ − ½ n_y: the normal of a texel centre reads that texel."""
    size = 16
    rng = np.random.default_rng(7)
    sphere_img = rng.uniform(0.05, 1.0, (size, size, 3)).astype(np.float32)
    rows, cols = np.meshgrid(np.arange(3, 13), np.arange(3, 13), indexing="ij")
    nx = (cols + 0.5) / size * 2.0 - 1.0
    ny = 1.0 - (rows + 0.5) / size * 2.0
    nz = np.sqrt(np.clip(1.0 - nx * nx - ny * ny, 0.0, 1.0))
    normal = np.dstack([nx, ny, nz]).astype(np.float32)
    normal[0, 0] = 0.0  # one background pixel
    out = rs.lit_sphere(normal, flat_curvature(rows.shape), sphere_img, gamma=2.0, gain=GAIN)
    expect = sphere_img[rows, cols]
    expect[0, 0] = 0.0
    np.testing.assert_allclose(out.lobes["specular"], expect, rtol=1e-5, atol=1e-6)
    # with curvature: σ(κ, L_ls(n) / L*_ls) applied to the texel
    k = 2.0
    curved = rs.lit_sphere(normal, flat_curvature(rows.shape, k), sphere_img, gamma=2.0, gain=GAIN)
    delta = lum(expect) / lum(sphere_img).max()
    s = sigma(np.full(rows.shape, math.tanh(2 * k * GAIN), np.float32), delta, 0.5, 2.0)
    np.testing.assert_allclose(
        curved.lobes["specular"], expect * s[..., None], rtol=1e-3, atol=1e-6
    )
    # a grey sphere image is the same as its RGB copy
    grey = rs.lit_sphere(
        normal, flat_curvature(rows.shape, k), sphere_img[..., 1], gamma=2.0, gain=GAIN
    )
    rgb = rs.lit_sphere(
        normal,
        flat_curvature(rows.shape, k),
        np.repeat(sphere_img[..., 1:2], 3, axis=2),
        gamma=2.0,
        gain=GAIN,
    )
    np.testing.assert_allclose(grey.lobes["specular"], rgb.lobes["specular"], rtol=1e-6)


def test_latlong_lookup_reads_the_texel_of_its_direction() -> None:
    h, w = 8, 16
    env = np.random.default_rng(3).random((h, w, 3)).astype(np.float32)
    dirs = texel_directions(h, w).astype(np.float32)
    np.testing.assert_allclose(rs.latlong_lookup(env, dirs), env, atol=1e-3)
    # the poles read the top (+y) and bottom (-y) rows, never a blend of the two
    rows = np.repeat(np.arange(h, dtype=np.float32)[:, None, None], w, axis=1).repeat(3, axis=2)
    poles = np.array([[[0.0, 1.0, 0.0], [0.02, 0.9998, 0.0], [0.0, -1.0, 0.0]]], np.float32)
    np.testing.assert_array_equal(rs.latlong_lookup(rows, poles)[0, :, 0], [0.0, 0.0, h - 1.0])
    # u = 0 at -z (the seam, where the first and last columns meet), +x a quarter turn on
    cols = np.repeat(np.arange(w, dtype=np.float32)[None, :, None], h, axis=0).repeat(3, axis=2)
    axes = np.array([[[0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]], np.float32)
    seen = rs.latlong_lookup(cols, axes)[0, :, 0]
    np.testing.assert_allclose(seen, [(w - 1) / 2, w / 4 - 0.5, w / 2 - 0.5], atol=1e-4)
    grey = rs.latlong_lookup(env[..., 0], dirs)
    assert grey.shape == (h, w, 1)
    np.testing.assert_allclose(grey[..., 0], env[..., 0], atol=1e-3)


def _environment_dirs(mode: str, normal: np.ndarray, ior: float = 1.5) -> np.ndarray:
    """Mirror r = 2(n·e)n − e or Snell's refracted eye ray, e = +z, float64."""
    n = normal.astype(np.float64)
    e = np.array([0.0, 0.0, 1.0])
    c = n[..., 2:3]
    if mode == "mirror":
        return 2.0 * c * n - e
    eta = 1.0 / ior
    k = 1.0 - eta * eta * (1.0 - c * c)
    return -eta * e + (eta * c - np.sqrt(k)) * n


@pytest.mark.parametrize("mode", ["mirror", "refraction"])
def test_environment_looks_along_the_reflected_or_refracted_view(mode: str) -> None:
    s, _ = scene("sphere")
    flat = flat_curvature(s.shape)
    out = rs.environment(s.normal, view_of(s), flat, direction_env(), mode=mode, gamma=3.0)
    seen = (out.lobes["specular"].astype(np.float64) - 0.5) / 0.5  # the direction looked along
    expect = _environment_dirs(mode, s.normal)
    expect /= np.linalg.norm(expect, axis=-1, keepdims=True)
    inner = s.interior(0.03)
    assert np.abs(seen[inner] - expect[inner]).max() < 0.05
    assert (out.lobes["specular"][~s.mask] == 0).all()
    # camera_to_world turns the looked-up direction into the map's frame
    rot = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # 90° about y
    turned = rs.environment(
        s.normal, view_of(s), flat, direction_env(), mode=mode, camera_to_world=rot
    )
    seen_t = (turned.lobes["specular"].astype(np.float64) - 0.5) / 0.5
    assert np.abs(seen_t[inner] - expect[inner] @ rot.T).max() < 0.05


def test_mirror_and_refraction_differ() -> None:
    s, curv = scene("sphere")
    view, env = view_of(s), direction_env()
    mirror = rs.environment(s.normal, view, curv, env, mode="mirror", gain=GAIN)
    refraction = rs.environment(s.normal, view, curv, env, mode="refraction", gain=GAIN)
    diff = np.abs(mirror.beauty - refraction.beauty).max(axis=2)[s.interior(0.05)]
    assert (diff > 0.1).mean() > 0.95
    # at normal incidence the mirror looks back at the camera (+z), the refraction through (-z)
    centre = np.zeros((1, 1, 3), np.float32)
    centre[..., 2] = 1.0
    flat = flat_curvature((1, 1))
    m = rs.environment(centre, centre, flat, direction_env(), mode="mirror").lobes["specular"]
    r = rs.environment(centre, centre, flat, direction_env(), mode="refraction").lobes["specular"]
    assert m[0, 0, 2] > 0.97 and r[0, 0, 2] < 0.03
    with pytest.raises(ValueError, match="mode"):
        rs.environment(centre, centre, flat, direction_env(), mode="glass")


def test_environment_accepts_a_grey_map() -> None:
    s, curv = scene("sphere")
    grey = smooth_env()[..., 1]
    a = rs.environment(s.normal, view_of(s), curv, grey, gain=GAIN)
    b = rs.environment(s.normal, view_of(s), curv, np.repeat(grey[..., None], 3, axis=2), gain=GAIN)
    np.testing.assert_allclose(a.lobes["specular"], b.lobes["specular"], rtol=1e-6)


def test_sh_irradiance_of_constant_and_linear_environments() -> None:
    """Irradiance / π of L(ω) = c + d·ω is c + (2/3) d·n (exact in order-2 SH, A1 = 2π/3)."""
    dirs = texel_directions(32, 64)
    rng = np.random.default_rng(11)
    n = rng.normal(size=(5, 7, 3))
    n = (n / np.linalg.norm(n, axis=-1, keepdims=True)).astype(np.float32)
    const = np.broadcast_to(np.array([0.2, 0.5, 1.5], np.float32), (32, 64, 3))
    np.testing.assert_allclose(
        rs.sh_irradiance(const, n), np.broadcast_to(const[0, 0], n.shape), rtol=2e-3
    )
    for axis in range(3):
        env = (1.0 + 0.5 * dirs[..., axis : axis + 1] * np.ones(3)).astype(np.float32)
        expect = 1.0 + (2.0 / 3.0) * 0.5 * n[..., axis : axis + 1] * np.ones(3)
        np.testing.assert_allclose(rs.sh_irradiance(env, n), expect, atol=3e-3, err_msg=str(axis))


def test_precomputed_diffuse_ao_only_is_mean_curvature_shading() -> None:
    """Without an environment δ̄ = 1 and σ(κ, 1) = e^{γκ}: AO brightened on convexities and
    darkened in concavities (Fig. 8b, mean-curvature shading)."""
    for shape, sign in (("sphere", 1.0), ("bowl", -1.0)):
        s, curv = scene(shape)
        ao = ao_of(s)
        out = rs.precomputed_diffuse(s.normal, curv, ao=ao, gamma=2.0, gain=GAIN)
        kappa = isotropic(curv, GAIN)
        expect = np.where(s.mask, ao * np.exp(2.0 * kappa), 0.0)
        np.testing.assert_allclose(out.lobes["diffuse"][..., 0], expect, rtol=1e-5, atol=1e-6)
        inner = s.interior(0.05)
        assert (sign * (out.lobes["diffuse"][..., 1][inner] - ao[inner]) > 0).all()
        assert (out.lobes["diffuse"][~s.mask] == 0).all()  # no surface, no light
    # a pinned white level L̄*: δ̄ = lum(L̄) / white
    s, curv = scene("sphere")
    irr = rs.sh_irradiance(smooth_env(), s.normal)
    white = 2.0 * float(lum(irr).max())
    out = rs.precomputed_diffuse(s.normal, curv, irradiance=irr, white=white, alpha=0.3, gain=GAIN)
    np.testing.assert_allclose(
        out.sigmas["diffuse"], sigma(isotropic(curv, GAIN), lum(irr) / white, 0.3, 1.0), rtol=1e-4
    )


# -- robustness ----------------------------------------------------------------------------------


@pytest.mark.parametrize("scenario", list(SCENARIOS))
def test_shapes_dtypes_finite_and_background(scenario: str) -> None:
    """Two spheres (a depth jump), a directional and a point light, strong scaling."""
    s, curv = scene("two_spheres")
    lights = [LIGHT, Light("point", (0.5, 1.5, -8.0), intensity=20.0)]
    out = run(scenario, s, curv, lights, alpha=0.1, **gammas(scenario, 30.0))
    h, w = s.shape
    for lobe in SCENARIOS[scenario]:
        img, sig = out.lobes[lobe], out.sigmas[lobe]
        assert img.dtype == np.float32 and img.shape == (h, w, 3), lobe
        assert sig.dtype == np.float32 and sig.shape == (h, w), lobe
        assert np.isfinite(img).all() and np.isfinite(sig).all(), lobe
        assert (img >= 0).all(), lobe
        assert (img[~s.mask] == 0).all(), lobe  # the background stays black
        assert (sig[~s.mask] == 1).all(), lobe  # no curvature there, no scaling
    assert out.beauty.dtype == np.float32
    np.testing.assert_allclose(out.beauty, sum(out.lobes.values()), rtol=1e-6)
