"""Reading parts through the binding after the header scan (:func:`read_parts`), the
passthrough that remembers what was read, and releasing decoded pixels."""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import OpenEXR

from gbuffer.capture import captured_output
from gbuffer.errors import FrameError
from gbuffer.exr.layout import PIXEL_TYPES, FileLayout, PartLayout, read_layout
from gbuffer.frame import Passthrough
from gbuffer.limits import Limits


@dataclass
class ExrPassthrough(Passthrough):
    """A :class:`Passthrough` read from a file, with what a lossless write-back needs.

    Attributes (beyond ``parts`` and ``primary``)
    ----------
    path : the file read.
    layout : its container (raw header attributes, chunk offsets).
    snapshot : per part, attribute name -> the value as decoded (to tell unchanged values).
    channel_ids : per part, channel name -> identity of the channel object and its pixels.
    source_stat : (size, mtime_ns) of the file when read (chunks are copied only if it holds).
    warnings : notes for the user (``describe`` lists them).
    preset_reason : why the preset was chosen (set by ``gbuffer.presets``).
    redecode : where released channels get their pixels back (:func:`release_pixels`).
    """

    path: str = ""
    layout: FileLayout | None = None
    snapshot: list[dict[str, Any]] = field(default_factory=list)
    channel_ids: list[dict[str, tuple[int, int]]] = field(default_factory=list)
    source_stat: tuple[int, int] = (0, 0)
    warnings: list[str] = field(default_factory=list)
    preset_reason: str = ""
    redecode: _Redecode | None = field(default=None, repr=False, compare=False)


