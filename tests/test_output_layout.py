"""Where ``depict enhance`` puts its result, what the output's header says, and that reading an
output back (preview, inspect, score, a second enhance) needs no flag and shows the result.

Real files: the Blender Cycles fixture and a render of examples/spot.obj, through the CLI in
process; Blender's own compositor lists the result pass when Debian's ``blender`` is installed.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import cv2
import numpy as np
import OpenEXR
import pytest

import gbuffer
from service.cli import main
from service.version import version

ROOT = Path(__file__).resolve().parents[1]
BLENDER_EXR = ROOT / "tests" / "fixtures" / "blender" / "cycles_multilayer.exr"
SPOT = ROOT / "examples" / "spot.obj"
RGBA = ("R", "G", "B", "A")


def depict(*argv: str | Path) -> int:
    try:
        return main([str(a) for a in argv])
    except SystemExit as exc:
        return int(exc.code or 0)


def read_file(path: Path) -> tuple[dict[str, object], dict[str, np.ndarray]]:
    """The header and channels of every part (the default ``part`` layout adds one), later
    parts' attributes over earlier ones'."""
    header: dict[str, object] = {}
    channels: dict[str, np.ndarray] = {}
    with OpenEXR.File(str(path), separate_channels=True) as f:
        for part in f.parts:
            header.update(part.header)
            channels.update({n: np.array(c.pixels) for n, c in part.channels.items()})
    return header, channels


@pytest.fixture(scope="module")
def blender_out(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("layout") / "shot_out.exr"
    assert depict("enhance", BLENDER_EXR, "-o", out) == 0
    return out


@pytest.fixture(scope="module")
def spot(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("spot") / "spot.exr"
    assert depict("render", SPOT, "-o", path, "--width", 64, "--height", 48) == 0
    return path


def test_blender_result_is_a_pass_of_the_view_layer(blender_out: Path) -> None:
    _, before = read_file(BLENDER_EXR)
    header, after = read_file(blender_out)
    assert {f"ViewLayer.Depict.{c}" for c in RGBA} <= set(after)
    assert not set(RGBA) & set(after)  # no bare R,G,B,A: Blender would not list them
    for name, pixels in before.items():  # the renderer's passes come back bit for bit
        np.testing.assert_array_equal(after[name], pixels, err_msg=name)
    result = np.dstack([after[f"ViewLayer.Depict.{c}"] for c in "RGB"])
    combined = np.dstack([before[f"ViewLayer.Combined.{c}"] for c in "RGB"])
    assert float(np.abs(result - combined).mean()) > 1e-3
    assert header["depict/result"] == "ViewLayer.Depict"
    assert header["depict/original"] == "ViewLayer.Combined"


def test_the_header_carries_camera_and_provenance(blender_out: Path) -> None:
    header, _ = read_file(blender_out)
    assert header["depict/version"] == version()
    assert header["depict/input"] == BLENDER_EXR.name
    steps = json.loads(str(header["depict/pipeline"]))["steps"]
    assert [s["op"] for s in steps] == ["radiance_scaling"]
    assert steps[0]["params"]["gamma"] == 1.0 and "white_percentile" in steps[0]["params"]
    assert steps[0]["params"]["preset"] == "default"
    assert "worldToCamera" in header and "worldToNDC" in header
    assert str(header["depict/cameraSource"]).startswith("solved from ViewLayer.Position")
    frame = gbuffer.read(blender_out)
    assert frame.camera is not None and frame.camera.source.startswith("file header")
    solved = gbuffer.read(BLENDER_EXR).camera
    assert solved is not None and solved.world_to_camera is not None
    np.testing.assert_allclose(frame.camera.world_to_camera, solved.world_to_camera, atol=1e-6)
    assert frame.camera.fov_y_deg == pytest.approx(solved.fov_y_deg, abs=1e-5)


def test_the_header_pipeline_reproduces_the_output(blender_out: Path, tmp_path: Path) -> None:
    header, first = read_file(blender_out)
    pipe = tmp_path / "pipe.json"
    pipe.write_text(str(header["depict/pipeline"]))
    again = tmp_path / "again.exr"
    assert depict("enhance", BLENDER_EXR, "-o", again, "--pipeline", pipe) == 0
    _, second = read_file(again)
    for name in (f"ViewLayer.Depict.{c}" for c in RGBA):
        np.testing.assert_array_equal(second[name], first[name])


def test_preview_inspect_and_score_of_an_output_show_the_result(
    blender_out: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    plain, mapped, original = (tmp_path / f"{n}.png" for n in ("plain", "mapped", "original"))
    assert depict("preview", blender_out, "-o", plain) == 0
    assert depict("preview", blender_out, "-o", mapped, "--map", "beauty=ViewLayer.Depict") == 0
    assert depict("preview", BLENDER_EXR, "-o", original) == 0
    a, b, c = (cv2.imread(str(p)) for p in (plain, mapped, original))
    np.testing.assert_array_equal(a, b)
    assert (np.abs(a.astype(int) - c) > 2).any(axis=2).mean() > 0.01  # the result, not Combined
    capsys.readouterr()
    assert depict("inspect", blender_out) == 0
    text = capsys.readouterr().out
    assert "ViewLayer.Depict.R,G,B (Depict's result: depict/result)" in text
    assert "depict: result in ViewLayer.Depict (original beauty: ViewLayer.Combined)" in text
    assert "camera source: file header (worldToCamera; solved from" in text
    assert depict("score", blender_out, "--json") == 0
    plain_score = json.loads(capsys.readouterr().out)["score"]
    assert depict("score", blender_out, "--json", "--map", "beauty=ViewLayer.Depict") == 0
    # the same beauty either way (the score moves by ~1e-12 with how the arrays lie in memory)
    assert json.loads(capsys.readouterr().out)["score"] == pytest.approx(plain_score, abs=1e-9)


def test_a_second_enhance_replaces_the_result_and_keeps_the_original(
    blender_out: Path, tmp_path: Path
) -> None:
    second = tmp_path / "second.exr"
    assert depict("enhance", blender_out, "-o", second, "--op", "unsharp_masking") == 0
    header, chans = read_file(second)
    _, before = read_file(BLENDER_EXR)
    _, first = read_file(blender_out)
    assert not any(n.startswith(("input", "ViewLayer.Depict1")) for n in chans)
    np.testing.assert_array_equal(chans["ViewLayer.Combined.R"], before["ViewLayer.Combined.R"])
    assert float(np.abs(chans["ViewLayer.Depict.R"] - first["ViewLayer.Depict.R"]).max()) > 0
    history = json.loads(str(header["depict/history"]))
    assert [h["input"] for h in history] == [BLENDER_EXR.name, blender_out.name]
    assert [h["pipeline"]["steps"][0]["op"] for h in history] == [
        "radiance_scaling",
        "unsharp_masking",
    ]


def test_canonical_input_keeps_its_beauty_once_under_input(spot: Path, tmp_path: Path) -> None:
    _, original = read_file(spot)
    once, twice = tmp_path / "once.exr", tmp_path / "twice.exr"
    assert depict("enhance", spot, "-o", once, "--layout", "same") == 0
    assert depict("enhance", once, "-o", twice, "--op", "unsharp_masking", "--layout", "same") == 0
    header, chans = read_file(twice)
    _, first = read_file(once)
    for c in RGBA:
        np.testing.assert_array_equal(chans[f"input.{c}"], original[c])
        assert chans[f"input.{c}"].dtype == original[c].dtype
    assert not any(n.startswith("input1.") for n in chans)
    assert float(np.abs(chans["R"] - first["R"]).max()) > 0
    assert header["depict/result"] == "" and header["depict/original"] == "input"


def test_an_output_in_the_default_layout_keeps_the_inputs_camera(
    spot: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The camera of a render's header stayed in the input's part, and the result's part (which
    holds the beauty read back) had none: a second enhance ran without a camera, and gave other
    pixels than with it, without a word; its original beauty was '?'."""
    out = tmp_path / "out.exr"
    assert depict("enhance", spot, "-o", out) == 0
    capsys.readouterr()
    assert depict("inspect", spot, "--json") == 0
    camera = tmp_path / "camera.json"
    camera.write_text(json.dumps(json.loads(capsys.readouterr().out)["camera"]))
    assert depict("inspect", out) == 0
    text = capsys.readouterr().out
    assert "camera source: file header (worldToCamera)" in text
    assert "depict: result in Depict (original beauty: R,G,B)" in text
    again, given = tmp_path / "again.exr", tmp_path / "given.exr"
    usm = ("--op", "unsharp_masking")
    assert depict("enhance", out, "-o", again, *usm) == 0
    assert depict("enhance", out, "-o", given, *usm, "--camera", camera) == 0
    for c in RGBA:
        np.testing.assert_array_equal(
            read_file(again)[1][f"Depict.{c}"], read_file(given)[1][f"Depict.{c}"]
        )


