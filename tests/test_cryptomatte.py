"""Cryptomatte decoding (gbuffer.cryptomatte) against the specification's hash vectors, a file
written by the specification here, and a real Blender Cycles render with Cryptomatte passes
(tests/fixtures/blender/cryptomatte.exr, made by make_cryptomatte.py)."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import OpenEXR
import pytest

import gbuffer
from gbuffer import cryptomatte
from gbuffer.errors import FrameError
from gbuffer.frame import Frame
from service import pipeline
from service.cli import main as cli
from service.registry import Context, PipelineError
from tests import exr_factory

FIXTURE = Path(__file__).parent / "fixtures" / "blender" / "cryptomatte.exr"
#: The float ids of the reference implementation's tests (Psyop's cryptomatte_utilities_tests).
SPEC_VECTORS = {
    "hello": 6.0705627102400005616e-17,
    "cube": -4.08461912519e15,
    "sphere": 2.79018604383e15,
    "plane": 3.66557617593e-11,
    "равнина": -1.3192631212399999468e-25,
    "mädchen": 6.2361298211599995797e25,
}
#: The spec file: names and the ranks each pixel holds (rank 0 first), coverages summing to 1.
NAMES = ("rock_a", "rock é", "tree")


@pytest.mark.parametrize(("name", "value"), SPEC_VECTORS.items())
def test_hash_matches_the_specification(name: str, value: float) -> None:
    assert np.float32(cryptomatte.id_float(name)) == np.float32(value)


def test_exponent_is_never_all_zeros_or_ones() -> None:
    for i in range(5000):
        exponent = (cryptomatte.id_bits(f"object{i}") >> 23) & 0xFF
        assert exponent not in (0, 0xFF)


def spec_coverages(h: int, w: int) -> dict[str, np.ndarray]:
    """Left third rock_a, middle third "rock é", right third tree; the two borders are
    anti-aliased columns shared 0.6/0.4 and 0.3/0.7, and one pixel holds all three names."""
    cov = {name: np.zeros((h, w), np.float32) for name in NAMES}
    a, b = w // 3, 2 * w // 3
    cov["rock_a"][:, :a] = 1.0
    cov["rock é"][:, a + 1 : b] = 1.0
    cov["tree"][:, b + 1 :] = 1.0
    cov["rock_a"][:, a], cov["rock é"][:, a] = 0.6, 0.4
    cov["rock é"][:, b], cov["tree"][:, b] = 0.3, 0.7
    cov["rock_a"][0, 0], cov["rock é"][0, 0], cov["tree"][0, 0] = 0.5, 0.3, 0.2
    return cov


def write_spec_file(
    path: Path, *, sidecar: bool = False, multipart: bool = False, with_gbuffer: bool = True
) -> dict[str, np.ndarray]:
    """A canonical G-buffer plus a Cryptomatte layer ``uCryptoObject`` written by the
    specification: ranks sorted by coverage, two channel groups (00, 01), manifest in the
    header or in a sidecar JSON; in the G-buffer's part, or in a part of its own
    (``multipart``); ``with_gbuffer`` False: the mattes alone. Returns the coverage of each
    name."""
    scene = exr_factory.make_scene()
    h, w = scene.shape
    cov = spec_coverages(h, w)
    stack_cov = np.stack([cov[n] for n in NAMES])
    stack_id = np.stack([np.full((h, w), cryptomatte.id_float(n), np.float32) for n in NAMES])
    order = np.argsort(-stack_cov, axis=0, kind="stable")
    ranked_cov = np.take_along_axis(stack_cov, order, 0)
    ranked_id = np.where(ranked_cov > 0, np.take_along_axis(stack_id, order, 0), 0.0)
    channels: dict[str, Any] = {}
    for rank in range(4):  # two groups of two ranks; the fourth rank is empty
        group, (id_c, cov_c) = divmod(rank, 2)[0], ("rg", "ba")[rank % 2]
        ids = ranked_id[rank] if rank < 3 else np.zeros((h, w), np.float32)
        covs = ranked_cov[rank] if rank < 3 else np.zeros((h, w), np.float32)
        channels[f"uCryptoObject{group:02d}.{id_c}"] = np.ascontiguousarray(ids, np.float32)
        channels[f"uCryptoObject{group:02d}.{cov_c}"] = np.ascontiguousarray(covs, np.float32)
    manifest = {n: f"{cryptomatte.id_bits(n):08x}" for n in NAMES}
    header: dict[str, Any] = {
        "compression": OpenEXR.ZIP_COMPRESSION,
        "cryptomatte/0a1b2c3/name": "uCryptoObject",
        "cryptomatte/0a1b2c3/hash": "MurmurHash3_32",
        "cryptomatte/0a1b2c3/conversion": "uint32_to_float32",
    }
    if sidecar:
        header["cryptomatte/0a1b2c3/manif_file"] = "sidecar/objects.json"
        (path.parent / "sidecar").mkdir(exist_ok=True)
        (path.parent / "sidecar" / "objects.json").write_text(json.dumps(manifest))
    else:
        header["cryptomatte/0a1b2c3/manifest"] = json.dumps(manifest, ensure_ascii=False)
    gbuffer_channels = exr_factory.canonical_channels(scene) if with_gbuffer else {}
    if multipart:
        zip_only = {"compression": OpenEXR.ZIP_COMPRESSION}
        parts = [
            OpenEXR.Part(zip_only, gbuffer_channels, "rgba"),
            OpenEXR.Part(header, channels, "crypto"),
        ]
        OpenEXR.File(parts).write(str(path))
    else:
        exr_factory.write_exr(path, header, {**gbuffer_channels, **channels})
    return cov


@pytest.mark.parametrize(("sidecar", "multipart"), [(False, False), (True, False), (False, True)])
def test_spec_file_decodes_exactly(tmp_path: Path, sidecar: bool, multipart: bool) -> None:
    cov = write_spec_file(tmp_path / "spec.exr", sidecar=sidecar, multipart=multipart)
    frame = gbuffer.read(tmp_path / "spec.exr")
    (layer,) = cryptomatte.layers(frame)
    assert layer.name == "uCryptoObject" and len(layer.ranks) == 4
    assert layer.part == (1 if multipart else 0) and frame.has("normal")
    assert set(layer.manifest) == set(NAMES)
    for patterns, expected in (
        (["tree"], cov["tree"]),
        (["rock*"], cov["rock_a"] + cov["rock é"]),
        (["rock é", "tree"], cov["rock é"] + cov["tree"]),
    ):
        found, chosen = cryptomatte.find_layer(frame, None, patterns)
        m = cryptomatte.matte(frame, found, list(chosen.values()))
        np.testing.assert_array_equal(m, np.clip(expected, 0, 1))
    named = cryptomatte.coverage_by_name(frame, layer)
    assert named == {n: pytest.approx(float(cov[n].sum()), abs=0.01) for n in NAMES}


def test_a_file_of_mattes_alone(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cov = write_spec_file(tmp_path / "mattes.exr", with_gbuffer=False)
    png = tmp_path / "tree.png"
    assert cli(["mask", str(tmp_path / "mattes.exr"), "cryptomatte:tree", "-o", str(png)]) == 0
    inside = int((cov["tree"] >= 1).sum())
    assert f"{inside} pixels inside" in capsys.readouterr().out
    assert (cv2.imread(str(png), cv2.IMREAD_GRAYSCALE) == 255).sum() == inside


def test_sidecars_are_not_read_where_files_are_not(tmp_path: Path) -> None:
    """The HTTP service runs with ``files=False``: an upload's sidecar path is not followed."""
    cov = write_spec_file(tmp_path / "spec.exr", sidecar=True)
    frame = gbuffer.read(tmp_path / "spec.exr")
    steps = [{"op": "curvature", "params": {"mask": "cryptomatte:tree"}}]
    with pytest.raises(PipelineError, match=r"names: none \(no manifest\)"):
        pipeline.run(frame, steps, context=Context(files=False))
    out = pipeline.run(frame, steps, context=Context(files=True))
    h = out.layer("curvature")["H"]
    assert not h[cov["tree"] == 0].any() and h[cov["tree"] == 1].any()


