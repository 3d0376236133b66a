"""The committed corpus subset (tests/fixtures/corpus): every pass, the object index, the camera
and the lights agree with what the frames show, and the scene scripts render them again.

The frames are real Cycles renders of the scenes in ``corpus/`` (``python -m bench.corpus ci``),
stored with radiance passes as HALF and geometry as FLOAT. These checks read them with OpenEXR
directly and through Depict's reader.
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import OpenEXR
import pytest

from bench import corpus
from ops.shading import parse_light
from service.cli import main

FRAMES = corpus.find_frames(corpus.CI_DIR)
LAYER = "ViewLayer"
RGB_PASSES = (
    "Combined", "DiffDir", "DiffInd", "DiffCol", "GlossDir", "GlossInd", "GlossCol",
    "TransDir", "TransInd", "TransCol", "AO", "Emit", "Env",
)  # fmt: skip
IDS = [f.name for f in FRAMES]


def channels(path: Path) -> dict[str, np.ndarray]:
    with OpenEXR.File(str(path), separate_channels=True) as exr:
        return {k: np.asarray(c.pixels) for k, c in exr.channels().items()}


def test_the_subset_is_complete_and_small() -> None:
    names = {f.name for f in FRAMES}
    expected = {corpus.stem(*key) for key in corpus.CI_FRAMES}
    assert names == expected
    assert {s for s, _, _ in corpus.CI_FRAMES} == set(corpus.scene_names())
    total = sum(f.exr.stat().st_size for f in FRAMES)
    assert total < 16 * 2**20, f"the CI corpus is {total / 2**20:.1f} MiB"


@pytest.mark.parametrize("frame", FRAMES, ids=IDS)
def test_every_pass_with_its_pixel_type(frame: corpus.CorpusFrame) -> None:
    ch = channels(frame.exr)
    for p in RGB_PASSES:
        for c in "RGB":
            assert ch[f"{LAYER}.{p}.{c}"].dtype == np.float16, p
    for p, comps in (("Depth", "Z"), ("Normal", "XYZ"), ("Position", "XYZ"), ("IndexOB", "X")):
        for c in comps:
            assert ch[f"{LAYER}.{p}.{c}"].dtype == np.float32, p
    assert frame.camera is not None and frame.lights is not None
    with OpenEXR.File(str(frame.exr)) as exr:
        header = dict(exr.header())
    assert header["BlenderMultiChannel"].startswith("Blender")
    assert header["compression"] == OpenEXR.ZIP_COMPRESSION


@pytest.mark.parametrize("frame", FRAMES, ids=IDS)
def test_depict_inspect_reads_the_frame_with_its_camera(
    frame: corpus.CorpusFrame, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["inspect", str(frame.exr), "--camera", str(frame.camera), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["preset"] == "blender" and info["size"] == [320, 240]
    cam = json.loads(frame.camera.read_text()) if frame.camera else {}
    assert info["camera"]["fov_y_deg"] == pytest.approx(cam["fov_y_deg"])
    for buffer in ("beauty", "normal", "depth", "position", "diffuse", "specular", "transmission"):
        assert buffer in info["buffers"], buffer


@pytest.mark.parametrize("frame", FRAMES, ids=IDS)
def test_object_index_separates_background_floor_and_objects(frame: corpus.CorpusFrame) -> None:
    ch = channels(frame.exr)
    index = ch[f"{LAYER}.IndexOB.X"]
    info = json.loads(frame.lights.read_text()) if frame.lights else {}
    ids = info["object_index"]
    assert set(np.unique(index).astype(int)) <= set(ids.values())
    depth = ch[f"{LAYER}.Depth.Z"]
    # background: the far depth Blender gives it and no index; floor and objects are surfaces
    assert np.all(depth[index == 0] > 1e9)
    assert np.all(depth[index > 0] < 1e3)
    assert (index == ids["floor"]).mean() > 0.3
    assert all((index == i).sum() > 200 for k, i in ids.items() if k not in ("background",))


@pytest.mark.parametrize("frame", FRAMES, ids=IDS)
def test_camera_projects_positions_onto_their_pixels(frame: corpus.CorpusFrame) -> None:
    ch = channels(frame.exr)
    h, w = ch[f"{LAYER}.Depth.Z"].shape
    cam = json.loads(frame.camera.read_text()) if frame.camera else {}
    w2c = np.asarray(cam["world_to_camera"], np.float64)
    pos = np.stack([ch[f"{LAYER}.Position.{c}"] for c in "XYZ"], -1).astype(np.float64)
    covered = ch[f"{LAYER}.Depth.Z"] < 1e3
    pc = pos[covered] @ w2c[:3, :3].T + w2c[:3, 3]
    f = 0.5 * h / math.tan(math.radians(cam["fov_y_deg"]) / 2.0)
    col = f * pc[:, 0] / -pc[:, 2] + w / 2.0 - 0.5
    row = -f * pc[:, 1] / -pc[:, 2] + h / 2.0 - 0.5
    rows, cols = np.nonzero(covered)
    assert np.abs(col - cols).max() < 0.01 and np.abs(row - rows).max() < 0.01
    # planar depth is -z of the camera-space position
    np.testing.assert_allclose(-pc[:, 2], ch[f"{LAYER}.Depth.Z"][covered], rtol=1e-5)


@pytest.mark.parametrize("frame", FRAMES, ids=IDS)
def test_cast_shadows_fall_away_from_the_key_light(frame: corpus.CorpusFrame) -> None:
    """The key light string (camera space) is the sun: taken back to world space, it faces the
    floor, and the floor's shadows lie on the far side of the objects from it."""
    lights = frame.light_strings()
    assert lights and all(parse_light(t) for t in lights)
    cam = json.loads(frame.camera.read_text()) if frame.camera else {}
    w2c = np.asarray(cam["world_to_camera"], np.float64)
    key = w2c[:3, :3].T @ np.asarray(parse_light(lights[0]).vector, np.float64)
    assert key[2] > 0.2  # above the horizon
    ch = channels(frame.exr)
    index = ch[f"{LAYER}.IndexOB.X"]
    pos = np.stack([ch[f"{LAYER}.Position.{c}"] for c in "XYZ"], -1).astype(np.float64)
    floor = (index == 1) & (ch[f"{LAYER}.Normal.Z"] > 0.99)  # the floor, not a backdrop
    direct = np.stack([ch[f"{LAYER}.DiffDir.{c}"] for c in "RGB"]).astype(np.float64).sum(0)
    shadow = floor & (direct < 0.5 * np.percentile(direct[floor], 90))
    objects = pos[index >= 2]
    near = np.linalg.norm(pos[..., :2] - objects[:, :2].mean(0), axis=-1) < 3.0
    offset = pos[shadow & near, :2].mean(0) - objects[:, :2].mean(0)
    assert float(offset @ key[:2]) < 0.0, (offset, key)


@pytest.mark.skipif(shutil.which("blender") is None, reason="blender is not installed")
def test_the_scene_script_renders_the_committed_frame_again(tmp_path: Path) -> None:
    """Blender renders the committed rock frame again from its script (to half precision, but
    for a rare pixel where Cycles' float rounding tips a sample)."""
    exr = corpus.render_scene("rock", "240p", 16, tmp_path, threads=2)
    packed = tmp_path / "packed.exr"
    corpus.pack(exr, packed)
    new, old = channels(packed), channels(corpus.CI_DIR / exr.name)
    assert set(new) == set(old)
    for name in old:
        a, b = new[name].astype(np.float32), old[name].astype(np.float32)
        off = np.abs(a - b) > 1e-3 + 2e-3 * np.abs(b)  # Cycles' float rounding, half's steps
        assert off.mean() < 1e-4, f"{name}: {off.sum()} pixels differ"
    for suffix in (".camera.json", ".lights.json"):
        got = json.loads(exr.with_suffix(suffix).read_text())
        want = json.loads((corpus.CI_DIR / (exr.stem + suffix)).read_text())
        assert got == want
