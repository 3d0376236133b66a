"""The compiled taps of the surface upsampling (ops/unsharp/_taps.py) against their rule written
out in NumPy: which fine pixels are re-weighted, and their taps and weights."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from ops.unsharp._taps import MAX_TAPS, apply_taps, fine_fixups, fixup_taps


def _level(seed: int, hc: int = 9, wc: int = 12) -> tuple[np.ndarray, ...]:
    """A level's depth guide (two surfaces: a slanted plane and a step up to a nearer one), its
    slopes per image pixel and cover (a few empty cells)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:hc, 0:wc].astype(np.float32)
    iz = (0.3 * xx + 0.1 * yy).astype(np.float32)
    iz[:, wc // 2 :] += np.float32(40.0)  # a depth step between the halves
    iz += rng.normal(0, 0.05, iz.shape).astype(np.float32)
    gx = np.full((hc, wc), 0.3, np.float32)
    gy = np.full((hc, wc), 0.1, np.float32)
    valid = (rng.random((hc, wc)) > 0.1).astype(np.uint8)
    return iz, gx, gy, valid


def _taps_by_rule(
    x: int, y: int, f: int, iz_p: float, level: tuple[np.ndarray, ...], d: float, thr: float
) -> dict[int, float]:
    """One pixel's taps {flat cell: weight}, in float64: the 2×2 bilinear taps, else the 4×4
    tent of radius 2; weight tent × max(0, 1 − (miss / thr)²) on covered cells, normalised."""
    iz, gx, gy, valid = level
    hc, wc = iz.shape
    u, v = (x + 0.5) / f - 0.5, (y + 0.5) / f - 0.5
    x0, y0 = int(np.floor(u)), int(np.floor(v))
    for first, m in ((0, 2), (-1, 4)):
        weights: dict[int, float] = {}
        for cy in range(y0 + first, y0 + first + m):
            for cx in range(x0 + first, x0 + first + m):
                dx, dy = u - cx, v - cy
                tent = max(0.0, 1 - abs(dx) * 2 / m) * max(0.0, 1 - abs(dy) * 2 / m)
                if not (0 <= cx < wc and 0 <= cy < hc) or not valid[cy, cx]:
                    continue
                pred = iz[cy, cx] + gx[cy, cx] * dx * d + gy[cy, cx] * dy * d
                w = tent * max(0.0, 1 - ((pred - iz_p) / thr) ** 2)
                if w > 0:
                    weights[cy * wc + cx] = w
        total = sum(weights.values())
        if total > 1e-4:
            return {k: w / total for k, w in weights.items()}
    return {}


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fixup_taps_follow_the_rule(seed: int) -> None:
    """Every fine pixel of the level (f = 4): the compiled taps and weights are the rule's, to
    float32 rounding; pixels on neither surface (a guide between the two) have none."""
    level = _level(seed)
    iz, gx, gy, valid = level
    f, d, thr = 4, 4.0, 16.0
    hc, wc = iz.shape
    yy, xx = (a.ravel().astype(np.int64) for a in np.mgrid[0 : hc * f, 0 : wc * f])
    near = cv2.resize(iz, (wc * f, hc * f), interpolation=cv2.INTER_LINEAR).ravel()
    iz_p = near.copy()
    iz_p[::7] += np.float32(20.0)  # half way to the other surface: nothing compatible
    n = xx.size
    taps = np.empty((n, MAX_TAPS), np.int32)
    wts = np.empty((n, MAX_TAPS), np.float32)
    count = np.empty(n, np.int8)
    flat = (iz.ravel(), gx.ravel(), gy.ravel(), valid.ravel(), wc, np.float32(d))
    fixup_taps(xx, yy, np.float32(1 / f), iz_p, *flat, np.float32(1 / thr), taps, wts, count)
    nones = 0
    for i in range(n):
        want = _taps_by_rule(int(xx[i]), int(yy[i]), f, float(iz_p[i]), level, d, thr)
        pairs = zip(taps[i, : count[i]], wts[i, : count[i]], strict=True)
        got = {int(t): float(w) for t, w in pairs if w}
        assert got.keys() == want.keys(), i
        np.testing.assert_allclose([got[k] for k in want], list(want.values()), atol=2e-6)
        nones += count[i] == 0
    assert 0 < nones < n // 7 + 1  # some pixels have no compatible tap, most do
    assert set(np.unique(count)) <= {0, 4, 16} and (count == 16).any()

    values = np.random.default_rng(seed).random(iz.size, dtype=np.float32)
    out = np.empty(n, np.float32)
    apply_taps(values, taps, wts, count, out)
    used = np.arange(MAX_TAPS)[None, :] < count[:, None]
    weighed = np.where(used, wts, 0.0) * values[np.where(used, taps, 0)]
    has = count > 0
    np.testing.assert_allclose(out[has], weighed.sum(axis=1)[has], atol=1e-6)
    assert np.isnan(out[~has]).all()


@pytest.mark.parametrize("f", [4, 8])
def test_fine_fixups_are_the_flagged_blocks_and_the_far_pixels(f: int) -> None:
    """The fine pixels on a surface whose 2×2 block of cells is flagged (nearest ×f of the
    padded block grid, offset by f/2) or whose guide is more than thr from the bilinear one:
    the same pixels as OpenCV's resizes give, in row-major order, by any strips of rows."""
    rng = np.random.default_rng(f)
    iz = _level(f)[0]
    hc, wc = iz.shape
    blocks = (rng.random((hc + 1, wc + 1)) > 0.8).astype(np.uint8)
    hf, wf = hc * f - 3, wc * f - 5  # (a fine grid that does not fill the last cells)
    near = cv2.resize(iz, (wc * f, hc * f), interpolation=cv2.INTER_LINEAR)[:hf, :wf]
    fine_iz = (near + rng.normal(0, 3.0, near.shape)).astype(np.float32)
    fine_valid = (rng.random((hf, wf)) > 0.05).astype(np.uint8)
    thr = np.float32(6.0)
    flag = cv2.resize(blocks, ((wc + 1) * f, (hc + 1) * f), interpolation=cv2.INTER_NEAREST)
    half = f // 2
    need = flag[half : half + hf, half : half + wf].astype(bool) | (np.abs(fine_iz - near) > thr)
    want = np.flatnonzero(need & fine_valid.astype(bool))
    assert 0 < want.size < need.size // 2

    found = []
    for r0 in range(0, hf, 13):
        r1 = min(hf, r0 + 13)
        out = np.empty((r1 - r0) * wf, np.int64)
        found.append(out[: fine_fixups(blocks, fine_valid, fine_iz, iz, f, thr, r0, r1, out)])
    got = np.concatenate(found)
    # the bilinear guide is OpenCV's to float32 rounding: a pixel just at thr may go either way
    at_edge = np.abs(np.abs(fine_iz - near) - thr).ravel() < 1e-4
    assert np.array_equal(got[~at_edge[got]], want[~at_edge[want]])
