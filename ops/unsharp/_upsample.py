"""Upsampling a smoothed level to the image, interpolating only between cells of a pixel's own
surface (the re-weighted taps near depth steps)."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from ops.numerics import put_points
from ops.parallel import run_strips, strip_rows
from ops.unsharp._common import _JUMP, Array
from ops.unsharp._levels import _block_flags, _Gather, _sub_resize, _touching
from ops.unsharp._surface import _Level
from ops.unsharp._taps import MAX_TAPS, apply_taps, fine_fixups, fixup_taps

_cv: Any = cv2  # OpenCV's stubs reject scalar operands (cv2.max(a, 0.0))


class _Upsampler:
    """Edge-aware upsampling from level ``lv`` to the grid of ``fine_iz``, read by strips of
    fine rows (:meth:`rows`), so that the caller can use each strip while it is in cache, from
    several threads at once.

    Bilinear, except at the few fine pixels whose four bilinear taps are not all on one surface
    (a tap block spanning a depth step of more than _JUMP level pixels, or holding an empty
    cell) or whose own depth guide departs from the interpolated one: there the taps are
    re-weighted by surface compatibility (|ΔI| < _JUMP level pixels, cell not empty), widening
    to a 4×4 tent where none of the four is compatible, and falling back to ``fallback`` (the
    pixel's own, less smoothed value) where no nearby cell lies on its surface. Nothing from
    another surface is interpolated in. ``fine_valid`` is uint8 0/1.

    Construction finds the re-weighted pixels and their taps and weights (``_FixupTaps``; at
    f >= 4, the pixels by a compiled scan of the fine rows): that depends on the levels'
    geometry only, not on the channels, so it can run while the channels are being smoothed.
    :meth:`bind` then gives the channels (level ``lv``) and computes the re-weighted values, one
    compiled pass over the points each; :meth:`rows` interpolates its rows and writes them in.
    """

    def __init__(
        self,
        lv: _Level,
        fine_iz: Array,
        fine_valid: Array,
        fine_k: int,
        fallback: list[Array],
    ) -> None:
        hf, wf = self.shape = fine_iz.shape[:2]
        f = self.f = 2 ** (lv.k - fine_k)  # fine pixels per coarse cell, per axis
        self.fallback = fallback
        self.coarse: list[Array] = []
        self.in_order = False  # idx ascending
        thr = np.float32(_JUMP * 2**lv.k)
        blocks = _block_flags(lv, thr)
        # flat fine indices of the re-weighted pixels (ascending where ``fine_k`` is 0)
        self.idx: Array | None = None
        self.at: tuple[Array, Array] | None = None  # their rows and columns (in the same order)
        self.taps: _FixupTaps | None = None  # their taps and weights (in the order of idx)
        self.vals: list[Array] = []  # their values, per channel (once bound)
        if f == 2:
            # the fine pixels of the flagged blocks that hold some surface (block (i, j) holds
            # cells i−1…i, j−1…j and fine pixels 2i−1…2i, 2j−1…2j), found on the coarse grid
            some = _touching(lv.valid_u8)
            bp = _cv.findNonZero(_cv.bitwise_and(blocks, some, dst=some))
            if bp is None:
                return
            bp = bp.reshape(-1, 2).astype(np.int64)
            xx = (2 * bp[:, 0] - 1)[:, None] + np.array([0, 1, 0, 1])[None, :]
            yy = (2 * bp[:, 1] - 1)[:, None] + np.array([0, 0, 1, 1])[None, :]
            ok = (xx >= 0) & (xx < wf) & (yy >= 0) & (yy < hf)
            xx, yy = xx[ok], yy[ok]
            idx = yy * wf + xx
            on = _Gather(yy, xx, wf)(fine_valid).view(bool)
            xx, yy, idx = xx[on], yy[on], idx[on]
        else:
            idx = _fine_fixups(blocks, fine_valid, fine_iz, lv.iz, f, thr)
            yy, xx = np.divmod(idx, wf)
        if idx.size == 0:
            return
        self.in_order = fine_k == 0
        if self.in_order and f == 2:  # read by strips of rows (:meth:`rows`): sorted
            order = np.argsort(idx, kind="stable")
            idx, xx, yy = idx[order], xx[order], yy[order]
        self.idx = idx
        self.at = (yy, xx)
        self.taps = _FixupTaps(xx, yy, f, lv, fine_iz.ravel()[idx], thr)

    def bind(self, coarse: list[Array]) -> _Upsampler:
        """Give the channels to upsample (level ``lv``, one per ``fallback``); returns self."""
        self.coarse = coarse
        self.vals = []
        if self.taps is not None and self.idx is not None:
            self.vals = self.taps.apply(coarse)
            if self.taps.none is not None:
                at = self.idx[self.taps.none]
                for col, fb in zip(self.vals, self.fallback, strict=True):
                    col[self.taps.none] = fb.ravel()[at]
        return self

    def rows(self, r: slice, cols: slice | None = None) -> list[Array]:
        """The upsampled channels at fine rows ``r`` (new arrays), columns ``cols`` (None: all;
        else they must hold every surface pixel of the rows)."""
        hf, wf = self.shape
        c = slice(0, wf) if cols is None else cols
        ups = [_sub_resize(a, self.f, r, c) for a in self.coarse]
        if self.idx is not None and r.start == 0 and r.stop == hf and cols is None:
            ups = [np.ascontiguousarray(u) for u in ups]
            for u, v in zip(ups, self.vals, strict=True):
                u.ravel()[self.idx] = v
        elif self.idx is not None:
            assert self.in_order, "strips of rows are read from the image's upsampling only"
            i0, i1 = (int(i) for i in np.searchsorted(self.idx, (r.start * wf, r.stop * wf)))
            if i1 > i0:  # (re-weighted pixels are on the surface: in the columns)
                assert self.at is not None
                yy, xx = self.at
                origin, width = (r.start, c.start, 0), c.stop - c.start
                for u, v in zip(ups, self.vals, strict=True):  # (compiled: without Python's lock)
                    put_points(u[None], yy, xx, v[:, None], i0, i1, origin, width)
        return ups

    def full(self) -> list[Array]:
        """All rows at once."""
        return self.rows(slice(0, self.shape[0]))


def _fine_fixups(
    blocks: Array, fine_valid: Array, fine_iz: Array, iz_c: Array, f: int, thr: np.float32
) -> Array:
    """:func:`ops.unsharp._taps.fine_fixups` of every fine row, by strips over the shared pool:
    the re-weighted pixels' flat indices, ascending."""
    hf, wf = fine_iz.shape
    found: dict[int, Array] = {}
    iz_c = np.ascontiguousarray(iz_c)

    def strip(r0: int, r1: int) -> None:
        out = np.empty((r1 - r0) * wf, np.int64)
        found[r0] = out[: fine_fixups(blocks, fine_valid, fine_iz, iz_c, f, thr, r0, r1, out)]

    run_strips(hf, strip, strip_rows(wf))
    return np.concatenate([found[r0] for r0 in sorted(found)])


#: Re-weighted pixels per strip of :class:`_FixupTaps` (a few milliseconds of work each).
_FIXUP_POINTS = 1 << 15


class _FixupTaps:
    """Surface-compatible interpolation at fine pixels (xx, yy) of level ``lv``'s cells: the
    taps and weights, to be applied to any channel of that level (:meth:`apply`); ``none``: the
    points where no compatible tap is found (None: there are none).

    Taps: the 2×2 bilinear ones, then (where none of those is compatible) a 4×4 tent of radius 2
    cells. A tap is compatible when its plane (``lv.grad``), extrapolated to the pixel, meets the
    pixel's depth guide ``iz_p`` within ``thr``; weight tent × (1 − (miss/thr)²), normalised.
    Both in one compiled pass over the points (:mod:`ops.unsharp._taps`).
    """

    def __init__(
        self, xx: Array, yy: Array, f: int, lv: _Level, iz_p: Array, thr: np.float32
    ) -> None:
        n = xx.size
        self.taps = np.empty((n, MAX_TAPS), np.int32)
        self.wts = np.empty((n, MAX_TAPS), np.float32)
        self.count = np.empty(n, np.int8)
        no_grad = np.empty(0, np.float32)
        gx, gy = (no_grad, no_grad) if lv.grad is None else (g.ravel() for g in lv.grad)
        level = (
            np.ascontiguousarray(lv.iz).ravel(),
            gx,
            gy,
            lv.valid_u8.ravel(),
            lv.cov.shape[1],
            np.float32(2**lv.k),
            np.float32(1.0 / thr),
        )
        xx, yy = np.ascontiguousarray(xx), np.ascontiguousarray(yy)
        iz_p = np.ascontiguousarray(iz_p, np.float32)
        inv_f = np.float32(1.0 / f)

        def points(i0: int, i1: int) -> None:
            at = slice(i0, i1)
            fixup_taps(xx[at], yy[at], inv_f, iz_p[at], *level, *self._of(at))

        run_strips(n, points, _FIXUP_POINTS)
        none = np.flatnonzero(self.count == 0)
        self.none = none if none.size else None

    def _of(self, at: slice) -> tuple[Array, Array, Array]:
        return self.taps[at], self.wts[at], self.count[at]

    def apply(self, arrs: list[Array]) -> list[Array]:
        """The interpolated values of each of ``arrs`` (channels of the level) at the points
        (NaN where no compatible tap is found: see ``none``); every channel on each range of
        points."""
        flat = [np.ascontiguousarray(arr, np.float32).ravel() for arr in arrs]
        outs = [np.empty(self.count.size, np.float32) for _ in arrs]

        def points(i0: int, i1: int) -> None:
            at = slice(i0, i1)
            for arr, out in zip(flat, outs, strict=True):
                apply_taps(arr, *self._of(at), out[at])

        run_strips(self.count.size, points, _FIXUP_POINTS)
        return outs
