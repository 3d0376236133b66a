"""The operators of service/operators/ through ``service.pipeline.run`` (Light Alignment:
tests/test_light_alignment_operator.py).

On a small OSMesa render of examples/spot.obj (lobes, albedo, AO, a perspective camera) and on
analytic G-buffers (tests/analytic.py) where an exact answer is known.
"""

from __future__ import annotations

import dataclasses
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
from ops.shading import parse_light
from service import pipeline
from service.registry import Context, PipelineError

SPOT = Path(__file__).resolve().parents[1] / "examples" / "spot.obj"
WIDTH, HEIGHT = 160, 120


def spot_frame() -> Frame:
    """A real render with ambient / diffuse / specular lobes, albedo, AO and a camera."""
    return frame_from_mesh(SPOT, WIDTH, HEIGHT)


@pytest.fixture(scope="module")
def spot() -> Frame:
    return spot_frame()


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


# -- radiance_scaling ------------------------------------------------------------------------------


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


def test_a_list_parameter_given_one_value_is_that_one_item() -> None:
    """``--set lobes=transmission`` (one value, not split at commas) was refused as "Input
    should be a valid list"."""
    from service.registry import get

    assert get("radiance_scaling").parse({"lobes": "diffuse"}).lobes == ["diffuse"]
    la = get("light_alignment")
    assert la.parse({"components": "specular"}).components == ["specular"]
    assert la.parse({"sigmas": 0.5}).sigmas == [0.5]
    with pytest.raises(PipelineError, match="lobes=True: Input should be a valid list"):
        get("radiance_scaling").parse({"lobes": True})


def test_a_number_or_a_word_has_its_range_in_the_schema_and_one_message() -> None:
    """``white``, ``sigma``, ``curvedness_norm``, ``roughness``: a number or a word (``auto``,
    ``frame``). Their ranges were checked but not in ``/v1/operators``' schemas, and a value
    refused was said once per member of the union (``white.constrained-float=…; white.literal
    ['auto']=…``)."""
    from service.registry import get

    for op, name, bound in (
        ("unsharp_masking", "white", "minimum"),
        ("unsharp_masking", "sigma", "exclusiveMinimum"),
        ("apparent_relief", "curvedness_norm", "minimum"),
        ("light_alignment", "roughness", "maximum"),
    ):
        spec = get(op).params.model_json_schema()["properties"][name]
        assert any(bound in part for part in spec["anyOf"]), spec
    for value, words in (("abc", "a number or 'auto'"), (1e-40, "greater than or equal to 1e-30")):
        with pytest.raises(PipelineError) as refused:
            get("unsharp_masking").parse({"white": value})
        assert str(refused.value) == (
            f"unsharp_masking: white={value!r}: Input should be {words} (linear white level of "
            "CIELAB (auto: 99th percentile; pin it))"
        )


def test_a_parameter_named_as_a_type_is_named_in_its_error() -> None:
    """Only a union's member right after its parameter is left out of where an error is."""
    from service.registry import get

    with pytest.raises(PipelineError, match="unknown parameter 'float'"):
        get("radiance_scaling").parse({"float": 3})
