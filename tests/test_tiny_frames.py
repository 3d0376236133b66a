"""Frames at the edge of what the operators can work on: a surface of one pixel, and a frame of
one pixel (OpenCV's Python binding takes an array of one element for a scalar, so crops of a
single pixel used to fail inside the operators with an OpenCV error: a 500 over HTTP)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import service.operators  # noqa: F401  (registers the operators)
from gbuffer.io import read
from ops.unsharp import unsharp_masking
from service import pipeline
from service.cli import main
from service.errors import PipelineError
from service.operators.base import REGISTRY
from tests.exr_factory import Scene, cropped, make_scene, write_canonical


def _one_covered_pixel(s: Scene, y: int, x: int) -> Scene:
    """``s`` with its surface cut down to pixel (y, x): background everywhere else."""
    keep = np.zeros(s.depth.shape, bool)
    keep[y, x] = True
    changes: dict[str, Any] = {}
    for f in dataclasses.fields(s):
        a = getattr(s, f.name)
        if isinstance(a, np.ndarray):
            off = np.inf if f.name in ("depth", "distance") else 0.0
            k = keep if a.ndim == 2 else keep[..., None]
            changes[f.name] = np.where(k, a, np.float32(off)).astype(np.float32)
    return dataclasses.replace(s, **changes)


@pytest.fixture(scope="module")
def one_covered(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Canonical EXRs of the test sphere cut down to one pixel of surface: in the middle of
    the frame and in its last row and column."""
    s = make_scene(48, 64)
    out = tmp_path_factory.mktemp("one")
    y, x = np.argwhere(np.isfinite(s.depth))[len(np.argwhere(np.isfinite(s.depth))) // 2]
    corner = cropped(s, slice(0, int(y) + 1), slice(0, int(x) + 1))
    row = cropped(s, slice(int(y), int(y) + 1), slice(0, 64))
    return {
        "middle": write_canonical(out / "middle.exr", _one_covered_pixel(s, int(y), int(x))),
        "corner": write_canonical(out / "corner.exr", _one_covered_pixel(corner, int(y), int(x))),
        "row": write_canonical(out / "row.exr", _one_covered_pixel(row, 0, int(x))),
    }


@pytest.mark.parametrize("where", ["middle", "corner", "row"])
@pytest.mark.parametrize("op", sorted(REGISTRY))
def test_every_operator_runs_on_a_surface_of_one_pixel(
    one_covered: dict[str, Path], where: str, op: str
) -> None:
    frame = read(one_covered[where])
    if op == "congruence" and where == "row":  # (its structure tensor needs 3 x 3 pixels)
        with pytest.raises(PipelineError, match="depth must be at least 3x3"):
            pipeline.run(frame, pipeline.compile([{"op": op}]))
        return
    out = pipeline.run(frame, pipeline.compile([{"op": op}]))
    background = frame.mask <= 0
    assert background.sum() == background.size - 1
    # what lies off the surface is the frame's own
    np.testing.assert_array_equal(
        out.buffers["beauty"][background], frame.buffers["beauty"][background]
    )
    assert np.isfinite(out.buffers["beauty"]).all()


@pytest.fixture(scope="module")
def one_pixel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    s = make_scene(48, 64)
    y, x = np.argwhere(np.isfinite(s.depth))[0]
    path = tmp_path_factory.mktemp("px") / "px.exr"
    return write_canonical(path, cropped(s, slice(int(y), int(y) + 1), slice(int(x), int(x) + 1)))


def test_a_frame_of_one_pixel_is_refused_naming_its_size(one_pixel: Path) -> None:
    frame = read(one_pixel)
    for op in sorted(REGISTRY):
        with pytest.raises(PipelineError, match="the frame is 1x1 pixels; the operators need"):
            pipeline.run(frame, pipeline.compile([{"op": op}]))


def test_depict_enhance_refuses_a_frame_of_one_pixel_in_one_line(
    one_pixel: Path, tmp_path: Path, capfd: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out.exr"
    try:
        code = main(["enhance", str(one_pixel), "-o", str(out)])
    except SystemExit as exc:
        code = int(exc.code or 0)
    assert code == 2
    lines = capfd.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "the frame is 1x1 pixels" in lines[0], lines
    assert not out.exists()


@pytest.mark.parametrize("alone", [1, 2])
def test_unsharp_masking_with_one_pixel_alone_in_a_strip_of_one_row(alone: int) -> None:
    """1024 columns make strips of 128 rows: a surface of 128 full rows and ``alone`` pixels
    in the next has a strip of one row holding them (one pixel failed inside OpenCV)."""
    rng = np.random.default_rng(0)
    img = (0.5 + 0.2 * rng.random((140, 1024, 3))).astype(np.float32)
    mask = np.zeros((140, 1024), bool)
    mask[:128] = True
    mask[128, 5 : 5 + alone] = True
    depth = np.where(mask, 5.0, np.inf).astype(np.float32)
    out = unsharp_masking(img, depth, None, mask, sigma_scene=0.05, pixel_size=depth / 1000)
    np.testing.assert_array_equal(out[~mask], img[~mask])
    assert np.isfinite(out).all() and not np.array_equal(out[mask], img[mask])


@pytest.mark.parametrize("rows", [1, 2, 3, 4, 5])
def test_unsharp_masking_where_the_fade_meets_a_strip_in_one_column(rows: int) -> None:
    """Pixels seen from afar (σ_px under one level) fade to the unsmoothed signal; where that
    box meets a strip's window in one column of up to four rows, OpenCV took the piece for a
    scalar (a failure at four rows, a wrong shape at one)."""
    rng = np.random.default_rng(0)
    img = (0.5 + 0.2 * rng.random((140, 1024, 3))).astype(np.float32)
    mask = np.zeros((140, 1024), bool)
    mask[:128] = True
    mask[128 : 128 + rows, 5:7] = True
    depth = np.where(mask, 5.0, np.inf).astype(np.float32)
    size = np.where(mask, 0.005, np.inf).astype(np.float32)
    size[128 : 128 + rows, 6] = 0.3  # (far: in the fade box, which starts at column 6)
    out = unsharp_masking(img, depth, None, mask, sigma_scene=0.05, pixel_size=size)
    np.testing.assert_array_equal(out[~mask], img[~mask])
    assert np.isfinite(out).all()
