"""Colour management: each frame's working space, and every colour computation in it.

Real files: the Blender fixture (linear Rec.709), its ACEScg copy (every colour converted by
OpenColorIO, ``chromaticities`` = AP1) and colour charts; OCIO's built-in studio config.
"""

from __future__ import annotations

import io
import json
import os
from contextlib import redirect_stdout
from pathlib import Path

import cv2
import numpy as np
import OpenEXR
import PyOpenColorIO as ocio
import pytest

import gbuffer
from analysis.score import score_frame
from gbuffer.colorspace import View, named
from gbuffer.errors import FrameError
from gbuffer.preview import display_encode, picture, srgb_encode
from ops import radiance_scaling as rs
from ops.color import lightness, luminance, rgb_to_lab
from ops.colorspace import (
    ACES_AP1,
    LINEAR_REC709,
    REC709_RGB_TO_XYZ,
    conversion,
    convert,
    from_chromaticities,
    rgb_to_xyz,
)
from service import pipeline
from service.cli import main
from service.images import load_image
from tests.colour_files import (
    MACBETH_SRGB,
    acescg_copy,
    chart,
    ocio_convert,
    space_copy,
    srgb_decode,
)

FIXTURE = Path(__file__).parent / "fixtures" / "blender" / "cycles_multilayer.exr"
ACESCG = from_chromaticities("ACEScg", ACES_AP1, "test")


@pytest.fixture(scope="module")
def pair(tmp_path_factory: pytest.TempPathFactory) -> tuple[gbuffer.Frame, gbuffer.Frame]:
    """The Blender fixture read as it is (Rec.709) and from its ACEScg copy."""
    path = tmp_path_factory.mktemp("colour") / "acescg.exr"
    acescg_copy(FIXTURE, path)
    return gbuffer.read(FIXTURE), gbuffer.read(path)


def _cli(*args: str) -> tuple[int, str]:
    """``depict ARGS``: (exit code, stdout)."""
    out = io.StringIO()
    with redirect_stdout(out):
        try:
            code = main(list(args))
        except SystemExit as exc:
            code = int(exc.code or 0)
    return code, out.getvalue()


# -- spaces -------------------------------------------------------------------------------------


def test_chromaticities_give_the_standard_matrices() -> None:
    """Rec.709 is IEC 61966-2-1's matrix bit for bit; AP1's Y row is ACES TB-2014-004's."""
    assert np.array_equal(
        rgb_to_xyz((0.64, 0.33, 0.3, 0.6, 0.15, 0.06, 0.3127, 0.329)), REC709_RGB_TO_XYZ
    )
    np.testing.assert_allclose(ACESCG.weights, [0.2722287, 0.6740818, 0.0536895], atol=1e-6)
    np.testing.assert_allclose(ACESCG.white[:2] / ACESCG.white.sum(), [0.32168, 0.33767], atol=1e-6)


def test_conversion_matches_opencolorio() -> None:
    """Rec.709 -> ACEScg with Bradford adaptation, as the studio config does it (to its
    published matrices' rounding)."""
    ours = conversion(LINEAR_REC709, ACESCG)
    theirs = ocio_convert(np.eye(3, dtype=np.float32)[None], "lin_rec709", "ACEScg")[0].T
    np.testing.assert_allclose(ours, theirs, atol=1e-4)


def test_each_frame_names_its_space_and_where_it_came_from(
    pair: tuple[gbuffer.Frame, gbuffer.Frame], tmp_path: Path
) -> None:
    rec709, acescg = pair
    assert (rec709.colorspace.name, rec709.colorspace.source) == (
        "Linear Rec.709 (sRGB)",
        "preset default (blender)",
    )
    assert (acescg.colorspace.name, acescg.colorspace.source) == (
        "ACEScg",
        "chromaticities attribute",
    )
    forced = gbuffer.read(FIXTURE, options={"colorspace": "ACEScg"})
    assert (forced.colorspace.name, forced.colorspace.source) == ("ACEScg", "--colorspace")
    chart(np.full((2, 3), 0.5), tmp_path / "plain.exr")
    plain = gbuffer.read(tmp_path / "plain.exr")
    assert (plain.preset, plain.colorspace.source) == ("canonical", "default")
    channels = {c: np.full((4, 4), 0.5, np.float32) for c in "RGB"}
    OpenEXR.File({"colorInteropID": "lin_ap1_scene"}, channels).write(str(tmp_path / "id.exr"))
    tagged = gbuffer.read(tmp_path / "id.exr").colorspace
    assert (tagged.name, tagged.source) == ("ACEScg", "colorInteropID attribute")
    acescg_copy(FIXTURE, tmp_path / "acescg.exr")
    code, text = _cli("inspect", str(tmp_path / "acescg.exr"))
    assert code == 0
    assert "colour space: ACEScg (from chromaticities attribute; luminance weights 0.2722" in text
    code, text = _cli("inspect", str(FIXTURE), "--json", "--colorspace", "lin_rec709")
    info = json.loads(text)["colorspace"]
    assert (info["name"], info["source"]) == ("Linear Rec.709 (sRGB)", "--colorspace")


