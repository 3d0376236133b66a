"""A file's channels as presets see them, and their pixels as float32 arrays on one grid.

Channel names. Multi-part files (Karma/Houdini) often put the layer in the part name and keep
bare channel names; they are seen as ``<part name>.<channel>`` (the first part's channels also
by their bare names). A layer ``L`` of three components is found as ``L.R/G/B``, ``L.X/Y/Z``,
``L.r/g/b``, ``L.x/y/z`` or ``L.red/green/blue``; of one component as ``L`` itself or
``L.Z/X/R/V/Y/A`` (lower case too).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from typing import Any

import cv2
import numpy as np

from gbuffer.errors import FrameError, OptionError
from gbuffer.exr import release_pixels, window
from gbuffer.frame import BUFFERS, Passthrough
from gbuffer.presets.options import ReadOptions

_SUFFIX3 = (
    ("R", "G", "B"),
    ("X", "Y", "Z"),
    ("r", "g", "b"),
    ("x", "y", "z"),
    ("red", "green", "blue"),
)
_SUFFIX1 = ("Z", "X", "R", "V", "Y", "A", "z", "x", "r", "v", "y", "a")


def flat_channels(
    parts: Sequence[tuple[dict[str, Any], dict[str, Any]]],
) -> dict[str, tuple[int, str]]:
    """Channel name as presets see it -> (part index, channel name in that part)."""
    flat: dict[str, tuple[int, str]] = {}
    multi = len(parts) > 1
    for i, (header, channels) in enumerate(parts):
        part_name = header.get("name") if multi else None
        for c in channels:
            if part_name and "." not in c:
                flat.setdefault(f"{part_name}.{c}", (i, c))
    for i, (_header, channels) in enumerate(parts):
        for c in channels:
            flat.setdefault(c, (i, c))
    return flat


def resolve(flat: Mapping[str, Any], layer: str, n: int) -> list[str] | None:
    """Channel names of ``layer`` with ``n`` components, or None."""
    if n == 1:
        if layer and layer in flat:
            return [layer]
        for s in _SUFFIX1:
            name = f"{layer}.{s}" if layer else s
            if name in flat:
                return [name]
        return None
    for suffixes in _SUFFIX3:
        names = [f"{layer}.{s}" if layer else s for s in suffixes]
        if all(name in flat for name in names):
            return names
    return None


def describe(names: Sequence[str]) -> str:
    """``["L.N.X", "L.N.Y", "L.N.Z"]`` -> ``"L.N.X,Y,Z"``."""
    heads = {n.rpartition(".")[0] for n in names}
    if len(names) > 1 and len(heads) == 1 and next(iter(heads)):
        head = next(iter(heads))
        return f"{head}." + ",".join(n.rpartition(".")[2] for n in names)
    return ",".join(names)


def channel_list(flat: Mapping[str, Any], limit: int = 24) -> str:
    names = list(flat)
    more = f", ... ({len(names) - limit} more)" if len(names) > limit else ""
    return ", ".join(names[:limit]) + more


class ChannelReader:
    """Loads channels of a passthrough as float32 arrays on the primary part's grid."""

    def __init__(
        self,
        pt: Passthrough,
        flat: dict[str, tuple[int, str]],
        where: str,
        strict: bool = True,
        release: bool = False,
    ) -> None:
        self.pt = pt
        self.flat = flat
        self.where = where
        self.strict = strict
        #: let go of a channel's decoded pixels after its last use (``uses`` counts them; not
        #: the beauty's, which the holes may need again): for writes that copy the input's parts
        self.release = release
        self.uses: Counter[str] = Counter()
        self.primary = 0
        self.grid = (0, 0, 0, 0)
        #: pixels with NaN/Inf radiance (or, when not strict, data): holes of the frame
        self.holes: np.ndarray | None = None
        #: channel -> its pixels with non-finite values (radiance; data, when not strict)
        self._bad: tuple[dict[str, np.ndarray], dict[str, np.ndarray]] = ({}, {})

    def add_holes(self, name: str, bad: np.ndarray, radiance: bool) -> None:
        """Make ``bad`` pixels holes, and mark them on the channel (a channel two buffers read,
        as a lobe's colour is, counts each pixel once)."""
        self.holes = bad.copy() if self.holes is None else self.holes | bad
        marked = self._bad[0 if radiance else 1]
        before = marked.get(name)
        marked[name] = bad.copy() if before is None else before | bad

    @property
    def hole_channels(self) -> dict[str, int]:
        """Radiance channel -> its pixels with non-finite values."""
        return {name: int(np.count_nonzero(bad)) for name, bad in self._bad[0].items()}

    @property
    def masked_channels(self) -> dict[str, int]:
        """Data channel (read when not strict) -> its pixels with non-finite values."""
        return {name: int(np.count_nonzero(bad)) for name, bad in self._bad[1].items()}

    def set_primary(self, index: int) -> None:
        self.primary = index
        header, channels = self.pt.parts[index]
        self.grid = window(header, "dataWindow", channels)

    @property
    def shape(self) -> tuple[int, int]:
        x0, y0, x1, y1 = self.grid
        return (y1 - y0 + 1, x1 - x0 + 1)

    def _pixels(
        self, name: str, buffer: str
    ) -> tuple[int, dict[str, Any], dict[str, Any], np.ndarray]:
        part, cname = self.flat[name]
        header, channels = self.pt.parts[part]
        ch = channels[cname]
        pixels = getattr(ch, "pixels", ch)
        if getattr(ch, "xSampling", 1) != 1 or getattr(ch, "ySampling", 1) != 1:
            raise FrameError(
                f"{self.where}: channel '{name}' is subsampled; the {buffer} buffer needs a "
                "full-resolution channel"
            )
        if pixels.dtype == np.uint32:
            raise FrameError(
                f"{self.where}: channel '{name}' is UINT; the {buffer} buffer needs a HALF or "
                "FLOAT channel (map another channel with --map)"
            )
        return part, header, channels, pixels

    def plane(self, name: str, buffer: str, fill: float = 0.0) -> np.ndarray:
        """One channel as a new float32 (H, W) array on the grid (``fill`` outside its window)."""
        pixels = self._pixels(name, buffer)[3]
        arr = self._float32(name, buffer, fill)
        return arr.copy() if arr is pixels else arr

    def _float32(self, name: str, buffer: str, fill: float) -> np.ndarray:
        """One channel as float32 (H, W) on the grid: the file's own (read-only) pixels when
        they already are, else a new array (``fill`` outside the channel's window)."""
        part, header, channels, pixels = self._pixels(name, buffer)
        src = self.grid if part == self.primary else window(header, "dataWindow", channels)
        if pixels.dtype == np.float16:  # cv2 converts 16F -> 32F several times faster
            half = cv2.multiply(pixels, 1.0, dtype=cv2.CV_32F)  # type: ignore[call-overload]
            arr = np.asarray(half, np.float32)
        else:
            arr = np.asarray(pixels, dtype=np.float32)
        if src == self.grid:
            return arr
        out = np.full(self.shape, fill, np.float32)
        gx0, gy0, gx1, gy1 = self.grid
        x0, y0 = max(src[0], gx0), max(src[1], gy0)
        x1, y1 = min(src[2], gx1), min(src[3], gy1)
        if x1 >= x0 and y1 >= y0:
            out[y0 - gy0 : y1 - gy0 + 1, x0 - gx0 : x1 - gx0 + 1] = arr[
                y0 - src[1] : y1 - src[1] + 1, x0 - src[0] : x1 - src[0] + 1
            ]
        return out

    def stack(self, names: Sequence[str], buffer: str, fill: float = 0.0) -> np.ndarray:
        """Channels ``names`` as one new float32 (H, W) or (H, W, C) array on the grid (float32
        channels are interleaved straight from the file's pixels, not copied first)."""
        if len(names) == 1:
            arr = self.plane(names[0], buffer, fill)
        else:
            planes = [self._float32(name, buffer, fill) for name in names]
            arr = np.asarray(cv2.merge(planes), np.float32)
            del planes
        if self.release and buffer != "beauty":
            self.uses.subtract(names)
            done = [self.flat[name] for name in names if self.uses[name] <= 0]
            release_pixels(self.pt, done)
        return arr