@pytest.mark.parametrize(
    "attributes",
    [
        {"depict/pipeline": "not json"},
        {"depict/pipeline": "{}", "depict/history": "5"},
        {"depict/pipeline": "{}", "depict/history": "[" * 5000 + "]" * 5000},
    ],
)
def test_provenance_that_is_not_depicts_starts_the_history_again(
    spot: Path, tmp_path: Path, attributes: dict[str, str], capsys: pytest.CaptureFixture[str]
) -> None:
    """Another tool's or a damaged file's depict/* attributes: enhance failed with a traceback
    (a history that is not a list), an error naming neither file nor attribute, or 'nested too
    deeply' (the service answered 500), and inspect refused the file."""
    header, chans = read_file(spot)
    kept = {k: v for k, v in header.items() if k in ("worldToCamera", "depict/fovYDeg")}
    odd = tmp_path / "odd.exr"
    with OpenEXR.File({**kept, **attributes}, dict(chans)) as f:
        f.write(str(odd))
    out = tmp_path / "out.exr"
    assert depict("enhance", odd, "-o", out) == 0
    assert depict("inspect", odd) == 0
    capsys.readouterr()
    history = json.loads(str(read_file(out)[0]["depict/history"]))
    earlier = attributes["depict/pipeline"]
    assert history[0]["pipeline"] == (earlier if earlier == "not json" else {})
    assert [h["input"] for h in history] == [None, odd.name]


