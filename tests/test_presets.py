"""Renderer presets and gbuffer.io: each layout read into the right canonical buffers."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import OpenEXR
import pytest

from gbuffer import (
    Camera,
    Frame,
    FrameError,
    MissingBufferError,
    MissingCameraError,
    ReadOptions,
    describe,
    detect,
    exr,
    read,
    write,
)
from gbuffer.presets import PRESETS
from tests import exr_factory as F

FIXTURE = Path(__file__).parent / "fixtures" / "blender"


@pytest.fixture(scope="module")
def scene() -> F.Scene:
    return F.make_scene()


def cam_dict(s: F.Scene) -> dict[str, Any]:
    return {"world_to_camera": s.world_to_camera.tolist(), "fov_y_deg": 40.0}


def inner(s: F.Scene) -> np.ndarray:
    """Pixels fully covered (alpha 1): where buffers must match the scene exactly."""
    return s.covered & (s.alpha == 1.0)


def close(a: np.ndarray, b: np.ndarray, mask: np.ndarray, tol: float) -> None:
    err = float(np.abs(a[mask] - b[mask]).max())
    assert err <= tol, err


def check_common(
    frame: Frame, s: F.Scene, half_tol: float = 2e-3, normal_tol: float = 1e-4
) -> None:
    m = inner(s)
    assert frame.buffers["normal"].dtype == np.float32
    close(frame.buffers["normal"], s.normal, m, normal_tol)
    close(frame.buffers["depth"], s.depth, m, 1e-4 * 5)
    assert np.isinf(frame.buffers["depth"][~s.covered]).all()
    assert (frame.buffers["normal"][~s.covered] == 0).all()
    assert (frame.buffers["coverage"][~s.covered] == 0).all()
    close(frame.buffers["beauty"], s.beauty, m, half_tol * 4)
    close(frame.buffers["diffuse"], s.diffuse, m, half_tol * 2)
    assert frame.shape == s.shape


# -- one test per renderer layout -----------------------------------------------------------------


def test_blender(tmp_path: Path, scene: F.Scene) -> None:
    path = F.write_blender(tmp_path / "b.exr", scene)
    no_position = F.write_blender(tmp_path / "np.exr", scene, position=False)
    with pytest.raises(MissingCameraError, match=r"--camera CAM\.json .*world_to_camera"):
        read(no_position)
    solved = read(path)  # the camera solved from the Position pass
    assert solved.camera is not None and solved.camera.world_to_camera is not None
    assert solved.camera.source == "solved from ViewLayer.Position.X,Y,Z (world positions)"
    assert solved.camera.fov_y_deg == pytest.approx(40.0, abs=1e-3)
    np.testing.assert_allclose(solved.camera.world_to_camera, scene.world_to_camera, atol=1e-4)
    frame = read(path, camera=cam_dict(scene))
    assert frame.camera is not None and frame.camera.source == "given"
    assert frame.camera.fit is not None and frame.camera.fit["rms_px"] < 1e-3
    assert frame.preset == "blender"
    check_common(frame, scene, normal_tol=2.5e-2)  # filtered normals (2x2 average)
    m = inner(scene)
    # world -> camera, renormalised: the unit 2x2-filtered normal
    nf = scene.normal_filtered
    unit = nf / np.linalg.norm(nf, axis=-1, keepdims=True).clip(1e-9)
    close(frame.buffers["normal"], unit, scene.covered, 1e-4)
    assert frame.sources["normal"] == "ViewLayer.Normal.X,Y,Z (world -> camera)"
    # lobes: (Dir + Ind) * Col, light and colour kept
    close(frame.buffers["diffuse"], scene.diffuse, scene.covered, 1e-5)
    close(frame.buffers["diffuse.light"], scene.diffuse_light, scene.covered, 1e-5)
    close(frame.buffers["specular.color"], scene.specular_color, scene.covered, 0)
    close(frame.buffers["transmission"], scene.transmission, scene.covered, 1e-6)
    close(frame.buffers["remainder"], scene.emission, m, 2e-3)  # emission (half beauty)
    close(frame.buffers["position"], scene.position, m, 1e-4)
    close(frame.buffers["ao"], scene.ao, m, 1e-3)
    # coverage: alpha at anti-aliased edges, 0 on background
    edge = scene.covered & (scene.alpha < 1)
    assert edge.any()
    assert (frame.buffers["coverage"][edge] < 1).all()
    close(frame.buffers["coverage"], scene.alpha, m, 0)


def test_blender5_names_and_view_layer(tmp_path: Path, scene: F.Scene) -> None:
    path = F.write_blender(tmp_path / "b5.exr", scene, layer="Shot Layer", blender5=True)
    frame = read(path, camera=cam_dict(scene))
    check_common(frame, scene, normal_tol=2.5e-2)
    assert frame.sources["diffuse.light"].startswith("Shot Layer.Diffuse Direct.R,G,B + ")
    assert frame.sources["ao"] == "Shot Layer.Ambient Occlusion.R"


def test_blender_two_view_layers(tmp_path: Path, scene: F.Scene) -> None:
    a = OpenEXR.File(str(F.write_blender(tmp_path / "a.exr", scene, layer="Fg")), True)
    chans = {k: c.pixels for k, c in a.channels().items()}
    chans.update({k.replace("Fg.", "Bg."): v * 0 for k, v in chans.items() if ".Combined." in k})
    both = F.write_exr(tmp_path / "two.exr", {"BlenderMultiChannel": "x"}, chans)
    frame = read(both, camera=cam_dict(scene))
    assert frame.sources["beauty"].startswith("Bg.") or frame.sources["beauty"].startswith("Fg.")
    assert any("view layers" in w for w in describe(frame)["warnings"])
    frame = read(both, camera=cam_dict(scene), options={"layer": "Fg"})
    check_common(frame, scene, normal_tol=2.5e-2)
    with pytest.raises(FrameError, match="view layer 'Nope' not in the file; layers: "):
        read(both, camera=cam_dict(scene), options={"layer": "Nope"})


def test_blender_composite_layer_is_not_the_view_layer(tmp_path: Path, scene: F.Scene) -> None:
    """A render saved with the compositor on has a "Composite" layer holding Combined alone."""
    a = OpenEXR.File(str(F.write_blender(tmp_path / "a.exr", scene)), True)
    chans = {k: c.pixels for k, c in a.channels().items()}
    chans.update(
        {k.replace("ViewLayer.", "Composite."): v for k, v in chans.items() if ".Combined." in k}
    )
    path = F.write_exr(tmp_path / "comp.exr", {"BlenderMultiChannel": "x"}, chans)
    frame = read(path)
    assert frame.sources["normal"].startswith("ViewLayer.Normal")
    assert frame.sources["beauty"].startswith("ViewLayer.Combined")
    assert frame.result_layer == "ViewLayer.Depict"


def test_arnold_camera_from_header_and_distance_depth(tmp_path: Path, scene: F.Scene) -> None:
    frame = read(F.write_arnold(tmp_path / "a.exr", scene))
    assert frame.preset == "arnold"
    assert frame.camera is not None and frame.camera.world_to_camera is not None
    np.testing.assert_allclose(frame.camera.world_to_camera, scene.world_to_camera, atol=1e-5)
    assert frame.camera.fov_y_deg == pytest.approx(40.0, abs=1e-4)
    check_common(frame, scene)
    assert "distance along the ray -> planar" in frame.sources["depth"]
    close(frame.buffers["specular"], scene.specular, scene.covered, 1e-6)
    # light = radiance / albedo
    close(frame.buffers["diffuse.light"], scene.diffuse_light, inner(scene), 2e-2)


def _pose_only_arnold(tmp_path: Path, scene: F.Scene, turn_deg: float = 0.0) -> Path:
    """The Arnold file with ``worldToCamera`` alone (no ``worldToNDC``), its pose turned by
    ``turn_deg`` about the camera's vertical axis."""
    with OpenEXR.File(str(F.write_arnold(tmp_path / "a.exr", scene)), True) as f:
        header = dict(f.header())
        chans = {k: c.pixels.copy() for k, c in f.channels().items()}
    del header["worldToNDC"]
    t = np.radians(turn_deg)
    turn = np.array([[np.cos(t), 0, np.sin(t), 0], [0, 1, 0, 0], [-np.sin(t), 0, np.cos(t), 0]])
    header["worldToCamera"] = (np.vstack([turn, [0, 0, 0, 1]]) @ header["worldToCamera"]).astype(
        np.float32
    )
    return F.write_exr(tmp_path / f"pose{turn_deg:g}.exr", header, chans)


