"""A depth-aware pyramid of a frame's geometry: 2×2 reductions that keep the front-most surface of
each block, and edge-aware upsampling that does not mix surfaces across depth jumps."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from ops.numerics import put_points
from ops.opencv import written
from ops.parallel import run_strips, strip_rows
from ops.pyramid._depth_kernels import (
    BACKGROUND,
    _build01_rows,
    _children,
    _down_geometry_rows,
    _down_unit_rows,
    _gather_unit,
    _jump_rows,
)
from ops.pyramid._jb import jb_weights_fast

__all__ = ["DepthPyramid", "normalize_field"]

F32 = NDArray[np.float32]

# Block members further than this many depth_sigma behind the block's front are left out.
_DOWN_EXCLUDE = 2.0
# A log-depth step between covered neighbouring samples larger than this many depth_sigma is
# treated as a discontinuity by the upsampling even without a second difference.
_STEP = 3.0
#: Points per task of :meth:`DepthPyramid.up_sparse`'s gathering (each a fraction of a ms).
_GATHER_POINTS = 8192
# Rows per strip for the strip-parallel helpers.
STRIP_ROWS = 32


def normalize_field(v: np.ndarray, mask: np.ndarray | None = None) -> F32:
    """Unit vectors along the last axis of ``v`` (..., 3); zero vectors stay 0. ``mask``: an
    (H, W) float 0/1 coverage the result is multiplied by."""
    v = np.asarray(v, np.float32)
    if v.ndim == 3 and v.shape[2] == 3 and v.shape[0] * v.shape[1] >= 4096:
        # planes (cv2.split / merge): the same arithmetic without strided or broadcast passes,
        # by strips of rows on every core
        out = np.empty(v.shape, np.float32)

        def rows(a: int, b: int) -> None:
            x, y, z = cv2.split(v[a:b])
            n2 = x * x
            n2 += y * y
            n2 += z * z
            inv = np.zeros_like(n2)
            np.divide(1.0, np.sqrt(n2), out=inv, where=n2 > 1e-20)
            if mask is not None:
                inv *= mask[a:b]  # 0/1: (v inv) m = v (inv m)
            for plane in (x, y, z):
                plane *= inv
            written(cv2.merge([x, y, z], dst=out[a:b]), out, slice(a, b))

        run_strips(v.shape[0], rows, strip_rows(v.shape[1]))
        return out
    n2 = v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1] + v[..., 2] * v[..., 2]
    inv = np.zeros_like(n2)
    np.divide(1.0, np.sqrt(n2), out=inv, where=n2 > 1e-20)
    out = np.asarray(v * inv[..., None], np.float32)
    if mask is not None:
        out *= mask[..., None]
    return out


def _log_depth(depth: F32, mask: np.ndarray | None, out: F32 | None = None) -> F32:
    """Log depth with background (mask 0, depth not finite or ≤ 0) pushed to ≥ BACKGROUND,
    by arithmetic only (masked writes cost ~8 ms at 1080p; cv2.log is slow on +inf, so clamp
    first; fmin maps NaN to 1e30)."""
    clamped = np.fmin(depth, BACKGROUND)  # NaN, +inf -> 1e30
    np.fmax(clamped, np.float32(1e-30), out=clamped)
    logd = cv2.log(clamped)
    invalid = ~((depth > 0) & (depth < np.inf))
    if mask is not None:
        invalid |= ~(mask > 0)
    if out is None:
        return np.asarray(cv2.scaleAdd(invalid.astype(np.float32), float(BACKGROUND), logd))
    cv2.scaleAdd(invalid.astype(np.float32), float(BACKGROUND), logd, out)
    return out


#: Pixels upsampled by joint bilateral weights (rows, columns), their samples and weights.
_SparseTaps = tuple[NDArray[np.int64], NDArray[np.int64], NDArray[np.int64], F32]


@dataclass
class DepthPyramid:
    """Log depth and coverage at pyramid levels 0 (input) … K, each level half the previous.

    Attributes
    ----------
    depth_sigma : standard deviation of the range kernel on log depth.
    logd : per level (h_k, w_k) log depth; background is ≥ :data:`BACKGROUND` at level 0 and 0
        at coarser levels.
    mask : per level (h_k, w_k) float32 coverage, 1 on surfaces, 0 on background.
    keep : per level k < K, (h_k, w_k) float32 weight of each pixel in the 2×2 block sums that
        make level k+1 (1 for covered pixels on the block's front surface, else 0).
    cover : per level k ≥ 1, (h_k, w_k) fraction of the level-(k−1) block that was kept.
    """

    depth_sigma: float
    logd: list[F32] = field(default_factory=list)
    mask: list[F32] = field(default_factory=list)
    keep: list[F32] = field(default_factory=list)
    cover: list[F32] = field(default_factory=list)
    _keep3: dict[int, F32] = field(default_factory=dict, repr=False)
    _masks: dict[int, np.ndarray] = field(default_factory=dict, repr=False)
    _taps: dict[tuple[int, int], _SparseTaps] = field(default_factory=dict, repr=False)

    @classmethod
    def build(
        cls, depth: np.ndarray, mask: np.ndarray | None, levels: int, depth_sigma: float
    ) -> DepthPyramid:
        """Pyramid of ``levels + 1`` levels from planar depth and an optional coverage mask.

        Background: mask 0/False, depth not finite (+inf, NaN) or ≤ 0.
        """
        depth = np.asarray(depth, np.float32)
        if depth.ndim != 2:
            raise ValueError(f"depth must be (H, W), got shape {depth.shape}")
        if mask is not None:
            mask = np.asarray(mask)
            if mask.shape != depth.shape:
                raise ValueError(
                    f"mask must have the depth's shape {depth.shape}, got {mask.shape}"
                )
        pyr = cls(depth_sigma=depth_sigma)
        h, w = depth.shape
        if levels >= 1 and h % 2 == 0 and w % 2 == 0:
            pyr._build_01(depth, mask)  # levels 0 and 1 in one pass of row strips
        else:
            logd = _log_depth(depth, mask)
            pyr.logd.append(logd)
            pyr.mask.append(np.asarray(logd < BACKGROUND, np.float32))
        for _ in range(levels - pyr.levels):
            low, m = pyr._down_geometry(pyr.logd[-1], pyr.mask[-1])
            pyr.logd.append(low)
            pyr.mask.append(m)
        return pyr

    def _build_01(self, depth: F32, mask: np.ndarray | None) -> None:
        """Levels 0 and 1 (even-sized level 0), strip by strip on all cores: the same per-pixel
        and per-block arithmetic as :func:`_log_depth` and :meth:`_down_geometry`, in one
        compiled pass (:func:`_build01_rows`) after the log of the clamped depth (cv2.log is
        slow on +inf), with the level-1 samples that lost pixels to another surface
        (:meth:`_excluded`)."""
        h, w = depth.shape
        depth = np.ascontiguousarray(depth)
        logd0 = np.empty((h, w), np.float32)
        mask0 = np.empty((h, w), np.float32)
        keep0 = np.empty((h, w), np.float32)
        cover0 = np.empty((h // 2, w // 2), np.float32)
        logd1 = np.empty((h // 2, w // 2), np.float32)
        mask1 = np.empty((h // 2, w // 2), np.float32)
        excl1 = np.empty((h // 2, w // 2), np.bool_)
        thr = np.float32(_DOWN_EXCLUDE * self.depth_sigma)
        no_mask = np.zeros((0, w), np.uint8)
        mask8 = None
        if mask is not None and mask.dtype == np.bool_:
            mask8 = np.ascontiguousarray(mask).view(np.uint8)

        def strip(b0: int, b1: int) -> None:  # level-1 rows b0:b1, level-0 rows 2 b0:2 b1
            r0, r1 = 2 * b0, 2 * b1
            d = depth[r0:r1]
            far = logd0[r0:r1]
            clamped = cv2.min(d, float(BACKGROUND))  # type: ignore[call-overload]
            cv2.max(clamped, 1e-30, clamped)  # type: ignore[call-overload]
            cv2.log(clamped, far)
            if mask is None:
                m8 = no_mask
            elif mask8 is not None:
                m8 = mask8[r0:r1]
            else:
                m8 = np.asarray(mask[r0:r1] > 0).view(np.uint8)
            _build01_rows(
                d, m8, thr, far, mask0[r0:r1], keep0[r0:r1],
                cover0[b0:b1], logd1[b0:b1], mask1[b0:b1], excl1[b0:b1],
            )  # fmt: skip

        run_strips(h // 2, strip, rows=max(1, strip_rows(w) // 2))
        self.logd += [logd0, logd1]
        self.mask += [mask0, mask1]
        self.keep.append(keep0)
        self.cover.append(cover0)
        self._masks[1001] = excl1

    def _down_geometry(self, logd: F32, m: F32) -> tuple[F32, F32]:
        """Level k + 1 from level k = ``self.levels`` (log depth ``logd``, coverage ``m``):
        the front-surface block means of :func:`_down_geometry_rows` (odd sizes padded with
        background), appending level k's ``keep`` and level k + 1's ``cover`` and excluded
        samples (:meth:`_excluded`). Returns level k + 1's log depth and coverage."""
        k = self.levels
        h, w = logd.shape
        ph, pw = h + (h & 1), w + (w & 1)
        excl = self._excluded(k)
        logd = np.ascontiguousarray(logd, np.float32)
        m = np.ascontiguousarray(m, np.float32)
        if (ph, pw) != (h, w):
            pad = ((0, ph - h), (0, pw - w))
            logd, m, excl = np.pad(logd, pad), np.pad(m, pad), np.pad(excl, pad)
        keep = np.empty((ph, pw), np.float32)
        cover = np.empty((ph // 2, pw // 2), np.float32)
        l_low = np.empty((ph // 2, pw // 2), np.float32)
        m_low = np.empty((ph // 2, pw // 2), np.float32)
        excl_low = np.empty((ph // 2, pw // 2), np.bool_)
        thr = np.float32(_DOWN_EXCLUDE * self.depth_sigma)

        def strip(b0: int, b1: int) -> None:
            r0, r1 = 2 * b0, 2 * b1
            _down_geometry_rows(
                logd[r0:r1], m[r0:r1], excl[r0:r1], thr, keep[r0:r1],
                cover[b0:b1], l_low[b0:b1], m_low[b0:b1], excl_low[b0:b1],
            )  # fmt: skip

        run_strips(ph // 2, strip, rows=max(1, strip_rows(pw) // 2))
        self.keep.append(keep if (ph, pw) == (h, w) else np.ascontiguousarray(keep[:h, :w]))
        self.cover.append(cover)
        self._masks[1000 + k + 1] = excl_low
        return l_low, m_low

    def _weighted(self, v: F32, lvl: int) -> F32:
        keep = self.keep[lvl]
        if v.ndim == 3 and v.shape[2] == 3:
            k3 = self._keep3.get(lvl)
            if k3 is None:
                k3 = self._keep3[lvl] = np.asarray(cv2.merge([keep, keep, keep]), np.float32)
            return np.asarray(cv2.multiply(v, k3), np.float32)
        return np.asarray(v * (keep[..., None] if v.ndim == 3 else keep), np.float32)

    def down(self, values: np.ndarray, k: int, k_to: int, unit: bool = True) -> F32:
        """Front-surface block averages of ``values`` (h_k, w_k[, C]) from level k to k_to.

        Each level-``k_to`` value averages the covered level-k pixels of its block that are on
        the block's front surface (every full-resolution pixel counts once). ``unit``: the values
        are a unit-vector field (C = 3), renormalised instead of divided by the weights.
        """
        v = np.asarray(values, np.float32)
        if k_to <= k:
            return v
        is_unit = unit and v.ndim == 3 and v.shape[2] == 3
        wsum: F32 | None = None
        for lvl in range(k, k_to):
            h, w = self.shape(lvl)
            ph, pw = h + (h & 1), w + (w & 1)
            if is_unit and (ph, pw) == (h, w) and v.flags.c_contiguous:
                v = self._down_unit(v, lvl)
                continue
            vw = self._weighted(v, lvl)
            wk = self.keep[lvl] if wsum is None else self.keep[lvl] * wsum
            if (ph, pw) != (h, w):
                pad = ((0, ph - h), (0, pw - w))
                vw = np.pad(vw, pad + (((0, 0),) if vw.ndim == 3 else ()))
                wk = np.pad(wk, pad)
            v = np.asarray(cv2.resize(vw, (pw // 2, ph // 2), interpolation=cv2.INTER_AREA))
            if not is_unit:
                wsum = np.asarray(cv2.resize(wk, (pw // 2, ph // 2), interpolation=cv2.INTER_AREA))
        if is_unit:
            return normalize_field(v, self.mask[k_to])
        assert wsum is not None
        inv = np.zeros_like(wsum)
        np.divide(1.0, wsum, out=inv, where=wsum > 0)
        return np.asarray(v * (inv[..., None] if v.ndim == 3 else inv), np.float32)

    def _down_unit(self, v: F32, lvl: int) -> F32:
        """Block sums / 4 of a unit-vector field (even-sized level, C-contiguous) weighted by
        ``keep``, strip-parallel (:func:`_down_unit_rows`); blocks without kept pixels are 0."""
        h, w = self.shape(lvl)
        out = np.empty((h // 2, w // 2, 3), np.float32)
        keep = self.keep[lvl]

        def strip(b0: int, b1: int) -> None:
            _down_unit_rows(v[2 * b0 : 2 * b1], keep[2 * b0 : 2 * b1], out[b0:b1])

        run_strips(h // 2, strip, rows=max(1, strip_rows(w) // 2))
        return out

    @property
    def levels(self) -> int:
        return len(self.logd) - 1

    def shape(self, k: int) -> tuple[int, int]:
        return (int(self.logd[k].shape[0]), int(self.logd[k].shape[1]))

    def up(self, values: np.ndarray, k: int, k_to: int = 0) -> F32:
        """Edge-aware upsampling of unit-vector fields (h_k, w_k, 3n), 0 on background, from
        level k to level ``k_to``: bilinear, except near depth jumps and where a block lost
        pixels to another surface, where the joint bilateral weights of
        :func:`~ops.pyramid._jb.jb_weights` apply (Kopf et al. 2007; :meth:`up_sparse`); then
        renormalised, background 0. Strip-parallel."""
        vals = np.asarray(values, np.float32)
        if k == k_to:
            return vals
        planes_k = [np.ascontiguousarray(vals[..., c]) for c in range(vals.shape[2])]
        sparse = self.up_sparse(planes_k, k, k_to)
        h_to, w_to = self.shape(k_to)
        out = np.empty((h_to, w_to, len(planes_k)), np.float32)
        m_to = self.mask[k_to]

        def strip(r0: int, r1: int) -> None:
            bufs: dict[str, F32] = {}

            def buf(name: str, shape: tuple[int, ...]) -> F32:
                got = bufs[name] = np.empty(shape, np.float32)
                return got

            planes = self.up_rows(planes_k, k, (r0, r1), buf, sparse, k_to)
            mrows = m_to[r0:r1]
            for c0 in range(0, len(planes) - 2, 3):
                x, y, z = planes[c0 : c0 + 3]
                n2 = x * x + y * y + z * z
                scale = np.zeros_like(n2)
                np.divide(mrows, np.sqrt(n2), out=scale, where=n2 > 1e-20)
                for plane in (x, y, z):
                    plane *= scale
            cv2.merge(planes, out[r0:r1])

        run_strips(h_to, strip, STRIP_ROWS)
        return out

    def _jumps(self, k: int) -> NDArray[np.bool_]:
        """(h_k, w_k): the samples of level k next to a depth jump (cached).

        A sample is next to a depth jump when the second difference of log depth along x or y,
        taken where both neighbours are covered, exceeds 2 ``depth_sigma`` (a slope does not
        produce one), or when the step to a covered 4-neighbour exceeds 3 ``depth_sigma``
        (steeper than most slopes; catches jumps where the other side is background, and
        coarse levels where an object is one or two samples wide). Background samples are not
        jumps: unit-vector fields are 0 there, so bilinear interpolation followed by
        renormalisation averages the covered samples only.
        """
        key = 3000 + k
        got = self._masks.get(key)
        if got is not None:
            return got
        logd, m = self.logd[k], self.mask[k] > 0
        jump = np.empty(m.shape, np.bool_)
        tau = np.float32(2.0 * self.depth_sigma)
        step = np.float32(_STEP * self.depth_sigma)  # (steeper than a steep slope)
        run_strips(
            m.shape[0],
            lambda r0, r1: _jump_rows(logd, m, tau, step, r0, r1, jump),
            strip_rows(m.shape[1]),
        )
        self._masks[key] = jump
        return jump

    def _excluded(self, k: int) -> NDArray[np.bool_]:
        """(h_k, w_k): samples of level k whose blocks lost a covered level-0 pixel to the
        front-surface selection of some level below (a surface not represented there); made
        with each level by :meth:`_down_geometry` (cached), else from the level below."""
        key = 1000 + k
        got = self._masks.get(key)
        if got is not None:
            return got
        if k == 0:
            out = np.zeros(self.shape(0), np.bool_)
        else:
            below = self._excluded(k - 1).astype(np.float32)
            below += self.mask[k - 1] - self.keep[k - 1]  # covered but not kept
            h, w = below.shape
            ph, pw = h + (h & 1), w + (w & 1)
            if (ph, pw) != (h, w):
                below = np.pad(below, ((0, ph - h), (0, pw - w)))
            out = cv2.resize(below, (pw // 2, ph // 2), interpolation=cv2.INTER_AREA) > 0
        self._masks[key] = out
        return out

    def _dirty(self, k: int) -> NDArray[np.uint8]:
        """(h_k, w_k) uint8: 1 where a pixel whose parent is this sample may have a bilinear
        footprint that is not all on its own surface: within one sample of a depth jump
        (:meth:`_jumps`) or of a sample that lost pixels to another surface."""
        key = 2000 + k
        got = self._masks.get(key)
        if got is not None:
            return got
        unsafe = self._jumps(k) | self._excluded(k)
        out = np.asarray(cv2.dilate(unsafe.astype(np.uint8), np.ones((3, 3), np.uint8)), np.uint8)
        self._masks[key] = out
        return out

    def up_sparse(
        self, planes_k: Sequence[np.ndarray], k: int, k_to: int = 0
    ) -> tuple[NDArray[np.int64], NDArray[np.int64], F32]:
        """The joint bilateral part of :meth:`up_rows` for a whole level: the level-``k_to``
        pixels whose parent sample is within one sample of a depth jump or of a block that lost
        pixels to another surface (:meth:`_dirty`, a sparse set), and their values from the
        level-k ``planes_k`` (unit-vector fields, 3 planes each) by the weights of
        :func:`~ops.pyramid._jb.jb_weights` (bilinear where the footprint is on the pixel's own
        surface), each vector renormalised. Returns (ys, xs, values (N, C)), sorted by row."""
        n_ch = len(planes_k)
        if n_ch % 3:
            raise ValueError(f"up_sparse takes unit-vector fields, 3 planes each; got {n_ch}")
        ys, xs, idx, w = self._sparse_taps(k, k_to)
        acc = np.empty((ys.size, n_ch), np.float32)
        flat = [np.ascontiguousarray(plane, np.float32).reshape(-1) for plane in planes_k]

        def points(n0: int, n1: int) -> None:
            for c0 in range(0, n_ch, 3):
                x, y, z = flat[c0 : c0 + 3]
                _gather_unit(idx, w, x, y, z, acc, c0, n0, n1)

        run_strips(ys.size, points, _GATHER_POINTS)
        return ys, xs, acc

    def _sparse_taps(self, k: int, k_to: int) -> _SparseTaps:
        """The pixels of :meth:`up_sparse` from level k to level ``k_to`` (rows, columns, sorted
        by row) and their samples and weights (:func:`~ops.pyramid._jb.jb_weights`, made by
        :func:`~ops.pyramid._jb.jb_weights_fast`): the geometry's alone, so kept for every later
        upsampling between the two levels (each light of Light Alignment upsamples the same
        levels)."""
        got = self._taps.get((k, k_to))
        if got is not None:
            return got
        f = 1 << (k - k_to)
        dirty = self._dirty(k)
        most = min(int(np.count_nonzero(dirty)) * f * f, math.prod(self.shape(k_to)))
        ys, xs = np.empty(most, np.int64), np.empty(most, np.int64)
        logd = np.empty(most, np.float32)
        n = _children(dirty, self.mask[k_to], self.logd[k_to], f, ys, xs, logd)
        ys, xs, logd = ys[:n].copy(), xs[:n].copy(), logd[:n]  # (ys, xs are kept: their size)
        if n:
            idx, w = jb_weights_fast(self.logd[k], self.mask[k], self.depth_sigma, f, ys, xs, logd)
            got = (ys, xs, idx, w)  # (jb_weights_fast: contiguous float32)
        else:
            got = (ys, xs, np.zeros((9, 0), np.int64), np.zeros((9, 0), np.float32))
        self._taps[(k, k_to)] = got
        return got

    def up_rows(
        self,
        planes_k: Sequence[np.ndarray],
        k: int,
        rows: tuple[int, int],
        buf: Callable[[str, tuple[int, ...]], F32],
        sparse: tuple[np.ndarray, np.ndarray, np.ndarray],
        k_to: int = 0,
        cols: tuple[int, int] | None = None,
    ) -> list[F32]:
        """Rows ``rows`` of level-k unit-vector fields, given as (h_k, w_k) planes (0 on
        background), upsampled to level ``k_to`` edge-aware, as planes in scratch buffers
        ``buf(name, shape)`` (for strip-parallel callers): bilinear, then the pixels of
        ``sparse`` (:meth:`up_sparse`) overwritten. The bilinear results are not renormalised
        (bilinear shortens unit vectors slightly, and to 0 … 1 next to background): callers
        renormalise. ``cols``: only these columns. Returns one (r1 − r0, x1 − x0) plane per
        channel (views into the buffers); :meth:`up_rows_wide` gives the uncropped rows.
        """
        x0, x1 = (0, self.shape(k_to)[1]) if cols is None else cols
        planes, c = self.up_rows_wide(planes_k, k, rows, buf, sparse, k_to, (x0, x1))
        return [plane[:, c : c + x1 - x0] for plane in planes]

    def up_rows_wide(
        self,
        planes_k: Sequence[np.ndarray],
        k: int,
        rows: tuple[int, int],
        buf: Callable[[str, tuple[int, ...]], F32],
        sparse: tuple[np.ndarray, np.ndarray, np.ndarray],
        k_to: int = 0,
        cols: tuple[int, int] | None = None,
    ) -> tuple[list[F32], int]:
        """:meth:`up_rows` with the columns left uncropped: returns C-contiguous planes of
        rows ``rows`` that hold columns ``cols`` from column offset ``c`` on, and ``c``
        (column x0 + j of the window is column c + j of each plane)."""
        r0, r1 = rows
        x0, x1 = (0, self.shape(k_to)[1]) if cols is None else cols
        f = 1 << (k - k_to)
        h_k, w_k = self.shape(k)
        s0 = max(0, math.floor((r0 + 0.5) / f - 0.5))
        s1 = min(h_k, math.floor((r1 - 0.5) / f - 0.5) + 2)
        t0 = max(0, math.floor((x0 + 0.5) / f - 0.5))
        t1 = min(w_k, math.floor((x1 - 0.5) / f - 0.5) + 2)
        size = ((t1 - t0) * f, (s1 - s0) * f)
        a, b = r0 - s0 * f, r1 - s0 * f
        c = x0 - t0 * f
        n_ch, n = len(planes_k), s1 - s0
        planes: list[F32]
        stack: F32 | None = None
        if n_ch > 1 and s0 > 0 and s1 < h_k:
            # the blocks of all planes one above the other, in one resize (a resize call costs
            # ~10 µs more than its pixels): the rows used never reach a block's edge (away from
            # the image's top and bottom, where the resize clamps), so no row mixes two planes
            src = buf(f"upsrc:{k}", (n_ch * n, t1 - t0))
            for ch, plane in enumerate(planes_k):
                src[ch * n : (ch + 1) * n] = plane[s0:s1, t0:t1]
            dst = buf(f"up:{k}", (n_ch * size[1], size[0]))
            cv2.resize(src, (size[0], n_ch * size[1]), dst, interpolation=cv2.INTER_LINEAR)
            stack = dst.reshape(n_ch, size[1], size[0])[:, a:b]
            planes = list(stack)
        else:
            planes = []
            for ch, plane in enumerate(planes_k):
                dst = buf(f"up:{k}:{ch}", (size[1], size[0]))
                cv2.resize(plane[s0:s1, t0:t1], size, dst, interpolation=cv2.INTER_LINEAR)
                planes.append(dst[a:b])
        ys, xs, vals = sparse
        i0, i1 = (int(i) for i in np.searchsorted(ys, [r0, r1]))
        if i1 > i0 and stack is not None:
            put_points(stack, ys, xs, vals, i0, i1, (r0, x0, c), x1 - x0)
        elif i1 > i0:
            yy, xx, vv = ys[i0:i1] - r0, xs[i0:i1] - x0, vals[i0:i1]
            inside = (xx >= 0) & (xx < x1 - x0)
            yy, xx, vv = yy[inside], xx[inside] + c, vv[inside]
            for ch, plane in enumerate(planes):
                plane[yy, xx] = vv[:, ch]
        return planes, c
