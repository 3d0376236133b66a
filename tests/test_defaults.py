"""The operators' defaults on a path-traced frame: shape detail added, lighting and noise kept.

On the committed Blender Cycles render (tests/fixtures/blender, its camera.json), with Gaussian
noise added to the beauty and the lobes of its ground plane (what fewer samples give), every
default is compared with the same operator's ``preset: "paper"`` (the equations as printed).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

import gbuffer
from gbuffer.frame import LOBES, Frame
from service import pipeline

BLENDER = Path(__file__).parent / "fixtures" / "blender"
REC709 = np.array([0.2126, 0.7152, 0.0722], np.float32)


def lum(rgb: np.ndarray) -> np.ndarray:
    return np.asarray(rgb, np.float32) @ REC709


@pytest.fixture(scope="module")
def frame() -> Frame:
    exr = BLENDER / "cycles_multilayer.exr"
    if not exr.is_file():
        pytest.skip(f"{exr} is absent (tests/fixtures/blender/README.md)")
    return gbuffer.read(exr, camera=BLENDER / "camera.json")


def ground(frame: Frame) -> np.ndarray:
    """Pixels of the flat ground plane well away from the objects: the normal is (0, 0, 1) in
    world space there, so in camera space it is the camera's world up."""
    up = np.asarray(frame.camera.world_to_camera, np.float32)[:3, 2]  # type: ignore[union-attr]
    flat = (frame.buffers["normal"] @ up > 0.9999) & (frame.mask > 0.5)
    return cv2.erode(flat.astype(np.uint8), np.ones((15, 15), np.uint8)).astype(bool)


def noisy(frame: Frame, amount: float = 0.15, seed: int = 1) -> Frame:
    """The frame with multiplicative Gaussian noise on the beauty and the lobes (the same
    factor per pixel, so beauty = Σ lobes + remainder still holds)."""
    rng = np.random.default_rng(seed)
    factor = (1.0 + amount * rng.standard_normal(frame.shape)).astype(np.float32)[..., None]
    out = frame.copy()
    for name in ("beauty", *LOBES, "remainder"):
        if name in out.buffers:
            out.buffers[name] = (out.buffers[name] * factor).astype(np.float32)
    return out


def grain(img: np.ndarray, where: np.ndarray) -> float:
    y = lum(img)
    return float(np.std((y - cv2.GaussianBlur(y, (0, 0), 1.5))[where]))


def run(frame: Frame, op: str, **params: Any) -> np.ndarray:
    out = pipeline.run(frame, [{"op": op, "params": params}]).buffers["beauty"]
    assert np.isfinite(out).all() and (out >= 0).all()
    return out


def test_unsharp_masking_keeps_flat_ground_and_its_noise(frame: Frame) -> None:
    f = noisy(frame)
    floor = ground(f)
    assert floor.sum() > 1500
    default = run(f, "unsharp_masking")
    paper = run(f, "unsharp_masking", preset="paper")
    before = f.buffers["beauty"]
    # no relief on the ground: left as rendered, shadows and noise included
    assert np.abs(default[floor] - before[floor]).max() < 1e-4
    assert grain(paper, floor) > 1.5 * grain(before, floor)
    # on the objects the contrast rises (the band between the fine scale and σ)
    objects = (f.mask > 0.5) & ~cv2.dilate(floor.astype(np.uint8), np.ones((9, 9))).astype(bool)
    assert np.abs(lum(default) - lum(before))[objects].mean() > 1e-3


def test_unsharp_masking_does_not_amplify_noise_on_curved_surfaces(frame: Frame) -> None:
    clean = run(frame, "unsharp_masking")
    f = noisy(frame)
    default = run(f, "unsharp_masking")
    paper = run(f, "unsharp_masking", preset="paper")
    objects = (f.mask > 0.5) & ~ground(f)
    # the noise the operator adds: the noisy result minus the clean one, against the input's
    added = grain(default - clean + frame.buffers["beauty"], objects)
    assert added < 1.15 * grain(f.buffers["beauty"], objects)
    assert grain(paper, objects) > 1.3 * grain(f.buffers["beauty"], objects)


@pytest.mark.parametrize("op", ["radiance_scaling", "light_alignment"])
def test_defaults_keep_the_objects_lighting(frame: Frame, op: str) -> None:
    """Mean luminance of each object-sized region within a few per cent, unlike the paper's."""
    covered = frame.mask > 0.5
    sigma_px = 0.04 * frame.image_height
    before = cv2.GaussianBlur(lum(frame.buffers["beauty"]), (0, 0), sigma_px)[covered]
    drift = {}
    for preset in ("default", "paper"):
        out = run(frame, op, preset=preset)
        after = cv2.GaussianBlur(lum(out), (0, 0), sigma_px)[covered]
        drift[preset] = float(np.percentile(np.abs(after / before - 1.0), 95))
    assert drift["default"] < 0.05
    assert drift["paper"] > 2 * drift["default"]


def test_light_alignment_ratio_is_bounded(frame: Frame) -> None:
    out = run(frame, "light_alignment")
    before = frame.buffers["beauty"]
    hot = (out > 2.0 * before + 1e-4) & (out > before.reshape(-1, 3).max(axis=0))
    assert hot.any(axis=2).mean() < 1e-3