def find_channels(
    reader: ChannelReader,
    buffer: str,
    layers: Sequence[str],
    prefix: str,
    opts: ReadOptions,
    n: int | None = None,
) -> list[str] | None:
    """Channels of ``buffer``: the user's mapping, else the first layer found."""
    n = n if n is not None else BUFFERS[buffer][0]
    flat = reader.flat
    if buffer in opts.mapping:
        spec = opts.mapping[buffer]
        names = [s.strip() for s in spec.split(",")] if isinstance(spec, str) else list(spec)
        if len(names) == 1 and (n > 1 or names[0] not in flat):
            found = resolve(flat, names[0], n)
            if found is None:
                raise OptionError(
                    f"{reader.where}: --map {buffer}={names[0]}: no layer '{names[0]}' with {n} "
                    f"component(s); channels: {channel_list(flat)}"
                )
            return found
        missing = [c for c in names if c not in flat]
        if missing or len(names) != n:
            raise OptionError(
                f"{reader.where}: --map {buffer}: needs {n} existing channel(s), got {names}; "
                f"channels: {channel_list(flat)}"
            )
        return names
    for layer in layers:
        full = f"{prefix}.{layer}" if prefix and layer else (layer or prefix)
        found = resolve(flat, full, n)
        if found is not None:
            return found
    return None


#: The largest radiance read as one: beyond it a value is a hole as NaN and Inf are (the
#: operators square radiance in float32, where squares of 1.8e19 and more overflow: a firefly of
#: 1e20 made the score and several operators NaN).
RADIANCE_MAX = 1e18


def check_finite(
    reader: ChannelReader,
    names: Sequence[str],
    arr: np.ndarray,
    background: np.ndarray | None,
    radiance: bool = False,
) -> None:
    """NaN/Inf on covered pixels (and, for radiance, values beyond ±:data:`RADIANCE_MAX`): a
    hole for radiance (and, when the reader is not strict, for data), else a FrameError naming
    the channel; the values become 0 either way."""
    if radiance:
        if arr.size == 0 or (arr.max() <= RADIANCE_MAX and arr.min() >= -RADIANCE_MAX):
            return  # (a NaN fails both comparisons)
        bad = ~(np.abs(arr) <= RADIANCE_MAX)
    else:
        bad = ~np.isfinite(arr)
        if not bad.any():
            return
    for k, name in enumerate(names):
        bad_k = bad if arr.ndim == 2 else bad[..., k]
        if background is not None:
            bad_k = bad_k & ~background
        if not bad_k.any():
            continue
        if radiance or not reader.strict:
            reader.add_holes(name, bad_k, radiance)
            continue
        ys, xs = np.nonzero(bad_k)
        raise FrameError(
            f"{reader.where}: channel '{name}' has {len(ys)} NaN/Inf value(s) on covered "
            f"pixels (first at x={xs[0]}, y={ys[0]} of the data window)"
        )
    arr[bad] = 0.0


def sum_into(arrays: Sequence[np.ndarray]) -> np.ndarray:
    """Σ arrays, accumulated into the first (the caller's own new array: no copy)."""
    out = arrays[0]
    for a in arrays[1:]:
        cv2.add(out, a, dst=out)
    return out
