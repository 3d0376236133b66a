"""How :func:`ops.light_alignment.align_components` runs: scratch buffers per thread, row strips on
every core, and one :class:`_Stage` per pyramid level (coarse scales at their own resolution,
the light carried to finer levels by the pyramid's edge-aware upsampling)."""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence
from typing import Any

import cv2
import numpy as np

from ops.filtering import F32, NormalPyramid
from ops.light_alignment._common import SoA
from ops.light_alignment._kernels import (
    _GUIDE_CODE,
    _eq1_rows,
    _guide_rows,
    _store_rows,
    _write_rows,
)
from ops.parallel import run_strips
from ops.pyramid import normalize_field


def _soa(arr: np.ndarray) -> SoA:
    return (
        np.ascontiguousarray(arr[..., 0]),
        np.ascontiguousarray(arr[..., 1]),
        np.ascontiguousarray(arr[..., 2]),
    )


class _Work:
    """Scratch buffers for strips of one shape, reused between calls (one set per thread).

    Temporaries of ~100 KB-1 MB would otherwise be fresh allocations (page faults) at every op.
    Buffers are flat and grow as needed; each call hands out a contiguous view of the current
    strip shape (:meth:`get` sets it), so strips of any width share the same memory.
    """

    _local = threading.local()

    def __init__(self, shape: tuple[int, int]) -> None:
        self._flat: dict[str, np.ndarray] = {}
        self._views: dict[str, F32] = {}
        self.shape = (0, 0)
        self.reshape(shape)

    def reshape(self, shape: tuple[int, int]) -> None:
        if shape == self.shape:
            return
        self.shape = shape
        self._views.clear()

    def __call__(self, name: str) -> F32:
        """A (rows, w) view of buffer ``name`` (C-contiguous)."""
        view = self._views.get(name)
        if view is None:
            n = self.shape[0] * self.shape[1]
            flat = self._flat.get(name)
            if flat is None or flat.size < n:
                flat = self._flat[name] = np.empty(max(n, 1), np.float32)
            view = self._views[name] = flat[:n].reshape(self.shape)
        return view

    def vec(self, name: str) -> SoA:
        return (self(name + ".x"), self(name + ".y"), self(name + ".z"))

    def arr(self, name: str, shape: tuple[int, ...]) -> F32:
        """A contiguous scratch array of any shape."""
        n = math.prod(shape)  # (np.prod of a tuple: ~5 µs, called per strip and source)
        flat = self._flat.get("@" + name)
        if flat is None or flat.size < n:
            flat = self._flat["@" + name] = np.empty(max(n, 1), np.float32)
        return flat[:n].reshape(shape)

    @classmethod
    def get(cls, shape: tuple[int, int]) -> _Work:
        """This thread's workspace, set to strips of ``shape``."""
        work: _Work | None = getattr(cls._local, "work", None)
        if work is None:
            work = cls._local.work = cls(shape)
        work.reshape(shape)
        return work


def _guide_soa(guide: str, n: SoA, view: SoA | None, ior: float, out: SoA, ws: _Work) -> SoA:
    """a_i for a guide (§6) on structure-of-arrays planes: n_i (diffuse), the reflected view
    vector (specular) or the refracted view vector (transmission) — the formulas of
    :func:`ops.shading.reflect` / :func:`ops.shading.refract` (the tests hold them equal), by
    the per-pixel functions :func:`_eq1_rows` uses.

    specular: r = 2 (n·v) n − v;  transmission: t = −η v + (η cos_i − √k) n, η = 1/ior,
    cos_i = n·v, k = 1 − η² (1 − cos_i²), t = 0 where k < 0.
    """
    if guide == "diffuse":
        return n
    assert view is not None
    _guide_rows(n, view, _GUIDE_CODE[guide], np.float32(1.0 / ior), out)
    return out


def _fill(vec: SoA, value: np.ndarray) -> SoA:
    for comp, val in zip(vec, value, strict=True):
        comp.fill(float(val))
    return vec


def _copy_in(vec: SoA, arr: np.ndarray) -> SoA:
    """Interleaved (h, w, 3) rows into structure-of-arrays buffers (``cv2.split`` into
    preallocated planes: ~5x faster than strided NumPy copies)."""
    if arr.dtype != np.float32 or arr.strides[1:] != (12, 4):
        arr = np.ascontiguousarray(arr, np.float32)
    cv2.split(arr, list(vec))  # rows may be strided (a column window)
    return vec


