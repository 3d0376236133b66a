"""The corpus sheets of the gallery (bench/gallery_corpus.py): crops where the detail and the lit
floor are, enlarged with whole pixels, one row per operator."""

from __future__ import annotations

import numpy as np

from bench import corpus, gallery_corpus, quality
from gbuffer.colorspace import View


def test_best_window_finds_the_densest_square() -> None:
    score = np.zeros((90, 120), np.float32)
    score[50:60, 100:110] = 1.0
    score[5:8, 5:8] = 2.0  # a higher peak, but less in all
    y0, y1, x0, x1 = gallery_corpus.best_window(score, 20)
    assert (y1 - y0, x1 - x0) == (20, 20)
    assert y0 <= 50 and y1 >= 60 and x0 <= 100 and x1 >= 110 and x1 <= 120


def test_sheet_of_a_corpus_frame() -> None:
    (cf,) = corpus.gather([corpus.CI_DIR], ["metal_240p_16spp"])
    ref = quality.reference(cf.read())
    windows = gallery_corpus.crop_windows(ref)
    assert [name for name, _ in windows] == ["detail", "lit floor"]
    (_, (y0, y1, x0, x1)), (_, (f0, f1, g0, g1)) = windows
    side = gallery_corpus.ROW // 4
    assert y1 - y0 == side and x1 - x0 == side
    assert ref.regions.objects[y0:y1, x0:x1].mean() > 0.5
    assert ref.regions.flat_floor[f0:f1, g0:g1].mean() > 0.9
    img = gallery_corpus.frame_sheet(cf, ["unsharp_masking", "light_alignment"], View())
    rows = 2 * gallery_corpus.ROW
    assert img.dtype == np.uint8 and rows < img.shape[0] < rows + 60
    # input, result and change at 100 %, then two crops before and after, 4x
    assert img.shape[1] >= 3 * 320 + 4 * gallery_corpus.ROW
    enlarged = gallery_corpus.enlarge(np.arange(12.0).reshape(3, 4), (0, 2, 1, 3), 4)
    assert enlarged.shape == (8, 8) and np.all(enlarged[:4, :4] == 1.0)
