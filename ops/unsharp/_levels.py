"""The coarser levels of the surface pyramid: front-most cells, selective reduction and the
domain-transform smoothing of each level (on a thread of its own)."""

from __future__ import annotations

import functools
import os
import threading
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import cv2
import numpy as np

from ops.parallel import run_strips
from ops.unsharp._common import _DT_DEPTH_GAIN, _DT_MODE, _JUMP, _KNEE, _SIGMA_C, _WALL, Array
from ops.unsharp._front import (
    AS_IS,
    CELLS,
    NAN_AS_ZERO,
    ON_SURFACE,
    SQUARED,
    front_sums,
    front_taps,
)
from ops.unsharp._reduce import block_averages, block_weights, step_flags
from ops.unsharp._surface import _guide_gradient, _Level, _plane_slope, _Surface

_cv: Any = cv2  # OpenCV's stubs reject scalar operands (cv2.max(a, 0.0))


def _finish_first_level(lv: _Level, surf: _Surface, sigs: list[Array]) -> None:
    """Level 1 as ``_surface`` averaged it (with the guide's slopes), the cells on a step
    holding the front-most surface only (``sigs``: the signals at full resolution)."""
    _front_most_cells(lv, surf, sigs)


class _Gather:
    """``a[rows, cols]`` of (H, W) or (H, W, C) arrays at fixed points, through the flat index
    where ``a`` is C-contiguous (NumPy's fast path), by (row, column) elsewhere (a view with a
    row stride is read in place, not copied)."""

    def __init__(self, rows: Array, cols: Array, w: int) -> None:
        self.rows, self.cols = rows, cols
        self.flat = rows * w + cols

    def __call__(self, a: Array) -> Array:
        if a.flags.c_contiguous:  # (np.take: 3x faster than indexing for rows of channels)
            return np.take(a.reshape(-1, *a.shape[2:]), self.flat, axis=0)
        return a[self.rows, self.cols]


def _front_most_cells(lv: _Level, surf: _Surface, sigs: list[Array]) -> None:
    """Make the level-1 cells that straddle a depth step hold the front-most surface only.

    The area average mixes the 2×2 pixels of a cell whatever they show; where a cell sits on a
    step (it touches a block ``_block_flags`` rejects), its pixels are re-averaged keeping
    those within _JUMP pixels (plus the cell's own slope) of the nearest one, as
    ``_reduce_selective`` does for the coarser levels. A one-pixel-wide object in front of a
    surface then keeps its own cells instead of half-mixing with what lies behind it.
    """
    thr = np.float32(_JUMP * 2)
    fl = _block_flags(lv, thr)
    cand = _cv.dilate(fl, _BLOCK, anchor=(0, 0))[:-1, :-1]  # cell touches a flagged block
    _cv.bitwise_and(cand, lv.valid_u8, dst=cand)
    pts = _cv.findNonZero(cand)
    if pts is None:
        return
    pts = pts.reshape(-1, 2)
    cx, cy = pts[:, 0].astype(np.intp), pts[:, 1].astype(np.intp)
    # per cell (N, 4): its pixels (top-left, top-right, bottom-left, bottom-right), whether
    # each is on the surface, and its weight (ops.unsharp._front, compiled)
    py, px, ok, wk, n = front_taps(cx, cy, surf.valid, surf.iz, lv.grad, float(thr))
    # (field at full resolution, how it is read, the level's array the cells are written in)
    sums: list[tuple[Array, int, Array]] = [
        (sig, ON_SURFACE, lv.sig[i]) for i, sig in enumerate(sigs)
    ]
    if len(lv.sig) > len(sigs):  # and the square of the one signal
        sums.append((sigs[-1], SQUARED, lv.sig[1]))
    sums.append((surf.iz, AS_IS, lv.iz))
    if surf.lps is not None:
        sums.append((surf.lps, AS_IS, lv.lps))
    if lv.nrm is not None and surf.normal is not None:  # (normals off the surface: any)
        sums += [(surf.normal[..., i], NAN_AS_ZERO, lv.nrm[i]) for i in range(3)]

    def cells(a: int, b: int) -> None:  # every field, into the level's cells a … b − 1
        at = slice(a, b)
        for field, mode, out in sums:
            front_sums(field, py[at], px[at], ok[at], wk[at], mode, cy[at], cx[at], out)

    run_strips(cx.size, cells, CELLS)
    lv.cov[cy, cx] = n * np.float32(0.25)
    if surf.lps is None:
        a, b = surf.lps_from
        lv.lps[cy, cx] = a * lv.iz[cy, cx] + b
    if lv.nrm is not None and surf.normal is not None and lv.grad is not None:
        nc = [q[cy, cx] for q in lv.nrm]  # the re-averaged cells' slopes
        gx, gy = _plane_slope(
            nc[0], nc[1], nc[2], cy.astype(np.float32), cx.astype(np.float32), 1, surf
        )
        bad = ~(np.isfinite(gx) & np.isfinite(gy)) | (n == 0)
        gx[bad] = 0.0
        gy[bad] = 0.0
        lv.grad[0][cy, cx] = gx
        lv.grad[1][cy, cx] = gy
    lv._valid = None


