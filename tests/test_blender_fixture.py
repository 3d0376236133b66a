"""Consistency of the Blender Cycles fixture (tests/fixtures/blender) with its camera.json.

The fixture is a real Cycles render (see tests/fixtures/blender/README.md and make_fixture.py).
These tests read it with OpenEXR directly, not through Depict's EXR reader, and check the
conventions Depict relies on: planar depth equal to -z_camera of the world-space Position, the
camera JSON projecting Position onto pixel centres, world-space Normal (unit inside smooth
surfaces, shorter at anti-aliased edges), and Combined equal to the sum of the lobes.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import OpenEXR
import pytest

from gbuffer.camera import Camera

FIXTURE = Path(__file__).parent / "fixtures" / "blender"
EXR = FIXTURE / "cycles_multilayer.exr"
WIDTH, HEIGHT = 160, 120
LAYER = "ViewLayer"
RGB_PASSES = (
    "DiffDir", "DiffInd", "DiffCol", "GlossDir", "GlossInd", "GlossCol",
    "TransDir", "TransInd", "TransCol", "AO", "Emit", "Env",
)  # fmt: skip
EXPECTED_CHANNELS = (
    {f"{LAYER}.Combined.{c}" for c in "RGBA"}
    | {f"{LAYER}.Depth.Z"}
    | {f"{LAYER}.Normal.{c}" for c in "XYZ"}
    | {f"{LAYER}.Position.{c}" for c in "XYZ"}
    | {f"{LAYER}.{p}.{c}" for p in RGB_PASSES for c in "RGB"}
)
BACKGROUND_DEPTH = 1e10


@pytest.fixture(scope="module")
def exr() -> Any:
    assert EXR.is_file(), f"missing fixture {EXR}: regenerate it (tests/fixtures/blender/README.md)"
    return OpenEXR.File(str(EXR), separate_channels=True)


@pytest.fixture(scope="module")
def buf(exr: Any) -> dict[str, np.ndarray]:
    """Each pass as a float64 (H, W) or (H, W, C) array."""
    ch = exr.parts[0].channels

    def stack(name: str, comps: str) -> np.ndarray:
        return np.stack([ch[f"{LAYER}.{name}.{c}"].pixels for c in comps], -1).astype(np.float64)

    out = {p: stack(p, "RGB") for p in (*RGB_PASSES, "Combined")}
    out["Depth"] = ch[f"{LAYER}.Depth.Z"].pixels.astype(np.float64)
    out["Normal"] = stack("Normal", "XYZ")
    out["Position"] = stack("Position", "XYZ")
    return out


@pytest.fixture(scope="module")
def camera_json() -> dict[str, Any]:
    return dict(json.loads((FIXTURE / "camera.json").read_text()))


@pytest.fixture(scope="module")
def scene() -> dict[str, Any]:
    return dict(json.loads((FIXTURE / "scene.json").read_text()))


def to_camera(points: np.ndarray, w2c: np.ndarray) -> np.ndarray:
    return points @ w2c[:3, :3].T + w2c[:3, 3]


def project(points: np.ndarray, cam: dict[str, Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World points -> (col, row, camera-space points); pixel centres at integer col/row."""
    pc = to_camera(points, np.asarray(cam["world_to_camera"], dtype=np.float64))
    f = 0.5 * HEIGHT / math.tan(math.radians(cam["fov_y_deg"]) / 2.0)
    col = pc[..., 0] / -pc[..., 2] * f + WIDTH / 2.0 - 0.5
    row = HEIGHT / 2.0 - 0.5 - pc[..., 1] / -pc[..., 2] * f
    return col, row, pc


def erode(mask: np.ndarray, px: int) -> np.ndarray:
    kernel = np.ones((2 * px + 1, 2 * px + 1), np.uint8)
    return cv2.erode(mask.astype(np.uint8), kernel, borderValue=0).astype(bool)


