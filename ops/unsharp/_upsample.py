"""Upsampling a smoothed level to the image, interpolating only between cells of a pixel's own
surface (the re-weighted taps near depth steps)."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from ops.unsharp._common import _JUMP, Array
from ops.unsharp._levels import _block_flags, _Gather, _sub_resize, _sum_taps, _touching
from ops.unsharp._surface import _Level

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

    Construction finds the re-weighted pixels and their taps and weights (``_FixupTaps``): that
    depends on the levels' geometry only, not on the channels, so it can run while the channels
    are being smoothed. :meth:`bind` then gives the channels (level ``lv``) and computes the
    re-weighted values, in one vectorised pass each (many small NumPy calls: in threads they
    would only contend for the GIL); :meth:`rows` interpolates its rows and writes them in.
    """

    def __init__(
        self,
        lv: _Level,
        fine_iz: Array,
        fine_valid: Array,
        fine_k: int,
        fallback: list[Array],
    ) -> None:
        hc, wc = lv.cov.shape
        hf, wf = self.shape = fine_iz.shape[:2]
        f = self.f = 2 ** (lv.k - fine_k)  # fine pixels per coarse cell, per axis
        self.fallback = fallback
        self.coarse: list[Array] = []
        self.in_order = False  # idx ascending
        thr = np.float32(_JUMP * 2**lv.k)
        blocks = (
            lv.flags[1] if lv.flags is not None and lv.flags[0] == thr else _block_flags(lv, thr)
        )
        # flat fine indices of the re-weighted pixels (ascending where ``fine_k`` is 0)
        self.idx: Array | None = None
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
            half = f // 2
            flag = _cv.resize(blocks, ((wc + 1) * f, (hc + 1) * f), interpolation=_cv.INTER_NEAREST)
            need = _cv.bitwise_and(flag[half : half + hf, half : half + wf], fine_valid)
            # a fine pixel whose own guide departs from the interpolated one: a small object
            # inside a cell (at f = 2 any such cell already differs from its neighbours)
            izn = _cv.resize(lv.iz, (wc * f, hc * f), interpolation=_cv.INTER_LINEAR)[:hf, :wf]
            far = _cv.compare(_cv.absdiff(fine_iz, izn), float(thr), _cv.CMP_GT)
            _cv.bitwise_and(far, fine_valid, dst=far)
            _cv.bitwise_or(need, far, dst=need)
            pts = _cv.findNonZero(need)
            if pts is None:
                return
            pts = pts.reshape(-1, 2)
            xx, yy = pts[:, 0], pts[:, 1]
            idx = yy.astype(np.int64) * wf + xx
        if idx.size == 0:
            return
        self.in_order = fine_k == 0
        if self.in_order:  # read by strips of rows (:meth:`rows`): sorted
            order = np.argsort(idx, kind="stable")
            idx, xx, yy = idx[order], xx[order], yy[order]
        self.idx = idx
        self.taps = _FixupTaps(xx, yy, f, lv, fine_iz.ravel()[idx], thr)

    def bind(self, coarse: list[Array]) -> _Upsampler:
        """Give the channels to upsample (level ``lv``, one per ``fallback``); returns self."""
        self.coarse = coarse
        self.vals = []
        if self.taps is not None and self.idx is not None:
            for arr, fb in zip(coarse, self.fallback, strict=True):
                col = self.taps.apply(arr)
                if self.taps.none is not None:
                    col[self.taps.none] = fb.ravel()[self.idx[self.taps.none]]
                self.vals.append(col)
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
            i0, i1 = np.searchsorted(self.idx, (r.start * wf, r.stop * wf))
            if i1 > i0:  # (re-weighted pixels are on the surface: in the columns)
                at_r, at_c = np.divmod(self.idx[i0:i1], wf)
                at_r -= r.start
                at_c -= c.start
                for u, v in zip(ups, self.vals, strict=True):
                    u[at_r, at_c] = v[i0:i1]
        return ups

    def full(self) -> list[Array]:
        """All rows at once."""
        return self.rows(slice(0, self.shape[0]))