def test_an_output_records_the_space_the_user_named(tmp_path: Path) -> None:
    out = tmp_path / "out.exr"
    assert _cli("enhance", str(FIXTURE), "-o", str(out), "--colorspace", "ACEScg")[0] == 0
    # the default layout adds a part: every part carries the new chromaticities (OpenEXR's
    # shared attributes), or no reader opens the file
    with OpenEXR.File(str(out)) as f:
        assert len({tuple(p.header["chromaticities"]) for p in f.parts}) == 1 < len(f.parts)
    space = gbuffer.read(out).colorspace
    assert (space.name, space.source) == ("ACEScg", "chromaticities attribute")
    np.testing.assert_allclose(space.matrix, ACESCG.matrix, atol=1e-6)


@pytest.mark.parametrize(
    ("name", "word"),
    [("no-such-space", "is not in the OCIO config"), ("srgb_tx", "is not linear")],
)
def test_a_bad_colorspace_is_one_line_and_exit_2(
    name: str, word: str, capsys: pytest.CaptureFixture[str]
) -> None:
    code, _ = _cli("inspect", str(FIXTURE), "--colorspace", name)
    err = capsys.readouterr().err
    assert code == 2
    assert word in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_the_config_in_ocio_is_used(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """$OCIO names the config: its displays and spaces, not the built-in studio config's."""
    path = tmp_path / "raw.ocio"
    path.write_text(ocio.Config.CreateRaw().serialize())
    monkeypatch.setenv("OCIO", str(path))
    assert View().resolved() == ("sRGB", "Raw")
    assert named("ACEScg").name == "ACEScg"  # standard chromaticities need no config
    with pytest.raises(FrameError, match=r"not in the OCIO config .*raw\.ocio"):
        named("lin_rec709")
    with pytest.raises(FrameError, match="not a scene-referred colour space"):
        named("raw")


@pytest.mark.parametrize("kind", ["missing", "fifo", "folder", "garbage"])
def test_an_unusable_ocio_config_is_one_line_and_exit_2(
    kind: str,
    monkeypatch: pytest.MonkeyPatch,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """$OCIO naming no file (OpenColorIO's ExceptionMissingFile is no ocio.Exception), a FIFO
    (OpenColorIO would wait for a writer for ever), a folder or a file that is no config."""
    path = tmp_path / f"{kind}.ocio"
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "folder":
        path.mkdir()
    elif kind == "garbage":
        path.write_text("ocio_profile_version: [\n")
    monkeypatch.setenv("OCIO", str(path))
    code, _ = _cli("preview", str(FIXTURE), "-o", str(tmp_path / "p.png"))
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.startswith(f"depict: error: cannot load the OCIO config {str(path)!r}: "), err
    assert len(err.strip().splitlines()) == 1
    assert not (tmp_path / "p.png").exists()


@pytest.mark.parametrize(
    ("attribute", "value", "words"),
    [
        ("chromaticities", (0.0,) * 8, "the file's chromaticities attribute is unusable"),
        ("colorInteropID", "nope_scene", "colour space 'nope_scene' is not in the OCIO config"),
        ("colorInteropID", "srgb_rec709_scene", "is not linear"),
    ],
)
def test_inspect_describes_a_file_whose_colour_attribute_is_unusable(
    attribute: str,
    value: object,
    words: str,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """``depict inspect`` never refuses a file whose header reads: the colour attribute it
    cannot use is a warning, the file described in the preset's space; enhancing it is
    refused in one line (it would be enhanced in a space the file does not say)."""
    with OpenEXR.File(str(FIXTURE), separate_channels=True) as f:
        header = dict(f.header())
        chans = {name: c.pixels.copy() for name, c in f.channels().items()}
    header.pop("chromaticities", None)
    header[attribute] = value
    path = tmp_path / "odd.exr"
    OpenEXR.File(header, chans).write(str(path))
    code, out = _cli("inspect", str(path))
    assert code == 0, capsys.readouterr().err
    assert words in out and "the preset's working space" in out
    assert "beauty" in out  # (its buffers described, not only its header)
    code, _ = _cli("enhance", str(path), "-o", str(tmp_path / "o.exr"))
    err = capsys.readouterr().err
    assert code == 2 and words in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o.exr").exists()


# -- a colour chart -----------------------------------------------------------------------------

#: sRGB 8-bit colours and their CIELAB (D65, white = 1), as published for sRGB (Lindbloom).
KNOWN_LAB = {
    (255, 0, 0): (53.2408, 80.0925, 67.2032),
    (0, 255, 0): (87.7347, -86.1827, 83.1793),
    (0, 0, 255): (32.2970, 79.1875, -107.8602),
    (255, 255, 0): (97.1393, -21.5537, 94.4780),
    (0, 255, 255): (91.1132, -48.0875, -14.1312),
    (255, 0, 255): (60.3242, 98.2343, -60.8249),
    (128, 128, 128): (53.5850, 0.0, 0.0),
}


def test_known_colours_come_back_from_a_chart_file(tmp_path: Path) -> None:
    srgb = np.array(list(KNOWN_LAB), np.float64)
    chart(srgb_decode(srgb), tmp_path / "chart.exr")
    frame = gbuffer.read(tmp_path / "chart.exr")
    patches = frame.buffers["beauty"][8, 8::16][None]
    lab = rgb_to_lab(patches, 1.0, frame.colorspace.matrix)[0]
    np.testing.assert_allclose(lab, np.array(list(KNOWN_LAB.values())), atol=0.01)
    y = luminance(patches, frame.colorspace.weights)[0]
    np.testing.assert_allclose(y[:3], [0.2126, 0.7152, 0.0722], atol=1e-6)


def test_a_colour_checker_in_acescg_has_the_same_lightness(tmp_path: Path) -> None:
    """The 24 ColorChecker patches stored in Rec.709 and in ACEScg: luminance within 2 %, L*
    within 0.3 (Bradford adaptation between the whites is not exactly Y-preserving)."""
    linear = srgb_decode(MACBETH_SRGB)
    chart(linear, tmp_path / "rec709.exr")
    chart(ocio_convert(linear, "lin_rec709", "ACEScg"), tmp_path / "acescg.exr", ACES_AP1)
    values = {}
    for name in ("rec709", "acescg"):
        frame = gbuffer.read(tmp_path / f"{name}.exr")
        patches = np.ascontiguousarray(frame.buffers["beauty"][8, 8::16][None])
        space = frame.colorspace
        values[name] = (
            luminance(patches, space.weights)[0],
            lightness(patches, 1.0, rgb_to_xyz=space.matrix)[0],
        )
    (y0, l0), (y1, l1) = values["rec709"], values["acescg"]
    np.testing.assert_allclose(y1, y0, rtol=0.02)
    np.testing.assert_allclose(l1, l0, atol=0.3)
    # the same numbers read as if they were Rec.709 (no colour management) are far off
    raw = gbuffer.read(tmp_path / "acescg.exr").buffers["beauty"][8, 8::16][None]
    wrong = lightness(np.ascontiguousarray(raw))[0]
    assert np.abs(wrong - l0).max() > 1.0


# -- operators and the score ---------------------------------------------------------------------

STEPS = [
    {"op": "radiance_scaling"},
    {"op": "radiance_scaling", "params": {"scenario": "beauty"}},
    {"op": "radiance_scaling", "params": {"scenario": "lit_sphere"}},  # the built-in matcap
    {"op": "radiance_scaling", "params": {"scenario": "mirror"}},  # the built-in sky
    {"op": "unsharp_masking"},
    {"op": "light_alignment"},
    {"op": "depth_unsharp_masking"},
]


def _change(before: gbuffer.Frame, step: dict[str, object]) -> np.ndarray:
    """The operator's change to the beauty, in linear Rec.709 (converted back by OCIO)."""
    after = pipeline.run(before, [step]).buffers["beauty"]
    if before.colorspace.name == "ACEScg":
        back = ocio_convert(after, "ACEScg", "lin_rec709")
        return back - ocio_convert(before.buffers["beauty"], "ACEScg", "lin_rec709")
    return after - before.buffers["beauty"]


@pytest.mark.parametrize("step", STEPS, ids=lambda s: json.dumps(s.get("params", s["op"])))
def test_rec709_and_acescg_copies_enhance_the_same(
    pair: tuple[gbuffer.Frame, gbuffer.Frame], step: dict[str, object]
) -> None:
    rec709, acescg = pair
    covered = rec709.mask > 0
    d0, d1 = _change(rec709, step)[covered], _change(acescg, step)[covered]
    assert np.abs(d0).mean() > 1e-4  # the operator did change the picture
    disagreement = np.abs(d1 - d0).sum() / np.abs(d0).sum()
    assert disagreement < 0.03, f"{step}: the changes differ by {disagreement:.1%}"


def test_a_matcap_file_shades_both_copies_alike(
    pair: tuple[gbuffer.Frame, gbuffer.Frame], tmp_path: Path
) -> None:
    """An 8-bit sRGB matcap (warm and saturated) is converted into each frame's space."""
    sphere = np.clip(rs.studio_matcap(64) * np.array([1.0, 0.6, 0.3], np.float32), 0.0, 1.0)
    encoded = np.where(sphere <= 0.0031308, 12.92 * sphere, 1.055 * sphere ** (1 / 2.4) - 0.055)
    cv2.imwrite(str(tmp_path / "warm.png"), np.round(encoded[..., ::-1] * 255).astype(np.uint8))
    step = {
        "op": "radiance_scaling",
        "params": {"scenario": "lit_sphere", "matcap": str(tmp_path / "warm.png")},
    }
    rec709, acescg = pair
    covered = rec709.mask > 0
    d0, d1 = _change(rec709, step)[covered], _change(acescg, step)[covered]
    assert np.abs(d1 - d0).sum() / np.abs(d0).sum() < 0.03


def test_rec709_and_acescg_copies_score_the_same(
    pair: tuple[gbuffer.Frame, gbuffer.Frame],
) -> None:
    rec709, acescg = pair
    assert abs(score_frame(rec709)["score"] - score_frame(acescg)["score"]) <= 0.005


# -- previews -----------------------------------------------------------------------------------


@pytest.mark.parametrize("view", [View(), View(view="raw"), View("Display P3 - Display")])
def test_rec709_and_acescg_copies_preview_alike(
    pair: tuple[gbuffer.Frame, gbuffer.Frame], view: View
) -> None:
    a, b = (np.round(picture(f, "beauty", 0.0, view) * 255.0) for f in pair)
    assert float(np.percentile(np.abs(a - b), 99)) <= 2.0


def test_a_space_the_config_lacks_previews_through_aces2065(
    pair: tuple[gbuffer.Frame, gbuffer.Frame],
) -> None:
    """Primaries of no config space (Rec.2020's, nudged) reach the view through ACES2065-1."""
    rec709 = pair[0]
    odd = from_chromaticities("odd", (0.70, 0.29, 0.18, 0.79, 0.13, 0.05, 0.3127, 0.329), "test")
    other = rec709.copy()
    other.buffers["beauty"] = convert(rec709.buffers["beauty"], LINEAR_REC709, odd)
    other.colorspace = odd
    a, b = (np.round(picture(f, "beauty", 0.0, View()) * 255.0) for f in (rec709, other))
    assert float(np.percentile(np.abs(a - b), 99)) <= 2.0


def test_the_raw_view_is_the_former_exposure_and_clip(
    pair: tuple[gbuffer.Frame, gbuffer.Frame],
) -> None:
    rec709 = pair[0]
    raw = picture(rec709, "beauty", 1.5, View(view="raw"))
    assert np.array_equal(raw, srgb_encode(rec709.buffers["beauty"], 1.5))


def test_the_view_transform_keeps_highlights_the_clip_loses() -> None:
    """Radiance 1..16 (HDR): the hard clip makes it all white; the ACES view keeps it graded."""
    ramp = np.geomspace(1.0, 16.0, 64, dtype=np.float32)[None, :, None].repeat(3, axis=2)
    clipped = display_encode(ramp, LINEAR_REC709, View(view="raw"))
    viewed = display_encode(ramp, LINEAR_REC709, View())
    assert np.all(clipped > 0.999)
    assert np.all(np.diff(viewed[0, :, 1]) > 0) and viewed.max() < 1.0


def test_an_unknown_display_is_refused(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    code, _ = _cli("preview", str(FIXTURE), "-o", str(tmp_path / "p.png"), "--display", "nope")
    assert code == 2
    assert "display 'nope' is not in the OCIO config" in capsys.readouterr().err
    assert not (tmp_path / "p.png").exists()


# -- parameter images ---------------------------------------------------------------------------


def test_parameter_images_come_in_the_frame_space(tmp_path: Path) -> None:
    """One matcap as an 8-bit sRGB PNG, a 16-bit TIFF, a Radiance HDR (linear) and an ACEScg
    EXR: read by OpenImageIO, all the same colours in the frame's space."""
    srgb = MACBETH_SRGB[:16].reshape(4, 4, 3)
    linear = srgb_decode(srgb).astype(np.float32)
    cv2.imwrite(str(tmp_path / "m.png"), srgb[..., ::-1].astype(np.uint8))
    cv2.imwrite(str(tmp_path / "m.tif"), (srgb[..., ::-1] * 257).astype(np.uint16))
    cv2.imwrite(str(tmp_path / "m.hdr"), linear[..., ::-1])
    ap1 = ocio_convert(linear, "lin_rec709", "ACEScg")
    header = {"chromaticities": ACES_AP1}
    OpenEXR.File(header, {c: ap1[..., i].copy() for i, c in enumerate("RGB")}).write(
        str(tmp_path / "m.exr")
    )
    expected = ocio_convert(linear, "lin_rec709", "ACEScg")
    for name, tol in (("m.png", 1e-4), ("m.tif", 1e-4), ("m.hdr", 0.02), ("m.exr", 1e-5)):
        got = load_image(tmp_path / name, space=ACESCG)
        np.testing.assert_allclose(got, expected, rtol=tol, atol=tol, err_msg=name)
    # data maps are numbers, not colours: not converted
    gain = load_image(tmp_path / "m.png", srgb=False, space=ACESCG)
    np.testing.assert_allclose(gain, srgb / 255.0, atol=1e-6)


def test_an_unreadable_parameter_image_is_a_frame_error(tmp_path: Path) -> None:
    (tmp_path / "bad.png").write_bytes(b"not a picture")
    with pytest.raises(FrameError, match="cannot read image"):
        load_image(tmp_path / "bad.png")


#: The chromaticities OpenEXR writes with CIE XYZ images (its sample ``Chromaticities/XYZ.exr``):
#: X, Y and Z as R, G and B, white E.
XYZ_E = (1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0 / 3.0, 1.0 / 3.0)


def test_a_cie_xyz_file_reads_and_enhances_as_its_rec709_original(tmp_path: Path) -> None:
    """The XYZ primaries' blue has y = 0: such a file was refused as "not a colour space". Its
    matrix is the identity and its luminance Y itself; the operators change its copy of the
    Blender fixture as they change the original (compared in Rec.709)."""
    xyz = from_chromaticities("XYZ", XYZ_E, "test")
    np.testing.assert_allclose(xyz.matrix, np.eye(3), atol=1e-15)
    assert xyz.weights == (0.0, 1.0, 0.0)
    space_copy(FIXTURE, tmp_path / "xyz.exr", lambda rgb: convert(rgb, LINEAR_REC709, xyz), XYZ_E)
    code, text = _cli("inspect", str(tmp_path / "xyz.exr"))
    assert code == 0 and "luminance weights 0.0000, 1.0000, 0.0000, white xy 0.3333 0.3333" in text
    original, copy = gbuffer.read(FIXTURE), gbuffer.read(tmp_path / "xyz.exr")
    covered = original.mask > 0
    for step in ({"op": "radiance_scaling"}, {"op": "unsharp_masking"}):
        d0 = pipeline.run(original, [step]).buffers["beauty"] - original.buffers["beauty"]
        after = pipeline.run(copy, [step]).buffers["beauty"]
        d1 = convert(after, xyz, LINEAR_REC709) - convert(
            copy.buffers["beauty"], xyz, LINEAR_REC709
        )
        d0, d1 = d0[covered], d1[covered]
        assert np.abs(d0).mean() > 1e-4
        assert np.abs(d1 - d0).sum() / np.abs(d0).sum() < 0.03, step
