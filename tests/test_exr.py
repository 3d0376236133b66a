"""gbuffer.exr: lossless passthrough of real EXR files, and clean refusals of bad ones."""

from __future__ import annotations

import struct
import time
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np
import OpenEXR
import pytest

from gbuffer import exr
from gbuffer.errors import FrameError, LimitError
from gbuffer.exr import read as exr_read
from tests.exr_factory import patch_data_window, rich_header, write_corrupt, write_raw_exr

RNG = np.random.default_rng(7)


def rand(h: int, w: int, dtype: Any) -> np.ndarray:
    if np.dtype(dtype) == np.uint32:
        return RNG.integers(0, 2**32 - 1, (h, w), dtype=np.uint32)
    return (RNG.standard_normal((h, w)) * 10).astype(dtype)


def same_value(a: Any, b: Any) -> bool:
    return exr_read._same_value(a, b)


def assert_identical(a: Path, b: Path) -> None:
    """Every part, channel (type, sampling, bits) and header attribute equal, read by OpenEXR."""
    fa = OpenEXR.File(str(a), separate_channels=True)
    fb = OpenEXR.File(str(b), separate_channels=True)
    assert len(fa.parts) == len(fb.parts)
    for pa, pb in zip(fa.parts, fb.parts, strict=True):
        ha, hb = dict(pa.header), dict(pb.header)
        assert sorted(ha) == sorted(hb)
        for key in ha:
            if key == "channels":
                assert [repr(c) for c in ha[key]] == [repr(c) for c in hb[key]]
            else:
                assert same_value(ha[key], hb[key]), key
        assert sorted(pa.channels) == sorted(pb.channels)
        for name, ca in pa.channels.items():
            cb = pb.channels[name]
            assert ca.type() == cb.type(), name
            assert (ca.xSampling, ca.ySampling, ca.pLinear) == (
                cb.xSampling,
                cb.ySampling,
                cb.pLinear,
            )
            assert ca.pixels.tobytes() == cb.pixels.tobytes(), name
    # and the raw attribute bytes (types the binding would change, e.g. double)
    la, lb = exr.read_layout(a), exr.read_layout(b)
    for x, y in zip(la.parts, lb.parts, strict=True):
        assert x.attributes == y.attributes


def single_part(tmp_path: Path, compression: Any = OpenEXR.ZIP_COMPRESSION) -> Path:
    h, w = 37, 53
    channels = {
        "R": rand(h, w, np.float16),
        "G": rand(h, w, np.float16),
        "B": rand(h, w, np.float16),
        "A": rand(h, w, np.float16),
        "depth.Z": rand(h, w, np.float32),
        "id.V": rand(h, w, np.uint32),
    }
    header = {"compression": compression, **rich_header()}
    path = tmp_path / "single.exr"
    OpenEXR.File(header, channels).write(str(path))
    return path


def test_round_trip_single_part_is_bit_identical(tmp_path: Path) -> None:
    src = single_part(tmp_path)
    pt = exr.read_parts(src)
    assert pt.parts[0][1]["id.V"].pixels.dtype == np.uint32
    assert pt.parts[0][0]["framesPerSecond"] == Fraction(24000, 1001)
    out = tmp_path / "out.exr"
    assert exr.write_parts(pt, out) == []
    assert_identical(src, out)


def test_re_encoded_part_keeps_types_and_attributes(tmp_path: Path) -> None:
    src = single_part(tmp_path, OpenEXR.PIZ_COMPRESSION)
    pt = exr.read_parts(src)
    channels = pt.parts[0][1]
    # new channel objects: the part is encoded again by the binding, not copied
    for name, ch in list(channels.items()):
        channels[name] = OpenEXR.Channel(name, ch.pixels.copy())
    out = tmp_path / "out.exr"
    exr.write_parts(pt, out)
    assert_identical(src, out)