def test_header_channels_and_storage(exr: Any) -> None:
    assert len(exr.parts) == 1
    header = exr.parts[0].header
    assert header["BlenderMultiChannel"] == "Blender V2.55.1 and newer"
    assert "worldToCamera" not in header  # Blender writes no camera: camera.json carries it
    assert header["compression"] == OpenEXR.ZIP_COMPRESSION
    lo, hi = header["dataWindow"]
    assert (hi[0] - lo[0] + 1, hi[1] - lo[1] + 1) == (WIDTH, HEIGHT)
    channels = exr.parts[0].channels
    assert set(channels) == EXPECTED_CHANNELS
    for name, ch in channels.items():
        assert ch.pixels.dtype == np.float32, name
        assert ch.pixels.shape == (HEIGHT, WIDTH), name


def test_camera_json_is_depict_form_and_rigid(camera_json: dict[str, Any], scene: dict) -> None:
    assert set(camera_json) == {"world_to_camera", "fov_y_deg", "projection"}
    cam = Camera.from_dict(camera_json)
    assert cam.projection == "perspective"
    w2c = cam.world_to_camera
    assert w2c is not None
    np.testing.assert_allclose(w2c[3], [0.0, 0.0, 0.0, 1.0])
    rot = w2c[:3, :3]
    np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-6)
    assert np.linalg.det(rot) == pytest.approx(1.0, abs=1e-6)
    # the camera sits where scene.json says (the inverse maps the origin there)
    np.testing.assert_allclose(np.linalg.inv(w2c)[:3, 3], scene["camera"]["location"], atol=1e-5)
    # sensor fit AUTO on a landscape frame: the sensor width spans the horizontal field of view
    c = scene["camera"]
    half_x = c["sensor_width_mm"] / (2.0 * c["lens_mm"])
    assert camera_json["fov_y_deg"] == pytest.approx(
        math.degrees(2.0 * math.atan(half_x * HEIGHT / WIDTH)), abs=1e-9
    )


def test_background_values(buf: dict[str, np.ndarray], scene: dict[str, Any]) -> None:
    bg = buf["Depth"] >= 1e9
    assert 0.1 < bg.mean() < 0.6
    assert np.all(buf["Depth"][bg] == BACKGROUND_DEPTH)
    assert np.all(buf["Position"][bg] == 0.0)
    deep = erode(bg, 3)  # away from anti-aliased edges
    assert np.all(buf["Normal"][deep] == 0.0)
    assert np.all(buf["AO"][deep] == 0.0)
    np.testing.assert_allclose(buf["Env"][deep], np.broadcast_to(
        scene["world"]["background_color"], buf["Env"][deep].shape), atol=1e-6)  # fmt: skip


def test_depth_is_planar_minus_z_of_position(buf: dict, camera_json: dict[str, Any]) -> None:
    fg = buf["Depth"] < 1e9
    z_cam = to_camera(buf["Position"][fg], np.asarray(camera_json["world_to_camera"]))[:, 2]
    assert np.all(z_cam < 0.0)  # in front of an OpenGL camera
    np.testing.assert_allclose(buf["Depth"][fg], -z_cam, rtol=0, atol=1e-4)  # measured 1.4e-6


def test_position_projects_onto_pixel_centres(buf: dict, camera_json: dict[str, Any]) -> None:
    """Depth and Position are point samples of the pixel-centre ray (not filtered)."""
    fg = buf["Depth"] < 1e9
    col, row, _ = project(buf["Position"], camera_json)
    cols, rows = np.meshgrid(np.arange(WIDTH), np.arange(HEIGHT))
    assert np.abs(col - cols)[fg].max() < 0.01  # measured 0.001 px
    assert np.abs(row - rows)[fg].max() < 0.01


def test_camera_view_vectors_match_position(buf: dict, camera_json: dict[str, Any]) -> None:
    """Depict's Camera.view_vectors points from each pixel's surface point to the eye."""
    cam = Camera.from_dict(camera_json)
    fg = buf["Depth"] < 1e9
    pc = to_camera(buf["Position"], np.asarray(camera_json["world_to_camera"]))
    to_eye = -pc / np.linalg.norm(pc, axis=-1, keepdims=True)
    v = cam.view_vectors((HEIGHT, WIDTH), (WIDTH, HEIGHT)).astype(np.float64)
    assert np.abs(v - to_eye)[fg].max() < 1e-4
    # and the pixel size at depth: focal length in pixels from the same field of view
    f = cam.focal_px(HEIGHT)
    np.testing.assert_allclose(-pc[fg][:, 0] / pc[fg][:, 2] * f + WIDTH / 2 - 0.5,
                               np.nonzero(fg)[1], atol=0.01)  # fmt: skip


