"""The LLA comparison bench (analysis.compare): methods × directions, scores, tables, pictures."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
import trimesh

from analysis.compare import compare
from analysis.methods import METHODS, resolve_params
from analysis.pictures import contact_sheet, plot
from analysis.result import ComparisonResult
from analysis.score import score_frame
from bench import compare_meshes
from gbuffer.frame import Frame
from gbuffer.render import auto_camera, render
from ops.congruence import congruence
from ops.directions import comparison_directions
from ops.shading import lambert

MODELS = Path(__file__).resolve().parents[2] / "shared" / "models"
SIZE = 96


@pytest.fixture(scope="module")
def frame() -> Frame:
    """A real OSMesa render of an icosphere with radial bumps, seen from the front."""
    mesh = trimesh.creation.icosphere(subdivisions=5)
    v = np.asarray(mesh.vertices, np.float64)
    bump = 0.04 * np.sin(9.0 * v[:, 0]) * np.sin(9.0 * v[:, 1]) * np.sin(9.0 * v[:, 2] + 0.5)
    mesh = trimesh.Trimesh(v * (1.0 + bump)[:, None], mesh.faces, process=False)
    cam = auto_camera(mesh, width=SIZE, height=SIZE, azimuth_deg=0.0, elevation_deg=0.0)
    return render(mesh, SIZE, SIZE, camera=cam, ao="none")


@pytest.fixture(scope="module")
def result(frame: Frame) -> ComparisonResult:
    return compare(frame, directions=3, label="bumpy sphere")


def test_every_method_runs_and_scores_in_unit_interval(result: ComparisonResult) -> None:
    assert result.methods == METHODS
    assert result.numbers == (1, 2, 3)
    assert result.scores.shape == (len(METHODS), 3)
    assert np.all(np.isfinite(result.scores))
    assert np.all((result.scores >= 0.0) & (result.scores <= 1.0))
    assert np.all(result.scores > 0.05)  # a lit, bumpy surface is never scored as shapeless
    for m in METHODS:
        assert len(result.results[m]) == 3
        for k in (1, 2, 3):
            img = result.image(m, k)
            assert img.shape == (SIZE, SIZE) and img.dtype == np.float32
            assert np.all(np.isfinite(img)) and img.min() >= 0.0
            assert img.max() <= 1.0  # display range (Radiance Scaling's σ reaches e^4)
            assert result.score_map(m, k).shape == (SIZE, SIZE)
            assert result.score(m, k) == result.scores[METHODS.index(m), k - 1]
    means = result.means
    for i, m in enumerate(METHODS):
        assert means[m] == pytest.approx(result.scores[i].mean())


def test_methods_differ_from_lambert(result: ComparisonResult) -> None:
    base = result.image("lambert", 2)
    for m in METHODS[1:]:
        assert np.abs(result.image(m, 2) - base).max() > 0.05, m


def test_lambert_method_is_ops_shading_lambert(frame: Frame, result: ComparisonResult) -> None:
    normal = frame.buffers["normal"]
    mask = frame.mask > 0.5
    for k, light in enumerate(comparison_directions(3), start=1):
        expected = np.where(mask, lambert(normal, light), 0.0).astype(np.float32)
        np.testing.assert_allclose(result.image("lambert", k), expected, rtol=0, atol=1e-6)


def test_scores_are_the_congruence_of_the_images(frame: Frame, result: ComparisonResult) -> None:
    """Every rendering is scored on the scale of the frame's Lambert rendering under #1."""
    depth = np.where(frame.mask > 0.5, frame.buffers["depth"], np.inf).astype(np.float32)
    assert result.shading_norm["mode"] == "reference"
    normal = frame.buffers["normal"]
    reference = congruence(result.image("lambert", 1), depth, frame.mask > 0.5, normal=normal)
    assert result.shading_norm["value"] == pytest.approx(reference.shading_norm, rel=1e-6)
    for m in ("lambert", "light_alignment"):
        direct = congruence(
            result.image(m, 3),
            depth,
            frame.mask > 0.5,
            shading_norm=reference.shading_norm,
            normal=normal,
        )
        # the threaded strips sum in varying order: the scale and the score agree to ~1e-9
        assert result.score(m, 3) == pytest.approx(direct.score, abs=1e-7)
        own = congruence(result.image(m, 3), depth, frame.mask > 0.5, normal=normal)
        assert own.shading_norm != pytest.approx(reference.shading_norm)


def test_per_image_normalisation_scores_each_rendering_alone(frame: Frame) -> None:
    res = compare(
        frame, ["lambert", "light_alignment"], directions=[1, 3], shading_norm="per_image"
    )
    depth = np.where(frame.mask > 0.5, frame.buffers["depth"], np.inf).astype(np.float32)
    for m in ("lambert", "light_alignment"):
        normal = frame.buffers["normal"]
        direct = congruence(res.image(m, 3), depth, frame.mask > 0.5, normal=normal)
        assert res.score(m, 3) == pytest.approx(direct.score, abs=1e-9)
    assert res.shading_norm == {"mode": "per_image", "value": None}
    with pytest.raises(ValueError, match="shading_norm"):
        compare(frame, ["lambert"], directions=1, shading_norm="nope")