def test_multi_part_tiled_and_scanline_round_trip(tmp_path: Path) -> None:
    tiles = OpenEXR.TileDescription()
    tiles.xSize, tiles.ySize = 16, 8
    tiles.mode, tiles.roundingMode = OpenEXR.ONE_LEVEL, OpenEXR.ROUND_DOWN
    h, w = 30, 41
    beauty = OpenEXR.Part(
        {"compression": OpenEXR.PIZ_COMPRESSION, "type": OpenEXR.tiledimage, "tiles": tiles},
        {c: rand(h, w, np.float16) for c in "RGBA"},
        "rgba",
    )
    normals = OpenEXR.Part(
        {"compression": OpenEXR.ZIPS_COMPRESSION, "lineOrder": OpenEXR.DECREASING_Y},
        {c: rand(h, w, np.float32) for c in "XYZ"},
        "N",
    )
    src = tmp_path / "multi.exr"
    OpenEXR.File([beauty, normals]).write(str(src))
    pt = exr.read_parts(src)
    assert [h.get("name") for h, _ in pt.parts] == ["rgba", "N"]
    out = tmp_path / "out.exr"
    exr.write_parts(pt, out)
    assert_identical(src, out)
    # change one part only: the other still comes back chunk for chunk
    pt.parts[1][1]["extra"] = OpenEXR.Channel("extra", np.ones((h, w), np.float32))
    exr.write_parts(pt, out)
    back = OpenEXR.File(str(out), separate_channels=True)
    assert back.parts[0].header["tiles"] == tiles
    assert back.parts[1].header["lineOrder"] == OpenEXR.DECREASING_Y
    assert set(back.parts[1].channels) == {"X", "Y", "Z", "extra"}
    src_parts = OpenEXR.File(str(src), separate_channels=True).parts
    for name in "XYZ":
        assert np.array_equal(
            back.parts[1].channels[name].pixels, src_parts[1].channels[name].pixels
        )


def test_lossy_part_untouched_is_copied_bit_for_bit(tmp_path: Path) -> None:
    """DWAA is not idempotent: re-encoding decoded pixels changes them; copying does not."""
    src = tmp_path / "dwaa.exr"
    OpenEXR.File(
        {"compression": OpenEXR.DWAA_COMPRESSION},
        {c: rand(64, 64, np.float16) for c in "RGB"},
    ).write(str(src))
    pt = exr.read_parts(src)
    out = tmp_path / "out.exr"
    exr.write_parts(pt, out)
    assert out.read_bytes() == src.read_bytes()


def test_data_window_inside_display_window(tmp_path: Path) -> None:
    h, w = 20, 30
    header = {
        "compression": OpenEXR.ZIP_COMPRESSION,
        "dataWindow": exr.box2i(5, 7, 5 + w - 1, 7 + h - 1),
        "displayWindow": exr.box2i(0, 0, 99, 59),
    }
    src = tmp_path / "window.exr"
    OpenEXR.File(header, {"Z": rand(h, w, np.float32)}).write(str(src))
    pt = exr.read_parts(src)
    assert pt.parts[0][1]["Z"].pixels.shape == (h, w)
    assert exr.window(pt.parts[0][0], "dataWindow") == (5, 7, 34, 26)
    out = tmp_path / "out.exr"
    pt.parts[0][1]["Z2"] = OpenEXR.Channel("Z2", np.zeros((h, w), np.float32))
    exr.write_parts(pt, out)
    back = OpenEXR.File(str(out), separate_channels=True)
    assert exr.window(back.header(), "dataWindow") == (5, 7, 34, 26)
    assert exr.window(back.header(), "displayWindow") == (0, 0, 99, 59)