def _copy_value(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.copy()
    if isinstance(value, tuple):
        return tuple(_copy_value(v) for v in value)
    if isinstance(value, list):
        return list(value)
    return value


def _same_value(a: Any, b: Any) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return (
            isinstance(a, np.ndarray)
            and isinstance(b, np.ndarray)
            and a.dtype == b.dtype
            and a.shape == b.shape
            and bool(np.array_equal(a, b, equal_nan=a.dtype.kind == "f"))
        )
    if isinstance(a, tuple | list) or isinstance(b, tuple | list):
        return (
            type(a) is type(b)
            and len(a) == len(b)
            and all(_same_value(x, y) for x, y in zip(a, b, strict=True))
        )
    if type(a) is not type(b):
        return False
    if isinstance(a, float) and math.isnan(a) and math.isnan(b):
        return True
    try:
        return bool(a == b)
    except Exception:
        return False


def read_parts(
    path: str | Path, max_pixels: int | None = None, *, limits: Limits | None = None
) -> ExrPassthrough:
    """Read every part of an EXR file, pixels in their original types, for passthrough.

    Parameters
    ----------
    path : the EXR file (single- or multi-part, scanline or tiled, any pixel type and
        compression the OpenEXR library decodes).
    max_pixels : refuse (:class:`LimitError`) any part whose data window holds more pixels,
        before decoding anything (overrides ``limits.max_pixels``).
    limits : pixels, decoded bytes and channels the header may claim
        (:class:`gbuffer.limits.Limits`); default: :meth:`Limits.from_env`.

    Returns
    -------
    ExrPassthrough whose ``parts`` are ``(header, channels)``: ``header`` maps the attributes
    stored in the file (minus the structural ``channels`` and ``chunkCount``) to the binding's
    Python values; ``channels`` maps names to ``OpenEXR.Channel`` (read-only pixel arrays of
    shape (H, W) for full-resolution channels, dtype float16/float32/uint32). What the library
    printed while decoding a file it could decode is in ``warnings``.

    Raises
    ------
    FrameError
        Not an EXR, truncated, corrupt, deep data, or a channel of an unknown pixel type; one
        line naming the problem and the file (with the library's own words when it gave any).
    LimitError
        A header over ``limits`` (or ``max_pixels``).
    """
    where = str(path)
    if max_pixels is not None and (not isinstance(max_pixels, int) or max_pixels < 1):
        raise ValueError(f"max_pixels must be a positive integer or None, got {max_pixels!r}")
    limits = limits or Limits.from_env()
    if max_pixels is not None:
        limits = dataclasses.replace(limits, max_pixels=max_pixels)
    try:
        st = os.stat(path)
    except OSError as exc:
        raise FrameError(f"{where}: cannot read ({exc.strerror or exc})") from None
    layout = read_layout(path)
    _check_layout(layout, where)
    limits.check(layout, where)
    out = ExrPassthrough(path=where, layout=layout, source_stat=(st.st_size, st.st_mtime_ns))
    with captured_output() as printed:
        try:
            _decode(out, where)
        except FrameError as exc:
            error: FrameError | None = exc
        else:
            error = None
    if error is not None:
        said = f" ({_library_words(printed, where)})" if printed else ""
        raise FrameError(f"{error}{said}") from error.__cause__
    out.warnings += [f"OpenEXR: {line}" for line in printed[:3]]
    return out


def _check_layout(layout: FileLayout, where: str) -> None:
    """FrameError for what the binding cannot read: empty windows, deep data, bad types."""
    for i, part in enumerate(layout.parts):
        if part.width < 1 or part.height < 1:
            raise FrameError(f"{where}: part {i} has an empty data window {part.data_window}")
        if part.storage.startswith("deep"):
            raise FrameError(
                f"{where}: part {i} holds deep data ({part.storage}); Depict reads "
                "flat images only (flatten it first)"
            )
        for name, ptype, xs, ys, _ in part.channels:
            if ptype not in PIXEL_TYPES:
                raise FrameError(
                    f"{where}: channel '{name}' has pixel type {ptype}, not UINT, HALF or FLOAT"
                )
            if xs < 1 or ys < 1:
                raise FrameError(f"{where}: channel '{name}' has sampling {xs}x{ys}")
            _check_sampling(part, name, xs, ys, where)
        for name, raw in part.attributes.items():
            if raw.type == "deepImageState":
                raise FrameError(
                    f"{where}: attribute '{name}' of type deepImageState (deep data) cannot be "
                    "read by the OpenEXR binding; flatten the file first"
                )


def _check_sampling(part: PartLayout, name: str, xs: int, ys: int, where: str) -> None:
    """FrameError for a subsampled channel OpenEXR refuses (the binding says only that it cannot
    open the file): its data window's origin and size are multiples of the sampling, and a
    tiled part has none."""
    x0, y0 = part.data_window[:2]
    for axis, step, origin, size in (("x", xs, x0, part.width), ("y", ys, y0, part.height)):
        if step != 1 and part.storage.startswith("tiled"):
            raise FrameError(
                f"{where}: channel '{name}' is subsampled ({xs}x{ys}) in a tiled part, which "
                "OpenEXR does not allow"
            )
        if origin % step or size % step:
            raise FrameError(
                f"{where}: channel '{name}' has {axis} sampling {step}, which the data window's "
                f"{axis} origin {origin} and size {size} are not multiples of (OpenEXR refuses it)"
            )


def _decode(out: ExrPassthrough, where: str) -> None:
    """Decode every part with the binding into ``out`` (pixels made read-only)."""
    assert out.layout is not None
    layout = out.layout
    try:
        parts = list(OpenEXR.File(where, separate_channels=True).parts)
        if len(parts) != len(layout.parts):
            raise FrameError(
                f"{where}: corrupt pixel data (the OpenEXR library could not decode part "
                f"{len(parts)} of {len(layout.parts)})"
            )
        for i, (part, lay) in enumerate(zip(parts, layout.parts, strict=True)):
            decoded = dict(part.header)
            header = {
                k: v
                for k, v in decoded.items()
                if k in lay.attributes and k not in ("channels", "chunkCount")
            }
            channels = dict(part.channels)
            for name, _ptype, xs, ys, _ in lay.channels:
                ch = channels.get(name)
                if ch is None:
                    raise FrameError(f"{where}: channel '{name}' of part {i} was not decoded")
                pixels = ch.pixels
                want = (math.ceil(lay.height / ys), math.ceil(lay.width / xs))
                if not isinstance(pixels, np.ndarray) or pixels.ndim != 2:
                    raise FrameError(f"{where}: channel '{name}' decoded to no 2-D array")
                if xs == ys == 1 and pixels.shape != want:
                    raise FrameError(
                        f"{where}: channel '{name}' decoded to {pixels.shape}, expected {want}"
                    )
                pixels.flags.writeable = False
            out.parts.append((header, channels))
            out.snapshot.append({k: _copy_value(v) for k, v in header.items()})
            out.channel_ids.append({n: (id(c), id(c.pixels)) for n, c in channels.items()})
    except FrameError:
        raise
    except Exception as exc:  # the binding raises RuntimeError/ValueError with C++ messages
        raise FrameError(f"{where}: cannot decode ({_one_line(exc)})") from exc


class ReleasedChannel:
    """A channel of an :class:`ExrPassthrough` whose decoded pixels were let go
    (:func:`release_pixels`): its name, pixel type and sampling stay; ``pixels`` decodes the
    file again (once for all its channels) the first time anything asks for them."""

    def __init__(self, name: str, channel: Any, source: _Redecode) -> None:
        self.name = name
        self.xSampling = getattr(channel, "xSampling", 1)
        self.ySampling = getattr(channel, "ySampling", 1)
        self.pLinear = getattr(channel, "pLinear", False)
        self.dtype = channel.pixels.dtype
        self._source = source
        self._part = -1

    @property
    def pixels(self) -> np.ndarray:
        return self._source.pixels(self._part, self.name)


@dataclass
class _Redecode:
    """The file of a passthrough decoded again, on first use, for its released channels."""

    path: str
    parts: list[dict[str, Any]] | None = None

    def pixels(self, part: int, name: str) -> np.ndarray:
        if self.parts is None:
            with captured_output():
                decoded = OpenEXR.File(self.path, separate_channels=True).parts
                self.parts = [dict(p.channels) for p in decoded]
        pixels: np.ndarray = self.parts[part][name].pixels
        pixels.flags.writeable = False
        return pixels


def release_pixels(pt: Passthrough, only: Iterable[tuple[int, str]] | None = None) -> None:
    """Let go of the decoded pixels of every channel of ``pt`` (an :class:`ExrPassthrough` read
    from a file), or of the ``(part, channel name)`` pairs in ``only``, keeping what writing
    needs: its parts are still copied chunk for chunk, and a channel's ``pixels`` are decoded
    again if something reads them. For a write that adds layers beside the input's parts (the
    ``part`` and ``sidecar`` layouts): the file's decoded channels need not stay in memory beside
    the frame's buffers (:func:`gbuffer.io.read` with ``release=True`` lets each go as soon as
    its buffer is made)."""
    if not isinstance(pt, ExrPassthrough) or not pt.path or pt.layout is None:
        return
    if pt.redecode is None:
        pt.redecode = _Redecode(pt.path)
    pairs = (
        [(i, name) for i, (_, channels) in enumerate(pt.parts) for name in channels]
        if only is None
        else list(only)
    )
    for index, name in pairs:
        channels = pt.parts[index][1]
        channel = channels.get(name)
        if isinstance(channel, ReleasedChannel) or not hasattr(channel, "pixels"):
            continue  # gone already, or never decoded (None has no pixels either)
        released = ReleasedChannel(name, channel, pt.redecode)
        released._part = index
        channels[name] = released
        pt.channel_ids[index][name] = (id(released), 0)


def _library_words(printed: list[str], where: str) -> str:
    """The most telling line the OpenEXR library printed: its last error, without the path."""
    errors = [line for line in printed if "ERR" in line or "rror" in line] or printed
    text = errors[-1].replace(f"{where}: ", "")
    for prefix in ("Warning:", "Error:"):
        text = text.removeprefix(prefix).strip()
    return f"OpenEXR: {text}"


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__
