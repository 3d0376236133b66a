"""Scaling function σ (Radiance Scaling Eq. 2) and lobe scaling (Eq. 4), ops.radiance_scaling."""

from __future__ import annotations

import numpy as np
import pytest

from ops.color import luminance, luminance_of_sum, luminance_of_sum_rows
from ops.colorspace import REC709_Y
from ops.curvature import isotropic, principal_curvatures
from ops.pyramid.upsample import Upsampled
from ops.radiance_scaling import (
    covered_percentile,
    reflectance_delta,
    scale_lobes,
    scaling_function,
    sigma,
    white_level,
)
from tests import analytic

ALPHAS = (0.1, 0.25, 0.5, 0.8)
GAMMAS = (0.5, 3.0, 10.0, 30.0)


def _grid() -> tuple[np.ndarray, np.ndarray]:
    k = np.linspace(-1.0, 1.0, 129, dtype=np.float32)
    d = (np.arange(257) / 256.0).astype(np.float32)  # 1 - d is exact in float32
    kk, dd = np.meshgrid(k, d)
    return kk, dd


@pytest.mark.parametrize("alpha", ALPHAS)
@pytest.mark.parametrize("gamma", GAMMAS)
def test_sigma_properties(alpha: float, gamma: float) -> None:
    kk, dd = _grid()
    s32 = sigma(kk, dd, alpha, gamma)
    assert s32.dtype == np.float32 and s32.shape == kk.shape
    s = s32.astype(np.float64)
    # σ = 1 where κ = 0 or δ = α.
    np.testing.assert_allclose(sigma(np.zeros_like(dd), dd, alpha, gamma), 1.0, rtol=1e-6)
    np.testing.assert_allclose(
        sigma(kk, np.full_like(kk, np.float32(alpha)), alpha, gamma), 1.0, rtol=1e-6
    )
    # Reciprocity of convex and concave: σ(κ, δ) σ(-κ, δ) = 1.
    np.testing.assert_allclose(s * sigma(-kk, dd, alpha, gamma), 1.0, rtol=1e-6)
    # Symmetry in α: σ_α(κ, 1 - δ) = 1 / σ_{1-α}(κ, δ).
    np.testing.assert_allclose(
        sigma(kk, 1.0 - dd, alpha, gamma) * sigma(kk, dd, 1.0 - alpha, gamma), 1.0, rtol=1e-6
    )
    # End points: σ(κ, 0) = e^{-γκ}, σ(κ, 1) = e^{γκ}.
    k = kk[0].astype(np.float64)
    np.testing.assert_allclose(sigma(kk[0], 0.0, alpha, gamma), np.exp(-gamma * k), rtol=1e-5)
    np.testing.assert_allclose(sigma(kk[0], 1.0, alpha, gamma), np.exp(gamma * k), rtol=1e-5)


@pytest.mark.parametrize("alpha", ALPHAS)
@pytest.mark.parametrize("gamma", (0.5, 3.0, 10.0))
def test_sigma_is_the_printed_equation(alpha: float, gamma: float) -> None:
    kk, dd = _grid()
    inner = dd < 0.99  # the printed form itself cancels badly at δ -> 1
    np.testing.assert_allclose(
        sigma(kk, dd, alpha, gamma)[inner], scaling_function(kk, dd, alpha, gamma)[inner], rtol=1e-5
    )


@pytest.mark.parametrize("alpha", ALPHAS)
def test_sigma_is_monotonic_in_delta(alpha: float) -> None:
    """Applied to a ramp of δ, σ makes no new extremum: increasing on convexities, decreasing in
    concavities (convexities brighten what is above α and darken what is below, RS §4)."""
    ramp = np.linspace(0.0, 1.0, 4097, dtype=np.float32)
    for kappa in (-1.0, -0.3, 0.3, 1.0):
        s = sigma(kappa, ramp, alpha, 5.0).astype(np.float64)
        steps = np.diff(s)
        if kappa > 0:
            assert (steps > 0).all()
            assert s[ramp > alpha + 1e-3].min() > 1.0 > s[ramp < alpha - 1e-3].max()
        else:
            assert (steps < 0).all()
            assert s[ramp > alpha + 1e-3].max() < 1.0 < s[ramp < alpha - 1e-3].min()


