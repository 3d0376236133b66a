"""Where ``depict enhance --layout`` puts the new layers: the input's part (``same``), an added
part whose neighbours are the input's parts copied chunk for chunk (``part``), or a file of their
own (``sidecar``). Real files: the Blender Cycles fixture and a render of examples/spot.obj, through
the CLI in process; Blender's compositor reads the ``part`` output when ``blender`` is installed."""

from __future__ import annotations

import errno
import inspect
import json
import os
import shutil
from pathlib import Path

import numpy as np
import OpenEXR
import pytest

import gbuffer
from gbuffer import exr
from gbuffer.exr import layout as exr_layout
from gbuffer.io import DEFAULT_LAYOUT, LAYOUTS
from gbuffer.render import auto_camera, load_mesh, render
from service import output, pipeline
from service.cli import main
from service.cli.args import DEFAULT_LAYOUT as CLI_DEFAULT
from service.cli.args import LAYOUTS as CLI_LAYOUTS
from service.enhance import WriteRequest, enhance_frame
from tests import exr_factory
from tests.test_output_layout import blender_passes, write_compressed

ROOT = Path(__file__).resolve().parents[1]
BLENDER_EXR = ROOT / "tests" / "fixtures" / "blender" / "cycles_multilayer.exr"
SPOT = ROOT / "examples" / "spot.obj"
RESULT = [f"ViewLayer.Depict.{c}" for c in "RGBA"]


def depict(*argv: str | Path | int) -> int:
    try:
        return main([str(a) for a in argv])
    except SystemExit as exc:
        return int(exc.code or 0)


def parts(path: Path) -> list[tuple[dict[str, object], dict[str, np.ndarray]]]:
    """Every part of ``path``: its header and its channels' pixels."""
    with OpenEXR.File(str(path), separate_channels=True) as f:
        return [
            (dict(p.header), {n: np.array(c.pixels) for n, c in p.channels.items()})
            for p in f.parts
        ]


def chunks(path: Path, index: int) -> list[bytes]:
    """The compressed chunks of part ``index`` (scanline or tiled), without the multi-part part
    number."""
    layout = exr.read_layout(path)
    part = layout.parts[index]
    skip = 4 if layout.multipart else 0
    with open(path, "rb") as f:
        sizes = [exr_layout._chunk_size(f, off, part, layout.multipart) for off in part.offsets]
    data = path.read_bytes()
    return [data[off + skip : off + n] for off, n in zip(part.offsets, sizes, strict=True)]


@pytest.fixture(scope="module")
def outputs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    work = tmp_path_factory.mktemp("layouts")
    out = {}
    for layout in LAYOUTS:
        out[layout] = work / f"{layout}.exr"
        assert depict("enhance", BLENDER_EXR, "-o", out[layout], "--layout", layout) == 0
    return out


def test_the_parser_and_the_http_form_offer_the_writers_layouts() -> None:
    """One default everywhere: ``part`` (the input's parts copied, nothing re-encoded)."""
    assert CLI_LAYOUTS == LAYOUTS and CLI_DEFAULT == DEFAULT_LAYOUT == "part"
    schema = json.loads((ROOT / "openapi" / "openapi.json").read_text())
    form = schema["components"]["schemas"]["Body_enhance_v1_enhance_post"]["properties"]
    assert tuple(form["layout"]["enum"]) == LAYOUTS
    assert form["layout"]["default"] == DEFAULT_LAYOUT
    assert WriteRequest().layout == DEFAULT_LAYOUT
    for function in (gbuffer.write, pipeline.finish, output.finish):
        assert inspect.signature(function).parameters["layout"].default == DEFAULT_LAYOUT


def test_part_layout_copies_the_input_and_adds_only_the_result(outputs: dict[str, Path]) -> None:
    [(_, before)] = parts(BLENDER_EXR)
    (first, kept), (added_header, added) = parts(outputs["part"])
    assert set(kept) == set(before)
    assert chunks(outputs["part"], 0) == chunks(BLENDER_EXR, 0)  # not re-encoded
    assert sorted(added) == sorted(RESULT)
    assert added_header["name"] == "ViewLayer.Depict"
    assert added_header["depict/result"] == "ViewLayer.Depict"
    assert "depict/pipeline" not in first  # the provenance goes with the result
    [(_, same)] = parts(outputs["same"])
    for name in RESULT:
        np.testing.assert_array_equal(added[name], same[name])


SHM = Path("/dev/shm")