def test_a_pose_without_field_of_view_is_completed_from_world_positions(
    tmp_path: Path, scene: F.Scene
) -> None:
    """A header's ``worldToCamera`` without ``worldToNDC``, beside a world-space position pass:
    the field of view is solved from the positions, so the distance depth is made planar and
    sizes in scene units work, as with the whole camera in the file."""
    whole = read(F.write_arnold(tmp_path / "whole.exr", scene))
    frame = read(_pose_only_arnold(tmp_path, scene))
    assert frame.camera is not None and frame.camera.has_intrinsics
    assert (
        frame.camera.source == "file header (worldToCamera), its field of view solved from P.X,Y,Z"
    )
    assert frame.camera.fov_y_deg == pytest.approx(40.0, abs=1e-3)
    assert frame.camera.fit is not None and frame.camera.fit["rms_px"] < 1e-3
    np.testing.assert_array_equal(frame.camera.world_to_camera, whole.camera.world_to_camera)
    assert describe(frame)["warnings"] == []
    assert frame.sources["depth"] == "Z (distance along the ray -> planar)"
    covered = scene.covered
    close(frame.buffers["depth"], whole.buffers["depth"], covered, 1e-5)


def test_a_pose_the_positions_do_not_fit_is_not_completed(tmp_path: Path, scene: F.Scene) -> None:
    """The same with the pose turned by 10°: no field of view makes the points land on their
    pixels with it, so the camera stays a pose, and both warnings say why."""
    frame = read(_pose_only_arnold(tmp_path, scene, turn_deg=10.0))
    assert frame.camera is not None and not frame.camera.has_intrinsics
    warnings = describe(frame)["warnings"]
    assert any(
        w.startswith(
            "the field of view of the camera in the file (file header (worldToCamera)) is not "
            "solved from P.X,Y,Z: with the file's pose, the solved one puts the points "
        )
        for w in warnings
    ), warnings
    assert any("has no field of view" in w and "camera JSON" in w for w in warnings), warnings
    assert "distance along the ray" in " ".join(warnings)


