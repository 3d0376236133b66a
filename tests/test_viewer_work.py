"""What the viewer runs on the workers: the downscaled copy previews are computed on (and that a
look tuned on it carries to the full frame), and the colour space read from the header."""

from __future__ import annotations

import io
import os
import shutil
import struct
from pathlib import Path
from typing import Any

import numpy as np
import OpenEXR
import pytest
from OpenImageIO import ImageBuf
from PIL import Image

from analysis.score import score_frame
from gbuffer.errors import FrameError
from gbuffer.frame import Frame
from gbuffer.io import inspect, read
from gbuffer.preview import quick_png, write_png
from gbuffer.render import load_mesh, render
from ops import curvature as curv_ops
from ops.congruence import score as congruence_score
from service import pipeline
from service.enhance import ReadRequest
from service.http.worker import give_back_memory
from service.memo import Memo
from service.registry import Context, operators
from service.viewer import work
from service.viewer.work import colour_space, downscale, shrink_factor
from tests import exr_factory
from tests.live_server import ROOT

#: What the viewer adds to what ``depict inspect --json`` says of a frame.
VIEWER_KEYS = ("operators", "colour_space", "layers")


@pytest.fixture(scope="module")
def sphere(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("work") / "sphere.exr"
    return exr_factory.write_canonical(path, exr_factory.make_scene(h=96, w=128))


def test_downscale_keeps_source_geometry_averages_radiance_and_keeps_the_camera(
    sphere: Path,
) -> None:
    frame = read(sphere)
    small = downscale(frame, 2)
    assert small.shape == (48, 64) and small.display_size == (64, 48)
    assert small.camera == frame.camera and not small.passthrough.parts
    covered = np.isfinite(small.buffers["depth"])
    lengths = np.linalg.norm(small.buffers["normal"][covered], axis=1)
    assert np.allclose(lengths, 1.0, atol=1e-5)  # one source pixel's normal, not an average
    depths = set(np.unique(frame.buffers["depth"][np.isfinite(frame.buffers["depth"])]))
    assert set(np.unique(small.buffers["depth"][covered])) <= depths  # never a blend across edges
    assert small.buffers["beauty"].mean() == pytest.approx(frame.buffers["beauty"].mean(), rel=0.02)
    assert np.array_equal(small.buffers["normal"], frame.buffers["normal"][1::2, 1::2])
    assert small.buffers["beauty"][0, 0] == pytest.approx(
        frame.buffers["beauty"][:2, :2].mean((0, 1))
    )
    same = downscale(frame, 1)
    assert same.buffers is frame.buffers and not same.passthrough.parts


@pytest.fixture(scope="module")
def cow() -> Frame:
    return render(load_mesh(ROOT / "examples" / "spot.obj"), 800, 600)


@pytest.mark.parametrize(
    ("height", "asked", "factor"), [(1080, 540, 2), (960, 540, 2), (720, 540, 1), (2160, 540, 4)]
)
def test_shrink_factor_is_the_nearest_whole_number(height: int, asked: int, factor: int) -> None:
    assert shrink_factor((1920, height), asked) == factor
    assert shrink_factor((1920, height), 10 * height) == 1


@pytest.mark.parametrize(("size", "factor"), [((1, 144), 1), ((3, 1080), 3), ((1920, 1080), 15)])
def test_shrink_factor_is_no_more_than_the_narrower_side(
    size: tuple[int, int], factor: int
) -> None:
    """(A column of 144 pixels shrunk by 2 had no block left: numpy's reshape error.)"""
    assert shrink_factor(size, 72) == factor
    frame = Frame(buffers={"beauty": np.ones((size[1], size[0], 3), np.float32)}, display_size=size)
    small = downscale(frame, shrink_factor(size, 72))
    assert small.buffers["beauty"].size > 0


@pytest.mark.parametrize("op", ["radiance_scaling", "light_alignment", "unsharp_masking"])
def test_a_look_tuned_on_the_preview_carries_to_the_full_frame(cow: Frame, op: str) -> None:
    """An operator on the half-size copy vs the full-size result downscaled: the two differ far
    less than either differs from the input (sizes are relative to the image height)."""
    steps = pipeline.compile([{"op": op}])
    full, _ = pipeline.run_timed(cow, steps, Context())
    on_preview, _ = pipeline.run_timed(downscale(cow, 2), steps, Context())
    reference = downscale(full, 2).buffers["beauty"]
    carried = np.abs(on_preview.buffers["beauty"] - reference).mean()
    effect = np.abs(reference - downscale(cow, 2).buffers["beauty"]).mean()
    assert effect > 0 and carried < 0.3 * effect, (carried, effect)


def chromaticities(values: tuple[float, ...]) -> tuple[str, str, bytes]:
    return ("chromaticities", "chromaticities", struct.pack("<8f", *values))


@pytest.mark.parametrize(
    ("extra", "expected"),
    [
        ((), "not stated"),
        ((chromaticities((0.713, 0.293, 0.165, 0.830, 0.128, 0.044, 0.32168, 0.33767)),), "ACEScg"),
        ((chromaticities((0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.329)),), "Rec.709"),
        ((chromaticities((0.7, 0.3, 0.2, 0.7, 0.1, 0.1, 0.3, 0.3)),), "chromaticities 0.7, 0.3"),
        ((("colorSpace", "string", b"ACES - ACEScg"),), "ACES - ACEScg (colorSpace attribute)"),
    ],
)
def test_colour_space_from_the_header(
    tmp_path: Path, extra: tuple[tuple[str, str, bytes], ...], expected: str
) -> None:
    path = exr_factory.write_raw_exr(tmp_path / "c.exr", {"Y": np.ones((4, 4), np.float32)}, extra)
    assert expected in colour_space(str(path))


@pytest.fixture
def stored(sphere: Path, tmp_path: Path) -> Path:
    """A frame's folder as the viewer keeps it (``in.exr``)."""
    folder = tmp_path / "frame"
    folder.mkdir()
    (folder / "in.exr").write_bytes(sphere.read_bytes())
    return folder


def test_an_uploads_inspection_makes_the_first_previews_copy(
    stored: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The upload's inspection decodes the file once: it says what ``depict inspect`` says, and
    the copy at the page's preview height is made from that decode, so the first picture and
    preview read no EXR; a file that does not read as previews read it is only described."""
    info = work.inspect_job(str(stored / "in.exr"), ReadRequest(), 48)["info"]
    assert {k: v for k, v in info.items() if k not in VIEWER_KEYS} == inspect(stored / "in.exr")
    assert info["layers"][-1] == work.SCORE_MAP
    assert sorted(p.name for p in stored.glob("small_*")) == ["small_2.layers.pkl", "small_2.pkl"]

    def no_read(*args: object, **kwargs: object) -> None:
        raise AssertionError("the EXR was decoded again")

    monkeypatch.setattr(ReadRequest, "read", no_read)
    small, score = work._small(stored, 2, ReadRequest())
    assert small.shape == (48, 64) and score is not None
    work.layer_job(str(stored), 2, "beauty", ReadRequest(), str(stored / "beauty.png"))
    monkeypatch.undo()

    broken = exr_factory.make_scene(h=96, w=128)
    broken.normal[...] = np.nan
    exr_factory.write_canonical(stored / "in.exr", broken)
    for cache in stored.glob("small_*"):
        cache.unlink()
    info = work.inspect_job(str(stored / "in.exr"), ReadRequest(), 48)["info"]
    assert {k: v for k, v in info.items() if k not in VIEWER_KEYS} == inspect(stored / "in.exr")
    assert not list(stored.glob("small_*"))
    with pytest.raises(FrameError, match=r"N\.X"):
        work._small(stored, 2, ReadRequest())


def test_a_tiled_file_is_kept_for_its_previews(stored: Path) -> None:
    """A tiled (or mip-mapped) file's header holds what the binding cannot pickle (its
    ``TileDescription``): the upload's inspection keeps its copies all the same, and a preview
    that reads a layer of the file (a mask) finds it."""
    src = ImageBuf(str(stored / "in.exr"))
    src.set_write_tiles(32, 32)
    assert src.write(str(stored / "tiled.exr")), src.geterror()
    (stored / "tiled.exr").replace(stored / "in.exr")
    with OpenEXR.File(str(stored / "in.exr")) as f:
        assert "tiles" in f.header()
    work.inspect_job(str(stored / "in.exr"), ReadRequest(), 48)
    layers = work._file_layers(stored, 2, work._small(stored, 2, ReadRequest())[0])
    assert "tiles" not in layers.passthrough.parts[0][0]
    steps = pipeline.compile([{"op": "radiance_scaling", "params": {"mask": "depth"}}])
    out, _ = pipeline.run_timed(layers, steps, Context(files=False))
    assert out.shape == (48, 64)


def test_a_frame_too_small_to_score_lists_no_score_map(tmp_path: Path) -> None:
    """Under 3 pixels on a side no score is made: the layers the page offers leave out the
    score map, and asking for it says why."""
    folder = tmp_path / "tiny"
    folder.mkdir()
    exr_factory.write_canonical(folder / "in.exr", exr_factory.make_scene(h=2, w=2))
    info = work.inspect_job(str(folder / "in.exr"), ReadRequest(), 2)["info"]
    assert "depth" in info["layers"] and work.SCORE_MAP not in info["layers"]
    with pytest.raises(FrameError, match="has no depth, or this copy of it is under 3 pixels"):
        work.layer_job(str(folder), 1, work.SCORE_MAP, ReadRequest(), str(folder / "s.png"))


def test_a_file_with_no_buffer_is_described_and_its_previews_say_why_there_are_none(
    tmp_path: Path,
) -> None:
    """A luminance-only image (one Y channel): the upload is described (it failed on the
    shape of a frame with no buffers), and a preview says there is nothing to preview."""
    folder = tmp_path / "y"
    folder.mkdir()
    plane = np.linspace(0, 1, 40 * 60, dtype=np.float32).reshape(40, 60)
    OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION}, {"Y": plane}).write(
        str(folder / "in.exr")
    )
    info = work.inspect_job(str(folder / "in.exr"), ReadRequest(), 40)["info"]
    assert info["size"] == [60, 40] and info["layers"] == []
    steps = pipeline.compile([{"op": "radiance_scaling"}])
    with pytest.raises(FrameError, match="no buffer Depict reads"):
        work.preview_job(str(folder), 1, steps, ReadRequest(), 0.0, False)


def test_a_previews_score_is_the_scores_own(stored: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A preview scores its result on the shape's side the copy was scored with (made once per
    copy, not again at each preview): the same numbers as scoring the result from scratch."""
    work._small(stored, 2, ReadRequest())  # (the copy, and its score's shape side)
    made: list[object] = []
    shape_flow = congruence_score.shape_flow

    def counted(*args: Any, **kwargs: Any) -> congruence_score.ShapeFlow:
        made.append(args)
        return shape_flow(*args, **kwargs)

    monkeypatch.setattr(congruence_score, "shape_flow", counted)
    for params in ({"gamma": 3.0}, {"gamma": 0.5, "alpha": 0.8}):
        steps = pipeline.compile([{"op": "radiance_scaling", "params": params}])
        made.clear()
        answer = work.preview_job(str(stored), 2, steps, ReadRequest(), 0.0, False)
        assert made == []  # (the copy's, not one of its own)
        small, before = work._small(stored, 2, ReadRequest())
        assert before is not None
        out, _ = pipeline.run_timed(small, steps, Context(files=False))
        fresh = score_frame(out, shading_norm=before["shading_norm"] or None)
        assert answer["score"] == {"before": before["score"], "after": fresh["score"]}


def _assert_kept_as_fresh(
    frame: Frame, spec: list[dict[str, Any]], memo: Memo, debug: bool = False
) -> None:
    """The pipeline ``spec`` on ``frame`` with ``memo`` gives the same bits as without one."""
    steps = pipeline.compile(spec)
    kept, _ = pipeline.run_timed(frame, steps, Context(files=False, memo=memo, debug_layers=debug))
    fresh, _ = pipeline.run_timed(frame, steps, Context(files=False, debug_layers=debug))
    for got, want in ((kept.buffers, fresh.buffers), (kept.outputs, fresh.outputs)):
        assert got.keys() == want.keys()
        for name, array in want.items():
            assert np.asarray(got[name]).tobytes() == np.asarray(array).tobytes(), (spec, name)


def test_previews_keep_what_their_sliders_did_not_change(
    stored: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Radiance Scaling's curvature and smoothed lights are kept between previews of a copy
    while the parameters they depend on stay (γ or α moves): computed again only for a scale
    not kept; every result the same, bit for bit, as a run that keeps nothing."""
    small, _ = work._small(stored, 2, ReadRequest())
    computed: list[float] = []
    principal = curv_ops.principal_curvatures

    def counted(*args: Any, **kwargs: Any) -> curv_ops.Curvature:
        computed.append(kwargs["scale"])
        return principal(*args, **kwargs)

    monkeypatch.setattr(curv_ops, "principal_curvatures", counted)
    memo = Memo()
    sequence = [{"gamma": 3.0}, {"gamma": 0.5}, {"scale": 0.05}, {"alpha": 0.8}, {"gamma": 2.0}]
    for params in sequence:
        _assert_kept_as_fresh(small, [{"op": "radiance_scaling", "params": params}], memo)
    assert len(computed) == 2 * len(sequence) - 3  # (the kept runs: the two scales, once each)
    # steps that read the kept curvature's full-resolution fields before others read it (which
    # then took another path, rounding otherwise), with and without debug layers
    mixed: list[list[dict[str, Any]]] = [
        [{"op": "unsharp_masking", "params": {"relief_only": True}}, {"op": "radiance_scaling"}],
        [{"op": "curvature"}],
        [{"op": "curvature"}],
        [{"op": "radiance_scaling", "params": {"scenario": "phong", "anisotropy": 0.5}}],
        [{"op": "radiance_scaling"}],
    ]
    for debug in (False, True):
        memo = Memo()
        for spec in mixed:
            _assert_kept_as_fresh(small, spec, memo, debug)
    steps = pipeline.compile([{"op": "radiance_scaling", "params": {"gamma": 1.5}}])
    work.preview_job(str(stored), 2, steps, ReadRequest(), 0.0, False)
    assert work._memo(stored / "small_2.pkl") is work._memo(stored / "small_2.pkl")
    computed.clear()
    work.preview_job(str(stored), 2, steps, ReadRequest(), 0.0, False)
    assert computed == []  # (the copy's memo: its curvature from the preview before)


def test_a_worker_keeps_the_shrunk_frame_for_the_next_preview(stored: Path, tmp_path: Path) -> None:
    """Every slider move previews the same frame: its shrunk copy is kept by the worker that
    made or read it; a preview leaves it as it was, a file written again is read again, and
    only the last files read are kept."""
    steps = pipeline.compile([{"op": "radiance_scaling", "params": {"gamma": 3.0}}])

    def preview() -> dict[str, object]:
        return work.preview_job(str(stored), 2, steps, ReadRequest(), 0.0, True)

    first = preview()
    small, _ = work._small(stored, 2, ReadRequest())
    assert work._small(stored, 2, ReadRequest())[0] is small
    beauty = small.buffers["beauty"].copy()
    again = preview()
    assert again["image"] == first["image"] and again["score"] == first["score"]
    assert np.array_equal(small.buffers["beauty"], beauty)
    pickled = stored / "small_2.pkl"
    pickled.write_bytes(pickled.read_bytes())  # written again: another time
    os.utime(pickled, ns=(1, 1))
    assert work._small(stored, 2, ReadRequest())[0] is not small
    for i in range(work.KEEP_LOADED):  # other files read since: the frame's is let go
        other = tmp_path / f"other{i}.pkl"
        other.write_bytes(pickled.read_bytes())
        work._load(other)
    assert pickled not in work._loaded


def test_what_a_worker_keeps_is_bounded_and_let_go_with_its_frame(
    stored: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A shrunk copy larger than the bytes a worker keeps is read at every preview; a frame
    deleted (forgotten, expired) is let go in the worker's next pause."""
    pickled = stored / "small_2.pkl"
    monkeypatch.setattr(work, "KEEP_LOADED_BYTES", 100_000)  # (the copy: 380 kB)
    small, _ = work._small(stored, 2, ReadRequest())
    assert sum(np.asarray(a).nbytes for a in small.buffers.values()) > work.KEEP_LOADED_BYTES
    assert pickled not in work._loaded
    assert work._small(stored, 2, ReadRequest())[0] is not small  # read again
    monkeypatch.undo()
    kept = work._small(stored, 2, ReadRequest())[0]
    assert work._small(stored, 2, ReadRequest())[0] is kept
    shutil.rmtree(stored)
    give_back_memory()  # (the HTTP workers' pause)
    assert pickled not in work._loaded


def test_what_previews_keep_counts_in_the_bytes_a_worker_keeps(
    stored: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The curvature and lights a preview keeps (:func:`work._memo`) count in
    :data:`work.KEEP_LOADED_BYTES` beside the copy: over it, they are let go, not the copy, and
    the preview is the same."""
    steps = pipeline.compile([{"op": "radiance_scaling"}])
    first = work.preview_job(str(stored), 2, steps, ReadRequest(), 0.0, False)
    pickled = stored / "small_2.pkl"
    kept = work._memo(pickled)
    copy_bytes = work._loaded[pickled][2]
    assert kept.nbytes > 0
    assert sum(k[2] + k[3].nbytes for k in work._loaded.values()) <= work.KEEP_LOADED_BYTES
    monkeypatch.setattr(work, "KEEP_LOADED_BYTES", copy_bytes + kept.nbytes - 1)
    again = work.preview_job(str(stored), 2, steps, ReadRequest(), 0.0, False)
    assert {**again, "op_s": None} == {**first, "op_s": None}
    assert pickled in work._loaded and work._memo(pickled) is kept
    assert copy_bytes + kept.nbytes <= work.KEEP_LOADED_BYTES
    assert kept.nbytes > 0  # (what fits is kept: the least recently used went)


def test_previews_keep_nothing_an_earlier_step_made(stored: Path) -> None:
    """Radiance Scaling after Light Alignment smooths the lights Light Alignment made, new at
    every preview: that result would never be asked for again, and is not kept (it held 1.8
    times what was counted); the curvature of the copy's own normals is."""
    steps = pipeline.compile([{"op": "light_alignment"}, {"op": "radiance_scaling"}])
    held = []
    for _ in range(3):
        work.preview_job(str(stored), 2, steps, ReadRequest(), 0.0, False)
        held.append(work._memo(stored / "small_2.pkl").nbytes)
    assert held[0] > 0 and held == held[:1] * 3


def test_the_viewers_pictures_are_quick_pngs_of_the_same_pixels(tmp_path: Path) -> None:
    """Pictures for the browser are PNGs made for speed (OpenCV, one filter, run-length
    matching): the same pixels, in the same order of channels, as the PNG ``depict preview``
    writes (OpenImageIO, default settings), in other bytes; written to a file, the same bytes."""
    ramp = np.linspace(0.0, 1.0, 320 * 240 * 3, dtype=np.float32).reshape(240, 320, 3)
    noisy = np.clip(ramp + np.random.default_rng(0).normal(0, 0.05, ramp.shape), 0, 1)
    noisy[:40, :40] = (1.0, 0.0, 0.0)  # a red corner: channels kept in order
    default, quick = tmp_path / "default.png", tmp_path / "quick.png"
    write_png(noisy, default)
    encoded = quick_png(noisy)
    assert encoded != default.read_bytes()  # (one encoder: the same bytes)
    pixels = np.asarray(Image.open(io.BytesIO(encoded)))
    assert pixels.shape == (240, 320, 3) and tuple(pixels[0, 0]) == (255, 0, 0)
    assert np.array_equal(pixels, np.asarray(Image.open(default)))
    write_png(noisy, quick, quick=True)
    assert quick.read_bytes() == encoded


def test_no_operator_writes_into_the_frame_it_is_given(sphere: Path) -> None:
    """The viewer hands one kept frame to every preview (and ``pipeline.run`` copies a frame's
    dicts, not its arrays): every operator, with its defaults and with debug layers, leaves
    every buffer of its input as it was."""
    frame = read(sphere)
    before = {name: np.array(a, copy=True) for name, a in frame.buffers.items()}
    for name in operators():
        for debug in (False, True):
            try:
                pipeline.run(frame, [{"op": name}], debug_layers=debug)
            except FrameError:  # (an operator this frame cannot feed)
                continue
            for buffer, value in before.items():
                assert np.array_equal(frame.buffers[buffer], value, equal_nan=True), (name, buffer)