def _rows(v: SoA, r0: int, r1: int) -> SoA:
    """Rows r0:r1 of planes (C-contiguous views: the kernels take a column offset)."""
    return (v[0][r0:r1], v[1][r0:r1], v[2][r0:r1])


Win = tuple[int, int, int, int]  # rows r0:r1, columns x0:x1 (at the stage's level)
State = tuple[int, SoA]  # a component's light aligned so far: (level, planes, 0 on background)
# a strip's input to the kernels: planes, the window's first column in them, renormalise?, and
# the interleaved rows (rows, 3 W) the kernel reads instead of the planes (or None)
Src = tuple[SoA, int, bool, F32 | None]
_NO_PLANES: SoA = (np.zeros((1, 1), np.float32),) * 3
_NO_FLAT: F32 = np.zeros((0, 3), np.float32)


def _flat_rows(arr: np.ndarray, r0: int, r1: int) -> F32 | None:
    """Rows r0:r1 of an (H, W, 3) float32 array as flat (rows, 3 W) rows, or None when it is
    not C-contiguous float32 (then it is split into planes)."""
    if arr.dtype != np.float32 or not arr.flags.c_contiguous:
        return None
    return np.asarray(arr[r0:r1].reshape(r1 - r0, 3 * arr.shape[1]), np.float32)


# Rows per strip, and at least this many pixels per strip (coarse levels are narrow): each call
# then works long enough for the two threads to overlap rather than wait on each other.
_ROWS = 64
_STRIP_PIXELS = 1 << 15