def test_vray_camera_from_camera_transform(tmp_path: Path, scene: F.Scene) -> None:
    frame = read(F.write_vray(tmp_path / "v.exr", scene))
    assert frame.preset == "vray"
    assert frame.camera is not None and frame.camera.world_to_camera is not None
    np.testing.assert_allclose(frame.camera.world_to_camera, scene.world_to_camera, atol=1e-5)
    assert frame.camera.fov_y_deg == pytest.approx(40.0, abs=1e-4)
    check_common(frame, scene)
    assert frame.sources["depth"] == "Z"  # raw Z, never the remapped VRayZDepth
    assert frame.sources["normal"] == "VRayNormals.X,Y,Z"
    close(frame.buffers["diffuse.light"], scene.diffuse_light, scene.covered, 1e-5)
    close(frame.buffers["transmission"], scene.transmission, scene.covered, 1e-6)


def test_renderman_left_handed_normals(tmp_path: Path, scene: F.Scene) -> None:
    frame = read(F.write_renderman(tmp_path / "r.exr", scene))
    assert frame.preset == "renderman"
    check_common(frame, scene)
    assert frame.sources["normal"] == "Nn.x,y,z (camera-lh -> camera)"
    # no camera in the file: solved from __Pworld, which then becomes camera-space
    assert frame.camera is not None and frame.camera.source.startswith("solved from __Pworld")
    assert frame.camera.fov_y_deg == pytest.approx(40.0, abs=1e-3)
    close(frame.buffers["position"], scene.position, inner(scene), 1e-3)
    frame = read(tmp_path / "r.exr", camera=cam_dict(scene))
    close(frame.buffers["position"], scene.position, inner(scene), 1e-4)


def test_karma_multi_part(tmp_path: Path, scene: F.Scene) -> None:
    path = F.write_karma(tmp_path / "k.exr", scene)
    frame = read(path, camera=cam_dict(scene))
    assert frame.preset == "karma"
    assert frame.passthrough.primary == 0
    check_common(frame, scene, half_tol=2e-2)  # the beauty part is DWAA
    assert frame.sources["normal"] == "N.X,Y,Z (world -> camera)"
    assert frame.sources["depth"] == "depth.Z"
    assert frame.sources["diffuse"] == "directdiffuse.R,G,B"