def _touching(cells: Array) -> Array:
    """uint8 (h + 1, w + 1): the 2×2 blocks (the bilinear taps, as in ``_block_flags``) that
    hold a cell where ``cells`` (uint8, (h, w)) is non-zero; block (i, j) holds cells
    i−1…i, j−1…j."""
    near = _cv.copyMakeBorder(cells, 1, 0, 1, 0, _cv.BORDER_CONSTANT, value=0)
    return _cv.dilate(near, _BLOCK, anchor=(0, 0), borderType=_cv.BORDER_CONSTANT, borderValue=0)


def _reduce_selective(lv: _Level, surf: _Surface) -> _Level:
    """Next coarser level, each cell keeping only the front-most surface of its 2×2 block.

    Each sample predicts the depth guide at the block centre along its own plane (normals); the
    samples within _JUMP (at this level's scale) of the nearest prediction are averaged and the
    others (a farther surface) dropped, so a coarse cell does not mix an object with what lies
    behind it, while a steep surface keeps all its samples (weight 1 within _JUMP/2 of the
    front, fading to 0 at _JUMP: no hard switch along a contact). Compiled passes
    (``ops.unsharp._reduce``).
    """
    c = np.ascontiguousarray
    grad = None if lv.grad is None else (c(lv.grad[0]), c(lv.grad[1]))
    sel, cov, inv = block_weights(c(lv.cov), c(lv.iz), grad, lv.k, _JUMP, float(_BIG))
    # every field in one pass of strips: the guide, its log pixel size (unless it is made from
    # the guide), the signals and the normals
    nrm = [] if lv.nrm is None else lv.nrm
    own_lps = [] if surf.lps is None else [lv.lps]
    fields = [lv.iz, *own_lps, *lv.sig, *nrm]
    iz, *rest = block_averages([c(f, dtype=np.float32) for f in fields], sel, inv)
    if surf.lps is None:
        a, b = surf.lps_from
        lps = _cv.addWeighted(iz, a, iz, 0.0, b)
    else:
        lps = rest.pop(0)
    sig, reduced_nrm = rest[: len(lv.sig)], rest[len(lv.sig) :]
    out = _Level(lv.k + 1, cov, sig, iz, lps, None if lv.nrm is None else reduced_nrm)
    out.grad = _guide_gradient(out, surf)
    return out


_BLOCK = np.ones((2, 2), np.uint8)


@functools.lru_cache(maxsize=16)
def _ramp(h: int, w: int) -> Array:
    """(KNEE/2)(row + column), read-only (cached per level shape)."""
    ramp = np.add.outer(np.arange(h, dtype=np.float32), np.arange(w, dtype=np.float32))
    ramp *= np.float32(0.5 * _KNEE)
    ramp.flags.writeable = False
    return ramp


_SMOOTHER: ThreadPoolExecutor | None = None
_SMOOTHER_LOCK = threading.Lock()


def _smoother() -> ThreadPoolExecutor:
    """The thread the pyramid's domain transforms run on, in the background of the rest of
    its work (one, shared, created on first use; a forked child makes its own)."""
    global _SMOOTHER
    with _SMOOTHER_LOCK:
        if _SMOOTHER is None:
            _SMOOTHER = ThreadPoolExecutor(1, "depict-smooth")
        return _SMOOTHER


def _forget_smoother() -> None:  # in a forked child: the parent's thread is not there
    global _SMOOTHER, _SMOOTHER_LOCK
    _SMOOTHER, _SMOOTHER_LOCK = None, threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_smoother)


