"""The surface pyramid's front-most cells (``ops.unsharp._levels._front_most_cells``, compiled in
``ops.unsharp._front``) against the rule written out here in NumPy: the level-1 cells beside a
depth step re-averaged from their 2×2 pixels, keeping those near the front-most one; every field
of the level the same, bit for bit."""

from __future__ import annotations

import copy
from typing import Any

import cv2
import numpy as np
import pytest

from ops.unsharp import _front, _levels
from ops.unsharp._levels import _BLOCK, _block_flags, _front_most_cells
from ops.unsharp._surface import _Level, _plane_slope, _Surface, _surface, _valid

_cv: Any = cv2
JUMP = 4.0  # ops.unsharp._common._JUMP
BIG = np.float32(1.0e30)


def _reference(lv: _Level, surf: _Surface, sigs: list[np.ndarray]) -> None:
    """The rule in NumPy, on (taps, cells) arrays: weight 1 within thr/2 (plus twice the cell's
    slope) of the cell's front-most pixel, fading to 0 at thr, 0 off the surface, normalised;
    the four taps summed in order."""
    thr = np.float32(JUMP * 2)
    cand = _cv.dilate(_block_flags(lv, thr), _BLOCK, anchor=(0, 0))[:-1, :-1]
    _cv.bitwise_and(cand, lv.valid_u8, dst=cand)
    cy, cx = np.nonzero(cand)
    hf, wf = surf.iz.shape
    px = (2 * cx)[None, :] + np.array([0, 1, 0, 1])[:, None]
    py = (2 * cy)[None, :] + np.array([0, 0, 1, 1])[:, None]
    inside = (px < wf) & (py < hf)
    px, py = np.minimum(px, wf - 1), np.minimum(py, hf - 1)
    ok = inside & (surf.valid[py, px] != 0)
    iz = surf.iz[py, px]
    slope = np.float32(0.0)
    if lv.grad is not None:
        slope = (np.abs(lv.grad[0][cy, cx]) + np.abs(lv.grad[1][cy, cx]))[None, :]
    front = np.where(ok, iz, BIG).min(axis=0, keepdims=True)
    keep = (front + thr + 2.0 * slope - iz) / (np.float32(0.5) * thr)
    keep = np.clip(keep, np.float32(0.0), np.float32(1.0)) * ok
    n = ((keep[0] + keep[1]) + keep[2]) + keep[3]
    wk = keep / np.maximum(n, np.float32(1e-6))[None, :]

    def tap_sum(v: np.ndarray) -> np.ndarray:
        t = wk * v
        return ((t[0] + t[1]) + t[2]) + t[3]

    lv.cov[cy, cx] = n * np.float32(0.25)
    for i, sig in enumerate(sigs):
        lv.sig[i][cy, cx] = tap_sum(np.where(ok, sig[py, px], np.float32(0.0)))
    if len(lv.sig) > len(sigs):
        vals = np.where(ok, sigs[0][py, px], np.float32(0.0))
        lv.sig[1][cy, cx] = tap_sum(vals * vals)
    iz_c = tap_sum(iz)
    lv.iz[cy, cx] = iz_c
    a, b = surf.lps_from
    lv.lps[cy, cx] = a * iz_c + b if surf.lps is None else tap_sum(surf.lps[py, px])
    if lv.nrm is not None and surf.normal is not None:
        nv = surf.normal[py, px]
        nc = [
            tap_sum(np.where(np.isnan(nv[..., i]), np.float32(0.0), nv[..., i])) for i in range(3)
        ]
        for i in range(3):
            lv.nrm[i][cy, cx] = nc[i]
        if lv.grad is not None:
            fy, fx = cy.astype(np.float32), cx.astype(np.float32)
            gx, gy = _plane_slope(nc[0], nc[1], nc[2], fy, fx, 1, surf)
            bad = ~(np.isfinite(gx) & np.isfinite(gy)) | (n == 0)
            gx[bad], gy[bad] = 0.0, 0.0
            lv.grad[0][cy, cx], lv.grad[1][cy, cx] = gx, gy
    lv._valid = None