def test_a_file_that_uses_input_gets_a_fresh_name(spot: Path, tmp_path: Path) -> None:
    _, chans = read_file(spot)
    chans["input.R"] = np.zeros_like(chans["R"])
    taken = tmp_path / "taken.exr"
    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION}, dict(chans)) as f:
        f.write(str(taken))
    out = tmp_path / "out.exr"
    assert depict("enhance", taken, "-o", out, "--layout", "same") == 0
    out_header, result = read_file(out)
    np.testing.assert_array_equal(result["input.R"], chans["input.R"])  # theirs, untouched
    np.testing.assert_array_equal(result["input1.R"], chans["R"])
    assert out_header["depict/original"] == "input1"


def test_output_layer_names(
    spot: Path, blender_out: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "named.exr"
    assert depict("enhance", spot, "-o", out, "--output-layer", "shot.Depict") == 0
    header, chans = read_file(out)
    assert {f"shot.Depict.{c}" for c in RGBA} <= set(chans) and "input.R" not in chans
    assert header["depict/result"] == "shot.Depict"
    capsys.readouterr()
    assert depict("enhance", spot, "-o", tmp_path / "bad.exr", "--output-layer", "N") == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "would overwrite the input's channels N.X" in err
    assert not (tmp_path / "bad.exr").exists()
    assert depict("enhance", spot, "-o", tmp_path / "bad.exr", "--output-layer", "a..b") == 2
    assert "is not a layer name" in capsys.readouterr().err
    # naming the earlier Depict result replaces it
    again = tmp_path / "again.exr"
    assert depict("enhance", blender_out, "-o", again, "--output-layer", "ViewLayer.Depict") == 0


def blender_passes(exr: Path, tmp_path: Path) -> list[str]:
    """The passes Blender's compositor Image node lists for ``exr``."""
    script = tmp_path / "list.py"
    script.write_text(
        "import bpy, sys\n"
        "image = bpy.data.images.load(sys.argv[-1])\n"
        "scene = bpy.context.scene\n"
        "scene.use_nodes = True\n"
        "node = scene.node_tree.nodes.new('CompositorNodeImage')\n"
        "node.image = image\n"
        "print('PASSES', [s.name for s in node.outputs if s.enabled])\n"
    )
    cmd = ["blender", "-b", "--factory-startup", "--python", str(script), "--", str(exr)]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=300, check=True)
    line = next(x for x in run.stdout.splitlines() if x.startswith("PASSES"))
    return list(eval(line[len("PASSES ") :]))  # a printed Python list of strings


@pytest.mark.skipif(shutil.which("blender") is None, reason="Debian's blender is not installed")
def test_blenders_compositor_lists_the_depict_pass(blender_out: Path, tmp_path: Path) -> None:
    passes = blender_passes(blender_out, tmp_path)
    assert "Depict" in passes and "Combined" in passes and "Position" in passes