def test_sidecar_outside_the_file_directory_is_refused(tmp_path: Path) -> None:
    write_spec_file(tmp_path / "spec.exr", sidecar=True)
    frame = gbuffer.read(tmp_path / "spec.exr")
    header = frame.passthrough.parts[0][0]
    header["cryptomatte/0a1b2c3/manif_file"] = "../elsewhere.json"
    with pytest.raises(FrameError, match="not a relative path"):
        cryptomatte.layers(frame)


@pytest.fixture(scope="module")
def blender() -> Frame:
    if not FIXTURE.is_file():
        pytest.skip(f"{FIXTURE} is absent (tests/fixtures/blender/README.md)")
    return gbuffer.read(FIXTURE)


def test_blender_manifest_ids_are_the_hash_of_the_names(blender: Frame) -> None:
    found = cryptomatte.layers(blender)
    assert [x.short for x in found] == ["CryptoObject", "CryptoMaterial"]
    for layer in found:
        assert len(layer.ranks) == 4
        for name, bits in layer.manifest.items():
            assert bits == cryptomatte.id_bits(name), name
    assert {"Suzanne", "Sphere", "Torus", "Ground", "GlassPane", "EmitCube"} <= set(
        found[0].manifest
    )


def test_blender_coverage_sums_to_one_and_matches_the_index_pass(blender: Frame) -> None:
    layer = cryptomatte.layers(blender)[0]
    every = cryptomatte.matte(blender, layer, list(layer.manifest.values()))
    surface = np.isfinite(blender.buffers["depth"]).astype(np.uint8)
    inner = cv2.erode(surface, np.ones((5, 5), np.uint8)) > 0  # 2+ px from the sky
    assert float(np.abs(every[inner] - 1.0).max()) < 1e-3  # named objects cover the surfaces
    sky = cv2.dilate(surface, np.ones((5, 5), np.uint8)) == 0  # 2+ px from any surface
    assert sky.sum() > 1000 and not every[sky].any() and every.max() <= 1.0
    _, chosen = cryptomatte.find_layer(blender, None, ["Suzanne"])
    m = cryptomatte.matte(blender, layer, list(chosen.values()))
    index = blender.layer("ViewLayer.IndexOB")["X"] == 3  # Suzanne's pass index
    inside, edge = m >= 1.0, (m > 0) & (m < 1)
    assert 2000 < inside.sum() < 5000 and edge.sum() > 100
    assert not (inside & ~index).any()  # fully covered pixels are Suzanne's in the index pass
    assert not ((m == 0) & index).any()
    material = cryptomatte.find_layer(blender, "CryptoMaterial", ["SuzanneMat"])
    np.testing.assert_array_equal(
        cryptomatte.matte(blender, material[0], list(material[1].values())), m
    )


