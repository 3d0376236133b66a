"""``ops.shading.shade_directions``, the shading Light Alignment relights with, and the kept
lighting's gain on the relit lobes (``ops.shading.apply_gain``), on analytic G-buffers
(tests/analytic.py) where an exact answer is known."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np
import pytest

from ops import shading
from ops.filtering import normal_pyramid
from ops.light_alignment import align_lights
from ops.shading import parse_light, shade_directions, shade_lobes
from tests import analytic

LIGHTS = [parse_light("-0.4,0.6,0.7"), parse_light("0.6,0.2,0.5@1,0.8,0.6*0.35")]


@pytest.fixture(scope="module")
def ball() -> analytic.Scene:
    return analytic.sphere(40, 0.7, width=48)


def positions(s: analytic.Scene) -> np.ndarray:
    p = np.zeros((*s.shape, 3), np.float32)
    p[..., 2] = -np.where(s.mask, s.depth, 0.0)
    return p


def test_shade_directions_without_directions_is_shade_lobes(ball: analytic.Scene) -> None:
    view = np.array([0.0, 0.0, 1.0], np.float32)
    pos = positions(ball)
    got = shade_directions(ball.normal, view, pos, LIGHTS, None, shininess=24.0)
    ref = shade_lobes(ball.normal, pos, view, 1.0, LIGHTS, shininess=24.0)
    np.testing.assert_allclose(got["diffuse"], ref["diffuse.light"], atol=1e-5)
    np.testing.assert_allclose(got["specular"], ref["specular.light"], atol=1e-5)
    assert set(got) == {"diffuse", "specular"}
    # Lambert by hand: Σ E_i max(n·ℓ_i, 0)
    lam = sum(
        shading.lambert(ball.normal, np.asarray(li.vector, np.float32))[..., None]
        * np.float32(li.intensity)
        * np.asarray(li.color, np.float32)
        for li in LIGHTS
    )
    np.testing.assert_allclose(got["diffuse"], lam, atol=1e-5)
    assert got["specular"].max() > 0.5
    # explicit constant directions give the same as none
    fields = [np.broadcast_to(np.float32(li.vector), (*ball.shape, 3)).copy() for li in LIGHTS]
    same = shade_directions(
        ball.normal, view, pos, LIGHTS, {"diffuse": fields, "specular": fields}, shininess=24.0
    )
    for lobe in ("diffuse", "specular"):
        np.testing.assert_allclose(same[lobe], got[lobe], atol=1e-5)


def test_shade_directions_per_component(ball: analytic.Scene) -> None:
    view = np.array([0.0, 0.0, 1.0], np.float32)
    pos = positions(ball)
    base = shade_directions(ball.normal, view, pos, LIGHTS)
    other = [np.broadcast_to(np.float32([0.0, 0.0, 1.0]), (*ball.shape, 3)).copy()] * 2
    moved = shade_directions(ball.normal, view, pos, LIGHTS, {"diffuse": other})
    np.testing.assert_array_equal(moved["specular"], base["specular"])  # its own light
    e = sum(np.float32(li.intensity) * np.asarray(li.color, np.float32) for li in LIGHTS)
    expected = np.maximum(ball.normal[..., 2], 0.0)[..., None] * e
    np.testing.assert_allclose(moved["diffuse"], expected, atol=1e-5)


@pytest.mark.parametrize("specular", ["blinn_phong", "ggx"])
def test_positions_are_read_by_point_lights_only(ball: analytic.Scene, specular: str) -> None:
    # directional lights shade and align alike without positions (Light Alignment skips
    # rebuilding them); a point light without them is refused by name
    view = np.array([0.0, 0.0, 1.0], np.float32)
    pos = positions(ball)
    directional = [li for li in LIGHTS if li.kind == "directional"]
    assert directional
    with_pos = shade_directions(ball.normal, view, pos, directional, specular=specular)
    without = shade_directions(ball.normal, view, None, directional, specular=specular)
    for lobe, got in without.items():
        assert np.array_equal(got, with_pos[lobe]), lobe
    pyr = normal_pyramid(ball.normal, ball.depth, ball.mask, scales=3)
    comps = {"diffuse": [0.5, 0.5]}
    aligned = align_lights(directional, pyr, None, view, comps)
    assert np.array_equal(
        aligned["diffuse"][0], align_lights(directional, pyr, pos, view, comps)["diffuse"][0]
    )
    point = [shading.Light("point", (1.0, 1.0, 2.0))]
    with pytest.raises(ValueError, match="point lights need the surface positions"):
        shade_directions(ball.normal, view, None, point)
    with pytest.raises(ValueError, match="point lights need the surface positions"):
        align_lights(point, pyr, None, view, comps)


@pytest.mark.parametrize("ior", [1.5, 0.8])
def test_shade_directions_transmission_is_the_refracted_view_lobe(
    ball: analytic.Scene, ior: float
) -> None:
    """Directional lights with a transmission lobe (a path-traced frame's glass): the compiled
    pass gives Σ_i E_i max(t·ℓ_i, 0)^e with t the refracted view ray (:func:`transmission`),
    0 where the ray cannot enter (total internal reflection, ior < 1) and off the surface, and
    the per-light direction fields of the component are used."""
    view = np.array([0.0, 0.0, 1.0], np.float32)
    pos = positions(ball)
    lights = [parse_light("0.3,-0.2,-1"), parse_light("-0.5,0.1,-0.6@1,0.5,0.25*2")]
    kw = {"transmission": True, "ior": ior, "transmission_exponent": 8.0}
    got = shade_directions(ball.normal, view, pos, lights, **kw)
    want = sum(
        shading.transmission(ball.normal, np.float32(li.vector), view, ior, 8.0)[..., None]
        * (ball.mask[..., None] * np.float32(li.intensity) * np.asarray(li.color, np.float32))
        for li in lights
    )
    np.testing.assert_allclose(got["transmission"], want, rtol=1e-4, atol=1e-6)
    assert got["transmission"][ball.mask].max() > 0.1
    assert not got["transmission"][~ball.mask].any()
    if ior < 1.0:  # grazing view rays are totally reflected: no transmission there
        nv = ball.normal[..., 2]
        inside = ball.mask & (1.0 - ior**-2 * (1.0 - nv * nv) < -0.05)
        assert inside.sum() > 20 and not got["transmission"][inside].any()
    fields = [np.broadcast_to(np.float32([0.0, 0.0, -1.0]), (*ball.shape, 3)).copy()] * 2
    moved = shade_directions(ball.normal, view, pos, lights, {"transmission": fields}, **kw)
    np.testing.assert_array_equal(moved["diffuse"], got["diffuse"])  # its own light
    assert np.abs(moved["transmission"] - got["transmission"]).max() > 0.1


def test_apply_gain_scales_the_relit_lobes_and_moves_the_beauty_with_them() -> None:
    """The kept lighting's gain on Light Alignment's relit lobes: each lobe and light × gain in
    place, the beauty + Σ (gain − 1) lobe_j; lights do not count in the beauty."""
    rng = np.random.default_rng(3)
    shape = (37, 53, 3)
    lobes = [rng.random(shape, dtype=np.float32) for _ in range(3)]
    lights = [rng.random(shape, dtype=np.float32)]
    beauty = rng.random(shape, dtype=np.float32) + sum(lobes)
    gain = rng.uniform(0.5, 1.5, shape[:2]).astype(np.float32)
    gain[::3] = 1.0
    want_beauty = beauty + (gain[..., None] - 1.0) * sum(lobes)
    want = [x * gain[..., None] for x in (*lobes, *lights)]
    kept = beauty.copy()
    shading.apply_gain(beauty, gain, lobes, lights)
    for got, expected in zip((*lobes, *lights), want, strict=True):
        np.testing.assert_array_equal(got, expected)
    np.testing.assert_allclose(beauty, want_beauty, rtol=1e-6, atol=1e-6)
    np.testing.assert_array_equal(beauty[::3], kept[::3])  # a gain of 1 changes nothing
    # arrays it cannot change in place are refused, not silently left as they were
    wide = np.zeros((37, 106, 3), np.float32)
    for bad in (wide[:, ::2], beauty.astype(np.float64)):
        with pytest.raises(ValueError, match="C-contiguous float32"):
            shading.apply_gain(bad, gain, lobes, lights)
        with pytest.raises(ValueError, match="C-contiguous float32"):
            shading.apply_gain(beauty, gain, [bad], lights)


def test_shade_directions_point_light_matches_shade_lobes(ball: analytic.Scene) -> None:
    view = np.array([0.0, 0.0, 1.0], np.float32)
    pos = positions(ball)
    lights = [parse_light("point:1,2,-6*20")]
    got = shade_directions(ball.normal, view, pos, lights)
    ref = shade_lobes(ball.normal, pos, view, 1.0, lights)
    m = ball.mask
    np.testing.assert_allclose(got["diffuse"][m], ref["diffuse.light"][m], rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(got["specular"][m], ref["specular.light"][m], rtol=1e-4, atol=1e-6)


def test_half_lambert_is_never_zero_on_the_unlit_side(ball: analytic.Scene) -> None:
    view = np.array([0.0, 0.0, 1.0], np.float32)
    light = [parse_light("1,0,0")]
    out = shade_directions(ball.normal, view, positions(ball), light, diffuse="half_lambert")
    d = out["diffuse"][..., 0]
    nl = ball.normal[..., 0]
    unlit = ball.mask & (nl < 0)
    assert unlit.sum() > 100
    assert d[unlit].min() > 0.0
    np.testing.assert_allclose(d[ball.mask], ((nl[ball.mask] + 1.0) / 2.0) ** 2, atol=1e-5)
    lam = shade_directions(ball.normal, view, positions(ball), light)["diffuse"][..., 0]
    assert lam[unlit].max() == 0.0
    np.testing.assert_array_equal(d[~ball.mask], 0.0)  # no surface, no light


def test_ggx_roughness_pass_matches_the_scalar(ball: analytic.Scene) -> None:
    view = np.array([0.0, 0.0, 1.0], np.float32)
    pos = positions(ball)
    kw: dict[str, Any] = {"specular": "ggx", "f0": 0.08}
    scalar = shade_directions(ball.normal, view, pos, LIGHTS, roughness=0.3, **kw)["specular"]
    const = np.full(ball.shape, 0.3, np.float32)
    array = shade_directions(ball.normal, view, pos, LIGHTS, roughness=const, **kw)["specular"]
    np.testing.assert_allclose(array, scalar, rtol=1e-5, atol=1e-7)
    assert scalar.max() > 0.05
    # a pass that varies: each half equals the scalar shading of its own roughness
    split = np.where(np.arange(ball.shape[1])[None, :] < ball.shape[1] // 2, 0.3, 0.7)
    split = np.broadcast_to(split, ball.shape).astype(np.float32)
    mixed = shade_directions(ball.normal, view, pos, LIGHTS, roughness=split, **kw)["specular"]
    rough = shade_directions(ball.normal, view, pos, LIGHTS, roughness=0.7, **kw)["specular"]
    left = split == np.float32(0.3)
    np.testing.assert_allclose(mixed[left], scalar[left], rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(mixed[~left], rough[~left], rtol=1e-5, atol=1e-7)
    # the ggx term is the one of ops.shading.ggx for one white light
    one = [parse_light("-0.4,0.6,0.7")]
    got = shade_directions(ball.normal, view, pos, one, roughness=0.3, **kw)["specular"][..., 0]
    ref = shading.ggx(ball.normal, np.float32(one[0].vector), view, 0.3, 0.08)
    np.testing.assert_allclose(got[ball.mask], ref[ball.mask], rtol=1e-5, atol=1e-7)


def test_shade_directions_transmission_and_no_specular(ball: analytic.Scene) -> None:
    view = np.array([0.0, 0.0, 1.0], np.float32)
    out = shade_directions(
        ball.normal,
        view,
        positions(ball),
        [parse_light("0,0,-1")],
        specular="none",
        transmission=True,
    )
    assert set(out) == {"diffuse", "transmission"}
    assert out["transmission"].max() > 0.1  # lit from behind: light comes through
    np.testing.assert_array_equal(out["diffuse"], 0.0)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"diffuse": "oren_nayar"}, "diffuse"),
        ({"specular": "phong"}, "specular"),
        ({"shininess": 0.0}, "shininess"),
        ({"roughness": 0.0, "specular": "ggx"}, "roughness"),
        ({"roughness": 1.5}, "roughness"),
        ({"f0": 1.5}, "f0"),
        ({"ior": 0.0}, "ior"),
        ({"transmission_exponent": -1.0}, "transmission_exponent"),
        ({"directions": {"glossy": []}}, "glossy"),
        ({"directions": {"diffuse": []}}, "one field per light"),
    ],
)
def test_shade_directions_validation(
    ball: analytic.Scene, kwargs: dict[str, Any], match: str
) -> None:
    view = np.array([0.0, 0.0, 1.0], np.float32)
    with pytest.raises(ValueError, match=match):
        shade_directions(ball.normal, view, positions(ball), LIGHTS, **kwargs)


def test_shade_directions_rejects_a_bad_normal_shape(ball: analytic.Scene) -> None:
    with pytest.raises(ValueError, match="normal"):
        shade_directions(ball.normal[..., :2], np.float32([0, 0, 1]), positions(ball), LIGHTS)


@pytest.mark.parametrize("power", [1, 2, 3, 7, 24, 32, 33, 100, 1000])
def test_whole_exponents_are_raised_in_the_kernels_as_cv2_pow_raises_them(power: int) -> None:
    # Blinn-Phong's (n·h)^s and the transmission lobe's power: a whole exponent is raised inside
    # the pass that adds the terms, bit for bit what cv2.pow gives (its binary powers)
    from ops.shading._kernels import _add_gated, _add_terms, int_power

    assert int_power(float(power)) == power
    assert int_power(32.5) == int_power(0.0) == int_power(1e9) == 0
    rng = np.random.default_rng(power)
    rows, wid = 5, 37
    base = rng.random((rows, wid), dtype=np.float32)
    base[0, :4] = [0.0, 1.0, np.float32(1) - np.float32(6e-8), 1e-3]
    gate = (rng.random((rows, wid)) > 0.3).astype(np.float32)
    d_term = rng.random((rows, wid), dtype=np.float32)
    e = np.float32([0.8, 1.0, 0.6])
    raised = np.asarray(cv2.pow(base, float(power)), np.float32)
    for first in (True, False):
        start = rng.random((rows, 3 * wid), dtype=np.float32)
        od = [start.copy() for _ in range(2)]
        os_ = [start.copy() for _ in range(2)]
        _add_terms(d_term.copy(), raised.copy(), gate, e, first, True, 0, od[0], os_[0])
        _add_terms(d_term.copy(), base.copy(), gate, e, first, True, power, od[1], os_[1])
        np.testing.assert_array_equal(os_[1], os_[0])
        np.testing.assert_array_equal(od[1], od[0])
        out = [start.copy() for _ in range(2)]
        _add_gated(raised.copy(), gate, e, first, 0, out[0])
        _add_gated(base.copy(), gate, e, first, power, out[1])
        np.testing.assert_array_equal(out[1], out[0])
