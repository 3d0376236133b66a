"""The ``depict`` command line, in process (``service.cli.main``), on files under tmp_path.

Every command on a small render of examples/spot.obj (the errors and warnings:
tests/test_cli_errors.py).
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import OpenEXR
import pytest

import gbuffer
from ops import relief as rl
from service import pipeline
from service.cli import main
from service.registry import operators

SPOT = Path(__file__).resolve().parents[1] / "examples" / "spot.obj"
W, H = 96, 72


def depict(*argv: str | Path) -> int:
    """``depict ARGV`` in process; argparse's own exits give their code too."""
    try:
        return main([str(a) for a in argv])
    except SystemExit as exc:
        return int(exc.code or 0)


def channels(path: Path) -> dict[str, np.ndarray]:
    """Every part's channels (the default ``part`` layout adds one), as float32."""
    with OpenEXR.File(str(path), separate_channels=True) as f:
        return {
            name: np.asarray(c.pixels, np.float32)
            for part in f.parts
            for name, c in part.channels.items()
        }


def render_spot(folder: Path) -> Path:
    """A W×H render of examples/spot.obj in ``folder``."""
    path = folder / "spot.exr"
    assert depict("render", SPOT, "-o", path, "--width", W, "--height", H) == 0
    return path


@pytest.fixture(scope="module")
def exr(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return render_spot(tmp_path_factory.mktemp("cli"))


@pytest.fixture(scope="module")
def covered_pixel(exr: Path) -> tuple[int, int]:
    """(x, y) of a pixel well inside the surface."""
    mask = (gbuffer.read(exr).mask > 0).astype(np.uint8)
    inner = cv2.erode(mask, np.ones((7, 7), np.uint8))
    ys, xs = np.nonzero(inner)
    i = len(ys) // 2
    return int(xs[i]), int(ys[i])


# -- render, inspect, preview, ops --------------------------------------------------------------


def test_render_writes_a_canonical_gbuffer(
    exr: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "r.exr"
    assert depict("render", SPOT, "-o", out, "--width", 64, "--height", 48, "--light", "0,1,1") == 0
    assert capsys.readouterr().out.strip() == f"wrote {out} (64x48)"
    frame = gbuffer.read(out)
    assert frame.shape == (48, 64)
    assert {"beauty", "normal", "depth", "diffuse", "specular"} <= set(frame.buffers)
    assert frame.camera is not None and frame.camera.fov_y_deg is not None
    assert 0.05 < float(frame.mask.mean()) < 0.9
    names = channels(exr)
    assert {"R", "G", "B", "A", "N.X", "N.Y", "N.Z", "depth.Z"} <= set(names)


def test_inspect_text_and_json(exr: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert depict("inspect", exr) == 0
    text = capsys.readouterr().out
    first = text.splitlines()[0]
    assert first == f"{exr}: {W}x{H}, preset canonical"
    assert "buffers:" in text and re.search(r"^\s+normal\s+<- N\.X,Y,Z$", text, re.M)
    assert re.search(r"^\s+camera: \{.*\"fov_y_deg\"", text, re.M)
    assert depict("inspect", "--json", exr) == 0
    info = json.loads(capsys.readouterr().out)
    assert set(info) == {
        "file",
        "preset",
        "preset_reason",
        "size",
        "display_window",
        "data_window",
        "parts",
        "buffers",
        "camera",
        "camera_source",
        "camera_fit",
        "colorspace",
        "missing",
        "depict",
        "cryptomatte",
        "problems",
        "operators",
        "warnings",
    }
    assert "colour space: Linear Rec.709 (sRGB) (from default;" in text
    assert (info["colorspace"]["name"], info["colorspace"]["source"]) == (
        "Linear Rec.709 (sRGB)",
        "default",
    )
    assert info["camera_source"] == "file header (worldToCamera)"
    assert info["missing"] == [] and info["problems"] == [] and info["depict"] is None
    assert info["operators"]["not_runnable"] == {}
    assert "radiance_scaling" in info["operators"]["runnable"]
    assert info["file"] == str(exr)
    assert info["size"] == [W, H]
    assert info["display_window"] == info["data_window"] == [0, 0, W - 1, H - 1]
    assert info["preset"] == "canonical"
    assert info["buffers"]["depth"] == {"source": "depth.Z", "shape": [H, W]}
    assert info["camera"]["projection"] == "perspective"
    assert len(info["parts"]) == 1 and "N.X" in info["parts"][0]["channels"]


@pytest.mark.parametrize("layer", ["beauty", "normal", "depth", "position", "P", "N"])
def test_preview_writes_a_png(
    exr: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], layer: str
) -> None:
    out = tmp_path / f"{layer}.png"
    assert depict("preview", exr, "-o", out, "--layer", layer) == 0
    assert capsys.readouterr().out.strip() == f"wrote {out} ({layer})"
    img = cv2.imread(str(out), cv2.IMREAD_UNCHANGED)  # (a signed vector layer, position or
    assert img is not None and img.shape == (H, W, 3) and img.dtype == np.uint8  # P, made 9
    assert img.max() > img.min()  # channels: an empty "cannot write PNG" error)


def test_warmup_runs_every_operator(capsys: pytest.CaptureFixture[str]) -> None:
    assert depict("warmup") == 0
    text = capsys.readouterr().out
    assert re.findall(r"^  (\w+)\s+\d+\.\d\d s$", text, re.M)[: len(operators())] == list(
        operators()
    )
    assert "kernels ready" in text


WARM_COVERS = """
import gc
import numba
from gbuffer.render import auto_camera, load_mesh, render
from service import pipeline
from service.warmup import EXAMPLE, warm

def loaded():
    kernels = [d for d in gc.get_objects() if isinstance(d, numba.core.dispatcher.Dispatcher)]
    return {d.py_func.__qualname__: len(d.overloads) for d in kernels}

warm()
before = loaded()
mesh = load_mesh(EXAMPLE)
frame = render(mesh, 480, 1080, camera=auto_camera(mesh, width=480, height=1080))
for op in ("curvature", "radiance_scaling"):
    pipeline.run(frame, [{"op": op}])
glass = frame.copy()  # a transmission lobe, as a path-traced frame's glass has
glass.buffers["transmission"] = frame.buffers["diffuse"]
pipeline.run(glass, [{"op": "light_alignment"}])
after = loaded()
print(sorted(name for name, n in after.items() if n > before.get(name, 0)))
"""


def test_warmup_loads_every_kernel_a_full_height_frame_needs() -> None:
    """After ``depict warmup``, curvature and Radiance Scaling on a 1080-row frame (whose
    curvature runs on a coarser working grid), and Light Alignment on it with a transmission
    lobe, need no kernel compiled or loaded for new types: the first real frame does not pay a
    compilation."""
    run = subprocess.run([sys.executable, "-c", WARM_COVERS], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.strip().splitlines()[-1] == "[]"


def test_ops_lists_every_registered_operator(capsys: pytest.CaptureFixture[str]) -> None:
    assert depict("ops") == 0
    text = capsys.readouterr().out
    listed = re.findall(r"^(\w+): ", text, re.M)
    assert listed == list(operators())
    for name in ("light_alignment", "unsharp_masking", "depth_unsharp_masking", "apparent_relief"):
        assert name in listed
    assert re.search(r"^    sigmas\s+", text, re.M)  # parameters are listed under each
    # defaults made by a factory are shown as values (lists as JSON), not as pydantic's marker
    assert "Undefined" not in text
    assert re.search(r'^    lights\s+= \["-0.4,0.6,0.7", "0.6,0.2,0.5\*0.35"\]', text, re.M)
    assert depict("ops", "--json") == 0
    schemas = json.loads(capsys.readouterr().out)
    assert [s["name"] for s in schemas] == list(operators())
    la = next(s for s in schemas if s["name"] == "light_alignment")
    assert "sigmas" in la["params"]["properties"] and la["needs"] == ["normal", "depth"]


# -- enhance ------------------------------------------------------------------------------------


def test_enhance_with_op_set_debug_layers_and_output_layer(
    exr: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "la.exr"
    argv = [
        "enhance", exr, "-o", out,
        "--op", "light_alignment", "--set", "sigmas=0.5,0.3", "--set", "form=relight",
        "--op", "unsharp_masking", "--set", "amount=1.5",
        "--debug-layers", "--output-layer", "enh",
    ]  # fmt: skip
    assert depict(*argv) == 0
    assert capsys.readouterr().out.strip() == f"wrote {out}"
    got, src = channels(out), channels(exr)
    assert {"enh.R", "enh.G", "enh.B", "enh.A"} <= set(got)
    assert {f"lla_light.{c}.{a}" for c in ("diffuse", "specular") for a in "XYZ"} <= set(got)
    assert {"lla_light2.diffuse.X", "lla_n1.X", "lla_n2.Y", "lla_n3.Z"} <= set(got)
    assert not any(n.startswith("lla_n4") for n in got)
    assert not any(n.startswith("input.") for n in got)  # R,G,B,A were not replaced
    for c in ("R", "G", "B", "A", "N.X", "depth.Z"):
        np.testing.assert_array_equal(got[c], src[c])
    # the layer holds what the pipeline makes of the file
    spec = [
        {"op": "light_alignment", "params": {"sigmas": [0.5, 0.3], "form": "relight"}},
        {"op": "unsharp_masking", "params": {"amount": 1.5}},
    ]
    made = pipeline.run(gbuffer.read(exr), spec)
    ref = made.buffers["beauty"]
    enh = np.dstack([got["enh.R"], got["enh.G"], got["enh.B"]])
    np.testing.assert_allclose(enh, ref, rtol=2e-3, atol=2e-3)
    assert np.abs(enh - np.dstack([src["R"], src["G"], src["B"]])).max() > 0.02
    # the aligned lights' layers (views of a field in memory) are written plane by plane
    for name in ("lla_light.diffuse.X", "lla_light.specular.Z", "lla_light2.diffuse.Y"):
        assert not made.outputs[name].flags.c_contiguous
        np.testing.assert_allclose(got[name], made.outputs[name], atol=2e-3)


@pytest.mark.parametrize(
    ("value", "lights"),
    [
        ("-0.4,0.6,0.7", ["-0.4,0.6,0.7"]),  # one light as ``depict ops`` writes it
        ("-.4,.6,.7", ["-.4,.6,.7"]),  # (numbers that are not JSON's)
        ("dir:.5,.5,.5", ["dir:.5,.5,.5"]),
        ("point:0,2,1@1,0.9,0.8*4", ["point:0,2,1@1,0.9,0.8*4"]),
        ("-1,1,1@1,0.9,0.8*2", ["-1,1,1@1,0.9,0.8*2"]),  # (a comma list of numbers and text)
        ('["-1,1,1", "1,0,1*0.5"]', ["-1,1,1", "1,0,1*0.5"]),  # several: a JSON list
    ],
)
def test_set_lights_takes_one_light_as_written(
    exr: Path, tmp_path: Path, value: str, lights: list[str]
) -> None:
    out = tmp_path / "lit.exr"
    argv = ["enhance", exr, "-o", out, "--output-layer", "lit"]
    argv += ["--op", "radiance_scaling", "--set", "scenario=phong", "--set", f"lights={value}"]
    assert depict(*argv) == 0
    spec = [{"op": "radiance_scaling", "params": {"scenario": "phong", "lights": lights}}]
    made = pipeline.run(gbuffer.read(exr), spec).buffers["beauty"]
    got = channels(out)
    np.testing.assert_allclose(np.dstack([got[f"lit.{c}"] for c in "RGB"]), made, atol=2e-3)


@pytest.mark.parametrize("op", ["light_warping", "exaggerated_shading"])
def test_set_light_takes_the_baselines_light_as_written(exr: Path, tmp_path: Path, op: str) -> None:
    """``--set light=-1,1,1`` was refused ('Input should be a valid string': the comma list
    arrived as three numbers), the default's own form included."""
    out = tmp_path / "lit.exr"
    assert depict("enhance", exr, "-o", out, "--op", op, "--set", "light=-1,1,1") == 0
    made = pipeline.run(gbuffer.read(exr), [{"op": op, "params": {"light": "-1,1,1"}}])
    got = channels(out)
    beauty = np.dstack([got[f"Depict.{c}"] for c in "RGB"])
    np.testing.assert_allclose(beauty, made.buffers["beauty"], atol=2e-3)


def test_enhance_with_a_pipeline_file(
    exr: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    spec = tmp_path / "pipe.json"
    spec.write_text(
        json.dumps({"steps": [{"op": "apparent_relief", "params": {"style": "counter"}}]})
    )
    out = tmp_path / "relief.exr"
    assert depict("enhance", exr, "-o", out, "--pipeline", spec, "--layout", "same") == 0
    got, src = channels(out), channels(exr)
    assert {"relief.X", "relief.S.X", "relief.S.Y"} <= set(got)
    assert not any(n.startswith("relief.color") for n in got)  # no --debug-layers
    for c in "RGBA":  # the input's beauty is kept beside the new one
        np.testing.assert_array_equal(got[f"input.{c}"], src[c])
    covered = src["A"] > 0.999
    assert set(np.unique(got["R"][covered]).tolist()) <= {0.0, 1.0}
    assert len(np.unique(got["R"][covered])) == 2


def test_enhance_without_steps_runs_the_default_pipeline(exr: Path, tmp_path: Path) -> None:
    """The default layout adds a part: the input's channels come back as they were, the
    result is the ``Depict`` layer that ``depict/result`` names."""
    out = tmp_path / "rs.exr"
    assert depict("enhance", exr, "-o", out) == 0
    got, src = channels(out), channels(exr)
    for name, pixels in src.items():
        np.testing.assert_array_equal(got[name], pixels, err_msg=name)
    with OpenEXR.File(str(out)) as f:
        assert len(f.parts) == 2 and f.parts[1].header["depict/result"] == "Depict"
    assert np.abs(got["Depict.R"] - src["R"]).max() > 1e-3


# -- score, compare -----------------------------------------------------------------------------


def test_score_text_and_json(exr: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert depict("score", exr) == 0
    text = capsys.readouterr().out.strip()
    m = re.fullmatch(
        rf"{re.escape(str(exr))}: congruence score (\d\.\d{{4}}) \(evaluated at {W}x{H}\)", text
    )
    assert m, text
    assert depict("score", exr, "--json") == 0
    data = json.loads(capsys.readouterr().out)
    keys = {"score", "shading_norm", "analysis_shape", "image_shape", "params", "warnings"}
    assert set(data) == keys and data["warnings"] == []
    assert data["shading_norm"] > 0
    assert 0.0 <= data["score"] <= 1.0
    assert f"{data['score']:.4f}" == m.group(1)
    assert data["image_shape"] == [H, W]
    # the score of the frame after a pipeline is the score of the enhanced beauty
    assert depict("score", exr, "--json", "--op", "exaggerated_shading") == 0
    after = json.loads(capsys.readouterr().out)
    assert after["score"] != pytest.approx(data["score"], abs=1e-4)
    assert depict("score", exr, "--json", "--percentile", "50") == 0
    assert json.loads(capsys.readouterr().out)["params"]["percentile"] == 50.0
    # a pinned shading scale far below the image's own saturates e_shading: a different score
    assert depict("score", exr, "--json", "--shading-norm", "1e-9") == 0
    pinned = json.loads(capsys.readouterr().out)
    assert pinned["params"]["shading_norm"] == 1e-9
    assert pinned["score"] != pytest.approx(data["score"], abs=1e-4)


def test_compare_json_plot_and_sheet(
    exr: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    plot, sheet = tmp_path / "plot.png", tmp_path / "sheet.png"
    argv = ["compare", exr, "--directions", "2", "--json", "--plot", plot, "--sheet", sheet]
    assert depict(*argv) == 0
    data = json.loads(capsys.readouterr().out)
    assert "sheet_png" not in data  # the sheet went to its file, as with --server
    assert data["label"] == exr.stem
    assert len(data["directions"]) == 2
    assert set(data["scores"]) == set(data["methods"])
    assert "lambert" in data["methods"] and "light_alignment" in data["methods"]
    for scores in data["scores"].values():
        assert len(scores) == 2 and all(0.0 <= s <= 1.0 for s in scores)
    for path in (plot, sheet):
        img = cv2.imread(str(path))
        assert img is not None and img.shape[0] > 50 and img.shape[1] > 50


def test_compare_text_table(exr: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    plot = tmp_path / "p.png"
    argv = [
        "compare",
        exr,
        "--directions",
        "2",
        "--methods",
        "lambert,light_alignment",
        "--plot",
        plot,
    ]
    assert depict(*argv) == 0
    text = capsys.readouterr().out
    rows = [line for line in text.splitlines() if line.startswith("|")]
    assert rows[0].startswith("| # |") and "Lambert" in rows[0] and "Light Alignment" in rows[0]
    assert len(rows) == 2 + 2 + 1  # header, rule, two directions, mean
    assert f"wrote {plot}" in text and plot.is_file()


def test_compare_renders_a_mesh(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    sheet = tmp_path / "mesh_sheet.png"
    argv = ["compare", SPOT, "--width", "64", "--height", "48", "--directions", "1"]
    assert (
        depict(*argv, "--methods", "lambert,exaggerated_shading", "--json", "--sheet", sheet) == 0
    )
    data = json.loads(capsys.readouterr().out)
    assert data["image_shape"] == [48, 64] and data["label"] == "spot"
    assert data["methods"] == ["lambert", "exaggerated_shading"]
    assert cv2.imread(str(sheet)) is not None


# -- Apparent Relief: relief-pick, arm ----------------------------------------------------------


def test_relief_pick_json_and_text(
    exr: Path, covered_pixel: tuple[int, int], capsys: pytest.CaptureFixture[str]
) -> None:
    x, y = covered_pixel
    assert depict("relief-pick", exr, x, y, "--json") == 0
    data = json.loads(capsys.readouterr().out)
    assert set(data) == {"x", "y", "s", "uv", "region", "r", "curvedness_norm"}
    assert (data["x"], data["y"]) == (x, y)
    s1, s2 = data["s"]
    assert np.hypot(s1, s2) <= 1.0 + 1e-6
    assert data["uv"] == pytest.approx([(s1 + 1) / 2, (s2 + 1) / 2], abs=1e-6)
    assert data["region"] in rl.REGIONS
    assert 0.0 <= data["r"] <= 1.0 and data["curvedness_norm"] > 0.0
    # the pick is what the operator writes at that pixel
    out = pipeline.run(gbuffer.read(exr), [{"op": "apparent_relief"}])
    assert data["r"] == pytest.approx(float(out.outputs["relief.X"][y, x]), abs=1e-6)
    assert s1 == pytest.approx(float(out.outputs["relief.S.X"][y, x]), abs=1e-6)
    # a pinned norm is used and reported
    assert depict("relief-pick", exr, x, y, "--json", "--curvedness-norm", "5") == 0
    assert json.loads(capsys.readouterr().out)["curvedness_norm"] == 5.0
    assert depict("relief-pick", exr, x, y) == 0
    text = capsys.readouterr().out
    assert text.startswith(f"pixel ({x}, {y}): S = (")
    assert "paint it: depict arm -o my_arm.png --paint " in text


def test_arm_template_and_paint(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    tpl = tmp_path / "template.png"
    assert depict("arm", "-o", tpl, "--size", "64") == 0
    assert capsys.readouterr().out.strip() == f"wrote {tpl} (ARM template, 64x64)"
    img = cv2.imread(str(tpl), cv2.IMREAD_UNCHANGED)
    assert img.shape == (64, 64, 3)
    base = "convex_black_concave_white"
    painted, plain = tmp_path / "painted.png", tmp_path / "plain.png"
    s1, s2 = 0.5, -0.2
    argv = ["arm", "-o", painted, "--size", "64", "--base", base, "--paint", f"{s1},{s2}=1"]
    assert depict(*argv) == 0
    assert capsys.readouterr().out.strip() == f"wrote {painted} (ARM, 64x64)"
    assert (
        depict("arm", "-o", plain, "--size", "64", "--base", base, "--paint", f"{s1},{s2}=0") == 0
    )
    a = cv2.imread(str(painted), cv2.IMREAD_UNCHANGED)
    b = cv2.imread(str(plain), cv2.IMREAD_UNCHANGED)
    assert a.shape == b.shape == (64, 64)
    col, row = round((s1 + 1) / 2 * 63), round((1 - (s2 + 1) / 2) * 63)
    assert a[row, col] == 255 and b[row, col] == 0
    far = a.astype(int) - b.astype(int)
    assert far[5, 5] == 0  # painting is local
    # painting on an image keeps what it holds
    repaint = tmp_path / "repaint.png"
    assert (
        depict("arm", "-o", repaint, "--size", "64", "--base", painted, "--paint=-0.5,-0.5=1") == 0
    )
    c = cv2.imread(str(repaint), cv2.IMREAD_UNCHANGED)
    assert c[row, col] == 255
