"""Mesh rendering (gbuffer.render): real OSMesa renders into float32 G-buffers."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest
import trimesh
from PIL import Image

from gbuffer.camera import Camera
from gbuffer.errors import FrameError
from gbuffer.frame import BUFFERS, RENDER_BUFFERS
from gbuffer.mesh import FILE_NORMALS
from gbuffer.render import (
    Rasterizer,
    auto_camera,
    canonical_outputs,
    channel_names,
    load_mesh,
    look_at,
    render,
)
from gbuffer.subdivision import View, levels_for
from gbuffer.surface import smooth_surface
from ops.shading import Light
from service import pipeline

MODELS = Path(__file__).resolve().parents[2] / "shared" / "models"
SPOT = Path(__file__).resolve().parents[1] / "examples" / "spot.obj"
W, H = 160, 120
DIST = 3.0
FOV = 40.0


@pytest.fixture(scope="module")
def sphere() -> trimesh.Trimesh:
    return trimesh.creation.icosphere(subdivisions=6)  # 82k faces, edges ≈ 1°


def front_camera(distance: float = DIST, fov: float = FOV) -> Camera:
    """A camera on +z looking at the origin."""
    w2c = np.eye(4)
    w2c[2, 3] = -distance
    return Camera(world_to_camera=w2c, fov_y_deg=fov)


def analytic_sphere(
    camera: Camera, width: int, height: int, centre: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact ray / unit-sphere intersection per pixel centre: (disc, position, normal)."""
    f = camera.focal_px(height)
    x = (np.arange(width) + 0.5 - width / 2) / f
    y = -(np.arange(height) + 0.5 - height / 2) / f
    gx, gy = np.meshgrid(x, y)
    d = np.stack([gx, gy, -np.ones_like(gx)], axis=2)
    d /= np.linalg.norm(d, axis=2, keepdims=True)
    b = -(d @ centre)
    disc = b * b - (centre @ centre - 1.0)
    t = -b - np.sqrt(np.maximum(disc, 0.0))
    p = d * t[..., None]
    return disc, p, p - centre


@pytest.fixture(scope="module")
def sphere_frame(sphere: trimesh.Trimesh):  # type: ignore[no-untyped-def]
    return render(sphere, W, H, camera=front_camera())


# -- geometry against the analytic sphere ----------------------------------------------------


def test_sphere_normals_match_the_analytic_normals(sphere_frame) -> None:  # type: ignore[no-untyped-def]
    disc, _, n_exact = analytic_sphere(front_camera(), W, H, np.array([0.0, 0.0, -DIST]))
    n = sphere_frame.buffers["normal"]
    interior = disc > 0.05 * disc.max()  # away from the silhouette
    cos = np.clip((n.astype(np.float64) * n_exact).sum(axis=2), -1.0, 1.0)
    err = np.degrees(np.arccos(cos))[interior]
    assert err.max() < 0.1, err.max()
    # unit length, facing the camera, 0 on background
    cover = sphere_frame.buffers["coverage"] > 0
    np.testing.assert_allclose(np.linalg.norm(n[cover], axis=1), 1.0, atol=1e-5)
    view = sphere_frame.view_vectors()
    assert np.all((n * view).sum(axis=2)[interior] > 0.0)
    assert np.all(n[~cover] == 0.0)


def test_sphere_depth_position_and_coverage(sphere_frame) -> None:  # type: ignore[no-untyped-def]
    disc, p_exact, _ = analytic_sphere(front_camera(), W, H, np.array([0.0, 0.0, -DIST]))
    b = sphere_frame.buffers
    interior = disc > 0.05 * disc.max()
    # planar depth = -z; the tessellation (sagitta ≈ 5e-5) bounds the difference
    np.testing.assert_allclose(b["depth"][interior], -p_exact[..., 2][interior], atol=3e-4)
    np.testing.assert_allclose(b["position"][interior], p_exact[interior], atol=3e-4)
    np.testing.assert_allclose(b["position"][..., 2], np.where(b["coverage"] > 0, -b["depth"], 0))
    cover = b["coverage"] > 0
    assert np.all(np.isposinf(b["depth"][~cover]))
    assert np.all(np.isfinite(b["depth"][cover])) and np.all(b["depth"][cover] > 0)
    assert set(np.unique(b["coverage"])) == {0.0, 1.0}
    np.testing.assert_array_equal(b["alpha"], b["coverage"])
    # the silhouette agrees with the exact one except on a few edge pixels
    assert np.mean(cover != (disc > 0)) < 0.005
    assert not cover[0].any() and not cover[-1].any()
    # every covered pixel lies on its own pixel ray (camera conventions agree)
    view = sphere_frame.view_vectors()
    p = b["position"][cover]
    np.testing.assert_allclose(
        -p / np.linalg.norm(p, axis=1, keepdims=True), view[cover], atol=1e-5
    )