def test_parts_with_other_data_windows_are_placed_on_the_grid(
    tmp_path: Path, scene: F.Scene
) -> None:
    h, w = scene.shape
    y0, x0 = 10, 20  # the normal part covers only a crop of the beauty's window
    crop = scene.normal[y0:, x0:]
    beauty = OpenEXR.Part({}, F._split(scene.beauty, F.RGB, "", np.float16), "C")
    normal = OpenEXR.Part(
        {
            "dataWindow": exr.box2i(x0, y0, w - 1, h - 1),
            "displayWindow": exr.box2i(0, 0, w - 1, h - 1),
        },
        F._split(crop, F.XYZ, "", np.float32),
        "N",
    )
    path = tmp_path / "crop.exr"
    OpenEXR.File([beauty, normal]).write(str(path))
    frame = read(path, preset="karma", options={"normal_space": "camera"})
    assert frame.shape == (h, w) and frame.passthrough.primary == 0
    n = frame.buffers["normal"]
    np.testing.assert_allclose(
        n[y0:, x0:][inner(scene)[y0:, x0:]], crop[inner(scene)[y0:, x0:]], atol=1e-6
    )
    assert (n[:y0] == 0).all() and (n[:, :x0] == 0).all()


def test_attribute_lists_of_numpy_scalars(tmp_path: Path, scene: F.Scene) -> None:
    frame = read(F.write_vray(tmp_path / "v.exr", scene))
    frame.attributes["depict/weights"] = [np.float32(0.5), np.float64(2.0)]
    frame.attributes["depict/gain"] = np.float32(1.5)
    write(frame, tmp_path / "o.exr")
    header = OpenEXR.File(str(tmp_path / "o.exr"), True).header()
    assert header["depict/weights"] == [0.5, 2.0] and header["depict/gain"] == 1.5
    frame.attributes["depict/bad"] = {"a": 1}
    with pytest.raises(FrameError, match="cannot write header attributes"):
        write(frame, tmp_path / "o2.exr")


def test_canonical_written_by_depict_reads_back(tmp_path: Path, scene: F.Scene) -> None:
    buffers = {
        "beauty": scene.beauty,
        "alpha": scene.alpha,
        "normal": scene.normal,
        "depth": scene.depth,
        "position": scene.position,
        "diffuse": scene.diffuse,
        "diffuse.light": scene.diffuse_light,
        "diffuse.color": scene.albedo,
        "ao": scene.ao,
    }
    frame = Frame(buffers=dict(buffers), camera=scene.camera)
    frame.set_layer("curvature", {"H": np.full(scene.shape, 0.5, np.float32)})
    out = tmp_path / "render.exr"
    write(frame, out)
    back = read(out)
    assert back.preset == "canonical"
    assert back.passthrough.preset_reason.startswith("header attribute depict/")
    assert back.camera is not None and back.camera.world_to_camera is not None
    np.testing.assert_allclose(back.camera.world_to_camera, scene.world_to_camera, atol=1e-6)
    check_common(back, scene)
    np.testing.assert_array_equal(back.buffers["depth"], scene.depth)  # float32, exact
    types = {n: c.type() for n, c in OpenEXR.File(str(out), True).channels().items()}
    assert types["depth.Z"] == OpenEXR.FLOAT and types["N.X"] == OpenEXR.FLOAT
    assert types["R"] == OpenEXR.HALF and types["curvature.H"] == OpenEXR.FLOAT
    assert np.all(back.layer("curvature")["H"] == 0.5)


# -- detection ------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("writer", "expected", "reason"),
    [
        (F.write_blender, "blender", "header attribute BlenderMultiChannel"),
        (F.write_arnold, "arnold", "header attribute arnold/version"),
        (F.write_vray, "vray", "header attribute "),
        (F.write_renderman, "renderman", "header Software="),
        (F.write_karma, "karma", "multi-part"),
        (F.write_canonical, "canonical", "header attribute depict/"),
    ],
)
def test_detect_by_header(
    tmp_path: Path, scene: F.Scene, writer: Any, expected: str, reason: str
) -> None:
    name, why = detect(exr.read_parts(writer(tmp_path / "f.exr", scene)))
    assert name == expected
    assert why.startswith(reason)


@pytest.mark.parametrize(
    ("writer", "expected"),
    [
        (F.write_blender, "blender"),
        (F.write_arnold, "arnold"),
        (F.write_vray, "vray"),
        (F.write_renderman, "renderman"),
    ],
)
def test_detect_by_channel_names(
    tmp_path: Path, scene: F.Scene, writer: Any, expected: str
) -> None:
    path = writer(tmp_path / "f.exr", scene, signature=False)
    name, why = detect(exr.read_parts(path))
    assert name == expected, why
    assert "names" in why or why == "header attribute cameraTransform"  # V-Ray's camera


