"""What the viewer runs on the workers: the downscaled copy previews are computed on (and that a
look tuned on it carries to the full frame), and the colour space read from the header."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from gbuffer.frame import Frame
from gbuffer.io import read
from gbuffer.render import load_mesh, render
from service import pipeline
from service.registry import Context
from service.viewer.work import colour_space, downscale, shrink_factor
from tests import exr_factory
from tests.live_server import ROOT


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
