"""The operators of service/operators/ through ``service.pipeline.run`` (the shading Light
Alignment relights with: tests/test_shade_directions.py).

On a small OSMesa render of examples/spot.obj (lobes, albedo, AO, a perspective camera) and on
analytic G-buffers (tests/analytic.py) where an exact answer is known.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from analysis.compare import frame_from_mesh
from analysis.score import score_frame
from gbuffer.errors import MissingBufferError, MissingCameraError
from gbuffer.frame import LOBES, Frame
from ops import shading
from ops.shading import parse_light, shade_directions
from service import pipeline
from service.operators.common import DEFAULT_LIGHTS
from service.registry import Context, PipelineError
from tests import analytic

SPOT = Path(__file__).resolve().parents[1] / "examples" / "spot.obj"
WIDTH, HEIGHT = 160, 120


@pytest.fixture(scope="module")
def spot() -> Frame:
    """A real render with ambient / diffuse / specular lobes, albedo, AO and a camera."""
    return frame_from_mesh(SPOT, WIDTH, HEIGHT)


def run(frame: Frame, op: str, params: dict[str, Any] | None = None, **kw: Any) -> Frame:
    return pipeline.run(frame, [{"op": op, "params": params or {}}], **kw)


def covered(frame: Frame) -> np.ndarray:
    return frame.mask > 0


def field(frame: Frame, layer: str, names: str = "XYZ") -> np.ndarray:
    channels = frame.layer(layer)
    assert set(names) <= set(channels), f"{layer}: {sorted(channels)}"
    return np.dstack([channels[n] for n in names])


def remainder(frame: Frame) -> np.ndarray:
    return frame.buffers["beauty"] - sum(
        frame.buffers[lobe] for lobe in LOBES if lobe in frame.buffers
    )


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


# -- light_alignment ----------------------------------------------------------------------------

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
    relight = {"form": "relight", "specular": "none"}
    assert _aligned(run(spot, "light_alignment", relight)) == {
        "lla_light.diffuse",
        "lla_light2.diffuse",
    }
    weighted = run(spot, "light_alignment", {"form": "relight", "transmission_weight": 0.5})
    assert _aligned(weighted) == both | {"lla_light.transmission", "lla_light2.transmission"}


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


@pytest.mark.parametrize("keep_lighting", [False, True])
def test_radiance_scaling_gives_each_renderer_lobe_its_own_gamma(
    spot: Frame, keep_lighting: bool
) -> None:
    """On a renderer's lobes, γ_diffuse = γ_specular = 0 (γ = 3 otherwise) leaves the beauty as
    it was, with or without the kept lighting; a γ of its own scales the specular lobe alone
    (the ambient lobe, left out, stays in the beauty as it was)."""
    base = {"gamma": 3.0, "keep_lighting": keep_lighting, "lobes": ["diffuse", "specular"]}
    still = run(spot, "radiance_scaling", {**base, "gamma_diffuse": 0.0, "gamma_specular": 0.0})
    np.testing.assert_allclose(still.buffers["beauty"], spot.buffers["beauty"], atol=1e-5)
    specular = run(spot, "radiance_scaling", {**base, "gamma_diffuse": 0.0})
    change = np.abs(specular.buffers["beauty"] - spot.buffers["beauty"]).max(axis=-1)
    assert change.max() > 0.01
    assert change[spot.buffers["specular"].max(axis=-1) == 0.0].max() < 1e-5


def test_radiance_scaling_leaves_what_it_does_not_scale_bit_for_bit(spot: Frame) -> None:
    """The pixels Eq. 4 leaves as they were (σ̄ = 1 for every lobe) come out bit for bit with
    the kept lighting too: its gain is exactly 1 there, and the beauty is not rebuilt as a sum
    that only rounds back to it."""
    frame = spot.copy()
    del frame.buffers["ambient"]  # (beauty = Σ lobes + a remainder, as in a path-traced frame)
    plain = run(frame, "radiance_scaling", {"keep_lighting": False})
    kept = run(frame, "radiance_scaling")
    left = (plain.buffers["beauty"] == frame.buffers["beauty"]).all(axis=-1) & covered(frame)
    assert left.sum() > 500 and (~left & covered(frame)).sum() > 500
    np.testing.assert_array_equal(kept.buffers["beauty"][left], frame.buffers["beauty"][left])


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


# -- unsharp_masking ----------------------------------------------------------------------------


def test_unsharp_amount_zero_is_the_identity(spot: Frame) -> None:
    out = run(spot, "unsharp_masking", {"amount": 0.0})
    np.testing.assert_array_equal(out.buffers["beauty"], spot.buffers["beauty"])
    changed = run(spot, "unsharp_masking", {"amount": 1.5})
    assert np.abs(changed.buffers["beauty"] - spot.buffers["beauty"]).max() > 0.02


@pytest.mark.parametrize("name", ["gain", "gain.X"])
def test_zero_gain_map_layer_is_the_identity(spot: Frame, name: str) -> None:
    frame = spot.copy()
    frame.outputs["gain.X"] = np.zeros(spot.shape, np.float32)
    out = run(frame, "unsharp_masking", {"gain_map": name, "amount": 2.0})
    np.testing.assert_array_equal(out.buffers["beauty"], spot.buffers["beauty"])
    frame.outputs["gain.X"] = np.ones(spot.shape, np.float32)
    ones = run(frame, "unsharp_masking", {"gain_map": name, "amount": 2.0})
    plain = run(spot, "unsharp_masking", {"amount": 2.0})
    np.testing.assert_allclose(ones.buffers["beauty"], plain.buffers["beauty"], atol=1e-5)


def test_gain_map_image_file(spot: Frame, tmp_path: Path) -> None:
    path = tmp_path / "gain.png"
    cv2.imwrite(str(path), np.zeros((30, 40), np.uint8))
    out = run(spot, "unsharp_masking", {"gain_map": str(path), "amount": 2.0})
    np.testing.assert_array_equal(out.buffers["beauty"], spot.buffers["beauty"])
    with pytest.raises(PipelineError, match="gain_map"):
        run(
            spot,
            "unsharp_masking",
            {"gain_map": str(path), "amount": 2.0},
            context=Context(files=False),
        )
    with pytest.raises(PipelineError, match="gain_map"):
        run(spot, "unsharp_masking", {"gain_map": "nolayer"}, context=Context(files=False))


def test_unsharp_on_the_diffuse_lobe_changes_only_by_that_lobe(spot: Frame) -> None:
    out = run(spot, "unsharp_masking", {"signal": "diffuse", "amount": 2.0})
    d_change = out.buffers["diffuse"] - spot.buffers["diffuse"]
    assert np.abs(d_change).max() > 0.02
    np.testing.assert_allclose(out.buffers["beauty"] - spot.buffers["beauty"], d_change, atol=1e-5)
    for lobe in ("ambient", "specular"):
        np.testing.assert_array_equal(out.buffers[lobe], spot.buffers[lobe])
    np.testing.assert_allclose(remainder(out), remainder(spot), atol=1e-5)


def test_unsharp_without_camera(spot: Frame) -> None:
    frame = spot.copy()
    frame.camera = None
    out = run(frame, "unsharp_masking", {"amount": 1.5})  # sigma 'auto' needs no camera
    assert np.abs(out.buffers["beauty"] - spot.buffers["beauty"]).max() > 0.02
    # documented: a 40° field of view is assumed in its place
    assert spot.camera is not None
    nominal = spot.copy()
    nominal.camera = dataclasses.replace(spot.camera, fov_y_deg=40.0)
    same = run(nominal, "unsharp_masking", {"amount": 1.5})
    np.testing.assert_allclose(out.buffers["beauty"], same.buffers["beauty"], atol=1e-6)
    with pytest.raises(MissingCameraError, match="camera"):
        run(frame, "unsharp_masking", {"sigma": 0.05})


def test_unsharp_measures_and_reuses_pinned_statistics(spot: Frame) -> None:
    ctx = Context()
    first = run(spot, "unsharp_masking", {"amount": 1.5}, context=ctx)
    assert set(ctx.measured) == {"unsharp_masking.sigma", "unsharp_masking.white.beauty"}
    pinned = Context(pinned=dict(ctx.measured))
    again = run(spot, "unsharp_masking", {"amount": 1.5}, context=pinned)
    np.testing.assert_array_equal(again.buffers["beauty"], first.buffers["beauty"])
    assert pinned.measured == {}
    explicit = run(
        spot,
        "unsharp_masking",
        {
            "amount": 1.5,
            "sigma": ctx.measured["unsharp_masking.sigma"],
            "white": ctx.measured["unsharp_masking.white.beauty"],
        },
    )
    np.testing.assert_allclose(explicit.buffers["beauty"], first.buffers["beauty"], atol=1e-6)


def test_unsharp_shadows_signal(spot: Frame) -> None:
    with pytest.raises(PipelineError, match="unlit"):
        run(spot, "unsharp_masking", {"signal": "shadows"})
    with pytest.raises(PipelineError, match="unlit"):
        run(spot, "unsharp_masking", {"signal": "shadows", "unlit": "nolayer"})
    frame = spot.copy()  # no shadows at all: T = 1 everywhere, nothing to enhance
    frame.set_layer("unlit", {c: spot.buffers["beauty"][..., i] for i, c in enumerate("RGB")})
    out = run(frame, "unsharp_masking", {"signal": "shadows", "unlit": "unlit", "amount": 2.0})
    np.testing.assert_allclose(out.buffers["beauty"], spot.buffers["beauty"], atol=1e-5)


def test_unsharp_bad_parameters(spot: Frame) -> None:
    for params, name in (
        ({"sigma": -1.0}, "sigma"),
        ({"amount": 11}, "amount"),
        ({"signal": "glossy"}, "signal"),
        ({"white": 0.0}, "white"),
    ):
        with pytest.raises(PipelineError, match=name):
            run(spot, "unsharp_masking", params)
    frame = spot.copy()
    del frame.buffers["diffuse"]
    with pytest.raises(MissingBufferError, match="diffuse"):
        run(frame, "unsharp_masking", {"signal": "diffuse"})


# -- depth_unsharp_masking ----------------------------------------------------------------------


def test_depth_unsharp_masking_only_darkens_near_depth_steps(spot: Frame) -> None:
    out = run(spot, "depth_unsharp_masking", {"amount": 2.0})
    diff = out.buffers["beauty"] - spot.buffers["beauty"]
    assert diff.max() <= 1e-5  # mode darken: values only go down
    darker = (diff < -0.02).any(axis=-1)
    assert darker.sum() > 20
    # the darkened pixels lie behind a closer surface (a silhouette) within a few σ
    depth = np.where(np.isfinite(spot.buffers["depth"]), spot.buffers["depth"], 1e6)
    k = 2 * int(3 * 0.02 * HEIGHT) + 1
    nearest = cv2.erode(depth.astype(np.float32), np.ones((k, k), np.uint8))
    behind = nearest < depth * 0.99
    assert behind[darker].mean() > 0.98
    np.testing.assert_array_equal(diff[~covered(spot)], 0.0)  # the background is kept
    # mode both also brightens, e.g. the rims in front of the (far) background
    both = run(spot, "depth_unsharp_masking", {"amount": 2.0, "mode": "both"})
    rim = cv2.dilate((~covered(spot)).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    rim &= covered(spot)
    brighter = ((both.buffers["beauty"] - spot.buffers["beauty"]) > 0.02).any(axis=-1)
    assert brighter[rim].mean() > 0.5
    zero = run(spot, "depth_unsharp_masking", {"amount": 0.0})
    np.testing.assert_allclose(zero.buffers["beauty"], spot.buffers["beauty"], atol=1e-5)


# -- apparent_relief ----------------------------------------------------------------------------


@pytest.mark.parametrize("style", ["cel", "counter", "xtoon", "descriptor"])
def test_every_relief_style_runs(spot: Frame, style: str) -> None:
    out = run(spot, "apparent_relief", {"style": style}, debug_layers=True)
    cov = covered(spot)
    beauty = out.buffers["beauty"]
    assert beauty.shape == spot.buffers["beauty"].shape and beauty.dtype == np.float32
    assert np.all(np.isfinite(beauty))
    np.testing.assert_array_equal(beauty[~cov], spot.buffers["beauty"][~cov])
    r = out.outputs["relief.X"]
    assert r.shape == spot.shape and 0.0 <= r.min() and r.max() <= 1.0
    s = field(out, "relief.S", "XY")
    assert np.linalg.norm(s, axis=-1).max() <= 1.0 + 1e-5
    assert {"relief.color.R", "relief.color.G", "relief.color.B"} <= set(out.outputs)
    if style == "cel":
        np.testing.assert_allclose(beauty[cov], np.repeat(r[cov][:, None], 3, axis=1), atol=1e-6)
    if style == "counter":
        assert set(np.unique(beauty[cov]).tolist()) == {0.0, 1.0}
    if style in ("xtoon", "descriptor"):
        assert np.unique(beauty[cov].reshape(-1, 3), axis=0).shape[0] > 10


def test_relief_debug_layers_only_when_asked(spot: Frame) -> None:
    out = run(spot, "apparent_relief")
    assert not any(n.startswith("relief.color") for n in out.outputs)
    assert {"relief.X", "relief.S.X", "relief.S.Y"} <= set(out.outputs)


def test_relief_mask_blends_the_effect(spot: Frame) -> None:
    params = {"style": "mask", "effect": {"op": "exaggerated_shading"}}
    out = run(spot, "apparent_relief", params)
    effect = run(spot, "exaggerated_shading").buffers["beauty"]
    before = spot.buffers["beauty"]
    r = out.outputs["relief.X"]
    cov = covered(spot)
    zero, one = cov & (r == 0.0), cov & (r == 1.0)
    assert zero.sum() > 10 and one.sum() > 5
    np.testing.assert_allclose(out.buffers["beauty"][zero], before[zero], atol=1e-6)
    np.testing.assert_allclose(out.buffers["beauty"][one], effect[one], atol=1e-5)
    blend = before + r[..., None] * (effect - before)
    np.testing.assert_allclose(out.buffers["beauty"][cov], blend[cov], atol=1e-5)
    with pytest.raises(PipelineError, match="effect"):
        run(spot, "apparent_relief", {"style": "mask"})
    with pytest.raises(PipelineError, match="apparent_relief"):
        run(spot, "apparent_relief", {"style": "mask", "effect": {"op": "apparent_relief"}})
    with pytest.raises(PipelineError, match="unknown operator"):
        run(spot, "apparent_relief", {"style": "mask", "effect": {"op": "nope"}})


def test_relief_curvedness_norm_is_measured_and_pinned(spot: Frame) -> None:
    key = "apparent_relief.curvedness_norm"
    ctx = Context()
    auto = run(spot, "apparent_relief", context=ctx)
    assert ctx.measured[key] > 0.0
    norm = 2.0 * ctx.measured[key]
    pinned_ctx = Context(pinned={key: norm})
    pinned = run(spot, "apparent_relief", context=pinned_ctx)
    assert key not in pinned_ctx.measured
    explicit = run(spot, "apparent_relief", {"curvedness_norm": norm})
    s_auto, s_pinned = field(auto, "relief.S", "XY"), field(pinned, "relief.S", "XY")
    np.testing.assert_allclose(s_pinned, field(explicit, "relief.S", "XY"), atol=1e-6)
    # twice the norm: half the length wherever S is not clamped to the unit disc
    inside = np.linalg.norm(s_auto, axis=-1) < 0.9
    np.testing.assert_allclose(s_pinned[inside], 0.5 * s_auto[inside], atol=1e-5)
    explicit_ctx = Context()
    run(spot, "apparent_relief", {"curvedness_norm": norm}, context=explicit_ctx)
    assert key not in explicit_ctx.measured


def test_relief_arm_from_a_layer_or_an_image(spot: Frame, tmp_path: Path) -> None:
    cov = covered(spot)
    frame = spot.copy()
    frame.outputs["myarm.X"] = np.full(spot.shape, 0.25, np.float32)
    out = run(frame, "apparent_relief", {"arm": "myarm"})
    np.testing.assert_allclose(out.outputs["relief.X"], 0.25, atol=1e-6)
    np.testing.assert_allclose(out.buffers["beauty"][cov], 0.25, atol=1e-6)
    path = tmp_path / "arm.png"
    cv2.imwrite(str(path), np.full((32, 32), 204, np.uint8))
    out = run(spot, "apparent_relief", {"arm": str(path)})
    np.testing.assert_allclose(out.outputs["relief.X"], 0.8, atol=1e-6)
    with pytest.raises(PipelineError, match="arm"):
        run(spot, "apparent_relief", {"arm": str(path)}, context=Context(files=False))
    with pytest.raises(PipelineError, match="toon"):
        run(
            spot,
            "apparent_relief",
            {"style": "xtoon", "toon": str(path)},
            context=Context(files=False),
        )


# -- baselines and congruence -------------------------------------------------------------------


@pytest.mark.parametrize("op", ["exaggerated_shading", "light_warping"])
def test_baselines_differ_from_lambert(spot: Frame, op: str) -> None:
    light = "-0.4,0.6,0.7"
    out = run(spot, op, {"light": light})
    cov = covered(spot)
    lam = shading.lambert(spot.buffers["normal"], np.asarray(parse_light(light).vector, np.float32))
    plain = lam[..., None] * spot.buffers["albedo"]
    assert np.abs(out.buffers["beauty"] - plain)[cov].max() > 0.1
    np.testing.assert_array_equal(out.buffers["beauty"][~cov], spot.buffers["beauty"][~cov])
    assert np.all(np.isfinite(out.buffers["beauty"]))
    # a constant albedo replaces the frame's
    grey = run(spot, op, {"light": light, "albedo": 0.5}).buffers["beauty"]
    np.testing.assert_allclose(grey[cov][:, 0], grey[cov][:, 1], atol=1e-6)
    with pytest.raises(PipelineError, match="light"):
        run(spot, op, {"light": "point:0,1,2"})


def test_congruence_writes_the_score_and_keeps_the_beauty(spot: Frame) -> None:
    out = run(spot, "congruence")
    np.testing.assert_array_equal(out.buffers["beauty"], spot.buffers["beauty"])
    score = out.attributes["depict/congruence"]
    assert isinstance(score, float) and 0.0 <= score <= 1.0
    assert score == pytest.approx(float(score_frame(spot, maps=False)["score"]), abs=1e-6)
    c = out.outputs["congruence.X"]
    assert c.shape == spot.shape and c.min() >= 0.0 and c.max() <= 1.0 and c.max() > 0.1
    for name in ("congruence.weight.X", "congruence.shading.X", "congruence.shape.Y"):
        assert out.outputs[name].shape == spot.shape
    # measuring after an enhancement measures the enhanced beauty
    after = pipeline.run(spot, [{"op": "exaggerated_shading"}, {"op": "congruence"}])
    assert after.attributes["depict/congruence"] != pytest.approx(score, abs=1e-4)


@pytest.mark.parametrize("value", [True, False, [True], [0.5, False]])
def test_no_parameter_reads_true_or_false_as_a_number(value: Any) -> None:
    """Pydantic reads true as 1 and false as 0 for a number: every operator's number parameters
    refuse them (``--set gamma=true`` ran with γ = 1), its switches still take them."""
    from pydantic import ValidationError

    from service.registry import REGISTRY

    refused = 0
    for name, op in REGISTRY.items():
        for field in op.params.model_fields:
            try:
                got = getattr(op.params(**{field: value}), field)
            except ValidationError as exc:
                refused += "expected a number, not true or false" in str(exc)
                continue
            items = got if isinstance(got, list) else [got]  # taken: no number made of it
            assert not any(type(v) in (int, float) for v in items), (name, field, got)
    assert refused > (20 if isinstance(value, bool) else 5)


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