def test_enhancements_beat_lambert_behind_the_object(frame: Frame) -> None:
    # #5: θ = 120°, the light behind on the right; Lambert leaves most of the sphere dark
    res = compare(frame, directions=[5], keep_images=False)
    lam = res.score("lambert", 5)
    assert res.score("exaggerated_shading", 5) > lam + 0.1
    assert res.score("light_alignment", 5) > lam + 0.05


def test_table_markdown_shape(result: ComparisonResult) -> None:
    lines = result.table_markdown().splitlines()
    assert lines[0].startswith("| # | θ° | φ° | Lambert |")
    rows = [ln for ln in lines if ln.startswith("|")]
    assert len(rows) == 2 + 3 + 1  # header, rule, 3 directions, mean
    for row in rows:
        assert row.count("|") == 3 + len(METHODS) + 1
    mean_cells = [c.strip().strip("*") for c in rows[-1].split("|")[4:-1]]
    assert [float(c) for c in mean_cells] == pytest.approx(
        [round(v, 3) for v in result.means.values()], abs=1e-9
    )
    assert "Light Alignment above Lambert at" in lines[-2]
    assert lines[-1].startswith("Shading strengths: one scale")


def test_to_json_shapes(result: ComparisonResult) -> None:
    data = json.loads(result.to_json())
    assert data["methods"] == list(METHODS)
    assert [d["index"] for d in data["directions"]] == [1, 2, 3]
    for d in data["directions"]:
        assert np.linalg.norm(d["vector"]) == pytest.approx(1.0, abs=1e-5)
    assert data["directions"][0]["theta_deg"] == pytest.approx(0.0)
    assert data["directions"][2]["theta_deg"] == pytest.approx(60.0)
    assert set(data["scores"]) == set(METHODS)
    assert all(len(v) == 3 for v in data["scores"].values())
    assert data["means"] == pytest.approx(result.means)
    assert data["claim"]["baseline"] == "lambert"
    assert data["params"]["radiance_scaling"]["alpha"] == 0.5
    assert data["params"]["radiance_scaling"]["gamma"] == 4.0
    assert data["image_shape"] == [SIZE, SIZE]


def test_plot_and_contact_sheet_are_written(result: ComparisonResult, tmp_path: Path) -> None:
    p = plot(result, tmp_path / "plot.png")
    img = cv2.imread(str(p))
    assert img is not None and img.shape[0] > 200 and img.shape[1] > 400
    assert img.std() > 10  # not a blank canvas
    s = contact_sheet(result, tmp_path / "sub" / "sheet.png", directions=[1, 3], tile=64)
    sheet = cv2.imread(str(s))
    assert sheet is not None
    assert sheet.shape[0] >= 2 * 64 and sheet.shape[1] >= 2 * len(METHODS) * 16
    # the score-map tiles are coloured (red ... blue), the renderings grey
    assert np.abs(sheet[..., 0].astype(int) - sheet[..., 2].astype(int)).max() > 60


def test_subset_of_directions_and_kept_images(frame: Frame) -> None:
    res = compare(frame, ["lambert", "light_warping"], directions=[1, 7], keep_images=[7])
    assert res.numbers == (1, 7)
    np.testing.assert_allclose(res.directions, comparison_directions(21)[[0, 6]])
    assert res.score("lambert", 7) == res.scores[0, 1]
    res.image("lambert", 7)
    with pytest.raises(ValueError, match="not kept"):
        res.image("lambert", 1)
    with pytest.raises(ValueError, match="direction"):
        res.score("lambert", 3)
    with pytest.raises(ValueError, match="not compared"):
        res.score("light_alignment", 1)
    assert "| 7 |" in res.table_markdown()


def test_albedo_frame_multiplies_the_white_rendering(frame: Frame) -> None:
    f = frame.copy()
    alb = np.zeros((SIZE, SIZE, 3), np.float32)
    alb[..., 0], alb[..., 1], alb[..., 2] = 0.9, 0.5, 0.2
    f.buffers["albedo"] = alb
    white = compare(f, ["lambert"], directions=[2])
    coloured = compare(f, ["lambert"], directions=[2], albedo="frame")
    img = coloured.image("lambert", 2)
    assert img.shape == (SIZE, SIZE, 3)
    np.testing.assert_allclose(img, alb * white.image("lambert", 2)[..., None], atol=1e-7)


def test_score_frame_scores_the_beauty(frame: Frame) -> None:
    out = score_frame(frame, maps=True)
    normal = frame.buffers["normal"]
    direct = congruence(frame.buffers["beauty"], frame.buffers["depth"], frame.mask, normal=normal)
    assert out["score"] == pytest.approx(direct.score, abs=1e-9)
    assert out["params"]["shape"] == "normals"
    by_depth = score_frame(frame, shape="depth")
    plain = congruence(frame.buffers["beauty"], frame.buffers["depth"], frame.mask)
    assert by_depth["score"] == pytest.approx(plain.score, abs=1e-9)
    assert by_depth["score"] != pytest.approx(out["score"], abs=1e-3)
    assert 0.0 < out["score"] <= 1.0
    assert out["image_shape"] == [SIZE, SIZE]
    layers = out["layers"]
    assert set(layers) >= {"congruence.X", "congruence.shading.X", "congruence.shape.Y"}
    assert all(a.shape == (SIZE, SIZE) and a.dtype == np.float32 for a in layers.values())
    coarse = score_frame(frame, integration_scale=0.05)
    assert coarse["params"]["integration_scale"] == 0.05
    assert coarse["score"] != out["score"]