def test_attributes_the_binding_cannot_write_come_back(tmp_path: Path) -> None:
    extra = (
        ("exposureD", "double", struct.pack("<d", 1.1)),
        ("emptyTags", "stringvector", b""),
        ("vendor/blob", "acmeBlob", b"\x00\x01\x02\xff"),
    )
    src = write_raw_exr(tmp_path / "raw.exr", {"Y": rand(9, 11, np.float32)}, extra)
    pt = exr.read_parts(src)
    out = tmp_path / "out.exr"
    exr.write_parts(pt, out)
    assert exr.read_layout(out).parts[0].attributes == exr.read_layout(src).parts[0].attributes
    # a part encoded again keeps them too, and a changed value is written as the new value
    header, channels = pt.parts[0]
    channels["Y"] = OpenEXR.Channel("Y", channels["Y"].pixels.copy())
    header["comment"] = "added"
    exr.write_parts(pt, out)
    attrs = exr.read_layout(out).parts[0].attributes
    assert attrs["exposureD"] == exr.RawAttribute("double", struct.pack("<d", 1.1))
    assert attrs["vendor/blob"].data == b"\x00\x01\x02\xff"
    assert attrs["comment"] == exr.RawAttribute("string", b"added")


def test_pixels_read_are_read_only(tmp_path: Path) -> None:
    pt = exr.read_parts(single_part(tmp_path))
    with pytest.raises(ValueError):
        pt.parts[0][1]["R"].pixels[0, 0] = 1.0


# -- bad files ------------------------------------------------------------------------------------


def test_not_an_exr(tmp_path: Path) -> None:
    bad = tmp_path / "notes.exr"
    bad.write_text("hello, this is not an image\n" * 10)
    with pytest.raises(FrameError, match=r"notes\.exr: not an OpenEXR file"):
        exr.read_parts(bad)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(FrameError, match="cannot read"):
        exr.read_parts(tmp_path / "absent.exr")


@pytest.mark.parametrize("keep", [0.5, 0.9, 30])
def test_truncated_file(tmp_path: Path, keep: float) -> None:
    src = single_part(tmp_path)
    data = src.read_bytes()
    cut = tmp_path / "cut.exr"
    cut.write_bytes(data[: int(len(data) * keep) if keep < 1 else int(keep)])
    with pytest.raises(FrameError, match=r"cut\.exr: truncated") as info:
        exr.read_parts(cut)
    assert "\n" not in str(info.value)


def test_corrupt_pixel_data(tmp_path: Path) -> None:
    bad = write_corrupt(tmp_path / "corrupt.exr")
    with pytest.raises(FrameError, match=r"corrupt\.exr: (corrupt|cannot decode)") as info:
        exr.read_parts(bad)
    assert "OpenEXR: (EXR_ERR_CORRUPT_CHUNK)" in str(info.value)  # the library's words


def test_huge_header_refused_before_decoding(tmp_path: Path) -> None:
    src = write_raw_exr(tmp_path / "huge.exr", {"R": rand(4, 4, np.float32)})
    patch_data_window(src, (0, 0, 99_999, 99_999))
    t0 = time.perf_counter()
    with pytest.raises(LimitError, match=r"100000x100000 = 10000000000 pixels, over the limit"):
        exr.read_parts(src, max_pixels=4096 * 4096)
    with pytest.raises(LimitError):  # the hard ceiling without a configured limit
        exr.read_parts(src)
    assert time.perf_counter() - t0 < 5.0  # nothing of 40 GB was allocated or decoded
    assert exr.read_parts(write_raw_exr(tmp_path / "ok.exr", {"R": rand(4, 4, np.float32)}), 16)


def test_unknown_pixel_type(tmp_path: Path) -> None:
    src = write_raw_exr(
        tmp_path / "type.exr", {"N.X": rand(4, 4, np.float32)}, pixel_types={"N.X": 7}
    )
    with pytest.raises(
        FrameError, match=r"channel 'N\.X' has pixel type 7, not UINT, HALF or FLOAT"
    ):
        exr.read_parts(src)