def test_gamma_zero_is_identity_and_inputs_are_clipped() -> None:
    kk, dd = _grid()
    assert (sigma(kk, dd, 0.3, 0.0) == 1.0).all()
    # δ outside [0, 1] and κ outside [-1, 1] are clipped; NaN δ counts as 0, NaN κ as 0.
    np.testing.assert_array_equal(
        sigma(0.5, [-2.0, 3.0], 0.3, 4.0), sigma(0.5, [0.0, 1.0], 0.3, 4.0)
    )
    np.testing.assert_array_equal(
        sigma([5.0, -7.0], 0.9, 0.3, 4.0), sigma([1.0, -1.0], 0.9, 0.3, 4.0)
    )
    assert sigma(0.5, np.nan, 0.3, 4.0) == sigma(0.5, 0.0, 0.3, 4.0)
    assert sigma(np.nan, 0.7, 0.3, 4.0) == 1.0
    # Huge γ stays finite.
    assert np.isfinite(sigma(kk, dd, 0.5, 1e4)).all()
    assert sigma(2.0, 0.25, 0.5, 1.0).shape == ()


@pytest.mark.parametrize(
    ("alpha", "gamma", "word"),
    [
        (0.0, 1.0, "alpha"),
        (1.0, 1.0, "alpha"),
        (-0.5, 1.0, "alpha"),
        (0.5, -1.0, "gamma"),
        (0.5, float("inf"), "gamma"),
        (float("nan"), 1.0, "alpha"),
    ],
)
def test_sigma_rejects_bad_parameters(alpha: float, gamma: float, word: str) -> None:
    with pytest.raises(ValueError, match=rf"{word}=.*allowed range"):
        sigma(0.5, 0.5, alpha, gamma)


# -- δ̄ and white levels --------------------------------------------------------------------------


def test_luminance_and_reflectance_delta() -> None:
    rng = np.random.default_rng(1)
    rgb = rng.random((8, 9, 3), dtype=np.float32) * 2.0
    y = luminance(rgb)
    np.testing.assert_allclose(y, rgb @ np.array([0.2126, 0.7152, 0.0722]), rtol=1e-5)
    d = reflectance_delta(rgb, 1.5)
    np.testing.assert_allclose(d, np.clip(y / 1.5, 0, 1), rtol=1e-5, atol=1e-7)
    bad = rgb.copy()
    bad[0, 0] = np.nan
    bad[0, 1] = np.inf
    bad[0, 2] = -1.0
    d = reflectance_delta(bad, 1.0)
    assert d[0, 0] == 0.0 and d[0, 1] == 1.0 and d[0, 2] == 0.0
    for white in (0.0, -1.0, float("inf")):
        with pytest.raises(ValueError, match="white"):
            reflectance_delta(rgb, white)


@pytest.mark.parametrize("count", [1, 2, 3])
def test_luminance_of_sum_is_the_luminance_of_the_total_bit_for_bit(count: int) -> None:
    """Summed strip by strip, never at full size, yet the same float32 values as summing whole
    frames in order and taking their luminance (the kept lighting's gain is 1 on that)."""
    rng = np.random.default_rng(count)
    rgbs = [
        rng.random((301, 257, 3), dtype=np.float32) * 10 ** rng.uniform(-3, 3) for _ in range(count)
    ]
    weights = (0.2627, 0.678, 0.0593)
    whole = rgbs[0].copy()
    for x in rgbs[1:]:
        whole += x
    got = luminance_of_sum(rgbs, weights)
    assert got.shape == (301, 257) and got.dtype == np.float32
    assert np.array_equal(got, luminance(whole, weights))


def test_luminance_of_sum_rows_takes_rows_of_any_layout() -> None:
    """Rows as (rows, W, 3), flat (rows, 3W) and a column window of a wider frame (not
    contiguous) are summed alike: the luminance of their total."""
    rng = np.random.default_rng(9)
    a, b, c = (rng.random((5, 7, 3), dtype=np.float32) for _ in range(3))
    wide = np.concatenate([c, c], axis=1)
    out = np.empty((5, 7), np.float32)
    luminance_of_sum_rows([a, b.reshape(5, 21), wide[:, :7]], REC709_Y, out)
    assert np.array_equal(out, luminance(a + b + c, REC709_Y))


