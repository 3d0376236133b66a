"""The command line never loses data and fails in one line: outputs that name inputs, FIFOs,
device nodes and symbolic links, unwritable places, absurd values, library chatter, control
bytes, NaN/Inf fireflies, decode bombs and deep pipelines. Real files, FIFOs, links and
devices; the CLI runs in process with its file descriptors watched (capfd)."""

from __future__ import annotations

import json
import os
import stat
import warnings
from pathlib import Path

import cv2
import numpy as np
import OpenEXR
import pytest
import trimesh

from gbuffer.errors import LimitError
from gbuffer.io import write as write_exr
from gbuffer.limits import RENDER_WORKING, Limits, _physical_memory
from gbuffer.render import render
from service.cli import main
from service.cli.args import error_line
from service.jobs import NOTHING_SCORED
from tests.exr_factory import (
    make_scene,
    render_with_nan,
    write_canonical,
    write_corrupt,
    write_decode_bomb,
    write_raw_exr,
)

SPOT = Path(__file__).resolve().parents[1] / "examples" / "spot.obj"


def depict(*argv: str | Path) -> int:
    try:
        return main([str(a) for a in argv])
    except SystemExit as exc:
        return int(exc.code or 0)


def one_error(capfd: pytest.CaptureFixture[str], words: str) -> str:
    """Exactly one line on stderr (fd 2, C++ output included), ``depict: error: ...``."""
    out, err = capfd.readouterr()
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("depict: error: ") and words in lines[0], lines[0]
    assert "Traceback" not in out + err and "Warning:" not in out
    return lines[0]