def test_unknown_file_falls_back_to_canonical(tmp_path: Path) -> None:
    path = F.write_exr(tmp_path / "x.exr", {}, {"foo": np.zeros((4, 4), np.float32)})
    assert detect(exr.read_parts(path)) == (
        "canonical",
        "no renderer signature found; using Depict's canonical names",
    )
    frame = read(path)
    assert frame.buffers == {}
    assert any("no buffer recognised" in w for w in describe(frame)["warnings"])
    with pytest.raises(MissingBufferError, match="the frame has no 'normal' buffer"):
        frame.need("normal", "curvature")


# -- overrides and conventions --------------------------------------------------------------------


def test_mapping_override_and_normal_space(tmp_path: Path, scene: F.Scene) -> None:
    chans = {
        **F._split(scene.beauty, F.RGB, "", np.float16),
        **F._split(scene.normal, ("x", "y", "z"), "MyLayer.N", np.float32),
        "dist": np.where(scene.covered, scene.distance, np.inf).astype(np.float32),
    }
    path = F.write_exr(tmp_path / "custom.exr", {}, chans)
    frame = read(path, preset="canonical", options={"mapping": {"normal": "MyLayer.N"}})
    close(frame.buffers["normal"], scene.normal, inner(scene), 1e-6)
    # explicit channel list, declared world space: converted with the camera
    world = scene.to_world_vectors(scene.normal)
    chans.update(F._split(world, F.XYZ, "w", np.float32))
    path = F.write_exr(tmp_path / "custom2.exr", {}, chans)
    opts = ReadOptions(
        mapping={"normal": ["w.X", "w.Y", "w.Z"], "depth": "dist"},
        normal_space="world",
        depth="distance",
    )
    frame = read(path, preset="canonical", camera=scene.camera, options=opts)
    close(frame.buffers["normal"], scene.normal, inner(scene), 1e-5)
    close(frame.buffers["depth"], scene.depth, inner(scene), 1e-5)
    assert frame.sources["normal"] == "w.X,Y,Z (world -> camera)"


def test_bad_options(tmp_path: Path, scene: F.Scene) -> None:
    path = F.write_vray(tmp_path / "v.exr", scene)
    with pytest.raises(FrameError, match="mapping key 'normals' is not a buffer; valid keys: "):
        read(path, options={"mapping": {"normals": "x"}})
    for empty in ("", " ", ",", [], [""]):  # (an empty --map value read the beauty's R,G,B)
        with pytest.raises(FrameError, match="mapping of 'normal' names no channel"):
            read(path, options={"mapping": {"normal": empty}})
    with pytest.raises(FrameError, match="normal_space='screen' must be one of world, camera"):
        read(path, options={"normal_space": "screen"})
    with pytest.raises(FrameError, match="preset='maya' is not known; valid: auto, blender"):
        read(path, preset="maya")
    with pytest.raises(FrameError, match=r"--map normal=Nope: no layer 'Nope' with 3"):
        read(path, options={"mapping": {"normal": "Nope"}})


def test_world_normals_without_camera_can_be_left_out(tmp_path: Path, scene: F.Scene) -> None:
    path = F.write_arnold(tmp_path / "a.exr", scene)
    pt = exr.read_parts(path)
    for header, channels in pt.parts:
        header.pop("worldToCamera")
        header.pop("worldToNDC")
        for name in ("P.X", "P.Y", "P.Z"):  # no position pass to solve the camera from
            channels.pop(name)
    from gbuffer.presets import to_frame

    with pytest.raises(MissingCameraError):
        to_frame(pt, "auto", None, None)
    frame = to_frame(pt, "auto", None, ReadOptions(require_camera=False))
    assert "normal" not in frame.buffers and "depth" in frame.buffers
    assert any("normals N.X,Y,Z left out" in w for w in describe(frame)["warnings"])


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nan_or_inf_in_normals(tmp_path: Path, scene: F.Scene, bad: float) -> None:
    n = scene.normal.copy()
    ys, xs = np.nonzero(inner(scene))
    n[ys[3], xs[3], 1] = bad
    n[0, 0, 0] = bad  # background: tolerated, made 0
    chans = F.canonical_channels(scene)
    chans.update(F._split(n, F.XYZ, "N", np.float32))
    path = F.write_exr(tmp_path / "nan.exr", {}, chans)
    with pytest.raises(FrameError, match=r"nan\.exr: channel 'N\.Y' has 1 NaN/Inf value\(s\)"):
        read(path)
    n[ys[3], xs[3], 1] = 0.0
    chans.update(F._split(n, F.XYZ, "N", np.float32))
    frame = read(F.write_exr(tmp_path / "ok.exr", {}, chans))
    assert frame.buffers["normal"][0, 0].tolist() == [0.0, 0.0, 0.0]