class _FixupTaps:
    """Surface-compatible interpolation at fine pixels (xx, yy) of level ``lv``'s cells: the
    taps and weights, to be applied to any channel of that level (:meth:`apply`); ``none``: the
    points where no compatible tap is found (None: there are none).

    Taps: the 2×2 bilinear ones, then (where none of those is compatible) a 4×4 tent of radius 2
    cells. A tap is compatible when its plane (``lv.grad``), extrapolated to the pixel, meets the
    pixel's depth guide ``iz_p`` within ``thr``; weight tent × (1 − (miss/thr)²), normalised.
    All in float32 (the offsets from the taps are multiples of 1/(2f), exact).
    """

    def __init__(
        self, xx: Array, yy: Array, f: int, lv: _Level, iz_p: Array, thr: np.float32
    ) -> None:
        hc, wc = lv.cov.shape
        valid_c = lv.valid.ravel()
        izc = lv.iz.ravel()
        d = np.float32(2**lv.k)
        grad = None if lv.grad is None else (lv.grad[0].ravel(), lv.grad[1].ravel())
        inv_f = np.float32(1.0 / f)
        u = (xx.astype(np.float32) + np.float32(0.5)) * inv_f - np.float32(0.5)
        v = (yy.astype(np.float32) + np.float32(0.5)) * inv_f - np.float32(0.5)
        x0 = np.floor(u).astype(np.intp)
        y0 = np.floor(v).astype(np.intp)
        inv_thr = np.float32(1.0 / thr)
        self.n = xx.size
        # per pass: (points it gives, (taps, points) flat cell indices, normalised weights)
        self.passes: list[tuple[Array | slice, Array, Array]] = []
        todo: Array | None = None  # None: all
        zero, one = np.float32(0.0), np.float32(1.0)
        # arrays are (taps, points): each tap's values are contiguous, sums over taps add rows
        for radius, offs in ((1.0, (0, 1)), (2.0, (-1, 0, 1, 2))):
            if todo is None:
                ut, vt, it, xt, yt = u, v, iz_p, x0, y0
            else:
                ut, vt, it, xt, yt = u[todo], v[todo], iz_p[todo], x0[todo], y0[todo]
            npt = ut.size
            m = len(offs)
            o = np.array(offs, np.intp)[:, None]
            cx = xt[None, :] + o  # (m, N)
            cy = yt[None, :] + o
            dx = ut[None, :] - cx.astype(np.float32)
            dy = vt[None, :] - cy.astype(np.float32)
            if radius == 1.0:  # |dx| < 1 at the two taps: the tent 1 − |dx| is positive
                tx = one - np.abs(dx)
                ty = one - np.abs(dy)
            else:
                inv_r = np.float32(1.0 / radius)
                tx = np.maximum(zero, one - np.abs(dx) * inv_r)
                ty = np.maximum(zero, one - np.abs(dy) * inv_r)
            tx[(cx < 0) | (cx >= wc)] = 0.0
            ty[(cy < 0) | (cy >= hc)] = 0.0
            # (m, m, N): rows of taps, columns of taps (np.clip is slow on small arrays)
            rowi = np.minimum(np.maximum(cy, 0), hc - 1)
            rowi *= wc
            coli = np.minimum(np.maximum(cx, 0), wc - 1)
            flat = rowi[:, None, :] + coli[None, :, :]
            pred = izc[flat]
            if grad is not None:  # the tap's plane extrapolated to the pixel
                ddx, ddy = dx * d, dy * d  # (exact: d is a power of 2)
                pred += grad[0][flat] * ddx[None, :, :] + grad[1][flat] * ddy[:, None, :]
            # weight 1 − (miss / thr)², miss = |pred − I| (the sign goes with the square)
            pred -= it[None, None, :]
            pred *= inv_thr
            np.square(pred, out=pred)
            wts = np.subtract(one, pred, out=pred)
            np.maximum(wts, zero, out=wts)
            wts *= ty[:, None, :] * tx[None, :, :]
            wts *= valid_c[flat]
            wts = wts.reshape(m * m, npt)
            flat = flat.reshape(m * m, npt)
            sw = _sum_taps(wts)
            found = sw > 1e-4
            nfound = int(np.count_nonzero(found))
            if nfound:
                rows: Array | slice
                if todo is None:  # all points (those not found get another pass, or none)
                    rows = slice(None)
                    with np.errstate(divide="ignore", invalid="ignore"):
                        wts /= sw[None, :]
                else:
                    if nfound < npt:
                        wts, flat, sw = wts[:, found], flat[:, found], sw[found]
                    wts /= sw[None, :]
                    rows = todo if nfound == npt else todo[found]
                self.passes.append((rows, flat, wts))
            todo = (
                None
                if nfound == npt
                else (np.flatnonzero(~found) if todo is None else todo[~found])
            )
            if todo is None:
                break
        self.none = todo  # (None: every point has a compatible tap)

    def apply(self, arr: Array) -> Array:
        """The interpolated values of ``arr`` (a channel of the level) at the points (garbage
        where no compatible tap is found: see ``none``)."""
        out = np.full(self.n, np.nan, dtype=np.float32)
        a = arr.ravel()
        for rows, flat, wts in self.passes:
            out[rows] = _sum_taps(wts * np.take(a, flat))
        return out