@pytest.mark.skipif(not SHM.is_dir(), reason="no /dev/shm: no second file system at hand")
def test_a_result_over_half_in_a_half_file_is_clamped_with_a_word(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--layout same writes the result into the input's HALF R,G,B: values past 65504 (a
    sharpened highlight of 40000) became +inf, with a NumPy RuntimeWarning on stderr."""
    frame = render(load_mesh(SPOT), 96, 72)
    frame.buffers["beauty"][36:38, 40:44] = 40000.0
    frame.outputs = {}
    fresh = tmp_path / "float.exr"
    gbuffer.write(frame, fresh)
    (header, channels), *_ = parts(fresh)
    half = tmp_path / "half.exr"
    kept = {k: v for k, v in header.items() if k not in ("channels", "chunkCount")}
    with OpenEXR.File(kept, {k: v.astype(np.float16) for k, v in channels.items()}) as f:
        f.write(str(half))
    out = tmp_path / "out.exr"
    usm = ("--op", "unsharp_masking", "--set", "amount=2")
    assert depict("enhance", half, "-o", out, "--layout", "same", *usm) == 0
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("depict: warning: values beyond HALF's largest")
    (_, result), *_ = parts(out)
    for c in "RGB":
        assert result[c].dtype == np.float16 and np.isfinite(result[c]).all()
        assert result[c].max() == np.float16(65504)


def test_part_layout_copies_chunks_across_file_systems(
    outputs: dict[str, Path], tmp_path: Path
) -> None:
    """The input's chunks are copied by the kernel within a file system; from another one (where
    the kernel refuses, as Linux does between tmpfs and a disk) they are read and written: the
    same file either way."""
    if SHM.stat().st_dev == tmp_path.stat().st_dev:
        pytest.skip("/dev/shm is on the same file system as the test's folder")
    other = SHM / f"depict-test-{tmp_path.name}.exr"
    shutil.copyfile(BLENDER_EXR, other)
    try:
        out = tmp_path / "across.exr"
        assert depict("enhance", other, "-o", out) == 0
    finally:
        other.unlink()
    assert chunks(out, 0) == chunks(outputs["part"], 0) == chunks(BLENDER_EXR, 0)
    assert chunks(out, 1) == chunks(outputs["part"], 1)  # (the headers name other inputs)


@pytest.mark.parametrize("layout", ["part", "sidecar"])
def test_a_frame_made_in_memory_keeps_its_buffers_in_every_layout(
    tmp_path: Path, layout: str
) -> None:
    """A frame with no file behind it (a render, the Python API) is written whole: its buffers
    are not let go as a read frame's are, whose parts are copied instead."""
    mesh = load_mesh(SPOT)
    frame = render(mesh, 64, 48, camera=auto_camera(mesh, width=64, height=48))
    plain = tmp_path / "plain.exr"
    gbuffer.write(frame, plain)
    out = tmp_path / f"{layout}.exr"
    enhance_frame(frame, out, pipeline.DEFAULT, WriteRequest(layout=layout))
    assert "normal" in frame.buffers
    written = {n for _, channels in parts(out) for n in channels}
    assert {n for _, channels in parts(plain) for n in channels} <= written