def test_uint_channel_for_a_float_buffer(tmp_path: Path, scene: F.Scene) -> None:
    chans = F.canonical_channels(scene)
    chans["depth.Z"] = np.ones(scene.shape, np.uint32)
    path = F.write_exr(tmp_path / "uint.exr", {}, chans)
    with pytest.raises(FrameError, match=r"channel 'depth\.Z' is UINT; the depth buffer needs"):
        read(path)


def test_data_window_inside_display_window(tmp_path: Path, scene: F.Scene) -> None:
    h, w = scene.shape
    header = {
        "dataWindow": exr.box2i(10, 4, 10 + w - 1, 4 + h - 1),
        "displayWindow": exr.box2i(0, 0, 99, 79),
    }
    frame = read(F.write_exr(tmp_path / "dw.exr", header, F.canonical_channels(scene)))
    assert frame.shape == (h, w)
    assert frame.origin == (10, 4) and frame.display_size == (100, 80)
    assert frame.buffers["normal"].shape == (h, w, 3)
    info = describe(frame)
    assert info["data_window"] == [10, 4, 10 + w - 1, 4 + h - 1]
    assert info["display_window"] == [0, 0, 99, 79] and info["size"] == [w, h]


def test_tiled_file(tmp_path: Path, scene: F.Scene) -> None:
    tiles = OpenEXR.TileDescription()
    tiles.xSize, tiles.ySize = 16, 16
    tiles.mode, tiles.roundingMode = OpenEXR.ONE_LEVEL, OpenEXR.ROUND_DOWN
    header = {"type": OpenEXR.tiledimage, "tiles": tiles, "compression": OpenEXR.PIZ_COMPRESSION}
    path = F.write_exr(tmp_path / "tiled.exr", header, F.canonical_channels(scene))
    frame = read(path)
    check_common(frame, scene)
    assert describe(frame)["parts"][0]["tiled"] is True


# -- writing frames -------------------------------------------------------------------------------


def test_no_op_write_is_bit_identical(tmp_path: Path, scene: F.Scene) -> None:
    src = F.write_blender(tmp_path / "b.exr", scene)
    frame = read(src, camera=cam_dict(scene))
    out = tmp_path / "out.exr"
    assert write(frame, out) == []
    assert out.read_bytes() == src.read_bytes()


def test_outputs_land_in_the_primary_part(tmp_path: Path, scene: F.Scene) -> None:
    src = F.write_karma(tmp_path / "k.exr", scene)
    frame = read(src, camera=cam_dict(scene))
    frame.set_layer("curvature", {"H": np.full(scene.shape, 0.25, np.float32), "K": scene.alpha})
    frame.outputs["R"] = frame.buffers["beauty"][..., 0] * 2  # over an existing HALF channel
    frame.attributes["depict/operators"] = "curvature"
    out = tmp_path / "out.exr"
    warnings = write(frame, out)
    assert len(warnings) == 1 and "written with DWAA as it was read" in warnings[0]
    a = OpenEXR.File(str(src), separate_channels=True)
    b = OpenEXR.File(str(out), separate_channels=True)
    primary = b.parts[0]
    assert set(primary.channels) == {"R", "G", "B", "A", "curvature.H", "curvature.K"}
    assert primary.channels["curvature.H"].type() == OpenEXR.FLOAT
    assert primary.channels["R"].type() == OpenEXR.HALF
    assert primary.header["compression"] == OpenEXR.DWAA_COMPRESSION  # kept
    assert "depict/sourceCompression" not in primary.header
    assert primary.header["depict/operators"] == "curvature"
    # DWAA re-quantises G, not the exact new 32-bit layer
    g_before, g_after = a.parts[0].channels["G"].pixels, primary.channels["G"].pixels
    assert np.allclose(g_after, g_before, atol=0.05, rtol=0.05)
    np.testing.assert_array_equal(primary.channels["curvature.H"].pixels, 0.25)
    for pa, pb in zip(a.parts[1:], b.parts[1:], strict=True):  # other parts untouched
        assert dict(pa.header).keys() == dict(pb.header).keys()
        for name, ch in pa.channels.items():
            assert ch.pixels.tobytes() == pb.channels[name].pixels.tobytes()
    back = read(out, camera=cam_dict(scene))
    assert back.preset == "karma"  # Depict's own marks do not hide the renderer
    assert np.allclose(back.layer("curvature")["H"], 0.25)


