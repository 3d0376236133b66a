"""The surface pyramid's edge-aware upsampling, whole (``_Upsampler.full``, as the kept lighting
reads it) and by strips of rows (``_Upsampler.rows``, as unsharp masking reads it), against the
rule written out here (OpenCV's bilinear resize of the level, the re-weighted pixels' values put
in by NumPy's flat indexing): the same numbers, bit for bit, whatever the strips and column
windows (the scene's top-left corner is off the surface, so the first
strips' windows start further right)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from ops.unsharp._pyramid import _surface_pyramid
from tests.test_unsharp_front import _scene, _surface_of


@pytest.mark.parametrize("pixel_size", ["perspective", "orthographic"])
def test_strips_of_the_upsampling_are_the_whole_image(pixel_size: str) -> None:
    shape = (96, 128)
    sc = _scene(shape, 3, pixel_size)
    surf, sub, first = _surface_of(sc, False)
    valid = surf.valid
    sigma = 12.0 * float(np.median(sc["ps"][valid > 0]))  # ~12 pixels: a few levels
    res = _surface_pyramid(surf, [sub, sc["sigs"][1]], first, sigma, None, 1.0)
    assert res is not None
    up = res[0]
    assert up.idx is not None and up.idx.size > 50  # pixels re-weighted beside the steps
    # the rule: OpenCV's bilinear resize of each level channel, the re-weighted values put in
    hc, wc = up.coarse[0].shape
    whole = []
    for a, v in zip(up.coarse, up.vals, strict=True):
        big = cv2.resize(a, (wc * up.f, hc * up.f), interpolation=cv2.INTER_LINEAR)
        ref = np.ascontiguousarray(big[: shape[0], : shape[1]])
        ref.ravel()[up.idx] = v
        whole.append(ref)
    for got, want in zip(up.full(), whole, strict=True):
        np.testing.assert_array_equal(got, want)
    shifted = 0
    for step in (7, 32):
        for r0 in range(0, shape[0], step):
            r = slice(r0, min(shape[0], r0 + step))
            cols = np.flatnonzero(valid[r].any(axis=0))
            window = slice(int(cols[0]), int(cols[-1]) + 1)  # the strip's surface columns
            shifted += window.start > 0
            for c in (slice(0, shape[1]), window):
                for got, want in zip(up.rows(r, c), whole, strict=True):
                    np.testing.assert_array_equal(got, want[r, c])
    assert shifted  # (a window that does not start at column 0)