def test_a_kernel_copy_that_stops_half_way_is_finished_by_hand(
    outputs: dict[str, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Where the system copies part of a chunk and then refuses (as a file system may), the rest
    of it and the chunks after it are read and written: the same file."""
    real = os.copy_file_range
    calls = []

    def half_then_refuse(src: int, dst: int, count: int, offset_src: int | None = None) -> int:
        calls.append(count)
        if len(calls) > 1:
            raise OSError(errno.EXDEV, "Invalid cross-device link")
        return real(src, dst, count // 2, offset_src)

    monkeypatch.setattr(os, "copy_file_range", half_then_refuse)
    out = tmp_path / "half.exr"
    assert depict("enhance", BLENDER_EXR, "-o", out) == 0
    assert len(calls) == 2
    assert out.read_bytes() == outputs["part"].read_bytes()


def test_sidecar_holds_only_the_new_layers(outputs: dict[str, Path]) -> None:
    [(header, channels)] = parts(outputs["sidecar"])
    assert sorted(channels) == sorted(RESULT)
    assert header["depict/result"] == "ViewLayer.Depict"
    assert header["depict/input"] == BLENDER_EXR.name
    [(_, same)] = parts(outputs["same"])
    for name in RESULT:
        np.testing.assert_array_equal(channels[name], same[name])
    assert outputs["sidecar"].stat().st_size < outputs["same"].stat().st_size / 2


@pytest.mark.parametrize("layout", LAYOUTS)
def test_every_layout_keeps_the_inputs_windows_where_the_file_put_them(
    layout: str, tmp_path: Path
) -> None:
    """A display window away from (0, 0), a data window inside it, a pixel aspect ratio: the
    result sits where the input's pixels do in every layout (a sidecar was written at the frame's
    own origin, the display window's corner, and lay 90 × 40 pixels off in a compositor); and it
    says the input's chromaticities (ACES AP1 here) and time code (a sidecar had neither)."""
    scene = exr_factory.make_scene(h=48, w=64)
    tc = OpenEXR.TimeCode()
    tc.hours, tc.minutes, tc.seconds, tc.frame = 1, 2, 3, 4
    windows = {
        "displayWindow": exr.box2i(90, 40, 179, 119),
        "dataWindow": exr.box2i(100, 50, 163, 97),
        "pixelAspectRatio": 1.25,
        "chromaticities": (0.713, 0.293, 0.165, 0.830, 0.128, 0.044, 0.32168, 0.33767),
        "timeCode": tc,
    }
    src = exr_factory.write_canonical(tmp_path / "offset.exr", scene, windows)
    out = tmp_path / f"{layout}.exr"
    assert depict("enhance", src, "-o", out, "--layout", layout) == 0
    [(source_header, _)] = parts(src)
    for header, _ in parts(out):  # (the result's part, and the input's copied beside it)
        for key in windows:
            assert str(header[key]) == str(source_header[key]), key


def test_the_same_layout_keeps_a_half_beauty_beside_the_result_as_half(tmp_path: Path) -> None:
    """``--layout same`` moves the input's own R, G, B, A aside for the result: HALF stays HALF,
    bit for bit (they were written as FLOAT, twice the bytes, and a different channel type)."""
    src = exr_factory.write_canonical(tmp_path / "half.exr", exr_factory.make_scene(h=48, w=64))
    [(_, given)] = parts(src)
    assert all(given[c].dtype == np.float16 for c in "RGBA")
    out = tmp_path / "same.exr"
    assert depict("enhance", src, "-o", out, "--layout", "same") == 0
    [(header, written)] = parts(out)
    kept = header["depict/original"]
    for c in "RGBA":
        assert written[f"{kept}.{c}"].dtype == np.float16
        assert written[f"{kept}.{c}"].tobytes() == given[c].tobytes()


def test_a_pxr24_warning_names_only_the_float_layers_it_rounds(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """PXR24 keeps HALF exact and rounds FLOAT to 24 bits: re-encoding a part names the new
    FLOAT layers only (it named the input's own R, G, B, A moved aside, HALF)."""
    scene = exr_factory.make_scene(h=48, w=64)
    src = exr_factory.write_canonical(
        tmp_path / "pxr24.exr", scene, {"compression": OpenEXR.PXR24_COMPRESSION}
    )
    out = tmp_path / "same.exr"
    capsys.readouterr()
    assert depict("enhance", src, "-o", out, "--layout", "same", "--op", "curvature") == 0
    [warning] = capsys.readouterr().err.splitlines()
    assert "rounded to 24 bits" in warning and "curvature.H" in warning
    [(header, written)] = parts(out)
    kept = header["depict/original"]
    assert f"{kept}.R" in written and f"{kept}." not in warning


def test_a_part_output_reads_back_and_enhances_again(
    outputs: dict[str, Path], tmp_path: Path
) -> None:
    frame = gbuffer.read(outputs["part"])
    assert "Depict's result" in frame.sources["beauty"]
    again = tmp_path / "again.exr"
    assert depict("enhance", outputs["part"], "-o", again, "--layout", "part") == 0
    after = parts(again)
    assert [sorted(c) for _, c in after] == [sorted(c) for _, c in parts(outputs["part"])]
    assert chunks(again, 0) == chunks(BLENDER_EXR, 0)


def test_part_layout_of_a_render_keeps_its_rgba(tmp_path: Path) -> None:
    src, out = tmp_path / "spot.exr", tmp_path / "out.exr"
    assert depict("render", SPOT, "-o", src, "--width", 64, "--height", 48) == 0
    assert depict("enhance", src, "-o", out, "--layout", "part") == 0
    [(_, before)] = parts(src)
    (_, kept), (header, added) = parts(out)
    assert sorted(added) == [f"Depict.{c}" for c in "ABGR"]  # not over the render's R,G,B,A
    assert header["depict/result"] == "Depict"
    for name in "RGBA":
        np.testing.assert_array_equal(kept[name], before[name])
    assert not np.array_equal(added["Depict.R"], before["R"])


def test_an_unknown_layout_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert depict("enhance", BLENDER_EXR, "-o", tmp_path / "o.exr", "--layout", "beside") == 2
    assert "--layout" in capsys.readouterr().err
    with pytest.raises(gbuffer.FrameError, match="layout 'beside'"):
        gbuffer.write(gbuffer.read(BLENDER_EXR), tmp_path / "o.exr", layout="beside")


@pytest.mark.skipif(shutil.which("blender") is None, reason="Debian's blender is not installed")
def test_blenders_compositor_reads_the_added_part(outputs: dict[str, Path], tmp_path: Path) -> None:
    passes = blender_passes(outputs["part"], tmp_path)
    assert "Depict" in passes and "Combined" in passes and "Position" in passes


def test_debug_layers_of_a_second_part_enhance_join_the_result_part(
    outputs: dict[str, Path], tmp_path: Path
) -> None:
    again = tmp_path / "again.exr"
    argv = ("enhance", outputs["part"], "-o", again, "--layout", "part", "--debug-layers")
    assert depict(*argv) == 0
    _, (header, result) = parts(again)  # no third part: the result's part took them
    assert set(RESULT) < set(result) and "curvature.H" in result
    assert len(json.loads(str(header["depict/history"]))) == 2
    assert chunks(again, 0) == chunks(BLENDER_EXR, 0)


def test_part_layout_keeps_a_lossy_part_as_it_was(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src = write_compressed(BLENDER_EXR, tmp_path / "dwaa.exr", "DWAA", tiled=True)
    out = tmp_path / "out.exr"
    assert depict("enhance", src, "-o", out, "--layout", "part") == 0
    assert "DWAA" not in capsys.readouterr().err  # nothing re-quantised, nothing to warn about
    assert chunks(out, 0) == chunks(src, 0)
    layout = exr.read_layout(out)
    assert [exr.COMPRESSION_NAMES[p.compression] for p in layout.parts] == ["DWAA", "ZIP"]


def test_released_pixels_come_back_when_read_and_the_input_is_still_copied(
    tmp_path: Path,
) -> None:
    frame = gbuffer.read(BLENDER_EXR)
    before = frame.layer("ViewLayer.Combined")
    exr.release_pixels(frame.passthrough)
    channels = frame.passthrough.parts[0][1]
    assert all(isinstance(c, exr.ReleasedChannel) for c in channels.values())
    again = frame.layer("ViewLayer.Combined")  # decoded again from the file
    assert sorted(again) == sorted(before)
    for name, pixels in before.items():
        np.testing.assert_array_equal(again[name], pixels)
    frame.outputs["ViewLayer.Extra.X"] = np.ones(frame.shape, np.float32)
    out = tmp_path / "out.exr"
    gbuffer.write(frame, out, layout="part")
    assert chunks(out, 0) == chunks(BLENDER_EXR, 0)


@pytest.mark.parametrize("source", ["blender", "depict"])
def test_a_released_read_lets_each_channel_go_after_its_last_buffer(
    source: str, tmp_path: Path
) -> None:
    """``read(..., release=True)`` (the ``part``/``sidecar`` path) gives the same buffers as a
    plain read without decoding the file a second time: a channel read by two buffers (Cycles'
    DiffCol is the albedo and the diffuse colour) goes only after the second."""
    path = BLENDER_EXR
    if source == "depict":
        path = tmp_path / "spot.exr"
        assert depict("render", SPOT, "-o", path, "--width", 160, "--height", 120) == 0
    kept = gbuffer.read(path)
    released = gbuffer.read(path, release=True)
    assert sorted(released.buffers) == sorted(kept.buffers)
    for key, arr in kept.buffers.items():
        np.testing.assert_array_equal(released.buffers[key], arr, err_msg=key)
    pt = released.passthrough
    assert isinstance(pt, exr.ExrPassthrough) and pt.redecode is not None
    assert pt.redecode.parts is None  # nothing was decoded again
    channels = pt.parts[0][1]
    assert all(isinstance(c, exr.ReleasedChannel) for c in channels.values())