def test_write_refuses_bad_outputs(tmp_path: Path, scene: F.Scene) -> None:
    frame = read(F.write_vray(tmp_path / "v.exr", scene))
    frame.outputs["x"] = np.zeros((3, 3), np.float32)
    with pytest.raises(FrameError, match=r"output 'x' has shape \(3, 3\); outputs are"):
        write(frame, tmp_path / "o.exr")
    frame.outputs.clear()
    frame.attributes["dataWindow"] = exr.box2i(0, 0, 1, 1)
    with pytest.raises(FrameError, match=r"frame.attributes may not set \['dataWindow'\]"):
        write(frame, tmp_path / "o.exr")
    assert not (tmp_path / "o.exr").exists()


def test_describe_is_json(tmp_path: Path, scene: F.Scene) -> None:
    frame = read(F.write_vray(tmp_path / "v.exr", scene))
    info = json.loads(json.dumps(describe(frame)))
    assert list(info) == [
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
        "warnings",
    ]
    assert info["colorspace"]["source"] == "default"  # V-Ray writes no chromaticities here
    assert info["camera_source"] == "file header (V-Ray cameraTransform)"
    assert info["camera_fit"] is None and info["missing"] == [] and info["depict"] is None
    assert info["parts"][0]["compression"] == "PIZ"
    assert info["buffers"]["normal"] == {"source": "VRayNormals.X,Y,Z", "shape": [48, 64, 3]}
    assert info["camera"]["fov_y_deg"] == pytest.approx(40.0, abs=1e-4)
    assert set(PRESETS) == {"blender", "arnold", "vray", "renderman", "karma", "canonical"}


def test_camera_argument_forms(tmp_path: Path, scene: F.Scene) -> None:
    path = F.write_blender(tmp_path / "b.exr", scene)
    cam_file = tmp_path / "cam.json"
    cam_file.write_text(json.dumps(cam_dict(scene)))
    for cam in (cam_file, str(cam_file), cam_dict(scene), Camera.from_dict(cam_dict(scene))):
        frame = read(path, camera=cam)
        close(frame.buffers["normal"], scene.normal, inner(scene), 2.5e-2)
    for number in (np.float32(40.0), np.int64(40)):  # (NumPy's numbers, from Python)
        assert Camera.from_dict({**cam_dict(scene), "fov_y_deg": number}).fov_y_deg == 40.0
    with pytest.raises(FrameError, match="camera must be a Camera, a dict or a path"):
        read(path, camera=42)  # type: ignore[arg-type]
    # a matrix of zeros was taken, and every normal turned into camera space became 0
    zero = {**cam_dict(scene), "world_to_camera": [[0.0] * 4] * 4}
    with pytest.raises(FrameError, match="world_to_camera has no inverse"):
        read(path, camera=zero)
    # true read as 1 (a field of view of 1°), a last row of zeros ignored
    for key, value in [("fov_y_deg", True), ("world_to_camera", [[1, 0, 0, True]] * 4)]:
        with pytest.raises(FrameError, match=f"camera JSON {key}: expected numbers, not true"):
            read(path, camera={**cam_dict(scene), key: value})
    rows = [list(r) for r in cam_dict(scene)["world_to_camera"][:3]] + [[0.0, 0.0, 0.0, 0.0]]
    with pytest.raises(FrameError, match=r"last row must be \[0, 0, 0, 1\]"):
        read(path, camera={**cam_dict(scene), "world_to_camera": rows})
    # numbers the header's float32 cannot hold (written as inf), or a pixel size of 0
    far = [list(r) for r in cam_dict(scene)["world_to_camera"]]
    far[2][3] = -1e300
    ortho = {"projection": "orthographic"}
    for cam, words in [
        ({**cam_dict(scene), "world_to_camera": far}, "numbers finite in float32"),
        ({**cam_dict(scene), **ortho, "ortho_height": 1e300}, r"ortho_height=1e\+300 is outside"),
        ({**cam_dict(scene), **ortho, "ortho_height": 1e-300}, "ortho_height=1e-300 is outside"),
        ({**cam_dict(scene), "fov_y_deg": 1e-297}, r"fov_y_deg=1e-297 is outside \[1e-06, 180\)"),
        # (a division by zero; a string taken as a number; an unknown key's list of valid ones)
        ({"focal_px": 0, "height": 480}, "focal_px must be a finite number above 0, got 0"),
        ({"focal_px": 500, "height": float("inf")}, "height must be a finite number above 0"),
        ({"fov_y_deg": "40"}, "camera JSON fov_y_deg: expected a number, got '40'"),
        ({"fov_y_deg": 40, "hieght": 2}, r"unknown keys \['hieght'\]; valid keys: .*'height'"),
        ({"fov_y_deg": 40, "world_to_camera": [["1", "0", "0", "0"]] * 4}, "rows of numbers"),
    ]:
        with pytest.raises(FrameError, match=words):
            read(path, camera=cam)