@pytest.mark.parametrize("sampling", [(3, 1), (1, 2)])
def test_a_sampling_the_window_is_no_multiple_of_is_named(
    tmp_path: Path, sampling: tuple[int, int]
) -> None:
    """OpenEXR refuses such a file, and its binding says only "Unable to open ... for read"."""
    src = write_raw_exr(tmp_path / "s.exr", {"N.X": rand(5, 4, np.float32)})
    data = bytearray(src.read_bytes())
    at = data.index(b"N.X\0") + 4 + 4 + 4  # (name, pixel type, pLinear and reserved)
    struct.pack_into("<2i", data, at, *sampling)
    src.write_bytes(bytes(data))
    axis, step, size = ("x", 3, 4) if sampling[0] != 1 else ("y", 2, 5)
    with pytest.raises(
        FrameError,
        match=rf"channel 'N\.X' has {axis} sampling {step}, which the data window's {axis} "
        rf"origin 0 and size {size} are not multiples of \(OpenEXR refuses it\)",
    ):
        exr.read_parts(src)


def test_max_pixels_must_be_positive(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="max_pixels"):
        exr.read_parts(single_part(tmp_path), max_pixels=0)


# -- writing safely -------------------------------------------------------------------------------


def test_failed_write_leaves_target_untouched(tmp_path: Path) -> None:
    src = single_part(tmp_path)
    pt = exr.read_parts(src)
    target = tmp_path / "target.exr"
    target.write_bytes(b"previous content")
    h, w = pt.parts[0][1]["R"].pixels.shape
    pt.parts[0][1]["bad"] = np.zeros((h, w), np.float64)  # not an EXR pixel type
    with pytest.raises(FrameError, match="channel 'bad' has dtype float64"):
        exr.write_parts(pt, target)
    assert target.read_bytes() == b"previous content"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["single.exr", "target.exr"]


def test_write_in_memory_passthrough(tmp_path: Path) -> None:
    from gbuffer.frame import Passthrough

    pixels = rand(5, 6, np.float32)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "note": "fresh"}
    out = tmp_path / "fresh.exr"
    exr.write_parts(Passthrough(parts=[(header, {"Z": pixels})]), out)
    back = OpenEXR.File(str(out), separate_channels=True)
    assert back.header()["note"] == "fresh"
    assert np.array_equal(back.channels()["Z"].pixels, pixels)


def test_written_files_get_the_usual_permissions(tmp_path: Path) -> None:
    """Atomic writes must not leave the private 0600 mode of a temporary file."""
    import os

    from gbuffer.atomic import atomic_path

    target = tmp_path / "out.bin"
    with atomic_path(target) as tmp:
        tmp.write_bytes(b"x")
    umask = os.umask(0o022)
    os.umask(umask)
    assert target.stat().st_mode & 0o777 == 0o666 & ~umask
    target.chmod(0o640)
    with atomic_path(target) as tmp:
        tmp.write_bytes(b"y")
    assert target.stat().st_mode & 0o777 == 0o640


def test_an_output_not_written_leaves_no_folders_it_made(tmp_path: Path) -> None:
    """Folders made for an output are removed when it fails (they stayed, empty); a folder that
    was there, or that holds something, stays."""
    import pytest

    from gbuffer.atomic import atomic_path
    from gbuffer.errors import OutputError

    (tmp_path / "kept").mkdir()
    with pytest.raises(RuntimeError), atomic_path(tmp_path / "kept/new/deeper/out.exr"):
        raise RuntimeError("the encoder failed")
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["kept"]
    long = "a" * 245  # the name fits, its temporary name (.NAME.XXXXXXXX.tmp.exr) does not
    with pytest.raises(OutputError, match="cannot write"), atomic_path(tmp_path / f"n/{long}.exr"):
        pass
    assert not (tmp_path / "n").exists()
    with pytest.raises(RuntimeError), atomic_path(tmp_path / "a/b/out.exr") as tmp:
        (tmp_path / "a/other.txt").write_text("another run's file")
        raise RuntimeError(tmp.name)
    assert sorted(p.name for p in (tmp_path / "a").iterdir()) == ["other.txt"]
    with atomic_path(tmp_path / "x/y/out.bin") as tmp:
        tmp.write_bytes(b"x")
    assert (tmp_path / "x/y/out.bin").read_bytes() == b"x"