def test_method_sections_are_their_operators_parameters(frame: Frame) -> None:
    """Radiance Scaling is the registry's operator: its γ = 0 (σ ≡ 1) leaves the Lambert term."""
    lam = compare(frame, ["lambert", "radiance_scaling"], directions=[3])
    flat = compare(
        frame, ["radiance_scaling"], directions=[3], params={"radiance_scaling": {"gamma": 0}}
    )
    assert lam.params["radiance_scaling"]["scenario"] == "phong"
    assert flat.params["radiance_scaling"]["gamma"] == 0
    np.testing.assert_allclose(
        flat.image("radiance_scaling", 3), lam.image("lambert", 3), rtol=0, atol=1e-6
    )
    assert np.abs(lam.image("radiance_scaling", 3) - lam.image("lambert", 3)).max() > 0.05
    with pytest.raises(ValueError, match="'lights' is set by the comparison"):
        resolve_params({"light_alignment": {"lights": ["0,0,1"]}})
    with pytest.raises(ValueError, match="'light' is set by the comparison"):
        resolve_params({"light_warping": {"light": "0,0,1"}})
    with pytest.raises(ValueError, match="Lambert takes no parameters"):
        resolve_params({"lambert": {"gamma": 1}})


def test_bad_arguments_raise_value_errors(frame: Frame) -> None:
    with pytest.raises(ValueError, match="unknown method 'phong'"):
        compare(frame, ["lambert", "phong"], directions=1)
    with pytest.raises(ValueError, match="at least one"):
        compare(frame, [], directions=1)
    with pytest.raises(ValueError, match=r"directions must be in \[1, 21\]"):
        compare(frame, directions=22)
    with pytest.raises(ValueError, match="direction numbers"):
        compare(frame, directions=[0, 3])
    with pytest.raises(ValueError, match="albedo"):
        compare(frame, directions=1, albedo="red")
    with pytest.raises(ValueError, match="unknown section 'phong'"):
        resolve_params({"phong": {}})
    for key in ("foo", "weights", "normal"):  # ('weights' was a TypeError: given twice)
        with pytest.raises(ValueError, match=f"congruence.*unknown parameter '{key}'"):
            compare(frame, ["lambert"], directions=1, params={"congruence": {key: 1}})
    with pytest.raises(ValueError, match="radiance_scaling"):
        compare(frame, ["radiance_scaling"], directions=1, params={"radiance_scaling": {"x": 1}})
    with pytest.raises(ValueError, match="alpha"):
        compare(
            frame, ["radiance_scaling"], directions=1, params={"radiance_scaling": {"alpha": 2}}
        )
    with pytest.raises(ValueError, match="sigmas"):
        compare(
            frame, ["light_alignment"], directions=1, params={"light_alignment": {"sigmas": [2]}}
        )
    no_depth = Frame(buffers={"normal": frame.buffers["normal"]})
    with pytest.raises(ValueError, match="depth"):
        compare(no_depth, directions=1)


@pytest.mark.models
def test_bench_script_on_a_real_mesh(tmp_path: Path) -> None:
    if not (MODELS / "spot.obj").is_file():
        pytest.skip(f"{MODELS / 'spot.obj'} is absent (the shared test meshes are not checked out)")
    out = tmp_path / "bench"
    rc = compare_meshes.main(
        [
            str(out),
            "--meshes",
            "spot",
            "--size",
            "64",
            "--directions",
            "3",
            "--methods",
            "lambert,light_alignment",
            "--models",
            str(MODELS),
            "--quiet",
        ]
    )
    assert rc == 0
    for name in ("spot.md", "spot.json", "spot_plot.png", "spot_sheet.png", "summary.md"):
        assert (out / name).stat().st_size > 100, name
    data = json.loads((out / "spot.json").read_text())
    assert data["methods"] == ["lambert", "light_alignment"]
    assert len(data["scores"]["lambert"]) == 3
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["meshes"]) == {"spot"}


def test_a_frame_without_usable_normals_scores_zero_instead_of_failing(frame: Frame) -> None:
    """(The reference rendering's shading scale was 0 and was passed on as a parameter out of
    range: "shading_norm=0.0 is outside the allowed range".)"""
    flat = frame.copy()
    flat.buffers = {**frame.buffers, "normal": np.zeros_like(frame.buffers["normal"])}
    res = compare(flat, ["lambert", "radiance_scaling"], directions=[1], keep_images=False)
    assert np.all(res.scores == 0.0)
    assert res.shading_norm["mode"] == "reference"