@pytest.mark.parametrize("odd", [False, True])
def test_covered_percentile_is_numpys_exactly(odd: bool) -> None:
    """The median (the kept lighting's scene scale) and other percentiles of the finite values
    of covered pixels: NumPy's values bit for bit, an odd or even count, without gathering them."""
    rng = np.random.default_rng(int(odd))
    values = (rng.random((700, 611), dtype=np.float32) * 0.01 + 0.001).astype(np.float32)
    values[rng.random(values.shape) < 0.01] = np.inf
    mask = rng.random(values.shape) > 0.3
    counted = mask & np.isfinite(values)
    if (counted.sum() % 2 == 1) != odd:
        mask[np.argwhere(counted)[0][0], np.argwhere(counted)[0][1]] = False
        counted = mask & np.isfinite(values)
    assert (counted.sum() % 2 == 1) == odd
    assert covered_percentile(values, mask, 50.0) == float(np.median(values[counted]))
    for p in (1.0, 37.5, 99.0):
        assert covered_percentile(values, mask, p) == float(np.percentile(values[counted], p))
    assert np.isnan(covered_percentile(values, np.zeros_like(mask), 50.0))  # nothing counts


@pytest.mark.parametrize("share", [0.3, 0.55, 0.9])
def test_covered_percentile_of_many_equal_values_is_numpys(share: float) -> None:
    """A large share of pixels holding one value (a wall facing the camera, a clipped light):
    the percentiles whose bracket holds only that value, and those beside it, are NumPy's."""
    rng = np.random.default_rng(7)
    values = (rng.random((600, 640), dtype=np.float32) + 0.5).astype(np.float32)
    tied = rng.random(values.shape) < share
    values[tied] = np.float32(1.0)
    mask = rng.random(values.shape) > 0.2
    counted = values[mask]
    for p in (1.0, 25.0, 50.0, 62.5, 75.0, 99.0):
        assert covered_percentile(values, mask, p) == float(np.percentile(counted, p)), p


def test_white_level_is_a_robust_percentile_of_covered_pixels() -> None:
    rng = np.random.default_rng(2)
    y = rng.random((64, 64)).astype(np.float32)
    mask = np.zeros((64, 64), bool)
    mask[8:56, 8:56] = True
    y_bg = y.copy()
    y_bg[~mask] = 1000.0  # bright background must not count
    y_bg[10, 10] = np.nan
    y_bg[11, 11] = np.inf
    expect = np.percentile(np.delete(y[mask], [np.ravel_multi_index((2, 2), (48, 48))]), 99)
    assert white_level(y_bg, mask) == pytest.approx(expect, rel=2e-2)
    assert white_level(y_bg, mask.astype(np.float32), 50.0) == pytest.approx(
        np.percentile(y[mask], 50), rel=2e-2
    )
    rgb = np.repeat(y[..., None], 3, axis=2)
    assert white_level(rgb, None, 100.0) == pytest.approx(float(y.max()), rel=1e-5)
    assert white_level(np.zeros((4, 4), np.float32), None) == 1.0  # nothing lit
    with pytest.raises(ValueError, match="percentile"):
        white_level(y, None, 0.0)


@pytest.mark.parametrize("shape", [(40, 50), (700, 900)])  # np.percentile / the band path
@pytest.mark.parametrize("percentile", [50.0, 99.0, 99.9, 100.0])
def test_white_level_equals_numpy_percentile_of_counted_pixels(
    shape: tuple[int, int], percentile: float
) -> None:
    """Exactly np.percentile of the covered finite values, on both of its paths, with bool and
    float masks and without one; RGB through its Rec. 709 luminance."""
    rng = np.random.default_rng(len(shape) + int(percentile))
    y = (rng.random(shape, dtype=np.float32) ** 3 * 5.0).astype(np.float32)
    y[rng.random(shape) < 0.01] = np.nan
    y[rng.random(shape) < 0.01] = np.inf
    y[rng.random(shape) < 0.01] = -np.inf
    mask = rng.random(shape) < 0.7
    expect = float(np.percentile(y[mask & np.isfinite(y)], percentile))
    assert white_level(y, mask, percentile) == expect
    assert white_level(y, mask.astype(np.float32), percentile) == expect
    assert white_level(y, None, percentile) == float(np.percentile(y[np.isfinite(y)], percentile))
    rgb = rng.random((*shape, 3), dtype=np.float32)
    rgb[3, 4, 1] = np.nan
    lum = luminance(rgb)
    ok = mask & np.isfinite(lum)
    assert white_level(rgb, mask, percentile) == float(np.percentile(lum[ok], percentile))