def write_compressed(src: Path, path: Path, codec: str, tiled: bool) -> Path:
    """``src`` re-saved with ``codec`` (radiance as HALF, the rest FLOAT), tiled or not."""
    header, chans = read_file(src)
    out: dict[str, np.ndarray] = {}
    for name, pixels in chans.items():
        radiance = name.rpartition(".")[2] in "RGBA" and "Position" not in name
        out[name] = np.ascontiguousarray(pixels.astype(np.float16 if radiance else np.float32))
    new = {"compression": getattr(OpenEXR, f"{codec}_COMPRESSION")}
    new["BlenderMultiChannel"] = header["BlenderMultiChannel"]
    if tiled:
        tiles = OpenEXR.TileDescription()
        tiles.xSize = tiles.ySize = 64
        new.update(type=OpenEXR.tiledimage, tiles=tiles)
    with OpenEXR.File(new, out) as f:
        f.write(str(path))
    return path


@pytest.mark.parametrize("codec", ["DWAA", "DWAB", "B44", "PXR24"])
def test_lossy_compression_is_kept_and_its_cost_said_on_stderr(
    codec: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src = write_compressed(BLENDER_EXR, tmp_path / "in.exr", codec, tiled=codec == "DWAA")
    out = tmp_path / "out.exr"
    capsys.readouterr()
    assert depict("enhance", src, "-o", out, "--op", "curvature", "--layout", "same") == 0
    err = capsys.readouterr().err
    header, chans = read_file(out)
    assert header["compression"] == getattr(OpenEXR, f"{codec}_COMPRESSION")
    assert (header.get("type") == OpenEXR.tiledimage) == (codec == "DWAA")
    if codec.startswith("DWA"):  # not ZIP at 3x the size (B44 stores new FLOAT layers raw)
        assert out.stat().st_size < 1.5 * src.stat().st_size
    frame = gbuffer.read(src)
    curvature = chans["curvature.H"]
    if codec == "B44":  # 32-bit layers exact, nothing to say
        assert err == ""
        with OpenEXR.File(str(out), separate_channels=True) as f:
            assert f.channels()["curvature.H"].pixels.dtype == np.float32
    else:
        lines = err.splitlines()
        assert len(lines) == 1 and lines[0].startswith("depict: warning: part 0 is written with")
        assert codec in lines[0]
    if codec in ("DWAA", "DWAB"):
        assert "curvature.dir.Y" in err  # a data layer DWA quantises
    assert curvature.shape == frame.shape


def two_view_layers(tmp_path: Path) -> Path:
    """The Blender fixture with a second view layer, ``Back``, of every pass (its beauty and
    lobes dimmed): the two tie on passes."""
    header, channels = read_file(BLENDER_EXR)
    back = {
        name.replace("ViewLayer.", "Back.", 1): (
            pixels * np.float32(0.25) if name.endswith((".R", ".G", ".B")) else pixels
        )
        for name, pixels in channels.items()
        if name.startswith("ViewLayer.")
    }
    path = tmp_path / "two.exr"
    OpenEXR.File(dict(header), {**channels, **back}).write(str(path))
    return path


def test_the_view_layer_read_is_the_one_asked_for(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A render with two view layers: the warning says how to choose, and ``--view-layer``
    chooses it (it could not be chosen: the warning's ``layer=...`` was no option); the result
    is a pass of that layer, made from that layer's passes."""
    src = two_view_layers(tmp_path)
    assert depict("inspect", src) == 0
    assert "(choose with --view-layer NAME, the view_layer form field over HTTP)" in (
        capsys.readouterr().out
    )
    results = {}
    for layer in ("ViewLayer", "Back"):
        out = tmp_path / f"{layer}.exr"
        assert depict("enhance", src, "-o", out, "--view-layer", layer) == 0
        _, channels = read_file(out)
        assert not [n for n in channels if n.endswith(".Depict.R") and not n.startswith(layer)]
        results[layer] = channels[f"{layer}.Depict.R"]
    _, channels = read_file(src)
    for layer, result in results.items():  # (each near its own beauty, the other 4x off)
        beauty = channels[f"{layer}.Combined.R"]
        assert abs(float(result.mean()) / float(beauty.mean()) - 1.0) < 0.2
    capsys.readouterr()
    assert depict("enhance", src, "-o", tmp_path / "x.exr", "--view-layer", "Front") == 2
    err = capsys.readouterr().err
    assert err == "depict: error: view layer 'Front' not in the file; layers: Back, ViewLayer\n"