def _smooth_level(
    lv: _Level, nsig: int, normal_sigma: float | None, box: tuple[slice, slice] | None = None
) -> list[Array]:
    """Domain-transform smoothing (normalised convolution, σ = 2 cells) of the first ``nsig``
    signal channels of a level, guided by the depth guide (and normals), empty cells walled off.

    The depth guide I enters as the pair I/2 ± (KNEE/2)(x + y): OpenCV's transform adds the L1
    norm of the guide step, and |a + b| + |a − b| = 2 max(|a|, |b|), so each step costs
    1 + max(|ΔI|, KNEE) instead of 1 + |ΔI|. Surfaces tilted less than atan(KNEE) are smoothed
    as if flat (σ is rescaled by 1 + KNEE), steeper ones and depth steps are stretched as before:
    this removes the crease that the L1 arc length |ΔI| has where the depth slope changes sign
    (it showed as lines across the middle of a sphere in L* − L*_σ).
    """
    bx = box if box is not None else (slice(None), slice(None))
    iz, valid = lv.iz[bx], lv.valid[bx]
    h, w = iz.shape
    gz = _cv.multiply(iz, 0.5 * _DT_DEPTH_GAIN / 2**lv.k)  # 0 in empty cells
    _, top, _, _ = _cv.minMaxLoc(gz, mask=valid.view(np.uint8))
    empty = (~valid).astype(np.float32)
    _cv.scaleAdd(empty, top + 0.5 * _WALL, gz, dst=gz)  # walls around the surface
    ramp = _ramp(h, w)
    chans = [_cv.add(gz, ramp), _cv.subtract(gz, ramp)]
    sigma = _SIGMA_C * (1.0 + _KNEE)
    if lv.nrm is not None and normal_sigma is not None:
        s = sigma / normal_sigma
        chans += [_cv.multiply(n[bx], s) for n in lv.nrm[:2]]
    guide = _cv.merge(chans)
    src = _cv.merge([g[bx] for g in lv.sig[:nsig]]) if nsig > 1 else lv.sig[0][bx]
    out = _cv.ximgproc.dtFilter(
        guide,
        src,
        sigmaSpatial=sigma,
        sigmaColor=sigma,
        mode=_DT_MODE,
        numIters=3,
    )
    # (empty cells hold whatever: nothing reads them - flagged blocks skip them)
    return [np.ascontiguousarray(out[:, :, i]) for i in range(nsig)] if nsig > 1 else [out]


_BIG = np.float32(1.0e30)


def _block_flags(lv: _Level, thr: np.float32) -> Array:
    """Per 2×2 block of cells (the bilinear taps), padded: 1 where it is not one surface.

    Entry (i, j) covers cells (i−1…i, j−1…j) (clamped at the borders). A block is flagged when
    one of its cells is empty, or when the four cells, each extrapolating the depth guide along
    its own plane (``grad``) to the block's centre, disagree by more than ``thr``: a step
    between surfaces, not a steep surface. uint8 0/1, shape (h + 1, w + 1); one compiled pass
    (``ops.unsharp._reduce.step_flags``).
    """
    c = np.ascontiguousarray
    grad = None if lv.grad is None else (c(lv.grad[0]), c(lv.grad[1]))
    return step_flags(c(lv.cov), c(lv.iz), grad, lv.k, float(thr))


def _sub_resize(a: Array, f: int, rows: slice, cols: slice) -> Array:
    """Rows ``rows``, columns ``cols`` of the bilinear ×``f`` upsampling of ``a`` (as
    ``cv2.resize(a, (w f, h f), INTER_LINEAR)``, bit for bit), resizing only the cells they
    read: bilinear taps are local, and OpenCV's weights depend on the position relative to the
    crop only through f · (first cell), an integer. A view (with a row stride) of a new array."""
    hc, wc = a.shape[:2]
    y0, y1 = max(rows.start // f - 1, 0), min((rows.stop - 1) // f + 2, hc)
    x0, x1 = max(cols.start // f - 1, 0), min((cols.stop - 1) // f + 2, wc)
    size = ((x1 - x0) * f, (y1 - y0) * f)
    sub = _cv.resize(a[y0:y1, x0:x1], size, interpolation=_cv.INTER_LINEAR)
    return sub[rows.start - y0 * f : rows.stop - y0 * f, cols.start - x0 * f : cols.stop - x0 * f]
