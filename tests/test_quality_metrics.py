"""The quality figures themselves (bench/quality.py), on real corpus frames: each must react to
what it measures and to nothing else."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from analysis.score import score_frame
from bench import corpus, quality
from gbuffer.frame import Frame


@pytest.fixture(scope="module")
def ref() -> quality.Reference:
    (cf,) = corpus.find_frames(corpus.CI_DIR, ["still_life_240p_16spp"])
    return quality.reference(cf.read())


def with_beauty(ref: quality.Reference, beauty: np.ndarray) -> Frame:
    out = ref.frame.copy()
    out.buffers["beauty"] = np.ascontiguousarray(beauty, np.float32)
    return out


def beauty(ref: quality.Reference) -> np.ndarray:
    return np.asarray(ref.frame.buffers["beauty"], np.float32)


def test_regions_are_disjoint_and_the_flat_floor_is_lit(ref: quality.Reference) -> None:
    r = ref.regions
    assert not (r.objects & r.floor).any()
    assert (r.objects | r.floor).sum() <= r.covered.sum()
    assert r.flat_floor.sum() > 0.2 * r.floor.sum()
    assert not (r.flat_floor & ~r.floor).any()
    direct = quality.file_luminance(ref.frame, "DiffDir")
    assert direct is not None
    shadowed = r.floor & (cv2.GaussianBlur(direct, (0, 0), 3.0) < 0.4 * np.median(direct[r.floor]))
    assert shadowed.sum() > 500  # the scene has cast shadows ...
    assert not (shadowed & r.flat_floor).any()  # ... and the noise region keeps out of them
    # a margin keeps it off the objects
    near = cv2.dilate(r.objects.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    assert not (near & r.flat_floor).any()


def test_without_an_index_every_covered_pixel_is_an_object(ref: quality.Reference) -> None:
    bare = Frame(buffers={k: v for k, v in ref.frame.buffers.items()}, camera=ref.frame.camera)
    r = quality.regions(bare)
    assert np.array_equal(r.objects, r.covered) and not r.floor.any()
    assert not r.flat_floor.any()


def test_doubling_the_beauty(ref: quality.Reference) -> None:
    b = beauty(ref)
    fig = quality.figures(ref, with_beauty(ref, 2.0 * b))
    assert fig.lum_objects == pytest.approx(2.0, rel=1e-6)
    assert fig.lum_covered == pytest.approx(2.0, rel=1e-6)
    assert fig.hot == 0.0  # twice the input is not more than twice the input
    assert fig.lf_corr == pytest.approx(1.0, abs=1e-6)
    assert fig.floor_noise == pytest.approx(1.0, abs=1e-5)  # relative noise ignores exposure
    assert fig.detail == pytest.approx(1.0, abs=1e-5)
    assert quality.misses(fig)[:1] == ["lum_objects"]


def test_hot_pixels_are_those_over_twice_their_input_and_the_input_maximum(
    ref: quality.Reference,
) -> None:
    b = beauty(ref)
    after = np.float32(2.5) * b
    expected = (after > b.reshape(-1, 3).max(axis=0)).any(axis=-1).mean()
    assert 0.01 < expected < 0.5
    assert quality.hot_fraction(b, after) == pytest.approx(expected)
    # a single spike far above the frame's maximum is one hot pixel
    spiked = b.copy()
    spiked[10, 20, 1] = 10.0 * float(b.max())
    assert quality.hot_fraction(b, spiked) == pytest.approx(1.0 / (b.shape[0] * b.shape[1]))


def test_negatives_and_non_finite_values_are_counted(ref: quality.Reference) -> None:
    b = beauty(ref).copy()
    assert quality.bad_pixels(b) == (0, 0)
    b[0, 0] = -0.1
    b[1, 1, 2] = -1e-6
    b[2, 2, 0] = np.nan
    b[3, 3] = np.inf
    assert quality.bad_pixels(b) == (2, 2)
    fig = quality.figures(ref, with_beauty(ref, b))
    assert (fig.negatives, fig.nonfinite) == (2, 2)
    assert math.isfinite(fig.lum_covered) and math.isfinite(fig.cong_after)


def test_noise_on_the_floor_raises_the_floor_noise_and_noise_on_objects_does_not(
    ref: quality.Reference,
) -> None:
    b = beauty(ref)
    rng = np.random.default_rng(1)
    grain = rng.normal(0.0, 0.15, b.shape[:2]).astype(np.float32)[..., None]
    floor_noisy = np.where(ref.regions.floor[..., None], b * (1.0 + grain), b)
    assert quality.figures(ref, with_beauty(ref, floor_noisy)).floor_noise > 1.5
    object_noisy = np.where(ref.regions.objects[..., None], b * (1.0 + grain), b)
    fig = quality.figures(ref, with_beauty(ref, object_noisy))
    assert fig.floor_noise == pytest.approx(1.0, abs=1e-6)


def test_blurring_lowers_the_detail_gain_and_sharpening_raises_it(ref: quality.Reference) -> None:
    b = beauty(ref)
    blurred = cv2.GaussianBlur(b, (0, 0), 1.5)
    sharpened = np.clip(2.0 * b - blurred, 0.0, None)
    assert quality.figures(ref, with_beauty(ref, blurred)).detail < 0.7
    assert quality.figures(ref, with_beauty(ref, sharpened)).detail > 1.3


def test_low_frequency_correlation(ref: quality.Reference) -> None:
    b = beauty(ref)
    covered = ref.regions.covered
    sigma = quality.LF_SIGMA * b.shape[0]
    assert quality.lf_correlation(b, b + np.float32(0.3), covered, sigma) == pytest.approx(
        1.0, abs=1e-6
    )
    # fine grain leaves the lighting as it was; light coming from the other side does not
    rng = np.random.default_rng(2)
    grainy = b * (1.0 + rng.normal(0.0, 0.2, b.shape[:2]).astype(np.float32)[..., None])
    assert quality.lf_correlation(b, grainy, covered, sigma) > 0.98
    relit = b * np.linspace(2.0, 0.1, b.shape[1], dtype=np.float32)[None, :, None]
    assert quality.lf_correlation(b, relit, covered, sigma) < 0.8


def test_congruence_is_that_of_depict_score(ref: quality.Reference) -> None:
    assert ref.congruence == pytest.approx(score_frame(ref.frame)["score"], abs=1e-9)
    fig = quality.figures(ref, ref.frame)
    assert fig.cong_after == pytest.approx(fig.cong_before, abs=1e-9)
    assert fig.cong_objects_after == pytest.approx(fig.cong_objects_before, abs=1e-9)
    # restricted to every covered pixel, the full-resolution maps give back the frame's score
    result = quality.frame_congruence(ref.frame)
    assert quality.masked_score(result, ref.regions.covered) == pytest.approx(
        result.score, abs=0.02
    )
    assert quality.masked_score(result, ref.regions.objects) != pytest.approx(result.score, 0.01)
    # flattening the objects' shading lowers their score
    b = beauty(ref)
    flat = np.where(ref.regions.objects[..., None], cv2.GaussianBlur(b, (0, 0), 6.0), b)
    assert quality.figures(ref, with_beauty(ref, flat)).cong_objects_after < ref.congruence_objects


def test_the_report_marks_what_misses_its_target(ref: quality.Reference) -> None:
    b = 1.05 * beauty(ref)
    b[5, 5] = -0.01
    fig = quality.figures(ref, with_beauty(ref, b))
    assert quality.misses(fig) == ["negatives"]
    text = quality.table([("f", "op", fig)], markdown=True)
    assert "| **1** |" in text and "| 1.050 |" in text
    assert " 1*" in quality.table([("f", "op", fig)])