def _scene(shape: tuple[int, int], seed: int, pixel_size: str) -> dict[str, Any]:
    """A slanted wall with a one- and a three-pixel bar and a disc in front of it, holes off the
    surface (normals NaN there), two signals with noise."""
    rng = np.random.default_rng(seed)
    h, w = shape
    rows, cols = np.indices(shape, dtype=np.float32)
    depth = (6.0 + 0.01 * cols + 0.002 * rows).astype(np.float32)
    depth[:, w // 3] = 3.5  # one pixel wide
    depth[:, w // 2 : w // 2 + 3] = 4.0
    disc = (rows - h / 3) ** 2 + (cols - 2 * w / 3) ** 2 < (h / 5) ** 2
    depth[disc] -= np.float32(2.0) + np.float32(0.01) * cols[disc]
    mask = (rng.random(shape) > 0.03).astype(np.float32)
    mask[: h // 8, : w // 8] = 0.0
    normal = rng.normal(0.0, 0.2, (h, w, 3)).astype(np.float32)
    normal[..., 2] = 1.0
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    normal[mask == 0] = np.nan
    f = np.float32(0.9 * h)
    ps = {
        "perspective": depth / f,
        "measured": (depth / f) * (1.0 + 0.2 * rng.random(shape)).astype(np.float32),
        "orthographic": np.full(shape, np.float32(0.01)),
    }[pixel_size].astype(np.float32)
    sigs = [(rng.random(shape) * 2.0 + 0.1 * cols).astype(np.float32) for _ in range(2)]
    return {"depth": depth, "ps": ps, "mask": mask, "normal": normal, "sigs": sigs}


def _surface_of(sc: dict[str, Any], squares: bool) -> tuple[_Surface, np.ndarray, _Level | None]:
    """``_surface`` of a scene: its first signal (and its square, or the second signal) at full
    resolution and level 1."""
    valid, ps_range, _, _ = _valid(sc["depth"], sc["ps"], sc["mask"])
    sig0 = sc["sigs"][0]
    h, w = sig0.shape
    return _surface(
        sc["depth"],
        sc["ps"],
        valid,
        sc["normal"],
        1.0,
        (w / 2.0, h / 2.0),
        ps_range,
        lambda r, out: np.copyto(out, sig0[r]),
        squares,
        () if squares else (sc["sigs"][1],),
    )


@pytest.mark.parametrize("shape", [(96, 128), (97, 131)])
@pytest.mark.parametrize("pixel_size", ["perspective", "measured", "orthographic"])
@pytest.mark.parametrize("squares", [False, True])
@pytest.mark.parametrize("cells", [_front.CELLS, 37])  # 37: the cells in ranges on the pool
def test_front_most_cells_are_the_numpy_rule(
    shape: tuple[int, int], pixel_size: str, squares: bool, cells: int, monkeypatch: Any
) -> None:
    for module in (_front, _levels):
        monkeypatch.setattr(module, "CELLS", cells)
    sc = _scene(shape, 7, pixel_size)
    others = () if squares else (sc["sigs"][1],)
    surf, sub, first = _surface_of(sc, squares)
    assert first is not None and (surf.lps is None) == (pixel_size != "measured")
    sigs = [sub, *others]
    got, want = copy.deepcopy(first), copy.deepcopy(first)
    _front_most_cells(got, surf, sigs)
    _reference(want, surf, sigs)
    assert not np.array_equal(got.cov, first.cov)  # cells were re-averaged
    fields = ["cov", "iz", "lps"]
    for name in fields:
        assert np.array_equal(getattr(got, name), getattr(want, name)), name
    assert len(got.sig) == len(want.sig)
    for a, b in zip(got.sig, want.sig, strict=True):
        assert np.array_equal(a, b)
    assert got.nrm is not None and want.nrm is not None
    for a, b in zip(got.nrm, want.nrm, strict=True):
        assert np.array_equal(a, b, equal_nan=True)
    assert got.grad is not None and want.grad is not None
    for a, b in zip(got.grad, want.grad, strict=True):
        assert np.array_equal(a, b)