def test_unknown_names_and_layers_list_what_the_file_has(blender: Frame) -> None:
    with pytest.raises(FrameError, match=r"no Cryptomatte name matches 'Nope'.*Suzanne"):
        cryptomatte.find_layer(blender, None, ["Nope"])
    with pytest.raises(FrameError, match=r"no Cryptomatte layer 'CryptoAsset'.*CryptoObject"):
        cryptomatte.find_layer(blender, "CryptoAsset", ["Suzanne"])
    plain = gbuffer.read(FIXTURE.parent / "cycles_multilayer.exr")
    with pytest.raises(FrameError, match="no Cryptomatte layer"):
        cryptomatte.find_layer(plain, None, ["Suzanne"])


def test_nan_coverage_is_no_coverage(blender: Frame, tmp_path: Path) -> None:
    """A damaged file's NaN in a coverage channel: a mask of it made the enhanced beauty NaN
    wherever the mask touched (3130 pixels of the fixture), without a word."""
    with OpenEXR.File(str(FIXTURE), separate_channels=True) as f:
        part = f.parts[0]
        header = {k: v for k, v in part.header.items() if k not in ("channels", "chunkCount")}
        channels = {k: c.pixels.copy() for k, c in part.channels.items()}
    channels["ViewLayer.CryptoObject00.g"][:] = np.nan
    damaged, out = tmp_path / "damaged.exr", tmp_path / "out.exr"
    exr_factory.write_exr(damaged, header, channels)
    mask = ["--set", "mask=cryptomatte:Suzanne"]
    assert cli(["enhance", str(damaged), "-o", str(out), "--op", "radiance_scaling", *mask]) == 0
    with OpenEXR.File(str(out), separate_channels=True) as f:
        result = {k: c.pixels for k, c in f.parts[-1].channels.items() if ".Depict." in k}
    assert sorted(result) == [f"ViewLayer.Depict.{c}" for c in "ABGR"]
    assert all(np.isfinite(v).all() for v in result.values())


def test_id_picture_colours_each_object(blender: Frame) -> None:
    picture = cryptomatte.id_picture(blender, cryptomatte.layers(blender)[0])
    assert picture.shape == (*blender.shape, 3) and picture.dtype == np.float32
    index = blender.layer("ViewLayer.IndexOB")["X"] == 3
    m = cryptomatte.matte(blender, cryptomatte.layers(blender)[0], [cryptomatte.id_bits("Suzanne")])
    colours = np.unique(picture[(m >= 1.0) & index].round(4), axis=0)
    assert len(colours) == 1  # one colour inside Suzanne, another on the ground
    assert not np.allclose(colours[0], picture[-1, 0])


@pytest.mark.skipif(shutil.which("blender") is None, reason="Debian's blender is not installed")
def test_the_fixture_script_renders_the_fixture(blender: Frame, tmp_path: Path) -> None:
    """make_cryptomatte.py in Blender gives the committed file again: the same channels and
    manifests, the same mattes (Cycles reruns differ by float rounding only)."""
    script = FIXTURE.parent / "make_cryptomatte.py"
    cmd = ["blender", "-b", "--factory-startup", "--python", str(script), "--", str(tmp_path)]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    again = gbuffer.read(tmp_path / "cryptomatte.exr")
    assert sorted(again.passthrough.parts[0][1]) == sorted(blender.passthrough.parts[0][1])
    for old, new in zip(cryptomatte.layers(blender), cryptomatte.layers(again), strict=True):
        assert (old.name, old.manifest) == (new.name, new.manifest)
        for name, bits in old.manifest.items():
            a, b = (cryptomatte.matte(f, x, [bits]) for f, x in ((blender, old), (again, new)))
            assert float(np.abs(a - b).max()) < 1e-3, name