# -- a real Blender render ------------------------------------------------------------------------


@pytest.mark.skipif(
    not (FIXTURE / "cycles_multilayer.exr").is_file(),
    reason="tests/fixtures/blender/cycles_multilayer.exr not present (see its README)",
)
def test_real_blender_render() -> None:
    frame = read(FIXTURE / "cycles_multilayer.exr", camera=FIXTURE / "camera.json")
    assert frame.preset == "blender"
    assert frame.passthrough.preset_reason == "header attribute BlenderMultiChannel"
    for name in ("beauty", "normal", "depth", "position", "diffuse", "specular", "ao"):
        assert name in frame.buffers, name
    cov = frame.buffers["coverage"]
    solid = cov > 0.999
    n = frame.buffers["normal"]
    length = np.linalg.norm(n[solid], axis=-1)
    assert np.allclose(length, 1.0, atol=1e-4)
    assert (n[solid][:, 2] > 0).mean() > 0.97  # camera space: surfaces face the camera
    # planar depth is -z of the camera-space position
    d, p = frame.buffers["depth"], frame.buffers["position"]
    finite = np.isfinite(d)
    assert finite.any() and np.isinf(d[~finite]).all()
    np.testing.assert_allclose(d[finite], -p[finite][:, 2], rtol=2e-3, atol=2e-3)
    # the remainder is what no lobe holds: emission + environment
    import OpenEXR as X

    ch = X.File(str(FIXTURE / "cycles_multilayer.exr"), True).channels()

    def rgb(name: str) -> np.ndarray:
        return np.stack([ch[f"ViewLayer.{name}.{c}"].pixels for c in "RGB"], -1).astype(np.float32)

    expected = rgb("Emit") + rgb("Env")
    err = np.abs(frame.buffers["remainder"] - expected)
    assert np.percentile(err, 99) < 0.05 * max(1.0, float(np.abs(expected).max()))


def test_a_channel_two_buffers_read_counts_its_holes_once(tmp_path: Path) -> None:
    """NaN at 2 covered pixels of Blender's DiffCol.G (read by the diffuse lobe and its colour):
    the warning counts 2 there, not 4."""
    src = Path(__file__).parent / "fixtures" / "blender" / "cycles_multilayer.exr"
    with OpenEXR.File(str(src), separate_channels=True) as f:
        header = dict(f.header())
        chans = {name: c.pixels.copy() for name, c in f.channels().items()}
    ys, xs = np.nonzero(chans["ViewLayer.Depth.Z"] < 1e3)
    for i in (10, 20):
        chans["ViewLayer.DiffCol.G"][ys[i], xs[i]] = np.nan
    path = tmp_path / "holes.exr"
    OpenEXR.File(header, chans).write(str(path))
    warnings = describe(read(path))["warnings"]
    assert any("(ViewLayer.DiffCol.G: 2) treated as holes" in w for w in warnings), warnings


def test_an_alpha_of_minus_inf_is_background_and_plus_inf_is_refused(
    tmp_path: Path, scene: F.Scene
) -> None:
    chans = F.canonical_channels(scene)
    alpha = chans["A"].copy()
    alpha[0, 0] = -np.inf  # (alpha <= 0: background, as it was before Inf was refused)
    chans["A"] = alpha
    frame = read(F.write_exr(tmp_path / "minus.exr", {}, chans))
    assert frame.mask[0, 0] == 0.0
    ys, xs = np.nonzero(inner(scene))
    alpha[ys[0], xs[0]] = np.inf
    with pytest.raises(FrameError, match=r"channel 'A' has 1 NaN/Inf value\(s\)"):
        read(F.write_exr(tmp_path / "plus.exr", {}, chans))