def _strip_rows(width: int) -> int:
    return max(_ROWS, -(-_STRIP_PIXELS // max(1, width)))


class _LightIn:
    """One light of an alignment: its direction (constant or per pixel), the original light at
    coarse levels, and the outputs its components are written in."""

    def __init__(
        self, shape: tuple[int, int], comps: dict[str, list[float]], const: F32 | None,
        lfield: F32 | None,
    ) -> None:  # fmt: skip
        self.const = const
        self.lfield = lfield
        self.rows: F32 | None = None
        if const is not None:  # a strip of the constant light (level-0 rows are copied from it)
            self.rows = np.empty((min(shape[0], _strip_rows(shape[1])), shape[1], 3), np.float32)
            self.rows[:] = np.tile(const, (shape[1], 1))
        self.outs = {g: np.empty((*shape, 3), np.float32) for g in comps}
        self._planes: dict[int, SoA] = {}

    def original(self, r0: int, r1: int) -> F32:
        """Rows r0:r1 of the light as given, (r1 − r0, W, 3): of its field, or of the constant's
        rows (a (3,) broadcast over (h, w, 3) is ~10x slower to copy from)."""
        if self.lfield is not None:
            return self.lfield[r0:r1]
        assert self.rows is not None
        return self.rows[: r1 - r0]

    def planes(self, k: int, pyr: NormalPyramid) -> SoA:
        """The original (per-pixel) light at level k > 0, 0 on background (cached)."""
        got = self._planes.get(k)
        if got is None:
            assert self.lfield is not None
            got = self._planes[k] = _soa(pyr.geometry.down(self.lfield, 0, k))
        return got


class _Inputs:
    """What every stage of one alignment shares: the lights (each aligned in the same pass over
    each strip, so that the fields and the view are read and upsampled once for all), the
    guides and their σ_i, the view and the pyramid."""

    def __init__(
        self,
        shape: tuple[int, int],
        comps: dict[str, list[float]],
        egam: float,
        ior: float,
        view: F32 | None,
        view_const: F32 | None,
        lights: list[tuple[F32 | None, F32 | None]],
        pyr: NormalPyramid | None = None,
        fields: list[F32] | None = None,
        mask: F32 | None = None,
        views: dict[int, SoA] | None = None,
    ) -> None:
        self.shape = shape
        self.comps = comps
        self.egam = egam
        self.ior = ior
        self.view = view
        self.view_const = view_const
        self.lights = [_LightIn(shape, comps, const, lfield) for const, lfield in lights]
        self.pyr = pyr
        self.fields = fields
        if pyr is not None:
            self.masks = pyr.geometry.mask
        else:
            assert mask is not None
            self.masks = [mask]
        # the view at coarse levels (view_planes); ``views``: a cache shared by the passes of
        # one view and pyramid
        self.views: dict[int, SoA] = {} if views is None else views

    def needs_view(self, comps: Sequence[str]) -> bool:
        return any(g != "diffuse" for g in comps)

    def view_planes(self, k: int) -> SoA:
        """The view at level k > 0 (the field is smooth: plain area averaging, each level from
        the finest one already made), renormalised, as planes (cached)."""
        got = self.views.get(k)
        if got is None:
            assert self.view is not None and self.pyr is not None
            hk, wk = self.pyr.geometry.shape(k)
            src = max((lv for lv in self.views if lv < k), default=0)
            base = self.view if src == 0 else cv2.merge(list(self.views[src]))
            f = 1 << (k - src)
            if base.shape[:2] == (hk * f, wk * f) and base.flags.c_contiguous:
                # an exact f×f block average: row strips on all cores give the same result
                small = np.empty((hk, wk, 3), np.float32)

                def strip(a: int, b: int) -> None:
                    cv2.resize(
                        base[a * f : b * f], (wk, b - a), small[a:b], interpolation=cv2.INTER_AREA
                    )

                run_strips(hk, strip, rows=max(1, _strip_rows(base.shape[1]) // f))
            else:
                small = np.asarray(
                    cv2.resize(base, (wk, hk), interpolation=cv2.INTER_AREA), np.float32
                )
            got = self.views[k] = _soa(normalize_field(small))
        return got


class _Stage:
    """The scales aligned at one pyramid level k, strip by strip, on the columns that hold
    surfaces: per strip the fields (those of coarser levels upsampled edge-aware and
    renormalised), the view and the incoming light of each component become
    structure-of-arrays buffers, and Eq. 1 is applied from the coarsest scale of the level to
    the finest. At level 0 the result is written to the outputs, whose other pixels (background,
    components left unchanged) keep the original light; at coarser levels it becomes the
    components' new states (0 on background). Every light of the inputs in each strip, one
    after the other, on the fields and view made once for all of them (``states``: one dict
    per light; the lights are aligned in step, so they all have a state or none)."""

    def __init__(
        self, inp: _Inputs, k: int, steps: list[int], states: list[dict[str, State | None]]
    ) -> None:
        self.inp = inp
        self.k = k
        self.steps = sorted(steps, reverse=True)
        self.states = states
        comps = inp.comps
        active = [g for g, sig in comps.items() if any(sig[j] > 0.0 for j in steps)]
        if k == 0:
            active = [g for g in comps if g in active or states[0].get(g) is not None]
        self.active = active
        self.mask = inp.masks[k]
        self.shape = (int(self.mask.shape[0]), int(self.mask.shape[1]))
        self.new: list[dict[str, SoA]] = [{} for _ in inp.lights]
        if k > 0:
            for new in self.new:
                for g in active:
                    new[g] = (
                        np.zeros(self.shape, np.float32),
                        np.zeros(self.shape, np.float32),
                        np.zeros(self.shape, np.float32),
                    )
        # what comes from coarser levels: the fields z = a_{j+1} and the lights aligned so far
        by_level: dict[int, list[tuple[str, SoA]]] = {}
        pyr = inp.pyr
        if pyr is not None:
            for j in steps:
                if pyr.levels[j + 1] > k and any(comps[g][j] > 0.0 for g in active):
                    by_level.setdefault(pyr.levels[j + 1], []).append(
                        (f"n{j + 1}", pyr.planes(j + 1))
                    )
            for li, light_states in enumerate(states):
                for g in active:
                    state = light_states.get(g)
                    if state is not None:
                        by_level.setdefault(state[0], []).append((f"light{li}:{g}", state[1]))
        self.sources: list[tuple[int, list[str], list[F32], tuple[Any, Any, Any]]] = []
        for lvl, items in sorted(by_level.items()):
            planes = [plane for _, vec in items for plane in vec]
            assert pyr is not None
            sparse = pyr.geometry.up_sparse(planes, lvl, k)
            self.sources.append((lvl, [n for n, _ in items], planes, sparse))
        self.with_view = inp.needs_view(active)

    # -- inputs of a strip: (planes, first column of the window in them, renormalise?) ------

    def upsample(self, win: Win, ws: _Work) -> dict[str, Src]:
        """The fields and lights of coarser levels on the window, bilinear + edge-aware, not
        yet renormalised (the kernels do it: bilinear shortens unit vectors, to 0 … 1 next to
        background)."""
        r0, r1, x0, x1 = win
        ups: dict[str, Src] = {}
        if not self.sources:
            return ups
        assert self.inp.pyr is not None
        geo = self.inp.pyr.geometry
        for lvl, names, planes_k, sparse in self.sources:
            planes, c = geo.up_rows_wide(
                planes_k, lvl, (r0, r1), ws.arr, sparse, k_to=self.k, cols=(x0, x1)
            )
            for i, name in enumerate(names):
                ups[name] = ((planes[3 * i], planes[3 * i + 1], planes[3 * i + 2]), c, True, None)
        return ups

    def field(self, i: int, win: Win, ws: _Work, ups: dict[str, Src]) -> Src:
        r0, r1, x0, x1 = win
        inp = self.inp
        if inp.fields is not None:
            return _copy_in(ws.vec(f"n{i}"), inp.fields[i][r0:r1, x0:x1]), 0, False, None
        assert inp.pyr is not None
        lvl = inp.pyr.levels[i]
        if lvl > self.k:
            return ups[f"n{i}"]
        if self.k == 0:
            flat = _flat_rows(inp.pyr.normals[i], r0, r1)
            if flat is not None:
                return _NO_PLANES, x0, False, flat
            return _copy_in(ws.vec(f"n{i}"), inp.pyr.normals[i][r0:r1, x0:x1]), 0, False, None
        return _rows(inp.pyr.planes(i), r0, r1), x0, False, None

    def field_planes(self, i: int, win: Win, ws: _Work) -> Src:
        """Level-0 field n_{i+1} of the pyramid split into planes (for the frame's z)."""
        r0, r1, x0, x1 = win
        assert self.inp.pyr is not None
        return _copy_in(ws.vec(f"n{i}"), self.inp.pyr.normals[i][r0:r1, x0:x1]), 0, False, None

    def view(self, win: Win, ws: _Work) -> Src:
        r0, r1, x0, x1 = win
        inp = self.inp
        if inp.view is None:
            assert inp.view_const is not None
            return _fill(ws.vec("view"), inp.view_const), 0, False, None
        if self.k == 0:
            flat = _flat_rows(inp.view, r0, r1)
            if flat is not None:
                return _NO_PLANES, x0, False, flat
            return _copy_in(ws.vec("view"), inp.view[r0:r1, x0:x1]), 0, False, None
        return _rows(inp.view_planes(self.k), r0, r1), x0, False, None

    def light(self, li: int, g: str, win: Win, ws: _Work, ups: dict[str, Src]) -> Src:
        if self.states[li].get(g) is not None:
            return ups[f"light{li}:{g}"]
        r0, r1, x0, x1 = win
        light = self.inp.lights[li]
        if light.lfield is None:
            assert light.const is not None
            return _fill(ws.vec("light_in"), light.const), 0, False, None
        if self.k == 0:
            return _copy_in(ws.vec("light_in"), light.lfield[r0:r1, x0:x1]), 0, False, None
        assert self.inp.pyr is not None
        return _rows(light.planes(self.k, self.inp.pyr), r0, r1), x0, False, None

    # -- a strip ------------------------------------------------------------------------------

    def keep(self, r0: int, r1: int, skip: Sequence[str] = ()) -> None:
        """Level 0: the original light on rows r0:r1 of every light's outputs, but those of the
        components in ``skip``."""
        for given in self.inp.lights:
            for g, dst in given.outs.items():
                if g not in skip:
                    np.copyto(dst[r0:r1], given.original(r0, r1))

    def strip(self, r0: int, r1: int) -> None:
        k = self.k
        width = self.shape[1]
        cols = np.flatnonzero(self.mask[r0:r1].max(axis=0)) if self.active else np.zeros(0, int)
        if not cols.size:
            if k == 0:  # all background, or no component changes
                self.keep(r0, r1)
            return
        # window width rounded up (a few scratch-buffer shapes serve every strip)
        x0 = int(cols[0])
        step = 128 if k == 0 else 16
        wd = min(width, -(-(int(cols[-1]) + 1 - x0) // step) * step)
        x0 = min(x0, width - wd)
        win = (r0, r1, x0, x0 + wd)
        if k == 0:  # components left unchanged keep the original light (the others: write)
            self.keep(r0, r1, self.active)
        ws = _Work.get((r1 - r0, wd))
        ups = self.upsample(win, ws)
        view = self.view(win, ws) if self.with_view else None
        fields: dict[int, Src] = {}
        for g in self.active:
            for li in range(len(self.inp.lights)):
                self.align(li, g, win, ws, ups, view, fields)

    def align(
        self,
        li: int,
        g: str,
        win: Win,
        ws: _Work,
        ups: dict[str, Src],
        view: Src | None,
        fields: dict[int, Src],
    ) -> None:
        """Light ``li``'s component ``g`` on a strip's window: Eq. 1 from the coarsest scale of
        the level to the finest, then written (``fields``: the strip's fields, made as they are
        first needed and kept for the other lights and components)."""
        inp = self.inp
        eta, egam = np.float32(1.0 / inp.ior), np.float32(inp.egam)
        light = self.light(li, g, win, ws, ups)
        ping = 0
        for j in self.steps:
            sig = inp.comps[g][j]
            if sig <= 0.0:
                continue
            for i in (j, j + 1):
                if i not in fields:
                    fields[i] = self.field(i, win, ws, ups)
            if fields[j + 1][3] is not None:  # z = a_{i+1} is read from planes
                fields[j + 1] = self.field_planes(j + 1, win, ws)
            na, oa, _, fa = fields[j]
            nb, ob, norm_b, _ = fields[j + 1]
            vw, ov, _, fv = view if view is not None else (_NO_PLANES, 0, False, None)
            out = ws.vec(f"light{ping}")
            _eq1_rows(
                na, nb, vw, light[0], out,
                _NO_FLAT if fa is None else fa, _NO_FLAT if fv is None else fv,
                (oa, ob, ov, light[1]), _GUIDE_CODE[g], (eta, np.float32(sig), egam),
                (norm_b, light[2]),
            )  # fmt: skip
            light = (out, 0, False, None)
            ping = 1 - ping
        self.write(li, g, light, win)

    def write(self, li: int, g: str, light: Src, win: Win) -> None:
        r0, r1, x0, x1 = win
        planes, ol, norm_l, _ = light
        if self.k == 0:  # the window's covered pixels; the original light everywhere else
            given = self.inp.lights[li]
            out, orig = given.outs[g][r0:r1], given.original(r0, r1)
            flat = (r1 - r0, 3 * self.shape[1])
            _write_rows(
                planes, ol, norm_l, self.mask[r0:r1], orig.reshape(flat), out.reshape(flat),
                x0, x1 - x0,
            )  # fmt: skip
            return
        new = _rows(self.new[li][g], r0, r1)
        _store_rows(planes, ol, norm_l, self.mask[r0:r1], new, x0, x1 - x0)

    def run(self) -> None:
        rows = _strip_rows(self.shape[1])
        run_strips(self.shape[0], self.strip, rows=rows)
        for light_states, new in zip(self.states, self.new, strict=True):
            for g, planes in new.items():
                light_states[g] = (self.k, planes)


def _align_full(inp: _Inputs) -> list[dict[str, F32]]:
    """Every scale at full resolution, strip by strip."""
    assert inp.fields is not None
    _Stage(inp, 0, list(range(len(inp.fields) - 1)), [{} for _ in inp.lights]).run()
    return [light.outs for light in inp.lights]


def _align_pyramid(inp: _Inputs) -> list[dict[str, F32]]:
    """Each scale at the level of its fine field, coarsest first, and the lights carried to
    finer levels by the pyramid's edge-aware upsampling; level 0 writes the outputs."""
    pyr = inp.pyr
    assert pyr is not None
    active = [j for j in range(pyr.scales - 1) if any(sig[j] > 0.0 for sig in inp.comps.values())]
    states: list[dict[str, State | None]] = [{g: None for g in inp.comps} for _ in inp.lights]
    for k in sorted({pyr.levels[j] for j in active} | {0}, reverse=True):
        if k > 0 and inp.needs_view(list(inp.comps)):
            for lv in sorted({pyr.levels[j] for j in active if 0 < pyr.levels[j] <= k}):
                if inp.view is not None:
                    inp.view_planes(lv)  # finest first: each from the previous
        _Stage(inp, k, [j for j in active if pyr.levels[j] == k], states).run()
    return [light.outs for light in inp.lights]