def test_white_level_is_exact_when_its_row_sample_misleads() -> None:
    """The rows the bracket is sampled from (every H/128-th) hold only dark values, the rest of
    the frame bright ones: the bracket misses and the level is still np.percentile's."""
    shape = (1024, 300)
    rng = np.random.default_rng(7)
    y = (rng.random(shape, dtype=np.float32) + 1.0).astype(np.float32)
    y[:: shape[0] // 128] = rng.random((128, shape[1]), dtype=np.float32) * 0.01
    mask = rng.random(shape) < 0.9
    for p in (50.0, 99.0):
        assert white_level(y, mask, p) == float(np.percentile(y[mask], p))


# -- scale_lobes -----------------------------------------------------------------------------------


def _lobes(shape: tuple[int, int], seed: int = 0) -> tuple[dict[str, np.ndarray], ...]:
    rng = np.random.default_rng(seed)
    lights = {n: rng.random((*shape, 3), dtype=np.float32) * 1.2 for n in ("diffuse", "specular")}
    colour = {"diffuse": (0.8, 0.4, 0.2), "specular": (1.0, 1.0, 1.0)}
    lobes = {n: lights[n] * np.array(colour[n], np.float32) for n in lights}
    return lobes, lights


def test_scale_lobes_reads_a_light_as_rgb_or_as_its_luminance() -> None:
    """δ̄ reads only a light's luminance: given as the (H, W) luminance (what the service passes,
    a third of the memory) a light scales its lobe as the RGB light does, in every working
    space's weights; a plane of another shape is refused."""
    shape = (70, 41)
    lobes, lights = _lobes(shape, seed=8)
    kappa = np.random.default_rng(9).uniform(-1, 1, shape).astype(np.float32)
    weights = (0.2627, 0.6780, 0.0593)  # Rec. 2020's
    args = (kappa, {"diffuse": 0.3, "specular": 0.7}, 4.0, {"diffuse": 1.1, "specular": "auto"})
    out_rgb, sig_rgb = scale_lobes(lobes, lights, *args, mask=None, weights=weights)
    planes = {n: luminance(x, weights) for n, x in lights.items()}
    out_y, sig_y = scale_lobes(lobes, planes, *args, mask=None, weights=weights)
    for n in lobes:
        np.testing.assert_allclose(sig_y[n], sig_rgb[n], rtol=1e-5)
    np.testing.assert_allclose(out_y, out_rgb, rtol=1e-5, atol=1e-6)
    with pytest.raises(ValueError, match="lights"):
        scale_lobes(lobes, {"diffuse": planes["diffuse"][:-1]}, *args)


def test_scale_lobes_is_identity_without_scaling() -> None:
    shape = (24, 32)
    lobes, lights = _lobes(shape)
    rng = np.random.default_rng(3)
    kappa = rng.uniform(-1, 1, shape).astype(np.float32)
    remainder = rng.random((*shape, 3), dtype=np.float32) * 0.1
    beauty = lobes["diffuse"] + lobes["specular"] + remainder
    out, sig = scale_lobes(lobes, lights, kappa, 0.5, 0.0, 1.0, remainder)
    np.testing.assert_allclose(out, beauty, rtol=1e-6)
    assert all((s == 1.0).all() for s in sig.values())


def test_scale_lobes_on_a_plane_is_identity() -> None:
    s = analytic.plane(64, tilt_x_deg=30.0, tilt_y_deg=10.0)
    kappa = isotropic(principal_curvatures(s.normal, s.depth, s.mask))
    lobes, lights = _lobes(s.shape)
    out, _ = scale_lobes(lobes, lights, kappa, 0.3, 8.0, "auto", mask=s.mask)
    np.testing.assert_allclose(out, lobes["diffuse"] + lobes["specular"], rtol=1e-5, atol=1e-6)


def test_scale_lobes_applies_sigma_per_lobe() -> None:
    shape = (150, 37)  # several row strips
    lobes, lights = _lobes(shape, seed=4)
    kappa = np.random.default_rng(5).uniform(-1, 1, shape).astype(np.float32)
    alpha = {"diffuse": 0.3, "specular": 0.7}
    gamma = {"diffuse": 2.0, "specular": 6.0}
    white: dict[str, float | str] = {"diffuse": 1.1, "specular": "auto"}
    mask = np.ones(shape, bool)
    out, sig = scale_lobes(lobes, lights, kappa, alpha, gamma, white, mask=mask)
    w_spec = white_level(lights["specular"], mask)
    s_d = sigma(kappa, reflectance_delta(lights["diffuse"], 1.1), 0.3, 2.0)
    s_s = sigma(kappa, reflectance_delta(lights["specular"], w_spec), 0.7, 6.0)
    np.testing.assert_allclose(sig["diffuse"], s_d, rtol=1e-5)
    np.testing.assert_allclose(sig["specular"], s_s, rtol=1e-5)
    expect = lobes["diffuse"] * s_d[..., None] + lobes["specular"] * s_s[..., None]
    np.testing.assert_allclose(out, expect, rtol=1e-5, atol=1e-6)
    # δ̄ uses the light without colour: tinting a lobe does not change its σ.
    tinted = dict(lobes, diffuse=lobes["diffuse"] * np.float32(0.1))
    _, sig2 = scale_lobes(tinted, lights, kappa, alpha, gamma, white, mask=mask)
    np.testing.assert_array_equal(sig2["diffuse"], sig["diffuse"])
    # A lobe without a light uses its own radiance.
    _, sig3 = scale_lobes(lobes, {}, kappa, 0.5, 2.0, 1.0)
    np.testing.assert_allclose(
        sig3["diffuse"], sigma(kappa, reflectance_delta(lobes["diffuse"], 1.0), 0.5, 2.0), rtol=1e-5
    )


@pytest.mark.parametrize("count", [1, 2, 3, 4, 7])
def test_scale_lobes_sums_any_number_of_lobes_in_every_mode(count: int) -> None:
    """Lobes are summed three per pass, then one by one: every count, with a remainder, with
    the beauty they are part of, or alone, and without σ layers, gives Σ σ_j · lobe_j, also
    where runs of κ = 0 are skipped."""
    shape = (70, 29)
    rng = np.random.default_rng(count)
    names = [f"lobe{j}" for j in range(count)]
    lights = {n: rng.random((*shape, 3), dtype=np.float32) * 1.5 for n in names}
    lobes = {n: lights[n] * rng.random(3).astype(np.float32) for n in names}
    kappa = rng.uniform(-1.2, 1.2, shape).astype(np.float32)
    kappa[3, 4] = np.nan  # counts as 0
    # κ = 0 at the start of rows, on whole rows and at the end of a row: the kernel skips those
    # pixels (σ = 1), which must change nothing
    kappa[:, :5] = 0.0
    kappa[10:14] = 0.0
    kappa[20, 7:] = 0.0
    kappa[21, 9:12] = 0.0
    alpha = {n: float(a) for n, a in zip(names, rng.uniform(0.1, 0.9, count), strict=True)}
    gamma = {n: [0.5, 3.0, 90.0][j % 3] for j, n in enumerate(names)}  # 90: γκ is clipped
    sig_ref = {
        n: sigma(np.nan_to_num(kappa), reflectance_delta(lights[n], 1.3), alpha[n], gamma[n])
        for n in names
    }
    scaled = sum(lobes[n] * sig_ref[n][..., None] for n in names)
    remainder = rng.random((*shape, 3), dtype=np.float32)
    beauty = remainder + sum(lobes[n] for n in names)
    out, sig = scale_lobes(lobes, lights, kappa, alpha, gamma, 1.3)
    for n in names:
        np.testing.assert_allclose(sig[n], sig_ref[n], rtol=2e-6)
    np.testing.assert_allclose(out, scaled, rtol=1e-5, atol=1e-5)
    bare, none = scale_lobes(lobes, lights, kappa, alpha, gamma, 1.3, with_sigmas=False)
    assert none == {}
    np.testing.assert_array_equal(bare, out)
    with_rem, _ = scale_lobes(lobes, lights, kappa, alpha, gamma, 1.3, remainder)
    np.testing.assert_allclose(with_rem, scaled + remainder, rtol=1e-5, atol=1e-5)
    rebuilt, _ = scale_lobes(lobes, lights, kappa, alpha, gamma, 1.3, beauty=beauty)
    np.testing.assert_allclose(rebuilt, scaled + remainder, rtol=1e-5, atol=2e-5)


@pytest.mark.parametrize("factor", [1, 2, 4])
def test_scale_lobes_reads_kappa_from_a_coarser_grid(factor: int) -> None:
    """κ given on a grid ``factor`` times coarser (as the operator passes it) is interpolated row
    by row inside the kernel: the same result as the full-resolution κ, with σ layers too."""
    grid = np.random.default_rng(factor).uniform(-1, 1, (35, 16)).astype(np.float32)
    field = Upsampled(grid, (35 * factor, 16 * factor))
    lobes, lights = _lobes(field.shape, seed=factor)
    beauty = lobes["diffuse"] + lobes["specular"]
    full = np.asarray(field)
    for extra in ({}, {"beauty": beauty}):
        out, sig = scale_lobes(lobes, lights, field, 0.4, 3.0, 1.2, **extra)  # type: ignore[arg-type]
        ref, sig_ref = scale_lobes(lobes, lights, full, 0.4, 3.0, 1.2, **extra)  # type: ignore[arg-type]
        np.testing.assert_allclose(out, ref, rtol=1e-6, atol=1e-6)
        for n in sig:
            np.testing.assert_allclose(sig[n], sig_ref[n], rtol=1e-6)
    with pytest.raises(ValueError, match=r"lobes\['diffuse'\] must have shape"):
        larger = Upsampled(grid, (35 * factor + 35, 16 * factor + 16))
        scale_lobes(lobes, lights, larger, 0.4, 3.0, 1.2)


def test_scale_lobes_enhances_a_lit_sphere() -> None:
    """On a convex sphere, lit parts (δ > α) brighten and dim parts darken: more contrast."""
    s = analytic.sphere(96)
    kappa = isotropic(principal_curvatures(s.normal, s.depth, s.mask))
    ell = np.array([0.5, 0.5, 0.7071], np.float32)
    light = np.repeat(np.clip(s.normal @ ell, 0, None)[..., None], 3, axis=2).astype(np.float32)
    out, sig = scale_lobes({"diffuse": light}, {"diffuse": light}, kappa, 0.5, 4.0, 1.0)
    inner = s.interior(0.05)
    y_in, y_out = light[..., 0][inner], out[..., 0][inner]
    assert (y_out[y_in > 0.55] > y_in[y_in > 0.55]).all()
    assert (y_out[(y_in < 0.45) & (y_in > 0.01)] < y_in[(y_in < 0.45) & (y_in > 0.01)]).all()
    assert y_out.std() > 1.1 * y_in.std()
    assert (sig["diffuse"][~s.mask] == 1.0).all()  # no curvature, no change on the background


def test_scale_lobes_rejects_bad_input() -> None:
    shape = (6, 7)
    lobes, lights = _lobes(shape)
    kappa = np.zeros(shape, np.float32)
    with pytest.raises(ValueError, match=r"alpha\['specular'\]"):
        scale_lobes(lobes, lights, kappa, {"diffuse": 0.5, "specular": 1.5}, 1.0, 1.0)
    with pytest.raises(ValueError, match="alpha has no value"):
        scale_lobes(lobes, lights, kappa, {"diffuse": 0.5}, 1.0, 1.0)
    with pytest.raises(ValueError, match=r"gamma\['diffuse'\]"):
        scale_lobes(lobes, lights, kappa, 0.5, -1.0, 1.0)
    with pytest.raises(ValueError, match="white"):
        scale_lobes(lobes, lights, kappa, 0.5, 1.0, "bright")
    with pytest.raises(ValueError, match="white"):
        scale_lobes(lobes, lights, kappa, 0.5, 1.0, 0.0)
    with pytest.raises(ValueError, match="remainder"):
        scale_lobes(lobes, lights, kappa, 0.5, 1.0, 1.0, np.zeros((6, 7, 4), np.float32))
    with pytest.raises(ValueError, match="kappa"):
        scale_lobes(lobes, lights, kappa[None], 0.5, 1.0, 1.0)
    with pytest.raises(ValueError, match=r"lobes\['diffuse'\]"):
        scale_lobes({"diffuse": np.zeros((6, 8, 3))}, {}, kappa, 0.5, 1.0, 1.0)
