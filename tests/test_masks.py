"""Masks on pipeline steps (service.masks): a real Blender render with Cryptomatte and index passes
(tests/fixtures/blender/cryptomatte.exr); Radiance Scaling and Light Alignment restricted to
Suzanne change nothing else, bit for bit."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

import gbuffer
from gbuffer.frame import Frame
from service import pipeline
from service.cli import main as cli
from service.masks import blend, matte, parse
from service.registry import Context, PipelineError, operators

FIXTURE = Path(__file__).parent / "fixtures" / "blender" / "cryptomatte.exr"
SUZANNE = "cryptomatte:Suzanne"


@pytest.fixture(scope="module")
def frame() -> Frame:
    if not FIXTURE.is_file():
        pytest.skip(f"{FIXTURE} is absent (tests/fixtures/blender/README.md)")
    return gbuffer.read(FIXTURE)


def run(frame: Frame, op: str, **params: Any) -> Frame:
    return pipeline.run(frame, [{"op": op, "params": params}])


def test_every_operator_takes_the_mask_parameters() -> None:
    for op in operators().values():
        assert {"mask", "mask_feather", "mask_amount", "mask_stats"} <= set(op.params.model_fields)
        schema = op.schema()["params"]["properties"]
        assert "cryptomatte:NAME" in schema["mask"]["description"]


@pytest.mark.parametrize("op", ["radiance_scaling", "light_alignment", "unsharp_masking"])
def test_a_masked_step_changes_only_the_object(frame: Frame, op: str) -> None:
    m = matte(frame, SUZANNE)
    full = run(frame, op)
    masked = run(frame, op, mask=SUZANNE)
    before, after = frame.buffers["beauty"], masked.buffers["beauty"]
    changed = (after != before).any(axis=-1)
    assert changed.sum() > 1000  # the operator did change Suzanne
    assert not changed[m == 0].any()  # and nothing else, bit for bit
    assert (full.buffers["beauty"] != before).any(axis=-1)[m == 0].sum() > 1000
    for name, array in masked.buffers.items():  # every buffer the step rewrote, too
        if name in frame.buffers and frame.buffers[name].shape == array.shape:
            assert np.array_equal(array[m == 0], frame.buffers[name][m == 0]), name
    inside = m >= 1.0  # the step's own result where m = 1
    np.testing.assert_array_equal(after[inside], full.buffers["beauty"][inside])
    edge = (m > 0) & (m < 1)  # and the blend at anti-aliased edges
    expected = before + m[..., None] * (full.buffers["beauty"] - before)
    np.testing.assert_allclose(after[edge], expected[edge], rtol=1e-6, atol=1e-7)


def test_blend_is_exact_at_both_ends() -> None:
    before = np.array([[1.0, 2.0, 3.0]], np.float32)
    after = np.array([[1e30, -7.0, 0.1]], np.float32)
    m = np.array([[0.0, 1.0, 0.25]], np.float32)
    out = blend(before, after, m)
    assert out[0, 0] == 1.0 and out[0, 1] == -7.0
    assert out[0, 2] == pytest.approx(3.0 + 0.25 * (0.1 - 3.0))
    np.testing.assert_array_equal(blend(None, after, m)[0, :2], [0.0, -7.0])


def test_invert_amount_and_feather(frame: Frame) -> None:
    m = matte(frame, SUZANNE)
    np.testing.assert_array_equal(matte(frame, "!" + SUZANNE), 1.0 - m)
    np.testing.assert_array_equal(matte(frame, SUZANNE, amount=0.5), m * np.float32(0.5))
    soft = matte(frame, SUZANNE, feather=0.01)
    sigma = 0.01 * frame.image_height
    expected = cv2.GaussianBlur(m, (0, 0), sigma, borderType=cv2.BORDER_REPLICATE)
    np.testing.assert_allclose(soft, expected, atol=1e-6)
    assert ((soft > 0) & (m == 0)).sum() > 200  # it reaches past the object
    assert soft.sum() == pytest.approx(m.sum(), rel=1e-3)
    lla = run(frame, "light_alignment", mask=SUZANNE, mask_feather=0.01)
    changed = (lla.buffers["beauty"] != frame.buffers["beauty"]).any(axis=-1)
    assert changed[m == 0].sum() > 200 and not changed[soft == 0].any()


def test_index_pass_and_layer_masks(frame: Frame) -> None:
    index = matte(frame, "index:ViewLayer.IndexOB=3")
    np.testing.assert_array_equal(index, frame.layer("ViewLayer.IndexOB")["X"] == 3)
    crypto = matte(frame, SUZANNE)
    assert ((index > 0) == (crypto > 0.5)).mean() > 0.998
    np.testing.assert_array_equal(matte(frame, "index:ViewLayer.IndexOB.X=3,99"), index)
    np.testing.assert_array_equal(matte(frame, "ViewLayer.AO.R"), frame.layer("ViewLayer.AO")["R"])
    np.testing.assert_array_equal(matte(frame, "coverage"), frame.buffers["coverage"])


def test_a_painted_mask_image(frame: Frame, tmp_path: Path) -> None:
    """A grey PNG painted at half the frame's size: resized to it, values scaled to [0, 1]."""
    h, w = frame.shape
    paint = np.zeros((h // 2, w // 2), np.uint8)
    cv2.circle(paint, (w // 4, h // 4), h // 8, 255, -1)
    path = tmp_path / "paint.png"
    cv2.imwrite(str(path), paint)
    m = matte(frame, str(path))
    expected = cv2.resize(paint.astype(np.float32) / 255, (w, h), interpolation=cv2.INTER_LINEAR)
    np.testing.assert_allclose(m, expected, atol=1e-6)
    out = run(frame, "light_alignment", mask=str(path))
    changed = (out.buffers["beauty"] != frame.buffers["beauty"]).any(axis=-1)
    assert changed.sum() > 100 and not changed[m == 0].any()
    with pytest.raises(PipelineError, match="no layer"):  # where files may not be read: HTTP
        pipeline.run(
            frame,
            [{"op": "light_alignment", "params": {"mask": str(path)}}],
            context=Context(files=False),
        )


def test_a_mask_from_an_earlier_step_output(frame: Frame) -> None:
    """Layers written by an earlier step are masks too (the curvature's mean curvature here)."""
    out = pipeline.run(
        frame,
        [{"op": "curvature"}, {"op": "radiance_scaling", "params": {"mask": "curvature.H"}}],
    )
    h = np.clip(out.layer("curvature")["H"], 0, 1)
    changed = (out.buffers["beauty"] != frame.buffers["beauty"]).any(axis=-1)
    assert changed.any() and not changed[h == 0].any()


@pytest.mark.parametrize("op", ["radiance_scaling", "unsharp_masking"])
def test_mask_stats_measure_inside_the_mask(frame: Frame, op: str) -> None:
    def white(**params: Any) -> dict[str, float]:
        context = Context()
        pipeline.run(frame, [{"op": op, "params": params}], context=context)
        return {k: v for k, v in context.measured.items() if ".white." in k}

    whole = white()
    assert whole and white(mask=SUZANNE) == whole  # the statistics of the whole frame unless asked
    hero = white(mask=SUZANNE, mask_stats=True)
    assert hero.keys() == whole.keys() and hero != whole
    assert white(mask="!cryptomatte:Nothing*,EmitCube", mask_stats=True) != hero
    everywhere = white(mask="!cryptomatte:EmitCube", mask_amount=1.0, mask_stats=True)
    assert everywhere != whole  # the emitter no longer counts


def test_congruence_of_one_object(frame: Frame) -> None:
    def score(**params: Any) -> float:
        out = pipeline.run(frame, [{"op": "congruence", "params": params}])
        return float(out.attributes["depict/congruence"])

    whole = score()  # (a score moves by ~1e-12 with the arrays' memory layout)
    assert score(mask=SUZANNE) == pytest.approx(whole, rel=1e-9)  # the frame's score
    hero = score(mask=SUZANNE, mask_stats=True)
    assert hero != pytest.approx(whole, rel=1e-3) and 0.0 < hero < 1.0
    assert score(mask="coverage", mask_stats=True) == pytest.approx(whole, rel=1e-9)


@pytest.mark.parametrize(
    ("spec", "words"),
    [
        ("cryptomatte:Nope", "no Cryptomatte name matches 'Nope'"),
        ("cryptomatte/CryptoAsset:Suzanne", "no Cryptomatte layer 'CryptoAsset'"),
        ("ViewLayer.Nope", "no layer 'ViewLayer.Nope'"),
        ("index:ViewLayer.Nope=3", "no layer 'ViewLayer.Nope'"),
    ],
)
def test_unknown_names_are_one_clear_error(frame: Frame, spec: str, words: str) -> None:
    with pytest.raises(PipelineError, match=words):
        run(frame, "radiance_scaling", mask=spec)


@pytest.mark.parametrize("spec", ["", "!", "index:IndexOB", "index:IndexOB=x", "cryptomatte:"])
def test_bad_syntax_is_refused_before_any_pixel(spec: str) -> None:
    with pytest.raises(ValueError, match="mask"):
        parse(spec)
    with pytest.raises(PipelineError, match="mask"):
        pipeline.compile([{"op": "radiance_scaling", "params": {"mask": spec}}])


def test_cli_mask_preview_inspect_and_enhance(
    frame: Frame, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    png = tmp_path / "m.png"
    assert cli(["mask", str(FIXTURE), "cryptomatte:Suz*", "-o", str(png)]) == 0
    m = matte(frame, SUZANNE)
    written = cv2.imread(str(png), cv2.IMREAD_GRAYSCALE)
    assert (written == 255).sum() == (m >= 1.0).sum() and (written == 0).sum() == (m == 0).sum()
    assert f"{int((m >= 1).sum())} pixels inside" in capsys.readouterr().out
    ids = tmp_path / "ids.png"
    assert cli(["preview", str(FIXTURE), "--layer", "cryptomatte", "-o", str(ids)]) == 0
    assert len(np.unique(cv2.imread(str(ids)).reshape(-1, 3), axis=0)) > 6
    assert cli(["inspect", str(FIXTURE)]) == 0
    text = capsys.readouterr().out
    assert "cryptomatte ViewLayer.CryptoObject (4 ranks): Ground" in text and "Suzanne (" in text
    out = tmp_path / "out.exr"
    args = ["enhance", str(FIXTURE), "-o", str(out), "--op", "radiance_scaling"]
    assert cli([*args, "--set", "mask=cryptomatte:Suzanne,Torus"]) == 0
    result = gbuffer.read(out)  # the Blender file's result layer
    before = frame.buffers["beauty"]
    after = np.dstack([result.layer("ViewLayer.Depict")[c] for c in "RGB"])
    keep = matte(frame, "cryptomatte:Suzanne,Torus") == 0
    assert np.array_equal(after[keep], before[keep]) and (after != before).any()


def test_cli_unknown_name_exits_2_with_one_line(
    frame: Frame, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out.exr"
    args = ["enhance", str(FIXTURE), "-o", str(out), "--op", "light_alignment"]
    assert cli([*args, "--set", "mask=cryptomatte:Nope"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no Cryptomatte name matches 'Nope'" in err
    assert "Traceback" not in err and not out.exists()


@pytest.mark.parametrize(
    ("spec", "words"),
    [
        (
            "cryptomatte:Suzanne,Suzane",
            "radiance_scaling: mask 'cryptomatte:Suzanne,Suzane': no name of "
            "ViewLayer.CryptoObject matches 'Suzane'; the others are used",
        ),
        (
            "index:ViewLayer.IndexOB.X=99",
            "radiance_scaling: mask 'index:ViewLayer.IndexOB.X=99' selects no pixel: the step "
            "changed nothing",
        ),
    ],
)
def test_a_mask_that_misses_is_said(
    frame: Frame, spec: str, words: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A misspelt name among others that match, or an index no pixel holds, ran without a word
    (a whole misspelt mask is refused: test_unknown_names_are_one_clear_error)."""
    context = Context()
    pipeline.run(frame, [{"op": "radiance_scaling", "params": {"mask": spec}}], context=context)
    assert context.warnings == [words]
    out = tmp_path / "out.exr"
    args = ["enhance", str(FIXTURE), "-o", str(out), "--op", "radiance_scaling"]
    assert cli([*args, "--set", f"mask={spec}"]) == 0
    assert f"depict: warning: {words}\n" in capsys.readouterr().err
    assert cli(["score", str(FIXTURE), "--op", "radiance_scaling", "--set", f"mask={spec}"]) == 0
    assert f"depict: warning: {words}\n" in capsys.readouterr().err