def test_orthographic_sphere() -> None:
    mesh = trimesh.creation.icosphere(subdivisions=5)
    cam = Camera(world_to_camera=look_at([0, 0, 4.0], [0, 0, 0]), projection="orthographic",
                 ortho_height=3.0)  # fmt: skip
    frame = render(mesh, 90, 60, camera=cam, ao="none")
    ps = 3.0 / 60
    x = (np.arange(90) + 0.5 - 45) * ps
    y = -(np.arange(60) + 0.5 - 30) * ps
    gx, gy = np.meshgrid(x, y)
    r2 = gx**2 + gy**2
    interior = r2 < 0.9**2
    zc = np.sqrt(np.maximum(1.0 - r2, 0.0))
    b = frame.buffers
    np.testing.assert_allclose(b["depth"][interior], (4.0 - zc)[interior], atol=2e-3)
    n_exact = np.stack([gx, gy, zc], axis=2)
    cos = (b["normal"] * n_exact).sum(axis=2)[interior]
    assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 0.3
    assert np.all(np.isposinf(b["depth"][r2 > 1.05**2]))
    assert np.all(b["ao"] == 1.0)


# -- shading, lights, AO ---------------------------------------------------------------------


def test_frame_buffers_outputs_and_header(sphere_frame) -> None:  # type: ignore[no-untyped-def]
    frame = sphere_frame
    assert frame.preset == "canonical"
    assert set(RENDER_BUFFERS) == set(frame.buffers)
    assert set(frame.buffers) <= set(BUFFERS)
    for name, arr in frame.buffers.items():
        assert arr.dtype == np.float32 and arr.shape[:2] == (H, W), name
        assert arr.shape[2:] == ((BUFFERS[name][0],) if BUFFERS[name][0] > 1 else ()), name
    b = frame.buffers
    np.testing.assert_allclose(b["beauty"], b["ambient"] + b["diffuse"] + b["specular"], 1e-6)
    for lobe in ("ambient", "diffuse", "specular"):
        np.testing.assert_allclose(b[lobe], b[f"{lobe}.color"] * b[f"{lobe}.light"], 1e-6)
    cover = b["coverage"] > 0
    np.testing.assert_allclose(b["albedo"][cover], 0.8, atol=1e-6)
    assert np.all(b["beauty"][~cover] == 0.0)
    assert np.all((b["ao"] >= 0) & (b["ao"] <= 1)) and np.all(b["ao"][~cover] == 1.0)
    # outputs: canonical EXR channel names holding the same pixels
    out = frame.outputs
    channels = ["R", "G", "B", "A", "N.X", "N.Y", "N.Z", "depth.Z", "P.X", "P.Y", "P.Z"]
    channels += ["albedo.R", "AO.X", "diffuse.light.R", "specular.color.B", "ambient.G"]
    for channel in channels:
        assert channel in out and out[channel].dtype == np.float32, channel
        assert out[channel].shape == (H, W) and out[channel].flags.c_contiguous, channel
    np.testing.assert_array_equal(out["N.Y"], b["normal"][..., 1])
    np.testing.assert_array_equal(out["depth.Z"], b["depth"])
    np.testing.assert_array_equal(out["diffuse.light.G"], b["diffuse.light"][..., 1])
    assert "coverage.X" not in out  # alpha carries it
    # the header round-trips the camera
    cam = Camera.from_header(frame.attributes)
    assert cam is not None and cam.fov_y_deg == pytest.approx(FOV)
    assert frame.camera is not None and frame.camera.world_to_camera is not None
    np.testing.assert_allclose(cam.world_to_camera, frame.camera.world_to_camera, atol=1e-6)


