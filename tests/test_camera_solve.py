"""Cameras solved from world-space position passes (gbuffer.camera_solve), against true cameras.

The Blender fixture's camera.json is the camera Blender rendered with; Blender renders of other
frames (landscape and portrait with sensor fit AUTO, orthographic) are made here when Debian's
``blender`` is installed. Synthetic frames cover what a renderer does not make easy: a data window
inside the display window, a scene that is one plane, a lens shift Depict's model cannot hold.
"""

from __future__ import annotations

import json
import math
import re
import shutil
import subprocess
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import OpenEXR
import pytest

import gbuffer
from gbuffer.camera import Camera
from gbuffer.camera_solve import MIN_POINTS, solve_camera, usable_pixels
from gbuffer.errors import FrameError
from tests import exr_factory as F

ROOT = Path(__file__).resolve().parents[1]
FIXTURE = ROOT / "tests" / "fixtures" / "blender"
BLENDER = shutil.which("blender")
needs_blender = pytest.mark.skipif(BLENDER is None, reason="Debian's blender is not installed")


def pose_error(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """(rotation angle between two world-to-camera matrices in degrees, camera centre distance)."""
    d = a[:3, :3] @ b[:3, :3].T
    skew = np.array([d[2, 1] - d[1, 2], d[0, 2] - d[2, 0], d[1, 0] - d[0, 1]]) / 2.0
    angle = math.degrees(math.asin(min(1.0, float(np.linalg.norm(skew)))))
    ca = -a[:3, :3].T @ a[:3, 3]
    cb = -b[:3, :3].T @ b[:3, 3]
    return angle, float(np.linalg.norm(ca - cb))


def assert_same_camera(solved: Camera, true: Camera, fov_deg: float = 0.01) -> None:
    assert solved.projection == true.projection
    assert solved.world_to_camera is not None and true.world_to_camera is not None
    if true.projection == "perspective":
        assert solved.fov_y_deg is not None and true.fov_y_deg is not None
        assert abs(solved.fov_y_deg - true.fov_y_deg) < fov_deg, (solved.fov_y_deg, true)
    else:
        assert solved.ortho_height == pytest.approx(true.ortho_height, rel=1e-4)
    angle, distance = pose_error(solved.world_to_camera, true.world_to_camera)
    assert angle < fov_deg and distance < 1e-3, (angle, distance)


# -- synthetic frames ------------------------------------------------------------------------------


def world_points(
    camera: Camera, shape: tuple[int, int], display: tuple[int, int], origin: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray]:
    """(world points of a wavy surface seen through ``camera``, its planar depth)."""
    h, w = shape
    rows, cols = np.mgrid[0:h, 0:w].astype(np.float64)
    depth = 4.0 + 0.8 * np.sin(cols / 7.0) * np.cos(rows / 5.0) + 0.02 * cols
    dw, dh = display
    if camera.projection == "orthographic":
        assert camera.ortho_height is not None
        px = camera.ortho_height / dh
        xc = (cols + origin[0] + 0.5 - dw / 2.0) * px
        yc = (dh / 2.0 - rows - origin[1] - 0.5) * px
    else:
        xs, ys = camera.image_coordinates(shape, display, origin)
        xc, yc = xs[None, :] * depth, -ys[:, None] * depth
    pc = np.stack([xc, yc, -depth, np.ones_like(depth)], -1)
    assert camera.world_to_camera is not None
    pw = pc @ np.linalg.inv(camera.world_to_camera).T
    return pw[..., :3].astype(np.float32), depth.astype(np.float32)


@pytest.mark.parametrize(
    "camera",
    [
        Camera(world_to_camera=F.look_at((3.0, -2.5, 1.5), (0.2, 0.1, 0.3)), fov_y_deg=40.0),
        Camera(world_to_camera=F.look_at((-6.0, 1.0, 4.0), (0.0, 0.0, 0.5)), fov_y_deg=12.0),
        Camera(
            world_to_camera=F.look_at((2.0, 5.0, 3.0), (0.0, 0.0, 0.0)),
            projection="orthographic",
            ortho_height=3.5,
        ),
    ],
    ids=["perspective", "telephoto", "orthographic"],
)
def test_solve_with_a_data_window_inside_the_display_window(camera: Camera) -> None:
    display, origin, shape = (120, 90), (17, 9), (60, 80)
    points, depth = world_points(camera, shape, display, origin)
    covered = np.ones(shape, bool)
    covered[:, :8] = False  # background, its points left at 0
    points[~covered] = 0.0
    solved, fit = solve_camera(points, covered, display, origin, depth)
    assert_same_camera(solved, camera, fov_deg=1e-3)
    assert fit.rms_px < 1e-3 and fit.outliers == 0 and fit.pixels > 1000


def test_points_on_one_plane_still_give_the_perspective_camera() -> None:
    camera = Camera(world_to_camera=F.look_at((0.5, -4.0, 2.5), (0.0, 0.0, 0.0)), fov_y_deg=35.0)
    shape = (72, 96)
    xs, ys = camera.image_coordinates(shape, (96, 72))
    assert camera.world_to_camera is not None
    c2w = np.linalg.inv(camera.world_to_camera)
    rays = np.stack(np.broadcast_arrays(xs[None, :], -ys[:, None], -1.0), -1) @ c2w[:3, :3].T
    eye = c2w[:3, 3]
    t = -eye[2] / rays[..., 2]  # the ground plane z = 0
    covered = t > 0
    points = np.where(covered[..., None], eye + t[..., None] * rays, 0.0).astype(np.float32)
    solved, fit = solve_camera(points, covered, (96, 72))
    assert_same_camera(solved, camera, fov_deg=1e-2)
    assert fit.rms_px < 1e-2


def test_a_lens_shift_shows_in_the_reprojection_error() -> None:
    camera = Camera(world_to_camera=F.look_at((3.0, -2.5, 1.5), (0.2, 0.1, 0.3)), fov_y_deg=40.0)
    points, _ = world_points(camera, (60, 80), (80, 60), (0, 0))
    # a renderer with a lens shift: the same points seen 6 pixels to the right
    shifted, _ = world_points(camera, (60, 86), (86, 60), (0, 0))
    _, fit = solve_camera(shifted[:, 6:], np.ones((60, 80), bool), (80, 60))
    _, exact = solve_camera(points, np.ones((60, 80), bool), (80, 60))
    assert exact.rms_px < 1e-3 and fit.rms_px > 0.05


def test_too_few_points_are_refused() -> None:
    points = np.zeros((8, 8, 3), np.float32)
    with pytest.raises(FrameError, match="usable pixels"):
        solve_camera(points, np.zeros((8, 8), bool), (8, 8))


# -- the Blender fixture and fresh Blender renders -------------------------------------------------


def test_blender_fixture_camera_is_solved_to_hundredths_of_a_degree() -> None:
    frame = gbuffer.read(FIXTURE / "cycles_multilayer.exr")
    true = Camera.from_json_file(FIXTURE / "camera.json")
    assert frame.camera is not None
    assert frame.camera.source == "solved from ViewLayer.Position.X,Y,Z (world positions)"
    assert_same_camera(frame.camera, true, fov_deg=1e-3)
    assert frame.camera.fit is not None and frame.camera.fit["rms_px"] < 1e-3
    # the normals are converted with it exactly as with the true camera
    given = gbuffer.read(FIXTURE / "cycles_multilayer.exr", camera=true)
    diff = np.abs(frame.buffers["normal"] - given.buffers["normal"])
    assert float(diff.max()) < 1e-4


def test_a_wrong_field_of_view_is_reported_in_pixels() -> None:
    data = json.loads((FIXTURE / "camera.json").read_text())
    data["fov_y_deg"] = 33.4  # the sensor's angle_y instead of the image's 37.3
    frame = gbuffer.read(FIXTURE / "cycles_multilayer.exr", camera=data)
    assert frame.camera is not None and frame.camera.fit is not None
    assert frame.camera.fit["rms_px"] > 3.0
    info = gbuffer.describe(frame)
    assert any("px (RMS) away from their pixels" in w for w in info["warnings"])


def render_blender(tmp: Path, *args: Any) -> tuple[Path, Camera, float]:
    """A Blender render of tests/blender/camera_frame.py: (EXR, true camera, angle_y)."""
    exr, cam = tmp / "frame.exr", tmp / "camera.json"
    script = ROOT / "tests" / "blender" / "camera_frame.py"
    assert BLENDER is not None
    cmd = [BLENDER, "-b", "--factory-startup", "--python", str(script), "--", str(exr), str(cam)]
    subprocess.run([*cmd, *map(str, args)], check=True, capture_output=True, timeout=300)
    data = json.loads(cam.read_text())
    angle_y = data.pop("blender_angle_y_deg")
    return exr, Camera.from_dict(data), angle_y


@needs_blender
@pytest.mark.parametrize(
    "args",
    [
        (240, 135, "PERSP", "AUTO", 35),
        (135, 240, "PERSP", "AUTO", 35),
        (240, 135, "PERSP", "VERTICAL", 50),
        (200, 150, "ORTHO", "AUTO", 6),
    ],
    ids=["landscape", "portrait", "vertical-fit", "orthographic"],
)
def test_fresh_blender_renders(tmp_path: Path, args: tuple[Any, ...]) -> None:
    exr, true, angle_y = render_blender(tmp_path, *args)
    frame = gbuffer.read(exr)
    assert frame.camera is not None and frame.camera.fit is not None
    assert_same_camera(frame.camera, true)
    assert frame.camera.fit["rms_px"] < 0.01
    if args[:2] == (240, 135) and args[3] == "AUTO":
        assert true.fov_y_deg is not None and abs(angle_y - true.fov_y_deg) > 3  # the trap


# -- inspect says what it found and what is missing ------------------------------------------------


def inspect_text(path: Path, *flags: str) -> tuple[int, str, str]:
    import contextlib
    import io

    from service.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(["inspect", str(path), *flags])
    return code, out.getvalue(), err.getvalue()


def test_inspect_of_a_blender_frame_shows_the_solved_camera_and_its_error() -> None:
    code, text, _ = inspect_text(FIXTURE / "cycles_multilayer.exr")
    assert code == 0
    assert "camera source: solved from ViewLayer.Position.X,Y,Z (world positions)" in text
    assert re.search(r"reprojection error against the position pass: RMS \S+ px", text)
    assert "operators: every one can run" in text
    code, text, _ = inspect_text(
        FIXTURE / "cycles_multilayer.exr", "--camera", str(FIXTURE / "camera.json")
    )
    assert code == 0 and "camera source: given" in text


def test_inspect_says_what_is_missing_instead_of_failing(tmp_path: Path) -> None:
    scene = F.make_scene()
    path = F.write_blender(tmp_path / "b.exr", scene, position=False)  # world normals, no camera
    code, text, err = inspect_text(path)
    assert code == 0 and err == ""
    assert "camera: none" in text and "missing: camera: none in the file" in text
    assert "missing: normal:" in text
    assert re.search(r"cannot run: curvature \(needs normal\)", text)
    assert "warning: normals ViewLayer.Normal.X,Y,Z left out" in text


def test_inspect_describes_a_file_with_nan_in_a_data_pass(tmp_path: Path) -> None:
    scene = F.make_scene()
    path = F.write_blender(tmp_path / "b.exr", scene)
    with OpenEXR.File(str(path), separate_channels=True) as f:
        header = dict(f.header())
        chans = {n: np.array(c.pixels) for n, c in f.channels().items()}
    ys, xs = np.nonzero(np.isfinite(scene.depth))
    chans["ViewLayer.Normal.Y"][ys[5], xs[5]] = np.nan  # on a covered pixel
    bad = tmp_path / "nan.exr"
    with OpenEXR.File(
        {"compression": header["compression"], "BlenderMultiChannel": "x"}, chans
    ) as f:
        f.write(str(bad))
    with pytest.raises(FrameError, match="NaN"):
        gbuffer.read(bad)
    code, text, _ = inspect_text(bad, "--json")
    assert code == 0
    info = json.loads(text)
    assert "normal" in info["buffers"] and len(info["parts"]) == 1
    assert any("NaN" in w for w in info["warnings"])  # masked, and said so


def test_usable_pixels_are_covered_finite_non_zero_points_with_usable_neighbours() -> None:
    rng = np.random.default_rng(1)
    points = rng.random((200, 300, 3)).astype(np.float32)
    points.reshape(-1)[::997] = np.nan
    points.reshape(-1)[1::1201] = np.inf
    points.reshape(-1)[2::5] = 0.0  # some components zero: still usable
    points[50:60, 50:60] = 0.0  # all three zero: not
    covered = rng.random((200, 300)) > 0.1
    ok = covered & np.isfinite(points).all(axis=-1) & (points != 0.0).any(axis=-1)
    inner = cv2.erode(ok.astype(np.uint8), np.ones((3, 3), np.uint8), borderValue=0) > 0
    got = usable_pixels(points, covered)
    assert inner.sum() >= MIN_POINTS and np.array_equal(got, inner)
    few = np.zeros_like(covered)
    few[:3, :3] = True  # too few inner pixels: every usable covered one
    assert np.array_equal(usable_pixels(points, few), few & ok)
