"""The presets as data: the table is consistent, each preset's declared clues detect its files
in the declared order, a preset made of data alone reads a file, and the help texts follow the
table."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from gbuffer import BUFFERS, LOBES, FrameError, detect, exr
from gbuffer.presets import (
    DEPTH_KINDS,
    PRESETS,
    SPACES,
    Detection,
    LobeSpec,
    Preset,
    find_preset,
    preset_help,
    preset_names,
    to_frame,
)
from gbuffer.presets.table import FALLBACK
from tests import exr_factory as F


@pytest.fixture(scope="module")
def scene() -> F.Scene:
    return F.make_scene()


def exr_with(tmp_path: Path, header: dict[str, Any], names: list[str], name: str = "f") -> Path:
    """A real one-part EXR with zero FLOAT channels ``names`` and extra header attributes."""
    channels = {n: np.zeros((4, 4), np.float32) for n in names}
    return F.write_exr(tmp_path / f"{name}.exr", header, channels)


def detected(path: Path) -> tuple[str, str]:
    return detect(exr.read_parts(path))


def test_the_table_is_consistent() -> None:
    assert list(PRESETS) == [p.name for p in PRESETS.values()]
    assert preset_names() == ("auto", *PRESETS)
    ranks = [p.detection.rank for p in PRESETS.values()]
    assert len(set(ranks)) == len(ranks)  # the order of the channel clues is never a tie
    for preset in PRESETS.values():
        assert preset.description
        assert set(preset.buffers) <= set(BUFFERS), preset.name
        assert set(preset.lobes) <= set(LOBES), preset.name
        for _, space in (*preset.normal, *preset.position):
            assert space in SPACES, preset.name
        assert preset.depth_kind in DEPTH_KINDS
        assert preset.detection.channels, f"{preset.name} declares no channel clue"
        if preset is not FALLBACK:
            assert preset.detection.header_keys and preset.detection.software, preset.name


@pytest.mark.parametrize(
    ("key", "expected"),
    [
        ("BlenderMultiChannel", "blender"),
        ("arnold/version", "arnold"),
        ("ARNOLD/host", "arnold"),
        ("vrayInfo/camera", "vray"),
        ("cameraTransform", "vray"),
        ("RenderMan/version", "renderman"),
        ("prmanVersion", "renderman"),
        ("PixarRenderer", "renderman"),
        ("karma:camera", "karma"),
        ("HoudiniVersion", "karma"),
    ],
)
def test_header_key_signatures(tmp_path: Path, key: str, expected: str) -> None:
    path = exr_with(tmp_path, {key: "1"}, ["R", "G", "B"])
    assert detected(path) == (expected, f"header attribute {key}")


@pytest.mark.parametrize(
    ("name", "word"), [(p.name, w) for p in PRESETS.values() for w in p.detection.software]
)
def test_each_preset_is_detected_by_its_software_words(
    tmp_path: Path, name: str, word: str
) -> None:
    value = f"{word.upper()} 7.2 (build 1)"
    path = exr_with(tmp_path, {"software": value}, ["R", "G", "B"])
    assert detected(path) == (name, f"header software={value!r}")


def test_header_attribute_names_weigh_more_than_software(tmp_path: Path) -> None:
    path = exr_with(tmp_path, {"software": "Blender 4.2", "arnold/version": "7"}, ["R"])
    assert detected(path)[0] == "arnold"


@pytest.mark.parametrize(
    ("names", "expected", "reason"),
    [
        (["ViewLayer.Combined.R", "VRayNormals.X"], "blender", "Blender pass names"),
        (["VRayNormals.X", "Nn.X", "diffuse_direct.R"], "vray", "V-Ray render element"),
        (["Nn.X", "diffuse_direct.R"], "renderman", "RenderMan AOV names (Nn)"),
        (["N.X", "Z", "diffuse_direct.R"], "arnold", "Arnold AOV names (diffuse_direct)"),
        # Depict's canonical names beside an Arnold-like layer: canonical
        (["N.X", "N.Y", "N.Z", "depth.Z", "diffuse_direct.R"], "canonical", "Depict canonical"),
        (["depth.Z"], "canonical", "Depict canonical"),
    ],
)
def test_channel_clues_in_rank_order(
    tmp_path: Path, names: list[str], expected: str, reason: str
) -> None:
    name, why = detected(exr_with(tmp_path, {}, names))
    assert (name, why[: len(reason)]) == (expected, reason)


def test_a_part_named_c_is_karma_and_depict_marks_weigh_less_than_renderer_names(
    tmp_path: Path, scene: F.Scene
) -> None:
    karma = F.write_karma(tmp_path / "k.exr", scene)
    assert detected(karma) == ("karma", "multi-part file with a part named 'C' (Karma beauty)")
    marked = exr_with(tmp_path, {"depict/result": "R"}, ["Nn.X", "R", "G", "B"], "m")
    assert detected(marked)[0] == "renderman"
    plain = exr_with(tmp_path, {"depict/result": "R"}, ["R", "G", "B"], "p")
    assert detected(plain) == ("canonical", "header attribute depict/result")


def test_a_preset_is_data(tmp_path: Path, scene: F.Scene) -> None:
    """A renderer the table does not know, read by declaring its names and conventions."""
    acme = Preset(
        name="acme",
        description="a renderer with its own names",
        buffers={"beauty": ("rgb",), "depth": ("zdepth",)},
        normal=(("nrm", "camera"),),
        lobes={"diffuse": LobeSpec(light=(("difflight",),), color=("diffcol",))},
        depth_kind="planar",
        depth_background=1e10,
        detection=Detection(header_keys="acme/.*", software=("acme",), rank=9),
    )
    ch = {
        **F._split(scene.beauty, ("r", "g", "b"), "rgb", np.float32),
        **F._split(scene.normal, ("x", "y", "z"), "nrm", np.float32),
        **F._split(scene.diffuse_light, F.RGB, "difflight", np.float32),
        **F._split(scene.albedo, F.RGB, "diffcol", np.float32),
        "zdepth": np.where(scene.covered, scene.depth, 1e10).astype(np.float32),
    }
    path = F.write_exr(tmp_path / "acme.exr", {}, ch)
    frame = to_frame(exr.read_parts(path), acme)
    assert frame.preset == "acme"
    assert frame.sources["normal"] == "nrm.x,y,z"
    assert frame.sources["diffuse"] == "(difflight.R,G,B) * diffcol.R,G,B"
    m = scene.covered
    np.testing.assert_allclose(frame.buffers["depth"][m], scene.depth[m], rtol=1e-6)
    assert np.isinf(frame.buffers["depth"][~m]).all()
    np.testing.assert_allclose(frame.buffers["diffuse"][m], scene.diffuse[m], atol=1e-6)


def test_unknown_names_are_refused_with_the_valid_ones() -> None:
    with pytest.raises(FrameError, match=r"preset='nope' is not known; valid: auto, blender, "):
        find_preset("nope")
    assert find_preset("vray") is PRESETS["vray"]


def test_help_texts_name_every_preset() -> None:
    from service.cli import build_parser
    from service.openapi import schema

    text = preset_help()
    assert all(name in text for name in preset_names())
    commands = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    shown = " ".join(commands.choices["enhance"].format_help().split())
    assert " ".join(text.split()) in shown
    forms = schema()["components"]["schemas"].values()
    fields = [f["properties"]["preset"] for f in forms if "preset" in f.get("properties", {})]
    assert any(field.get("description") == text for field in fields)