def test_light_from_the_left_brightens_the_left(sphere: trimesh.Trimesh) -> None:
    cam = front_camera()
    left = render(sphere, W, H, camera=cam, lights=[Light("directional", (-1.0, 0.0, 0.4))])
    lum = left.buffers["diffuse"].mean(axis=2)
    assert lum[:, : W // 2].mean() > 3.0 * lum[:, W // 2 :].mean()
    right = render(sphere, W, H, camera=cam, lights=[Light("directional", (1.0, 0.0, 0.4))])
    lum_r = right.buffers["diffuse"].mean(axis=2)
    assert lum_r[:, W // 2 :].mean() > 3.0 * lum_r[:, : W // 2].mean()


def test_point_light(sphere: trimesh.Trimesh) -> None:
    cam = front_camera()
    light = Light("point", (0.0, 0.0, -1.0), intensity=2.0)  # 1 unit in front of the sphere
    frame = render(sphere, W, H, camera=cam, lights=[light], ao="none", model="lambert")
    b = frame.buffers
    cover = b["coverage"] > 0
    p = b["position"]
    n = b["normal"]
    to_light = np.array([0.0, 0.0, -1.0]) - p
    d2 = (to_light**2).sum(axis=2)
    expected = 2.0 / d2 * np.maximum((n * to_light).sum(axis=2) / np.sqrt(d2), 0.0)
    np.testing.assert_allclose(b["diffuse.light"][..., 0][cover], expected[cover], 1e-4, 1e-6)
    # the nearest point (image centre) is lit at 2 / 1² and the light falls off outwards
    assert b["diffuse.light"][H // 2, W // 2, 0] == pytest.approx(2.0, rel=0.01)
    assert np.all(np.isfinite(b["beauty"]))


def test_ssao_darkens_a_concave_corner() -> None:
    # two boxes meeting at a right angle, seen from the open side of the corner
    floor = trimesh.creation.box(extents=(2.0, 0.1, 2.0))
    wall = trimesh.creation.box(extents=(2.0, 2.0, 0.1))
    wall.apply_translation((0.0, 1.0, -1.0))
    mesh = trimesh.util.concatenate([floor, wall])
    cam = Camera(world_to_camera=look_at([0.0, 2.5, 3.0], [0.0, 0.3, -0.5]), fov_y_deg=45.0)
    frame = render(mesh, W, H, camera=cam, ao_radius=0.4, shading="flat")
    b = frame.buffers
    ao = b["ao"]
    assert cam.world_to_camera is not None
    up = cam.world_to_camera[:3, :3] @ np.array([0.0, 1.0, 0.0])  # world +y in camera space
    floor_px = (b["coverage"] > 0) & ((b["normal"] @ up) > 0.99)
    # world position of each floor pixel: distance to the wall (z = -0.95 world)
    c2w = np.linalg.inv(cam.world_to_camera)
    pw = b["position"] @ c2w[:3, :3].T + c2w[:3, 3]
    near_wall = floor_px & (pw[..., 2] < -0.8) & (np.abs(pw[..., 0]) < 0.7)
    open_floor = floor_px & (pw[..., 2] > 0.0) & (np.abs(pw[..., 0]) < 0.7)
    assert near_wall.sum() > 20 and open_floor.sum() > 20
    assert ao[near_wall].mean() < ao[open_floor].mean() - 0.1
    assert ao[open_floor].mean() > 0.97
    # AO multiplies the ambient lobe
    np.testing.assert_allclose(b["ambient.light"][..., 0], 0.1 * ao * b["coverage"], atol=1e-6)
    none = render(mesh, W, H, camera=cam, ao="none", shading="flat", outputs=False)
    assert np.all(none.buffers["ao"] == 1.0)
    assert none.outputs == {}


# -- meshes, colours, cameras ----------------------------------------------------------------


def test_cube_shading_modes() -> None:
    cube = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    cam = Camera(world_to_camera=look_at([2.0, 1.5, 2.5], [0, 0, 0]), fov_y_deg=40.0)
    rot = cam.world_to_camera[:3, :3]
    axes = np.concatenate([np.eye(3), -np.eye(3)]) @ rot.T  # world axes in camera space
    for shading in ("flat", "auto", "smooth"):
        n = render(cube, W, H, camera=cam, ao="none", shading=shading).buffers["normal"]
        cover = np.linalg.norm(n, axis=2) > 0.5
        best = np.max(n[cover] @ axes.T, axis=1)
        if shading == "smooth":
            assert best.min() < 0.95, shading  # a smooth surface through the corners
        else:  # auto: a box is made of creases; every pixel has exactly a face's normal
            assert best.min() > 1.0 - 1e-5, shading


def test_vertex_colours_and_albedo_override() -> None:
    mesh = trimesh.creation.icosphere(subdivisions=3)
    mesh.visual.vertex_colors = np.tile([255, 0, 0, 255], (len(mesh.vertices), 1))
    frame = render(mesh, 64, 48, camera=front_camera(), ao="none")
    cover = frame.buffers["coverage"] > 0
    assert np.abs(frame.buffers["albedo"][cover] - [1.0, 0.0, 0.0]).max() < 1e-6
    assert frame.buffers["diffuse"][cover][:, 1].max() == 0.0
    # face colours: each pixel gets exactly one of the two (sRGB 0 / 255 -> linear 0 / 1)
    mesh.visual.face_colors = np.where(
        (np.arange(len(mesh.faces)) % 2 == 0)[:, None], [0, 255, 0, 255], [0, 0, 255, 255]
    )
    faces = render(mesh, 64, 48, camera=front_camera(), ao="none").buffers["albedo"][cover]
    green = np.abs(faces - [0.0, 1.0, 0.0]).max(axis=1) < 1e-6
    blue = np.abs(faces - [0.0, 0.0, 1.0]).max(axis=1) < 1e-6
    assert np.all(green | blue) and green.any() and blue.any()
    grey = render(mesh, 64, 48, camera=front_camera(), ao="none", albedo=(0.2, 0.3, 0.4))
    assert np.abs(grey.buffers["albedo"][cover] - [0.2, 0.3, 0.4]).max() < 1e-6


def test_texture_is_sampled_per_pixel() -> None:
    # a quad facing the camera, textured left half red, right half blue (sRGB 255 -> linear 1)
    verts = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    tex = np.zeros((8, 8, 3), np.uint8)
    tex[:, :4] = (255, 0, 0)
    tex[:, 4:] = (0, 0, 255)
    visual = trimesh.visual.TextureVisuals(uv=uv, image=Image.fromarray(tex))
    quad = trimesh.Trimesh(verts, faces, visual=visual, process=False)
    frame = render(quad, 80, 80, camera=front_camera(distance=3.0, fov=30.0), ao="none")
    alb = frame.buffers["albedo"]
    row = alb[40]
    cover = frame.buffers["coverage"][40] > 0
    xs = np.flatnonzero(cover)
    # away from the bilinear blend over the middle texel boundary (±6 px here)
    left, right = row[xs[: len(xs) // 2 - 8]], row[xs[len(xs) // 2 + 8 :]]
    assert len(left) > 20 and len(right) > 20
    assert np.abs(left - [1.0, 0.0, 0.0]).max() < 1e-4
    assert np.abs(right - [0.0, 0.0, 1.0]).max() < 1e-4


def test_auto_camera_frames_the_mesh() -> None:
    mesh = trimesh.creation.box(extents=(4.0, 1.0, 2.0))
    mesh.apply_translation((10.0, -3.0, 5.0))
    for projection in ("perspective", "orthographic"):
        for w, h in ((W, H), (H, W)):
            cam = auto_camera(mesh, width=w, height=h, projection=projection)  # type: ignore[arg-type]
            cover = render(mesh, w, h, camera=cam, ao="none").buffers["coverage"]
            assert cover.mean() > 0.1, (projection, w, h)
            edges = np.concatenate([cover[0], cover[-1], cover[:, 0], cover[:, -1]])
            assert not edges.any(), (projection, w, h)
    cam = auto_camera(mesh, width=W, height=H, azimuth_deg=30.0, elevation_deg=20.0)
    eye = np.linalg.inv(cam.world_to_camera)[:3, 3] - np.array([10.0, -3.0, 5.0])
    assert math.degrees(math.atan2(eye[1], math.hypot(eye[0], eye[2]))) == pytest.approx(20.0)
    assert math.degrees(math.atan2(eye[0], eye[2])) == pytest.approx(30.0)
    with pytest.raises(ValueError, match="fov_y_deg"):
        auto_camera(mesh, fov_y_deg=0.0)


def test_load_mesh_formats(tmp_path: Path) -> None:
    box = trimesh.creation.box(extents=(1.0, 2.0, 3.0))
    for suffix in ("obj", "ply", "stl", "glb", "off"):
        path = tmp_path / f"box.{suffix}"
        box.export(path)
        mesh = load_mesh(path)
        assert len(mesh.faces) == 12, suffix
        np.testing.assert_allclose(mesh.extents, (1.0, 2.0, 3.0), atol=1e-6)
    # a glTF scene of two nodes is flattened with its transforms
    scene = trimesh.Scene()
    scene.add_geometry(box, node_name="a")
    moved = np.eye(4)
    moved[:3, 3] = (5.0, 0.0, 0.0)
    scene.add_geometry(box, node_name="b", transform=moved)
    scene.export(tmp_path / "two.glb")
    both = load_mesh(tmp_path / "two.glb")
    assert len(both.faces) == 24
    np.testing.assert_allclose(both.bounds, [[-0.5, -1, -1.5], [5.5, 1, 1.5]], atol=1e-6)


def test_load_mesh_ply_triangle_strips(tmp_path: Path) -> None:
    path = tmp_path / "strip.ply"
    path.write_text(
        "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\n"
        "property float z\nelement tristrips 1\nproperty list int int vertex_indices\n"
        "end_header\n0 0 0\n0 1 0\n1 0 0\n1 1 0\n2 0 0\n7 0 2 1 3 -1 2 4\n"
    )
    mesh = load_mesh(path)
    # strip 0 2 1 3 -> (0 2 1), (2 3 1) [odd: swapped]; "2 4" alone makes no triangle
    assert len(mesh.faces) == 2
    normals = mesh.face_normals
    assert np.allclose(normals[0], normals[1])  # consistent winding along the strip
    assert abs(normals[0][2]) == pytest.approx(1.0)


@pytest.mark.parametrize(
    ("content", "name", "match"),
    [
        (None, "missing.obj", "does not exist"),
        ("", "empty.obj", "no triangles"),
        ("v 0 0 0\nv 1 0 0\n", "points.obj", "no triangles"),
        ("v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n", "nan.obj", r"finite vertices \(1 of 1 have"),
        ("v 0 0 0\nv 1 0 0\nv 0 inf 0\nf 1 2 3\nf 1 2 3\n", "inf.obj", r"\(2 of 2 have NaN or"),
        ("v 0 0 0\nv 1e30 0 0\nv 0 1 0\nf 1 2 3\n", "huge.obj", "not finite or over 1e\\+15"),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn nan nan nan\nvn 0 0 1\nvn 0 0 1\nf 1//1 2//2 3//3\n",
            "vn.obj",
            "vertex normals that are not finite",
        ),
        ("garbage \x00\x01 not a mesh", "bad.glb", "cannot read"),
        ("solid x\n", "x.fbx", "suffix"),
    ],
)
def test_load_mesh_errors(tmp_path: Path, content: str | None, name: str, match: str) -> None:
    path = tmp_path / name
    if content is not None:
        path.write_text(content)
    with pytest.raises(FrameError, match=match):
        load_mesh(path)


def test_a_mesh_path_that_is_not_a_file_is_named(tmp_path: Path) -> None:
    """("does not exist" for a folder; a FIFO with no writer blocked the reader.)"""
    import os

    os.mkfifo(tmp_path / "pipe.obj")
    (tmp_path / "dir.obj").mkdir()
    with pytest.raises(FrameError, match=r"pipe\.obj: it is a FIFO"):
        load_mesh(tmp_path / "pipe.obj")
    with pytest.raises(FrameError, match=r"dir\.obj: it is a directory"):
        load_mesh(tmp_path / "dir.obj")


def test_rasterizer_reuse_and_delete(sphere: trimesh.Trimesh) -> None:
    cam = front_camera()
    with Rasterizer() as raster:
        a = raster.rasterize(sphere, cam, 64, 48)
        b = raster.rasterize(sphere, cam, 32, 32)  # another size: a new framebuffer
        c = raster.rasterize(sphere, cam, 64, 48)
        assert b["normal"].shape == (32, 32, 3)
        np.testing.assert_array_equal(a["normal"], c["normal"])
        raster.delete()
        d = raster.rasterize(sphere, cam, 64, 48)  # a deleted rasterizer starts again
        np.testing.assert_array_equal(a["depth"], d["depth"])


def test_bad_render_parameters(sphere: trimesh.Trimesh) -> None:
    with pytest.raises(ValueError, match="width"):
        render(sphere, 0, 10)
    with pytest.raises(ValueError, match="height"):
        render(sphere, 10, 20000)
    with pytest.raises(ValueError, match="ao"):
        render(sphere, 10, 10, ao="hbao")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="model"):
        render(sphere, 10, 10, model="toon")
    with pytest.raises(ValueError, match="ao_radius"):
        render(sphere, 10, 10, ao_radius=-1.0)
    with pytest.raises(ValueError, match="shading"):
        render(sphere, 10, 10, shading="phong")  # type: ignore[arg-type]
    with pytest.raises(FrameError, match="world_to_camera"):
        render(sphere, 10, 10, camera=Camera(fov_y_deg=30.0))
    with pytest.raises(FrameError, match="fov_y_deg"):
        render(sphere, 10, 10, camera=Camera(world_to_camera=np.eye(4)))
    with pytest.raises(FrameError, match="ortho_height"):
        render(sphere, 10, 10, camera=Camera(world_to_camera=np.eye(4), projection="orthographic"))


def test_canonical_outputs_names() -> None:
    assert channel_names("beauty") == ("R", "G", "B")
    assert channel_names("transmission.color") == (
        "transmission.color.R",
        "transmission.color.G",
        "transmission.color.B",
    )
    assert channel_names("roughness") == ("roughness.X",)
    out = canonical_outputs({"coverage": np.ones((2, 3), np.float32)})
    assert list(out) == ["coverage.X"]
    with pytest.raises(ValueError, match="normal"):
        canonical_outputs({"normal": np.ones((2, 3), np.float32)})


@pytest.mark.models
def test_spot_renders_sensible_buffers() -> None:
    path = MODELS / "spot.obj"
    if not path.is_file():
        pytest.skip(f"{path} is absent (the shared test meshes are not checked out)")
    frame = render(path, 240, 180)
    b = frame.buffers
    cover = b["coverage"] > 0
    assert 0.05 < cover.mean() < 0.9
    edges = np.concatenate([cover[0], cover[-1], cover[:, 0], cover[:, -1]])
    assert not edges.any()
    np.testing.assert_allclose(np.linalg.norm(b["normal"][cover], axis=1), 1.0, atol=1e-5)
    assert np.all(b["depth"][cover] > 0) and np.all(np.isposinf(b["depth"][~cover]))
    assert np.all(np.isfinite(b["beauty"])) and b["beauty"][cover].mean() > 0.05
    assert b["ao"][cover].min() < 0.9  # ears, legs and belly occlude
    # trimesh's stand-in texture for an OBJ without materials is not used: default grey
    np.testing.assert_allclose(b["albedo"][cover], 0.8, atol=1e-6)
    assert b["normal"][cover][:, 2].mean() > 0.3  # facing the camera on the whole


# -- the smooth surface: UV seams, creases, coarse meshes ------------------------------------


def uv_ramp(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """``mesh`` textured with its own coordinates: red grows with u, green with v."""
    ramp = np.zeros((256, 256, 3), np.uint8)
    ramp[..., 0] = np.arange(256)[None, :]
    ramp[..., 1] = np.arange(256)[::-1, None]  # v grows upwards
    out = mesh.copy()
    out.visual = trimesh.visual.TextureVisuals(uv=mesh.visual.uv, image=Image.fromarray(ramp))
    return out


def seam_jumps(frame) -> np.ndarray:  # type: ignore[no-untyped-def]
    """Degrees the normal turns between neighbouring pixels across a UV seam (their texture
    coordinates jump, their depths do not), beyond the mean turn of the pairs on either side."""
    b = frame.buffers
    jumps = []
    for axis in (0, 1):
        n, uv, depth, cover = (
            np.moveaxis(a, axis, 0)
            for a in (
                b["normal"].astype(np.float64),
                b["albedo"][..., :2],
                b["depth"],
                b["coverage"],
            )
        )
        turn = np.degrees(np.arccos(np.clip((n[:-1] * n[1:]).sum(axis=-1), -1.0, 1.0)))
        with np.errstate(invalid="ignore"):  # inf - inf on the background
            same_surface = (cover[:-1] > 0) & (cover[1:] > 0)
            same_surface &= np.abs(depth[:-1] - depth[1:]) < 0.002 * depth[:-1]
        turn = np.where(same_surface, turn, np.nan)
        seam = np.abs(uv[:-1] - uv[1:]).max(axis=-1) > 0.1
        excess = turn[1:-1] - 0.5 * (turn[:-2] + turn[2:])
        jumps.append(excess[seam[1:-1] & np.isfinite(excess)])
    return np.concatenate(jumps)


def test_uv_seams_do_not_split_the_normals() -> None:
    spot = load_mesh(SPOT)  # split along its UV seams: 3225 vertices at 2930 positions
    frame = render(uv_ramp(spot), 640, 480, ao="none")
    jumps = seam_jumps(frame)
    assert jumps.size > 300  # the seams of the back, neck and head are in view
    # averaged per split vertex, the normals jumped by 6.8° (median) and 44° (99th percentile)
    assert np.median(jumps) < 0.5 and np.percentile(jumps, 99) < 2.0, np.percentile(jumps, 99)
    # the same as the mesh welded by position beforehand
    welded = spot.copy()
    welded.merge_vertices(merge_tex=True, merge_norm=True)
    assert len(welded.vertices) < len(spot.vertices)
    reference = render(welded, 640, 480, ao="none").buffers["normal"]
    np.testing.assert_allclose(frame.buffers["normal"], reference, atol=1e-5)


def fine_detail(frame) -> float:  # type: ignore[no-untyped-def]
    """RMS of the band-pass (minus a 2-pixel Gaussian) of the curvature operator's mapped mean
    curvature, 6 pixels and more inside the silhouette."""
    h = pipeline.run(frame, [{"op": "curvature"}]).outputs["curvature.H"]
    inside = cv2.erode((frame.buffers["coverage"] > 0).astype(np.uint8), np.ones((13, 13)))
    band = h - cv2.GaussianBlur(h, (0, 0), 2.0)
    return float(np.sqrt(np.mean(band[inside > 0] ** 2)))


def test_a_coarse_sphere_shows_no_triangles() -> None:
    w, h = 480, 360
    coarse = render(trimesh.creation.icosphere(subdivisions=1), w, h, camera=front_camera())
    fine = render(trimesh.creation.icosphere(subdivisions=5), w, h, camera=front_camera())
    # 80 faces against 20480: interpolated over the flat triangles, 5.0 times the fine detail
    assert fine_detail(coarse) < 1.2 * fine_detail(fine), fine_detail(coarse) / fine_detail(fine)
    # the refined surface passes through the vertices: the silhouette and normals of the sphere
    disc, _, n_exact = analytic_sphere(front_camera(), w, h, np.array([0.0, 0.0, -DIST]))
    cover = coarse.buffers["coverage"] > 0
    assert np.mean(cover != (disc > 0)) < 0.005  # 0.09 with flat triangles
    interior = disc > 0.05 * disc.max()
    cos = (coarse.buffers["normal"].astype(np.float64) * n_exact).sum(axis=2)[interior]
    assert np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).max() < 1.0


def test_only_coarse_meshes_are_refined() -> None:
    def levels(mesh: trimesh.Trimesh, width: int, height: int) -> int:
        surface = smooth_surface(mesh)
        cam = front_camera()
        verts = surface.vertices + cam.world_to_camera[:3, 3]
        view = View(1.0 / cam.focal_px(height), False, width, height, 0.1)
        return levels_for(surface, verts, view)

    ico = trimesh.creation.icosphere
    assert levels(ico(subdivisions=6), 320, 240) == 0  # edges under 2 pixels
    assert levels(ico(subdivisions=1), 320, 240) >= 4
    assert levels(ico(subdivisions=1), 16384, 16384) <= 8  # bounded by the triangle budget
    assert levels(trimesh.creation.box(), 1920, 1080) == 0  # flat faces stay as they are


def test_creases_stay_sharp_and_flat_faces_flat() -> None:
    # a coarse cylinder: its rims are creases, its caps planar, its side a smooth surface
    cylinder = trimesh.creation.cylinder(radius=1.0, height=2.0, sections=16)
    cam = Camera(world_to_camera=look_at([3.0, 4.0, 5.0], [0, 0, 0], up=(0, 0, 1)), fov_y_deg=40)
    b = render(cylinder, 320, 240, camera=cam, ao="none").buffers
    cover = b["coverage"] > 0
    axis = cam.world_to_camera[:3, :3] @ np.array([0.0, 0.0, 1.0])
    n = b["normal"].astype(np.float64)
    along = n @ axis
    cap = cover & (along > 0.5)
    facing = (n * cam_view(b["position"])).sum(axis=2) > 0.5
    side = cover & (np.abs(along) < 0.5) & facing
    assert cap.sum() > 2000 and side.sum() > 2000
    assert along[cap].min() > 1.0 - 1e-6  # the cap keeps the cap's normal
    c2w = np.linalg.inv(cam.world_to_camera)
    height = (b["position"][cap] @ c2w[:3, :3].T + c2w[:3, 3])[:, 2]
    np.testing.assert_allclose(height, 1.0, atol=1e-6)  # and its plane
    # the side is smooth: about 1.2° from pixel to pixel (its 16 flat faces: 22.5° at an edge)
    turn = np.degrees(np.arccos(np.clip((n[:, 1:] * n[:, :-1]).sum(axis=2), -1.0, 1.0)))
    assert turn[side[:, 1:] & side[:, :-1]].max() < 2.0


def cam_view(position: np.ndarray) -> np.ndarray:
    """Unit vectors from camera-space positions towards the camera."""
    return -position / np.maximum(np.linalg.norm(position, axis=2, keepdims=True), 1e-12)


def test_normals_from_the_file_are_kept(tmp_path: Path) -> None:
    # an icosphere whose OBJ gives every face its own normal (a faceted ball)
    ball = trimesh.creation.icosphere(subdivisions=2)
    lines = [f"v {x} {y} {z}" for x, y, z in ball.vertices]
    lines += [f"vn {x} {y} {z}" for x, y, z in ball.face_normals]
    lines += [f"f {a}//{i} {b}//{i} {c}//{i}" for i, (a, b, c) in enumerate(ball.faces + 1, 1)]
    path = tmp_path / "faceted.obj"
    path.write_text("\n".join(lines) + "\n")
    mesh = load_mesh(path)
    assert mesh.metadata[FILE_NORMALS]
    cam = front_camera()
    face_n = ball.face_normals @ cam.world_to_camera[:3, :3].T
    for shading, faceted in (("auto", True), ("smooth", False)):
        b = render(mesh, W, H, camera=cam, ao="none", shading=shading).buffers
        n = b["normal"][b["coverage"] > 0].astype(np.float64)
        best = np.max(n @ face_n.T, axis=1)  # the closest face normal
        assert (best.min() > 1.0 - 1e-6) == faceted, shading


@pytest.mark.models
def test_fandisk_keeps_its_creases() -> None:
    path = MODELS / "fandisk.obj"
    if not path.is_file():
        pytest.skip(f"{path} is absent (the shared test meshes are not checked out)")
    b = render(path, 320, 240, ao="none").buffers
    n = b["normal"].astype(np.float64)
    depth = b["depth"]
    turn = np.degrees(np.arccos(np.clip((n[:, 1:] * n[:, :-1]).sum(axis=2), -1.0, 1.0)))
    with np.errstate(invalid="ignore"):  # inf - inf on the background
        same_surface = np.abs(depth[:, 1:] - depth[:, :-1]) < 0.005 * depth[:, :-1]
    # neighbours on either side of a crease: smooth normals would turn by a few degrees at most
    assert np.count_nonzero(same_surface & (turn > 45.0)) > 50