@pytest.fixture(scope="module")
def frame(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("safety") / "frame.exr"
    write_exr(render(trimesh.creation.icosphere(subdivisions=2), 64, 48), path)
    return path


@pytest.fixture
def copy(frame: Path, tmp_path: Path) -> Path:
    path = tmp_path / "shot.exr"
    path.write_bytes(frame.read_bytes())
    return path


# -- outputs that name inputs ---------------------------------------------------------------------


def test_enhance_refuses_to_overwrite_its_input(
    copy: Path, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    before = copy.read_bytes()
    link = tmp_path / "link.exr"
    link.symlink_to(copy)
    hard = tmp_path / "hard.exr"
    os.link(copy, hard)
    for output in (copy, link, hard, tmp_path / "." / "shot.exr"):
        assert depict("enhance", copy, "-o", output) == 2
        one_error(capfd, "would be overwritten")
    assert depict("preview", copy, "-o", copy) == 2
    one_error(capfd, "would be overwritten")
    assert copy.read_bytes() == before


def test_batch_refuses_an_output_pattern_that_names_the_inputs(
    frame: Path, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    for f in (1, 2, 3):
        (tmp_path / f"shot.{f:04d}.exr").write_bytes(frame.read_bytes())
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    for pattern in ("shot.%04d.exr", "./shot.@@@@.exr", "shot.####.exr"):
        code = depict(
            "batch", tmp_path / "shot.####.exr", "-o", tmp_path / pattern, "--no-progress"
        )
        assert code == 2
        one_error(capfd, "overwritten" if "%" in pattern or "@" in pattern else "input pattern")
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


def test_a_batch_chunk_refuses_to_write_over_another_chunks_input(
    frame: Path, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    """A link in the output folder to an input frame that this run (--frames 1-2) does not
    read: a farm's chunk would have written over the input of a later chunk."""
    shots, outs = tmp_path / "in", tmp_path / "out"
    shots.mkdir()
    outs.mkdir()
    for f in range(1, 5):
        (shots / f"s.{f:04d}.exr").write_bytes(frame.read_bytes())
    (outs / "s.0002.exr").symlink_to(shots / "s.0004.exr")
    before = (shots / "s.0004.exr").read_bytes()
    argv = ["batch", shots / "s.####.exr", "-o", outs / "s.####.exr", "--frames", "1-2"]
    assert depict(*argv, "--no-progress") == 2
    one_error(capfd, "frame 2's output")
    assert (shots / "s.0004.exr").read_bytes() == before
    assert not (outs / "s.0001.exr").exists()


def test_batch_frame_ranges_are_bounded(copy: Path, capfd: pytest.CaptureFixture[str]) -> None:
    args = ("batch", copy.parent / "s.####.exr", "-o", copy.parent / "o.####.exr")
    assert depict(*args, "--frames", "1-1000000000") == 2
    one_error(capfd, "more than 100000 frames")


# -- special files and links as outputs ------------------------------------------------------------


def test_fifo_and_device_outputs_are_refused(
    copy: Path, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    fifo = tmp_path / "pipe.exr"
    os.mkfifo(fifo)
    assert depict("enhance", copy, "-o", fifo) == 2
    one_error(capfd, "FIFO")
    assert stat.S_ISFIFO(fifo.stat().st_mode)
    assert depict("preview", copy, "-o", tmp_path) == 2
    one_error(capfd, "a directory")
    if os.geteuid() == 0:  # a character device like /dev/null, made here
        null = tmp_path / "null.exr"
        os.mknod(null, 0o666 | stat.S_IFCHR, os.makedev(1, 3))
        assert depict("enhance", copy, "-o", null) == 2
        one_error(capfd, "character device")
        assert stat.S_ISCHR(null.stat().st_mode)


def test_symlinked_output_is_written_through(copy: Path, tmp_path: Path) -> None:
    real = tmp_path / "renders" / "out.exr"
    real.parent.mkdir()
    real.write_bytes(b"old")
    link = tmp_path / "latest.exr"
    link.symlink_to(real)
    assert depict("enhance", copy, "-o", link) == 0
    assert link.is_symlink() and link.resolve() == real.resolve()
    assert real.read_bytes()[:4] == b"\x76\x2f\x31\x01"


def test_unwritable_places_and_bad_values_are_one_line(
    copy: Path, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    blocked = copy  # a file: nothing can be created "inside" it, even by root
    assert depict("preview", copy, "-o", blocked / "p.png") == 2
    one_error(capfd, "cannot write")
    assert depict("arm", "-o", blocked / "arm.png", "--size", "64") == 2
    one_error(capfd, "cannot write")
    assert depict("compare", copy, "--directions", "1", "--plot", blocked / "plot.png") == 2
    one_error(capfd, "cannot write")
    assert depict("preview", copy, "-o", tmp_path / "p.png", "--exposure", "1e308") == 2
    one_error(capfd, "--exposure")
    assert not (tmp_path / "p.png").exists()


# -- one clean line per error ----------------------------------------------------------------------


def test_corrupt_pixels_give_one_line_with_the_library_words(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    bad = write_corrupt(tmp_path / "corrupt.exr")
    assert depict("enhance", bad, "-o", tmp_path / "o.exr") == 2
    line = one_error(capfd, "corrupt pixel data")
    assert "OpenEXR: (EXR_ERR_CORRUPT_CHUNK)" in line
    # inspect still describes what the header says
    assert depict("inspect", bad, "--json") == 0
    info = json.loads(capfd.readouterr().out)
    assert info["parts"][0]["channels"] == ["G", "R"]
    assert "pixels not described" in info["warnings"][0]
    assert "corrupt pixel data" in info["undecoded"]
    # and in text, without blaming buffers it could not read ("cannot run: ... needs normal")
    assert depict("inspect", bad) == 0
    text = capfd.readouterr().out
    assert "operators: none can run, the pixels could not be decoded" in text
    assert "cannot run:" not in text
    # a bad setting is not an undecodable file
    with pytest.MonkeyPatch.context() as env:
        env.setenv("DEPICT_MAX_PIXELS", "-5")
        assert depict("inspect", bad) == 2
    one_error(capfd, "DEPICT_MAX_PIXELS='-5' must be positive")


def test_control_bytes_in_names_are_escaped(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    name = "N\x1b[2J\n.X"
    src = write_raw_exr(
        tmp_path / "ctl.exr", {name: np.zeros((4, 4), np.float32)}, pixel_types={name: 7}
    )
    assert depict("enhance", src, "-o", tmp_path / "o.exr") == 2
    line = one_error(capfd, "pixel type 7")
    assert "\x1b" not in line and "N\\x1b[2J\\x0a.X" in line
    assert depict("inspect", src) == 0  # the header is described, escaped
    out = capfd.readouterr().out
    assert "\x1b" not in out and "N\\x1b[2J\\x0a.X" in out


def test_decode_bomb_is_refused_on_the_header(
    tmp_path: Path, capfd: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    bomb = write_decode_bomb(tmp_path / "bomb.exr")
    monkeypatch.setenv("DEPICT_MAX_DECODED_MB", "1024")
    assert depict("enhance", bomb, "-o", tmp_path / "o.exr") == 2
    one_error(capfd, "decode to 1266 MiB, over the limit of 1024 MiB (DEPICT_MAX_DECODED_MB)")


def test_a_render_too_large_for_memory_is_refused_before_it_starts(
    tmp_path: Path, capfd: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Over DEPICT_MAX_DECODED_MB (without it: the machine's memory). It used to start
    rendering whatever the size: 4096² took 10 GB, and 16384², the largest, 40 or more."""
    out = tmp_path / "big.exr"
    monkeypatch.setenv("DEPICT_MAX_DECODED_MB", "100")
    assert depict("render", SPOT, "-o", out, "--width", "2048", "--height", "2048") == 2
    one_error(capfd, "688 MiB, over the limit of 100 MiB (DEPICT_MAX_DECODED_MB)")
    assert not out.exists()
    # the bench's renders too (it rendered whatever size it was given)
    assert depict("compare", SPOT, "--width", "2048", "--height", "2048") == 2
    one_error(capfd, "compare: 2048x2048 pixels render 43 float channels, 688 MiB, over")


def test_deep_pipeline_file_is_one_line(
    copy: Path, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    deep = tmp_path / "deep.json"
    effect = '{"op": "x", "params": {"effect": ' * 4000 + "1" + "}}" * 4000
    deep.write_text('[{"op": "apparent_relief", "params": {"effect": ' + effect + "}}]")
    assert depict("enhance", copy, "-o", tmp_path / "o.exr", "--pipeline", deep) == 2
    one_error(capfd, "levels deep")


def test_missing_buffer_names_the_buffer(tmp_path: Path, capfd: pytest.CaptureFixture[str]) -> None:
    src = write_raw_exr(tmp_path / "depth.exr", {"depth.Z": np.ones((8, 8), np.float32)})
    assert depict("enhance", src, "-o", tmp_path / "o.exr") == 2
    line = one_error(capfd, "the frame has no 'normal' buffer")
    assert "(--map normal=LAYER)" in line
    assert "{name}" not in line


# -- fireflies -------------------------------------------------------------------------------------


def test_nan_and_inf_radiance_are_holes_passed_through(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    holes = {
        "beauty": [(36, 48, 0, np.nan), (30, 40, 1, np.inf), (33, 44, 2, 1e20)],
        "diffuse": [(40, 50, 2, np.nan)],
    }  # (1e20: finite, but its square overflows float32: NaN in the results around it)
    src = render_with_nan(tmp_path / "fireflies.exr", (96, 72), holes)
    with OpenEXR.File(str(src), separate_channels=True) as f:
        original = {n: c.pixels.copy() for n, c in f.channels().items()}
    out = tmp_path / "out.exr"
    assert depict("enhance", src, "-o", out, "--op", "unsharp_masking") == 0
    err = capfd.readouterr().err.splitlines()
    assert err == [
        "depict: warning: 4 pixel(s) with NaN/Inf radiance (or beyond 1e18) (B: 1, G: 1, R: 1, "
        "diffuse.B: 1) treated as holes: left out of the operators and written back unchanged"
    ]
    with OpenEXR.File(str(out), separate_channels=True) as f:
        result = {n: c.pixels for n, c in f.channels().items()}
    rgb = np.dstack([result[c] for c in "RGB"])
    assert np.isnan(rgb[36, 48, 0]) and np.isposinf(rgb[30, 40, 1]) and rgb[33, 44, 2] == 1e20
    others = np.delete(rgb.reshape(-1), [(36 * 96 + 48) * 3, (30 * 96 + 40) * 3 + 1])
    assert np.isfinite(others).all() and np.count_nonzero(others > 1e18) == 1
    for y, x in ((36, 48), (30, 40), (40, 50), (33, 44)):  # the holes: every channel as it was
        for c in "RGB":
            assert result[c][y, x].tobytes() == original[c][y, x].tobytes()
    assert not np.array_equal(result["R"], original["R"])  # the operator did work elsewhere


@pytest.mark.parametrize(
    ("buffer", "k", "value", "channel"),
    [
        ("normal", 0, np.nan, "N.X"),
        ("normal", 1, np.inf, "N.Y"),  # (Inf was let through, and reached the result)
        ("position", 2, -np.inf, "P.Z"),
    ],
)
def test_nan_or_inf_in_a_data_channel_is_refused_by_enhance_but_described_by_inspect(
    tmp_path: Path,
    capfd: pytest.CaptureFixture[str],
    buffer: str,
    k: int,
    value: float,
    channel: str,
) -> None:
    src = render_with_nan(tmp_path / "nan.exr", (64, 48), {buffer: [(24, 32, k, value)]})
    assert depict("enhance", src, "-o", tmp_path / "o.exr") == 2
    one_error(capfd, f"channel '{channel}' has 1 NaN/Inf value(s) on covered pixels")
    assert not (tmp_path / "o.exr").exists()
    assert depict("inspect", src) == 0
    out = capfd.readouterr().out
    assert f"warning: NaN/Inf in data channels on covered pixels ({channel}: 1): masked here" in out


def test_out_of_memory_is_one_line_naming_the_limits() -> None:
    """NumPy's and OpenCV's failures to allocate (a frame too large for the free memory)."""
    for exc in (MemoryError(), cv2.error("Insufficient memory) Failed to allocate 452984832")):
        line = error_line(exc)
        assert line is not None and line.startswith("out of memory: this run needs more")
        assert "DEPICT_MAX_DECODED_MB" in line
    assert error_line(cv2.error("Sizes of input arguments do not match")) is None  # a bug


@pytest.mark.parametrize(
    ("flag", "content", "words"),
    [
        ("--pipeline", b"\xff\xfe\x00binary", "cannot read pipeline {path}: it is not UTF-8 text"),
        ("--camera", b"\xff\xfe\x00binary", "cannot read camera file {path}: it is not UTF-8"),
        ("--camera", b'{"a": ' * 100_000 + b"1" + b"}" * 100_000, "{path}: nested too deeply"),
    ],
)
def test_unreadable_pipeline_and_camera_files_are_named(
    copy: Path,
    tmp_path: Path,
    capfd: pytest.CaptureFixture[str],
    flag: str,
    content: bytes,
    words: str,
) -> None:
    path = tmp_path / "given.json"
    path.write_bytes(content)
    assert depict("enhance", copy, "-o", tmp_path / "o.exr", flag, path) == 2
    one_error(capfd, words.format(path=path))


def test_a_fifo_or_a_folder_as_input_is_refused_without_waiting(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    """(A FIFO with no writer blocked the command; fed an EXR, it was read twice and its
    second reading found no magic number: "not an OpenEXR file".)"""
    fifo = tmp_path / "pipe.exr"
    os.mkfifo(fifo)
    assert depict("inspect", fifo) == 2  # returns at once: nothing opens the FIFO
    one_error(capfd, f"{fifo}: it is a FIFO (named pipe), not a regular file; an EXR is read")
    assert depict("enhance", tmp_path, "-o", tmp_path / "o.exr") == 2
    one_error(capfd, f"{tmp_path}: it is a directory, not a regular file")


@pytest.mark.timeout(60)
@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["inspect", "{frame}", "--camera", "{fifo}"], "cannot read camera file {fifo}: it is a"),
        (["score", "{frame}", "--pipeline", "{fifo}"], "cannot read pipeline {fifo}: it is a"),
        (["arm", "-o", "{out}", "--base", "{fifo}", "--paint", "0.5,0.5"], "--base '{fifo}': it"),
        (
            ["batch", "{seq}", "--frames", "1", "-o", "{seq_out}", "--pipeline", "{fifo}"],
            "cannot read pipeline {fifo}: it",
        ),
    ],
    ids=["camera", "pipeline", "ARM base", "batch pipeline"],
)
def test_a_fifo_named_by_an_option_is_refused_without_waiting(
    frame: Path, tmp_path: Path, capfd: pytest.CaptureFixture[str], argv: list[str], words: str
) -> None:
    """(A camera or pipeline file or an ARM image that is a FIFO with no writer blocked the
    command for ever.)"""
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    (tmp_path / "shot.0001.exr").write_bytes(frame.read_bytes())
    names = {"frame": frame, "fifo": fifo, "out": tmp_path / "out.png"}
    names |= {"seq": tmp_path / "shot.####.exr", "seq_out": tmp_path / "o.####.exr"}
    assert depict(*(a.format(**names) for a in argv)) == 2
    line = one_error(capfd, words.format(**names))
    assert line.endswith("it is a FIFO (named pipe), not a regular file"), line


def test_a_frame_with_no_covered_pixel_is_written_with_a_warning(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    """(Depth all 0, negative or infinite: the result was the input, without a word.)"""
    s = make_scene(48, 64)
    s.depth[...] = 0.0
    src = write_canonical(tmp_path / "flat.exr", s)
    out = tmp_path / "o.exr"
    assert depict("enhance", src, "-o", out) == 0
    err = capfd.readouterr().err.splitlines()
    assert err == [
        "depict: warning: no pixel is covered (no finite, positive depth on a surface): the "
        "operators changed nothing; check the depth channel (--map depth=...) and its "
        "background value"
    ]
    assert out.exists()
    capfd.readouterr()
    covered = write_canonical(tmp_path / "ok.exr", make_scene(48, 64))
    assert depict("enhance", covered, "-o", out) == 0
    assert "warning" not in capfd.readouterr().err


def test_a_score_of_no_scored_pixel_says_so(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    """(No pixel covered, or a beauty all NaN: "congruence score 0.0000" and nothing more.)"""
    s = make_scene(48, 64)
    s.depth[...] = np.inf
    src = write_canonical(tmp_path / "empty.exr", s)
    assert depict("score", src) == 0
    out, err = capfd.readouterr()
    assert "congruence score 0.0000" in out
    assert err.splitlines() == [f"depict: warning: {NOTHING_SCORED}"]
    assert depict("score", write_canonical(tmp_path / "ok.exr", make_scene(48, 64))) == 0
    assert "warning" not in capfd.readouterr().err


def test_without_a_size_limit_a_render_is_held_to_the_machines_memory() -> None:
    """About four times its buffers: 16384² (the largest size) needs 172 GiB."""
    if _physical_memory() >= 16384**2 * 172 * RENDER_WORKING:
        pytest.skip("this machine has the memory for the largest render")
    with pytest.raises(LimitError, match=r"16384x16384 pixels would take about 172\.0 GiB"):
        Limits().check_render(16384, 16384, "render")
    Limits().check_render(1024, 1024, "render")


def test_an_exr_output_named_otherwise_is_written_with_a_note(
    copy: Path, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    """(``-o shot.png`` wrote OpenEXR under a PNG's name without a word.)"""
    out = tmp_path / "shot.png"
    assert depict("enhance", copy, "-o", out) == 0
    err = capfd.readouterr().err.splitlines()
    assert err == [f"depict: warning: {out} is written as OpenEXR (its name does not end in .exr)"]
    assert out.read_bytes()[:4] == b"\x76\x2f\x31\x01"
    assert depict("enhance", copy, "-o", tmp_path / "shot.EXR") == 0
    assert capfd.readouterr().err == ""


def test_an_output_named_as_a_folder_is_a_folder(
    frame: Path, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    """``-o results/``: enhance writes into that folder, made for it (one input or several); a
    command that writes one file refuses it, rather than write a file named ``results``."""
    other = tmp_path / "other.exr"
    other.write_bytes(frame.read_bytes())
    assert depict("enhance", frame, "-o", f"{tmp_path / 'one'}/") == 0
    assert [p.name for p in (tmp_path / "one").iterdir()] == ["frame.exr"]
    assert depict("enhance", frame, other, "-o", f"{tmp_path / 'two'}/") == 0
    assert sorted(p.name for p in (tmp_path / "two").iterdir()) == ["frame.exr", "other.exr"]
    capfd.readouterr()
    assert depict("preview", frame, "-o", f"{tmp_path / 'shots'}/") == 2
    one_error(capfd, "it names a folder (it ends in /); give a file name")
    assert not (tmp_path / "shots").exists()
    assert depict("enhance", frame, other, "-o", tmp_path / "three") == 2
    one_error(capfd, "-o names a folder for their outputs (one that exists, or a name ending in /)")


def test_a_camera_with_a_pose_but_no_field_of_view(
    frame: Path, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    """A header with ``worldToCamera`` and neither ``worldToNDC`` nor ``depict/fovYDeg``: sizes
    relative to the image run as without a camera, sizes in scene units ask for one in one line
    (not "focal length asked of a camera ..."), and ``inspect`` says so."""
    with OpenEXR.File(str(frame), separate_channels=True) as f:
        header = dict(f.header())
        chans = {name: c.pixels.copy() for name, c in f.channels().items()}
    assert "worldToCamera" in header
    for key in ("worldToNDC", "depict/fovYDeg"):
        header.pop(key, None)
    src = tmp_path / "pose.exr"
    OpenEXR.File(header, chans).write(str(src))
    capfd.readouterr()
    assert depict("enhance", src, "-o", tmp_path / "o.exr") == 0
    err = capfd.readouterr().err
    assert "has no field of view" in err and "Traceback" not in err
    out = tmp_path / "u.exr"
    assert depict("enhance", src, "-o", out, "--op", "unsharp_masking", "--set", "sigma=0.1") == 2
    one_error(capfd, "the camera (file header (worldToCamera)) has no field of view (a file's ")
    assert not out.exists()
    assert depict("inspect", src) == 0
    assert "warning: the camera in the file (file header (worldToCamera)) has no field of view" in (
        capfd.readouterr().out
    )


def test_a_huge_normal_is_no_numpy_warning(
    tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    """A normal component of 1e38 (finite: its square overflows) is a normal of no length there,
    with no RuntimeWarning on stderr."""
    src = render_with_nan(tmp_path / "big.exr", (64, 48), {"normal": [(24, 32, 0, 1e38)]})
    capfd.readouterr()
    with warnings.catch_warnings(record=True) as caught:  # (what the process prints on stderr)
        warnings.simplefilter("always")
        assert depict("enhance", src, "-o", tmp_path / "o.exr") == 0
    assert [str(w.message) for w in caught] == []
    assert "Warning" not in capfd.readouterr().err


def test_parameters_that_overflow_float32_are_refused_not_written(
    frame: Path, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    """Values inside their ranges that take the result past float32: γ = 100 on radiance of 1e5
    (Radiance Scaling), a white level of 1e-30 (unsharp masking). The result was written with
    Inf in it, exit 0; now one line names the step, and nothing is written."""
    with OpenEXR.File(str(frame), separate_channels=True) as f:
        header = dict(f.header())
        chans = {name: c.pixels.copy() for name, c in f.channels().items()}
    for name in chans:
        if name in "RGB" or name.split(".")[0] in ("ambient", "diffuse", "specular"):
            if ".color." not in name:
                chans[name] = chans[name] * np.float32(1e5)
    bright = tmp_path / "bright.exr"
    OpenEXR.File(header, chans).write(str(bright))
    out = tmp_path / "o.exr"
    capfd.readouterr()
    for src, step in (
        (bright, ("--op", "radiance_scaling", "--set", "gamma=100", "--set", "gain=1")),
        (frame, ("--op", "unsharp_masking", "--set", "white=1e-30")),
    ):
        assert depict("enhance", src, "-o", out, *step) == 2
        one_error(capfd, f"{step[1]}: the result is NaN or infinite at ")
        assert not out.exists()


def test_a_depth_sigma_float32_cannot_square_is_out_of_range(
    frame: Path, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "o.exr"
    step = ("--op", "light_alignment", "--set", "depth_sigma=1e-30")
    assert depict("enhance", frame, "-o", out, *step) == 2
    one_error(capfd, "depth_sigma")
    assert not out.exists()


def test_a_gain_map_with_inf_is_one_line(
    frame: Path, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    step = ("--op", "unsharp_masking", "--set", "gain_map=depth.Z")  # (inf off the surface)
    with warnings.catch_warnings(record=True) as caught:  # (what the process prints on stderr)
        warnings.simplefilter("always")
        assert depict("enhance", frame, "-o", tmp_path / "o.exr", *step) == 2
    assert [str(w.message) for w in caught] == []
    one_error(capfd, "unsharp_masking: gain_map 'depth.Z' must be finite everywhere")


def test_apparent_relief_takes_its_light_as_the_other_operators_do(
    frame: Path, tmp_path: Path
) -> None:
    """``--set light=-1,1,1`` (its pieces) was refused as "Input should be a valid string"."""
    for light in ("light=-1,1,1", "light=-0.4,0.6,0.7", 'light="-1,1,1"'):
        step = ("--op", "apparent_relief", "--set", "style=counter", "--set", light)
        assert depict("enhance", frame, "-o", tmp_path / "o.exr", *step) == 0
