"""The Light Alignment operator through ``service.pipeline.run``: relight and ratio forms, the
aligned light layers, the components and scales aligned, parameters (the shading it relights
with: tests/test_shade_directions.py; the other operators: tests/test_operators.py).

On a small OSMesa render of examples/spot.obj (lobes, albedo, AO, a perspective camera) and on
analytic G-buffers (tests/analytic.py) where an exact answer is known.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from gbuffer.errors import MissingBufferError
from gbuffer.frame import Frame
from ops.shading import light_vectors, parse_light, shade_directions
from service import pipeline
from service.operators.common import DEFAULT_LIGHTS, holds_light
from service.registry import PipelineError
from tests import analytic
from tests.test_operators import covered, field, remainder, run, spot_frame


@pytest.fixture(scope="module")
def spot() -> Frame:
    return spot_frame()


def sphere_frame(height: int = 48, width: int = 64) -> Frame:
    s = analytic.sphere(height, 0.6, width=width)
    return Frame(buffers={"normal": s.normal, "depth": s.depth})


def light_text(vec: tuple[float, float, float]) -> str:
    return ",".join(f"{c:.8f}" for c in vec)


def tent(size: int = 128, half: float = 0.025) -> tuple[Frame, np.ndarray, np.ndarray]:
    """A ridge (two 35° flanks, ``half`` image heights wide each) on a plane facing the camera,
    as in tests/test_light_alignment.py (narrower, so that the operator's largest ``base``
    of 0.1 sees a plane at the coarse scale). Returns the frame and the left / right flanks."""
    u, _ = analytic.pixel_coords(size, size)
    slope = math.radians(35.0)
    on = np.abs(u) < half
    nx = np.where(on & (u > 0), math.sin(slope), np.where(on & (u < 0), -math.sin(slope), 0.0))
    nz = np.where(on, math.cos(slope), 1.0)
    normal = np.stack([nx, np.zeros_like(nx), nz], axis=-1).astype(np.float32)
    height = np.where(on, (half - np.abs(u)) * math.tan(slope), 0.0) * 2.0
    depth = (10.0 - height).astype(np.float32)
    margin = 0.006
    left = (u < -margin) & (u > -half + margin)
    right = (u > margin) & (u < half - margin)
    return Frame(buffers={"normal": normal, "depth": depth}), left, right


ZERO_SIGMAS = [0.0, 0.0, 0.0, 0.0, 0.0]


def test_relight_with_zero_sigmas_is_plain_shading(spot: Frame) -> None:
    out = run(spot, "light_alignment", {"sigmas": ZERO_SIGMAS, "form": "relight"})
    lights = [parse_light(t) for t in DEFAULT_LIGHTS]
    ref = shade_directions(
        spot.buffers["normal"], spot.view_vectors(), spot.positions(), lights, None
    )
    cov = covered(spot)
    for lobe in ("diffuse", "specular"):
        np.testing.assert_allclose(out.buffers[f"{lobe}.light"], ref[lobe], atol=1e-5)
    albedo = spot.buffers["albedo"]
    ambient = 0.1 * spot.buffers["ao"][..., None] * spot.mask[..., None]
    expected = albedo * (ambient + ref["diffuse"]) + 0.3 * ref["specular"]
    np.testing.assert_allclose(out.buffers["beauty"][cov], expected[cov], atol=1e-5)
    # background untouched, beauty = Σ lobes (relight replaces the lobes, no remainder)
    np.testing.assert_array_equal(out.buffers["beauty"][~cov], spot.buffers["beauty"][~cov])
    assert "remainder" not in out.buffers
    np.testing.assert_allclose(remainder(out)[cov], 0.0, atol=1e-5)


def test_ratio_with_zero_sigmas_leaves_the_beauty(spot: Frame) -> None:
    out = run(spot, "light_alignment", {"sigmas": ZERO_SIGMAS, "form": "ratio"})
    np.testing.assert_allclose(out.buffers["beauty"], spot.buffers["beauty"], atol=1e-5)
    for lobe in ("ambient", "diffuse", "specular"):
        np.testing.assert_allclose(out.buffers[lobe], spot.buffers[lobe], atol=1e-5)


def test_auto_form_is_ratio_with_lobes_and_relight_without(spot: Frame) -> None:
    params = {"sigmas": [0.6, 0.4, 0.2]}
    auto = run(spot, "light_alignment", params)
    ratio = run(spot, "light_alignment", {**params, "form": "ratio"})
    np.testing.assert_array_equal(auto.buffers["beauty"], ratio.buffers["beauty"])
    bare = Frame(buffers={k: spot.buffers[k] for k in ("normal", "depth")}, camera=spot.camera)
    auto = run(bare, "light_alignment", params)
    relight = run(bare, "light_alignment", {**params, "form": "relight"})
    np.testing.assert_array_equal(auto.buffers["beauty"], relight.buffers["beauty"])
    with pytest.raises(MissingBufferError, match="diffuse"):
        run(bare, "light_alignment", {**params, "form": "ratio"})


def test_ridge_lit_from_above_gets_two_different_sides() -> None:
    frame, left, right = tent()
    a = math.radians(1.5)  # 1.5° off the bisector (exactly on it both sides stay alike)
    params: dict[str, Any] = {
        "lights": [light_text((math.sin(a), 0.0, math.cos(a)))],
        "base": 0.1,
        "specular": "none",
        "ambient": 0.0,
        "form": "relight",
        "albedo": 1.0,
    }
    before = run(frame, "light_alignment", {**params, "sigmas": [0.0, 0.0]})
    after = run(frame, "light_alignment", {**params, "sigmas": [1.0, 0.0]})
    b = before.buffers["beauty"][..., 0]
    c = after.buffers["beauty"][..., 0]
    assert abs(b[right].mean() - b[left].mean()) < 0.05  # nearly alike without alignment
    assert c[right].mean() > 0.9  # the lit side faces the light
    assert c[left].mean() < 0.15  # the other side is grazed
    assert c[right].mean() - c[left].mean() > 0.7


def test_aligned_light_layers_are_unit_and_one_per_light_and_component(spot: Frame) -> None:
    lights = ["-0.4,0.6,0.7", "0.6,0.2,0.5*0.35", "0,-1,0.3"]
    out = run(spot, "light_alignment", {"lights": lights, "sigmas": [0.8, 0.5, 0.3]})
    cov = covered(spot)
    layers = {}
    for k, prefix in enumerate(("lla_light", "lla_light2", "lla_light3")):
        for component in ("diffuse", "specular"):
            v = field(out, f"{prefix}.{component}")
            np.testing.assert_allclose(np.linalg.norm(v, axis=-1)[cov], 1.0, atol=1e-4)
            # the background keeps the light itself
            own = np.asarray(parse_light(lights[k]).vector, np.float32)
            np.testing.assert_allclose(v[~cov], np.broadcast_to(own, v[~cov].shape), atol=1e-5)
            layers[prefix, component] = v
    assert not any(name.startswith("lla_light4") for name in out.outputs)
    assert not any(name.startswith("lla_light1.") for name in out.outputs)
    # each light has its own directions, rotated where the shape asks for it
    assert np.abs(layers["lla_light", "diffuse"] - layers["lla_light2", "diffuse"])[cov].max() > 0.5
    first = np.asarray(parse_light(lights[0]).vector, np.float32)
    assert np.abs(layers["lla_light", "diffuse"][cov] - first).max() > 0.05
    # no debug layers unless asked
    assert not any(name.startswith("lla_n") for name in out.outputs)


def test_only_the_listed_components_get_layers(spot: Frame) -> None:
    out = run(spot, "light_alignment", {"components": ["diffuse"], "sigmas": [0.5]})
    names = {n.rsplit(".", 1)[0] for n in out.outputs if n.startswith("lla_light")}
    assert names == {"lla_light.diffuse", "lla_light2.diffuse"}


def _aligned(frame: Frame) -> set[str]:
    return {n.rsplit(".", 1)[0] for n in frame.outputs if n.startswith("lla_light")}


def test_only_the_components_the_result_depends_on_are_aligned(spot: Frame) -> None:
    # ratio form: no transmission lobe, no transmission aligned (the same pixels as listing
    # diffuse and specular only), one when there is; relight: specular unless "none",
    # transmission with a weight
    both = {f"{k}.{c}" for k in ("lla_light", "lla_light2") for c in ("diffuse", "specular")}
    full = run(spot, "light_alignment")
    two = run(spot, "light_alignment", {"components": ["diffuse", "specular"]})
    assert _aligned(full) == _aligned(two) == both
    assert np.array_equal(full.buffers["beauty"], two.buffers["beauty"])
    glass = spot.copy()
    glass.buffers["transmission"] = spot.buffers["diffuse"]
    assert "lla_light.transmission" in _aligned(run(glass, "light_alignment"))
    light_alone = spot.copy()  # (a lobe's light without the lobe relights nothing)
    light_alone.buffers["transmission.light"] = spot.buffers["diffuse.light"]
    assert _aligned(run(light_alone, "light_alignment")) == both
    relight = {"form": "relight", "specular": "none"}
    assert _aligned(run(spot, "light_alignment", relight)) == {
        "lla_light.diffuse",
        "lla_light2.diffuse",
    }
    weighted = run(spot, "light_alignment", {"form": "relight", "transmission_weight": 0.5})
    assert _aligned(weighted) == both | {"lla_light.transmission", "lla_light2.transmission"}


def test_a_lobe_without_light_is_left_as_it_is(spot: Frame) -> None:
    # Blender writes transmission passes of a scene without glass: zeros. The ratio form leaves
    # that lobe and its light as they are (ρ · 0 is 0) instead of shading it twice: the same
    # pixels as a frame without it, the very arrays given back; its light is not aligned, and
    # its layers hold the lights as they are (the layers of a sequence do not depend on what a
    # frame holds)
    zero = np.zeros_like(spot.buffers["diffuse"])
    dark = spot.copy()
    dark.buffers.update({"transmission": zero, "transmission.light": zero.copy()})
    out, without = run(dark, "light_alignment"), run(spot, "light_alignment")
    for name in ("beauty", "diffuse", "specular", "diffuse.light", "specular.light"):
        assert np.array_equal(out.buffers[name], without.buffers[name]), name
    for name in ("transmission", "transmission.light"):
        assert out.buffers[name] is dark.buffers[name]
    assert _aligned(out) == _aligned(without) | {
        "lla_light.transmission",
        "lla_light2.transmission",
    }
    for k, text in enumerate(DEFAULT_LIGHTS):
        own = np.broadcast_to(np.float32(parse_light(text).vector), (*spot.shape, 3))
        assert np.array_equal(field(out, f"lla_light{k + 1 if k else ''}.transmission"), own)
    # a point light's: the direction towards it from every surface point
    point = "point:0.5,1,1*4"
    near = run(dark, "light_alignment", {"lights": [point]})
    towards = light_vectors(parse_light(point), dark.positions())
    assert np.array_equal(field(near, "lla_light.transmission"), towards)
    # light in the lobe's light alone (or a NaN) is light: the lobe is relit
    lit = dark.copy()
    lit.buffers["transmission.light"] = spot.buffers["diffuse.light"]
    assert (
        run(lit, "light_alignment").buffers["transmission.light"]
        is not spot.buffers["diffuse.light"]
    )
    assert holds_light(lit, "transmission") and not holds_light(dark, "transmission")
    nan = dark.copy()
    nan.buffers["transmission"] = zero.copy()
    nan.buffers["transmission"][3, 5, 1] = np.nan
    assert holds_light(nan, "transmission") and not holds_light(spot, "transmission")


@pytest.mark.parametrize("sigmas", [[0.5], [0.5, 0.3, 0.1, 0.2, 0.2]])
def test_debug_layers_hold_every_scale(spot: Frame, sigmas: list[float]) -> None:
    out = run(spot, "light_alignment", {"sigmas": sigmas}, debug_layers=True)
    scales = len(sigmas) + 1
    found = sorted({n.split(".")[0] for n in out.outputs if n.startswith("lla_n")})
    assert found == [f"lla_n{i}" for i in range(1, scales + 1)]
    cov = covered(spot)
    n1 = field(out, "lla_n1")
    np.testing.assert_allclose(np.linalg.norm(n1, axis=-1)[cov], 1.0, atol=1e-3)
    coarsest = field(out, f"lla_n{scales}")
    assert np.abs(coarsest - n1)[cov].max() > 0.05  # a smoothed field, not a copy


def test_ratio_form_keeps_emission_and_remainder(spot: Frame) -> None:
    frame = spot.copy()
    cov = covered(frame)
    emission = np.where(cov[..., None], np.float32([0.05, 0.2, 0.02]), 0.0).astype(np.float32)
    frame.buffers["beauty"] = (frame.buffers["beauty"] + emission).astype(np.float32)
    out = run(frame, "light_alignment", {"form": "ratio"})
    np.testing.assert_allclose(remainder(out), remainder(frame), atol=1e-5)
    np.testing.assert_allclose(remainder(out)[cov], emission[cov], atol=1e-5)
    # the lobes did change, and the beauty by exactly their change
    change = sum(
        out.buffers[lobe] - frame.buffers[lobe] for lobe in ("ambient", "diffuse", "specular")
    )
    assert np.abs(out.buffers["diffuse"] - frame.buffers["diffuse"]).max() > 0.05
    np.testing.assert_allclose(out.buffers["beauty"] - frame.buffers["beauty"], change, atol=1e-5)
    # a lobe's light follows its radiance (the colour is unchanged)
    np.testing.assert_allclose(
        out.buffers["diffuse.light"] * out.buffers["diffuse.color"],
        out.buffers["diffuse"],
        atol=1e-5,
    )


def test_relight_drops_the_lobes_it_does_not_relight(spot: Frame) -> None:
    out = run(spot, "light_alignment", {"form": "relight", "specular": "none"})
    assert "specular" not in out.buffers and "specular.light" not in out.buffers
    np.testing.assert_allclose(remainder(out)[covered(spot)], 0.0, atol=1e-5)


def test_roughness_from_the_frame_matches_a_constant(spot: Frame) -> None:
    params = {"form": "relight", "specular": "ggx", "sigmas": [0.5, 0.3]}
    const = run(spot, "light_alignment", {**params, "roughness": 0.35})
    frame = spot.copy()
    frame.buffers["roughness"] = np.full(spot.shape, 0.35, np.float32)
    from_frame = run(frame, "light_alignment", {**params, "roughness": "frame"})
    np.testing.assert_allclose(from_frame.buffers["beauty"], const.buffers["beauty"], atol=1e-5)
    with pytest.raises(MissingBufferError, match="roughness"):
        run(spot, "light_alignment", {**params, "roughness": "frame"})


@pytest.mark.parametrize(
    ("params", "name"),
    [
        ({"sigmas": [1.5]}, "sigmas"),
        ({"sigmas": [0.1, 0.2], "specular_sigmas": [0.1]}, "specular_sigmas"),
        ({"sigmas": [0.1], "transmission_sigmas": [-0.1]}, "transmission_sigmas"),
        ({"roughness": 0}, "roughness"),
        ({"roughness": 1.5}, "roughness"),
        ({"components": ["diffuse", "glossy"]}, "components"),
        ({"lights": ["1,2"]}, "lights"),
        ({"gamma": -1}, "gamma"),
        ({"sigma": [0.5]}, "sigma"),
    ],
)
def test_light_alignment_bad_parameters(params: dict[str, Any], name: str) -> None:
    with pytest.raises(PipelineError, match=name) as info:
        run(sphere_frame(16, 16), "light_alignment", params)
    assert str(info.value).startswith("light_alignment")


@pytest.mark.parametrize("ior", [1e-4, 1.5, 10.0])
def test_transmission_shading_is_finite_at_every_valid_ior(ior: float) -> None:
    """With a small ior (η = 10⁴) the refracted ray's t·ℓ of pixels whose view ray does not enter
    overflowed in its power, and inf × 0 made NaN of the beauty and every lobe."""
    h = w = 8
    y, x = np.mgrid[0:h, 0:w].astype(np.float32) / 8 - 0.45
    n = np.dstack([x, y, np.ones_like(x)])
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    t = np.full((h, w, 3), 0.2, np.float32)
    buffers = {"normal": n.astype(np.float32), "depth": np.full((h, w), 3.0, np.float32)}
    lobes = {"beauty": t * 2, "diffuse": t.copy(), "transmission": t.copy()}
    out = pipeline.run(
        Frame(buffers={**buffers, **lobes}), [{"op": "light_alignment", "params": {"ior": ior}}]
    )
    for name, values in {**out.buffers, **out.outputs}.items():
        assert np.isfinite(values).all(), name