def test_sphere_centre_projects_onto_the_sphere(buf: dict, camera_json: dict, scene: dict) -> None:
    sphere = scene["objects"]["Sphere"]
    centre, radius = np.asarray(sphere["location"]), float(sphere["radius"])
    col, row, _ = project(centre[None], camera_json)
    c, r = round(float(col[0])), round(float(row[0]))
    assert 0 <= c < WIDTH and 0 <= r < HEIGHT
    dist = np.linalg.norm(buf["Position"] - centre, axis=-1)
    assert dist[r, c] == pytest.approx(radius, abs=0.005)
    on_sphere = (buf["Depth"] < 1e9) & (np.abs(dist - radius) < 0.01)
    assert on_sphere.sum() > 500
    rows, cols = np.nonzero(on_sphere)
    assert cols.mean() == pytest.approx(col[0], abs=0.3)  # measured 0.04 px
    assert rows.mean() == pytest.approx(row[0], abs=0.3)


def test_normals_are_world_space(buf: dict[str, np.ndarray], scene: dict[str, Any]) -> None:
    n, p = buf["Normal"], buf["Position"]
    fg = buf["Depth"] < 1e9
    # ground plane (z = 0): world normal +Z exactly; in camera space it would be far from it
    ground = erode(fg & (np.abs(p[..., 2]) < 1e-4), 2)
    assert ground.sum() > 3000
    assert np.abs(n[ground] - [0.0, 0.0, 1.0]).max() < 1e-4
    # sphere interior: normal along P - centre (world space), unit to within the averaging
    sphere = scene["objects"]["Sphere"]
    centre, radius = np.asarray(sphere["location"]), float(sphere["radius"])
    radial = p - centre
    dist = np.linalg.norm(radial, axis=-1)
    inner = erode(fg & (np.abs(dist - radius) < 0.01), 2)
    length = np.linalg.norm(n[inner], axis=-1)
    assert 0.995 < length.min() and length.max() < 1.0005
    cos = np.sum(n[inner] / length[:, None] * radial[inner] / dist[inner][:, None], axis=-1)
    assert np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).max() < 1.0  # measured 0.4 degrees


def test_normals_shorten_at_antialiased_edges(buf: dict[str, np.ndarray]) -> None:
    """Normal is the filter-weighted mean of the samples: shorter where they disagree."""
    length = np.linalg.norm(buf["Normal"], axis=-1)
    bg = buf["Depth"] >= 1e9
    fg_edge = ~bg & ~erode(~bg, 1)
    assert length[fg_edge].min() < 0.6  # measured 0.31
    assert np.any(length[bg] > 0.1)  # background pixels partly covered by an object
    assert length.max() < 1.0 + 1e-5


def test_combined_is_sum_of_lobes_emission_and_environment(buf: dict[str, np.ndarray]) -> None:
    lobes = sum(
        (buf[f"{k}Dir"] + buf[f"{k}Ind"]) * buf[f"{k}Col"] for k in ("Diff", "Gloss", "Trans")
    )
    total = lobes + buf["Emit"] + buf["Env"]
    assert np.abs(buf["Combined"] - total).max() < 1e-4  # measured 1.3e-6
    for k in ("DiffDir", "GlossDir", "TransDir", "TransInd", "Emit"):
        assert buf[k].max() > 0.02, k  # every lobe is exercised


def test_ao_channels_are_equal(buf: dict[str, np.ndarray]) -> None:
    ao = buf["AO"]
    assert np.array_equal(ao[..., 0], ao[..., 1]) and np.array_equal(ao[..., 0], ao[..., 2])
    assert 0.0 <= ao.min() and ao.max() <= 1.0
