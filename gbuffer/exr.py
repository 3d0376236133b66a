"""Low-level EXR reading and writing with full passthrough (OpenEXR Python binding).

Reading (:func:`read_parts`) first parses the headers itself, without the library: the magic
number, every part's attributes (as raw bytes), the data windows and the chunk offset tables.
That refuses, before any pixel is decoded, a file that is not an EXR, is truncated, holds deep
data or a channel of an unknown pixel type, or that is over a :class:`Limits` (pixels of a data
window, decoded bytes, channels: :class:`LimitError`; a header claiming 100000 x 100000, or 83
float channels of 2000 x 2000 in a 1 MB ZIP file, allocates nothing). Only then does
``OpenEXR.File(path, separate_channels=True)`` decode the pixels, with what the library prints on
the terminal captured (:func:`gbuffer.capture.captured_output`) and put in the error or the
warnings instead. (``OpenEXR.setMaxImageSize`` exists but is process-global, so it would change
every other read and write in the process; the header scan does the same job locally.)

Writing (:func:`write_parts`) gives back every part, channel (pixel type, x/y sampling,
pLinear) and header attribute:

* a part whose channels were not touched (the same channel objects as read; their arrays are
  made read-only on reading so that they cannot change in place) is copied **chunk for chunk**
  from the source file: bit-identical even under lossy DWA/B44 compression, mip-maps and
  subsampled channels included;
* a changed part is encoded by the binding (its original compression, tiling, line order and
  windows) and its chunks are taken from that encoding;
* header attributes whose value did not change are written from their original bytes (so a
  ``double``, an empty ``stringvector`` or a vendor type the binding cannot write come back
  identical); new or changed values are serialised by the binding.

The container (magic, version flags, headers, offset tables, chunks) is assembled here and
written to a temporary file in the target directory, renamed into place only when complete;
chunks kept from the source are copied from it one at a time (never all held in memory), and a
re-encoded part's chunks are views of the binding's encoding (not copies).

Known limits of the binding, reported as :class:`FrameError`: deep parts are not read; a
*changed* part cannot have subsampled channels; a changed mip-mapped part is written with one
level (a warning says so).
"""

from __future__ import annotations

import dataclasses
import io
import math
import os
import struct
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
import OpenEXR

from gbuffer.atomic import atomic_path
from gbuffer.capture import captured_output
from gbuffer.errors import FrameError
from gbuffer.frame import Passthrough
from gbuffer.limits import HARD_MAX_PIXELS, Limits

MAGIC = b"\x76\x2f\x31\x01"

#: Threads the OpenEXR library compresses and decompresses chunks with (its default is 0: the
#: calling thread only); ``DEPICT_EXR_THREADS`` overrides the machine's core count.
EXR_THREADS = int(os.environ.get("DEPICT_EXR_THREADS") or os.cpu_count() or 1)
OpenEXR.set_global_thread_count(max(0, EXR_THREADS))
_TILED = 0x200
_LONG_NAMES = 0x400
_NON_IMAGE = 0x800
_MULTIPART = 0x1000
_KNOWN_FLAGS = _TILED | _LONG_NAMES | _NON_IMAGE | _MULTIPART

#: Pixel types of the EXR channel list.
PIXEL_TYPES = {0: "UINT", 1: "HALF", 2: "FLOAT"}
_DTYPES = {0: np.dtype(np.uint32), 1: np.dtype(np.float16), 2: np.dtype(np.float32)}

#: Compression names by their value in the file.
COMPRESSION_NAMES = {
    0: "NONE",
    1: "RLE",
    2: "ZIPS",
    3: "ZIP",
    4: "PIZ",
    5: "PXR24",
    6: "B44",
    7: "B44A",
    8: "DWAA",
    9: "DWAB",
    10: "HTJ2K256",
    11: "HTJ2K32",
    12: "LJ2K",
    13: "ZSTD",
}
#: Compressions that lose information (PXR24 rounds 32-bit floats to 24 bits).
LOSSY_COMPRESSIONS = frozenset({5, 6, 7, 8, 9})

STORAGES = ("scanlineimage", "tiledimage", "deepscanline", "deeptile")


_MAX_HEADER_BYTES = 64 << 20
_MAX_ATTRIBUTE_BYTES = 16 << 20

# Attributes that describe how the chunks are encoded: always taken from the encoding.
_CHUNK_ATTRIBUTES = frozenset(
    {"channels", "chunkCount", "compression", "dataWindow", "tiles", "type", "lineOrder"}
)
_REQUIRED = frozenset(
    {
        "channels",
        "compression",
        "dataWindow",
        "displayWindow",
        "lineOrder",
        "pixelAspectRatio",
        "screenWindowCenter",
        "screenWindowWidth",
    }
)
# Header keys given to the binding when a part is re-encoded (they define the chunks).
_ENCODE_KEYS = ("compression", "dataWindow", "displayWindow", "lineOrder", "tiles", "type")


# -- the container, parsed without the library ------------------------------------------------


@dataclass(frozen=True)
class RawAttribute:
    """One header attribute as stored: its type name and value bytes."""

    type: str
    data: bytes


@dataclass
class PartLayout:
    """One part's header, as stored in the file (no pixels)."""

    attributes: dict[str, RawAttribute]
    storage: str
    data_window: tuple[int, int, int, int]
    compression: int
    channels: list[tuple[str, int, int, int, bool]]  # name, pixel type, xs, ys, pLinear
    offsets: list[int] = field(default_factory=list)

    @property
    def name(self) -> str | None:
        raw = self.attributes.get("name")
        return None if raw is None else raw.data.decode("utf-8", "replace")

    @property
    def width(self) -> int:
        return self.data_window[2] - self.data_window[0] + 1

    @property
    def height(self) -> int:
        return self.data_window[3] - self.data_window[1] + 1


@dataclass
class FileLayout:
    """The container of an EXR file: version flags, part headers, chunk offset tables."""

    version: int
    parts: list[PartLayout]
    header_end: int
    size: int

    @property
    def multipart(self) -> bool:
        return bool(self.version & _MULTIPART)


class _Short(Exception):
    """The buffer ended before the header did (read more)."""


class _Bad(Exception):
    """The header bytes are malformed."""


def _cstring(buf: bytes, pos: int, limit: int = 255) -> tuple[str, int]:
    end = buf.find(b"\0", pos, pos + limit + 1)
    if end < 0:
        if len(buf) < pos + limit + 1:
            raise _Short
        raise _Bad(f"a name longer than {limit} bytes at byte {pos}")
    return buf[pos:end].decode("utf-8", "replace"), end + 1


def _parse_attributes(buf: bytes, pos: int) -> tuple[dict[str, RawAttribute], int]:
    attrs: dict[str, RawAttribute] = {}
    while True:
        if pos >= len(buf):
            raise _Short
        if buf[pos] == 0:
            return attrs, pos + 1
        name, pos = _cstring(buf, pos)
        type_name, pos = _cstring(buf, pos)
        if pos + 4 > len(buf):
            raise _Short
        (size,) = struct.unpack_from("<i", buf, pos)
        pos += 4
        if size < 0 or size > _MAX_ATTRIBUTE_BYTES:
            raise _Bad(f"attribute '{name}' claims {size} bytes")
        if pos + size > len(buf):
            raise _Short
        attrs[name] = RawAttribute(type_name, bytes(buf[pos : pos + size]))
        pos += size


def _parse_chlist(data: bytes) -> list[tuple[str, int, int, int, bool]]:
    out = []
    pos = 0
    while pos < len(data) and data[pos] != 0:
        name, pos = _cstring(data, pos)
        if pos + 16 > len(data):
            raise _Bad("the channel list is cut short")
        ptype, plinear, xs, ys = struct.unpack_from("<iB3xii", data, pos)
        pos += 16
        out.append((name, ptype, xs, ys, bool(plinear)))
    return out


def _part_layout(attrs: dict[str, RawAttribute], version: int) -> PartLayout:
    for key, kind in (("channels", "chlist"), ("compression", "compression")):
        if key not in attrs or attrs[key].type != kind:
            raise _Bad(f"the required attribute '{key}' is missing")
    dw = attrs.get("dataWindow")
    if dw is None or dw.type != "box2i" or len(dw.data) != 16:
        raise _Bad("the required attribute 'dataWindow' is missing")
    window = struct.unpack("<4i", dw.data)
    if "type" in attrs:
        storage = attrs["type"].data.decode("utf-8", "replace")
        if storage not in STORAGES:
            raise _Bad(f"unknown part type '{storage}'")
    else:
        storage = "tiledimage" if version & _TILED else "scanlineimage"
    return PartLayout(
        attributes=attrs,
        storage=storage,
        data_window=(window[0], window[1], window[2], window[3]),
        compression=attrs["compression"].data[0] if attrs["compression"].data else 0,
        channels=_parse_chlist(attrs["channels"].data),
    )


def _parse_headers(buf: bytes) -> tuple[int, list[dict[str, RawAttribute]], int]:
    if len(buf) < 8:
        raise _Short
    (version,) = struct.unpack_from("<I", buf, 4)
    if version & 0xFF != 2 or version & ~(_KNOWN_FLAGS | 0xFF):
        raise _Bad(f"unsupported version field 0x{version:x}")
    pos = 8
    parts = []
    if version & _MULTIPART:
        while True:
            if pos >= len(buf):
                raise _Short
            if buf[pos] == 0:
                pos += 1
                break
            attrs, pos = _parse_attributes(buf, pos)
            parts.append(attrs)
    else:
        attrs, pos = _parse_attributes(buf, pos)
        parts.append(attrs)
    if not parts:
        raise _Bad("no parts")
    return version, parts, pos


def _read_layout(f: BinaryIO, size: int, where: str) -> FileLayout:
    """Parse magic, version and headers of an open file (grows the read until it fits)."""
    head = f.read(4)
    if head != MAGIC:
        raise FrameError(f"{where}: not an OpenEXR file (magic number {head.hex(' ') or 'none'})")
    f.seek(0)
    want = 1 << 16
    while True:
        f.seek(0)
        buf = f.read(want)
        try:
            version, raw_parts, end = _parse_headers(buf)
            break
        except _Short:
            if len(buf) < want:
                raise FrameError(f"{where}: truncated file (it ends inside the header)") from None
            if want >= _MAX_HEADER_BYTES:
                raise FrameError(f"{where}: header larger than {_MAX_HEADER_BYTES} bytes") from None
            want *= 4
        except _Bad as exc:
            raise FrameError(f"{where}: corrupt header ({exc})") from None
    try:
        parts = [_part_layout(a, version) for a in raw_parts]
    except _Bad as exc:
        raise FrameError(f"{where}: corrupt header ({exc})") from None
    return FileLayout(version=version, parts=parts, header_end=end, size=size)


def _read_offsets(f: BinaryIO, layout: FileLayout, where: str) -> None:
    """Fill each part's chunk offsets; refuse a truncated or incomplete file."""
    f.seek(layout.header_end)
    if layout.multipart:
        for i, part in enumerate(layout.parts):
            raw = part.attributes.get("chunkCount")
            if raw is None or len(raw.data) != 4:
                raise FrameError(f"{where}: corrupt header (part {i} has no chunkCount)")
            (count,) = struct.unpack("<i", raw.data)
            if count < 0 or layout.header_end + 8 * count > layout.size:
                raise FrameError(f"{where}: truncated file (offset table of part {i} cut off)")
            data = f.read(8 * count)
            part.offsets = list(struct.unpack(f"<{count}Q", data))
    else:
        # Chunks follow the table: read entries until the table reaches the lowest offset.
        offsets: list[int] = []
        lowest = layout.size
        pos = layout.header_end
        while pos + 8 * len(offsets) < lowest:
            block = f.read(8 * 4096)
            if len(block) < 8:
                break
            for (off,) in struct.iter_unpack("<Q", block[: len(block) - len(block) % 8]):
                offsets.append(off)
                lowest = min(lowest, off)
                if pos + 8 * len(offsets) >= lowest:
                    break
        layout.parts[0].offsets = offsets
    table_end = layout.header_end + 8 * sum(len(p.offsets) for p in layout.parts)
    last = (-1, -1)
    for i, part in enumerate(layout.parts):
        if not part.offsets:
            raise FrameError(f"{where}: corrupt file (part {i} has no chunks)")
        for off in part.offsets:
            if off < table_end or off >= layout.size:
                raise FrameError(
                    f"{where}: truncated or incomplete file (a chunk of part {i} starts at "
                    f"byte {off}, the file has {layout.size} bytes)"
                )
            last = max(last, (off, i))
    off, i = last
    end = off + _chunk_size(f, off, layout.parts[i], layout.multipart)
    if end > layout.size:
        raise FrameError(
            f"{where}: truncated file (the last chunk ends at byte {end}, the file has "
            f"{layout.size} bytes)"
        )


def _chunk_size(f: BinaryIO, offset: int, part: PartLayout, multipart: bool) -> int:
    """Bytes of the chunk at ``offset`` (leader included); flat parts only."""
    lead = (4 if multipart else 0) + (16 if part.storage == "tiledimage" else 4)
    f.seek(offset + lead)
    raw = f.read(4)
    if len(raw) < 4:
        return lead + 4
    (packed,) = struct.unpack("<i", raw)
    return lead + 4 + max(packed, 0)


def read_layout(path: str | Path) -> FileLayout:
    """The container of an EXR file (headers as raw attributes, offset tables); no pixels."""
    where = str(path)
    try:
        with open(path, "rb") as f:
            size = os.fstat(f.fileno()).st_size
            layout = _read_layout(f, size, where)
            if not any(p.storage.startswith("deep") for p in layout.parts):
                _read_offsets(f, layout, where)
    except OSError as exc:
        raise FrameError(f"{where}: cannot read ({exc.strerror or exc})") from None
    return layout


# -- the passthrough ----------------------------------------------------------------------------


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
    """

    path: str = ""
    layout: FileLayout | None = None
    snapshot: list[dict[str, Any]] = field(default_factory=list)
    channel_ids: list[dict[str, tuple[int, int]]] = field(default_factory=list)
    source_stat: tuple[int, int] = (0, 0)
    warnings: list[str] = field(default_factory=list)
    preset_reason: str = ""


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
        for name, raw in part.attributes.items():
            if raw.type == "deepImageState":
                raise FrameError(
                    f"{where}: attribute '{name}' of type deepImageState (deep data) cannot be "
                    "read by the OpenEXR binding; flatten the file first"
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


def release_pixels(pt: Passthrough) -> None:
    """Let go of the decoded pixels of every channel of ``pt`` (an :class:`ExrPassthrough` read
    from a file), keeping what writing needs: its parts are still copied chunk for chunk, and a
    channel's ``pixels`` are decoded again if something reads them. For a write that adds
    layers beside the input's parts (the ``part`` and ``sidecar`` layouts), once the frame's
    buffers are made: the file's decoded channels need not stay in memory beside them."""
    if not isinstance(pt, ExrPassthrough) or not pt.path or pt.layout is None:
        return
    source = _Redecode(pt.path)
    for index, (_, channels) in enumerate(pt.parts):
        for name, channel in list(channels.items()):
            if isinstance(channel, ReleasedChannel) or not hasattr(channel, "pixels"):
                continue
            released = ReleasedChannel(name, channel, source)
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


# -- writing ------------------------------------------------------------------------------------


def _attr_bytes(name: str, raw: RawAttribute) -> bytes:
    return (
        name.encode()
        + b"\0"
        + raw.type.encode()
        + b"\0"
        + struct.pack("<i", len(raw.data))
        + raw.data
    )


def _plain(value: Any) -> Any:
    """Numpy scalars -> Python scalars (the binding rejects them); arrays in C order."""
    if isinstance(value, np.generic) and value.ndim == 0:
        return value.item()
    if isinstance(value, np.ndarray):
        return np.ascontiguousarray(value)  # the binding ignores strides
    if isinstance(value, tuple):
        return tuple(_plain(v) for v in value)
    if isinstance(value, list):  # the binding silently drops lists of numpy scalars
        return [_plain(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    return value


def _physical_order(offsets: list[int]) -> list[int]:
    return sorted(range(len(offsets)), key=offsets.__getitem__)


def _extract_chunks(data: io.BytesIO, layout: FileLayout, index: int) -> list[memoryview]:
    """Chunks of part ``index`` in table order, without the multi-part part-number prefix (views
    of ``data``'s buffer, not copies)."""
    part = layout.parts[index]
    skip = 4 if layout.multipart else 0
    view = data.getbuffer()
    chunks = []
    for off in part.offsets:
        n = _chunk_size(data, off, part, layout.multipart)
        chunks.append(view[off + skip : off + n])
    return chunks


@dataclass
class _FileChunks:
    """Chunks of a part left in the source file: (start, size) byte ranges, in table order,
    without the multi-part part-number prefix; copied to the output without being held."""

    path: str
    ranges: list[tuple[int, int]]

    def __len__(self) -> int:
        return len(self.ranges)

    def size(self, k: int) -> int:
        return self.ranges[k][1]


def _source_chunks(pt: ExrPassthrough, index: int) -> _FileChunks | None:
    """Where the original chunks of part ``index`` are, or None when the source file changed."""
    if pt.layout is None or not pt.path:
        return None
    try:
        st = os.stat(pt.path)
        if (st.st_size, st.st_mtime_ns) != pt.source_stat:
            return None
        part = pt.layout.parts[index]
        skip = 4 if pt.layout.multipart else 0
        ranges = []
        with open(pt.path, "rb") as f:
            for off in part.offsets:
                n = _chunk_size(f, off, part, pt.layout.multipart)
                ranges.append((off + skip, n - skip))
        return _FileChunks(pt.path, ranges)
    except OSError:
        return None


def _binding_attributes(values: dict[str, Any], where: str) -> dict[str, RawAttribute]:
    """Serialise header values with the binding (via a 1x1 file) and return the raw bytes."""
    if not values:
        return {}
    header = dict(values)
    header.setdefault("compression", OpenEXR.NO_COMPRESSION)
    buf = io.BytesIO()
    try:
        OpenEXR.File(header, {"Z": np.zeros((1, 1), np.float32)}).write(buf)
    except Exception as exc:
        raise FrameError(f"{where}: cannot write header attributes ({_one_line(exc)})") from exc
    data = buf.getvalue()
    layout = _read_layout(io.BytesIO(data), len(data), where)
    out = {k: v for k, v in layout.parts[0].attributes.items() if k in values}
    lost = sorted(set(values) - set(out))
    if lost:
        raise FrameError(
            f"{where}: header attribute(s) {lost} have values the OpenEXR binding cannot write "
            f"({', '.join(type(values[k]).__name__ for k in lost)})"
        )
    return out


def _encode_part(
    header: dict[str, Any], channels: dict[str, Any], storage: str, where: str, part_no: int
) -> tuple[dict[str, RawAttribute], list[memoryview], list[int], list[str]]:
    """Encode one part with the binding as a standalone file; its attributes and chunks."""
    warnings = []
    hdr = {k: _plain(header[k]) for k in _ENCODE_KEYS if k in header}
    hdr["type"] = getattr(OpenEXR, storage)
    tiles = hdr.get("tiles")
    if storage == "tiledimage" and tiles is not None and tiles.mode != OpenEXR.ONE_LEVEL:
        one = OpenEXR.TileDescription()
        one.xSize, one.ySize = tiles.xSize, tiles.ySize
        one.mode, one.roundingMode = OpenEXR.ONE_LEVEL, tiles.roundingMode
        hdr["tiles"] = one
        warnings.append(
            f"part {part_no}: mip/rip-map levels dropped on write (the OpenEXR binding writes "
            "one level)"
        )
    chans = {}
    for name, ch in channels.items():
        pixels = getattr(ch, "pixels", ch)
        if not isinstance(pixels, np.ndarray) or pixels.ndim != 2:
            raise FrameError(f"{where}: channel '{name}' is not a 2-D array")
        if pixels.dtype not in (np.float16, np.float32, np.uint32):
            raise FrameError(
                f"{where}: channel '{name}' has dtype {pixels.dtype}; EXR channels are "
                "float16, float32 or uint32"
            )
        xs, ys = getattr(ch, "xSampling", 1), getattr(ch, "ySampling", 1)
        if xs != 1 or ys != 1:
            raise FrameError(
                f"{where}: channel '{name}' is subsampled ({xs}x{ys}) in a part that changed; "
                "the OpenEXR binding cannot write subsampled channels"
            )
        chans[name] = OpenEXR.Channel(
            name, np.ascontiguousarray(pixels), 1, 1, bool(getattr(ch, "pLinear", False))
        )
    if not chans:
        raise FrameError(f"{where}: part {part_no} has no channels")
    try:
        data = _encode(hdr, chans)
    except Exception as exc:
        codec = compression_name(hdr)
        if int(hdr.get("compression", 0)) not in LOSSY_COMPRESSIONS:
            raise FrameError(f"{where}: cannot encode part {part_no} ({_one_line(exc)})") from exc
        hdr["compression"] = OpenEXR.ZIP_COMPRESSION  # keep the pixels, lose the size
        try:
            data = _encode(hdr, chans)
        except Exception as again:
            raise FrameError(
                f"{where}: cannot encode part {part_no} ({_one_line(again)})"
            ) from again
        warnings.append(
            f"part {part_no}: the OpenEXR binding cannot write it with {codec} "
            f"({_one_line(exc)}); written with ZIP"
        )
    size = data.seek(0, io.SEEK_END)
    data.seek(0)
    layout = _read_layout(data, size, where)
    _read_offsets(data, layout, where)
    part = layout.parts[0]
    return (
        part.attributes,
        _extract_chunks(data, layout, 0),
        _physical_order(part.offsets),
        warnings,
    )


def _encode(header: dict[str, Any], channels: dict[str, Any]) -> io.BytesIO:
    """One part encoded by the binding as a standalone file (the binding may raise)."""
    buf = io.BytesIO()
    OpenEXR.File(header, dict(channels)).write(buf)
    return buf


def _unchanged_pixels(pt: Passthrough, index: int, header: dict[str, Any]) -> bool:
    if not isinstance(pt, ExrPassthrough) or pt.layout is None or index >= len(pt.channel_ids):
        return False
    ids = pt.channel_ids[index]
    channels = pt.parts[index][1]
    if set(channels) != set(ids):
        return False
    for name, ch in channels.items():
        if isinstance(ch, ReleasedChannel):  # its pixels, if decoded again, are read-only
            if id(ch) != ids[name][0]:
                return False
            continue
        pixels = getattr(ch, "pixels", None)
        if (id(ch), id(pixels)) != ids[name] or pixels is None or pixels.flags.writeable:
            return False
    snap = pt.snapshot[index]
    return all(_same_value(header.get(k), snap.get(k)) for k in _CHUNK_ATTRIBUTES - {"channels"})


def write_parts(passthrough: Passthrough, path: str | Path) -> list[str]:
    """Write every part of ``passthrough`` to ``path`` (temporary file, then renamed).

    Parts, channels (pixel type, sampling, pLinear) and header attributes come back as they
    were read; see the module docstring for how unchanged parts and values are kept
    bit-identical. ``passthrough`` may also be a plain :class:`Passthrough` built in memory
    (headers of Python values, channels as ``OpenEXR.Channel`` or numpy arrays).

    Returns
    -------
    Warnings (e.g. mip-map levels that could not be kept); empty in the usual case.

    Raises
    ------
    FrameError
        Nothing to write, a value the binding cannot serialise, a channel array of the wrong
        type, or an I/O error; one line naming the file.
    """
    where = str(path)
    if not passthrough.parts:
        raise FrameError(f"{where}: nothing to write (no parts)")
    exr_pt = passthrough if isinstance(passthrough, ExrPassthrough) else None
    multipart = len(passthrough.parts) > 1 or (
        exr_pt is not None
        and exr_pt.layout is not None
        and exr_pt.layout.multipart
        and len(passthrough.parts) == len(exr_pt.layout.parts)
    )
    warnings: list[str] = []
    headers: list[dict[str, RawAttribute]] = []
    all_chunks: list[list[memoryview] | _FileChunks] = []
    storages: list[str] = []
    orders: list[list[int]] = []
    for i, (header, channels) in enumerate(passthrough.parts):
        snap = exr_pt.snapshot[i] if exr_pt is not None and i < len(exr_pt.snapshot) else {}
        orig = (
            exr_pt.layout.parts[i].attributes
            if exr_pt is not None and exr_pt.layout is not None and i < len(exr_pt.layout.parts)
            else {}
        )
        storage = header.get("type")
        kind = (
            storage.name
            if storage is not None and hasattr(storage, "name")
            else (
                exr_pt.layout.parts[i].storage
                if exr_pt is not None and exr_pt.layout is not None and orig
                else "scanlineimage"
            )
        )
        if kind.startswith("deep"):
            raise FrameError(f"{where}: part {i} is deep; deep parts cannot be written")
        chunks: list[memoryview] | _FileChunks | None = None
        if _unchanged_pixels(passthrough, i, header):
            assert exr_pt is not None
            chunks = _source_chunks(exr_pt, i)
        if chunks is not None:
            assert exr_pt is not None and exr_pt.layout is not None
            encoded = {k: v for k, v in orig.items() if k in _CHUNK_ATTRIBUTES}
            order = _physical_order(exr_pt.layout.parts[i].offsets)
        else:
            encoded, chunks, order, notes = _encode_part(header, channels, kind, where, i)
            warnings += notes
        # Attribute values: what the chunks need from the encoding, original bytes where the
        # value did not change, else the binding's serialisation of the new value.
        final: dict[str, RawAttribute] = {}
        fresh: dict[str, Any] = {}
        for key, value in header.items():
            if key in ("channels", "chunkCount"):
                continue
            if key in _CHUNK_ATTRIBUTES and key in encoded:
                final[key] = encoded[key]
            elif key in orig and key in snap and _same_value(value, snap[key]):
                final[key] = orig[key]
            else:
                fresh[key] = _plain(value)
        final.update(_binding_attributes(fresh, where))
        for key, raw in encoded.items():
            if key == "channels" or (key in _REQUIRED and key not in final):
                final[key] = raw
            elif key == "tiles" and kind == "tiledimage":
                final[key] = raw
        if multipart:
            name = header.get("name") or f"part{i}"
            final["name"] = RawAttribute("string", str(name).encode())
            final["type"] = RawAttribute("string", kind.encode())
            final["chunkCount"] = RawAttribute("int", struct.pack("<i", len(chunks)))
        else:
            final.pop("chunkCount", None)
            if "type" not in header and "type" not in orig:
                final.pop("type", None)
        rank = {k: n for n, k in enumerate(orig)}
        keys = sorted(final, key=lambda k: (rank.get(k, len(rank)), k))
        headers.append({k: final[k] for k in keys})
        all_chunks.append(chunks)
        orders.append(order)
        storages.append(kind)
    try:
        with atomic_path(path) as tmp:
            with open(tmp, "wb") as f:
                _assemble(f, headers, all_chunks, orders, storages, multipart)
    except OSError as exc:
        raise FrameError(f"{where}: cannot write ({exc.strerror or exc})") from None
    return warnings


def _assemble(
    out: BinaryIO,
    headers: list[dict[str, RawAttribute]],
    chunks: Sequence[Sequence[bytes | memoryview] | _FileChunks],
    orders: list[list[int]],
    storages: list[str],
    multipart: bool,
) -> None:
    """Write magic, version flags, headers, offset tables and chunks of an EXR file to ``out``.

    ``orders[p]`` lists part p's chunk indices in the order they are laid out in the file
    (e.g. decreasing y for ``DECREASING_Y``); the offset table stays in index order. Chunks
    left in a source file (:class:`_FileChunks`) are copied from it one at a time.
    """
    version = 2
    long_names = any(len(k) > 31 or len(r.type) > 31 for h in headers for k, r in h.items()) or any(
        len(name) > 31 for h in headers for name, *_ in _parse_chlist(h["channels"].data)
    )
    if long_names:
        version |= _LONG_NAMES
    if multipart:
        version |= _MULTIPART
    elif storages[0] == "tiledimage":
        version |= _TILED
    head = bytearray(MAGIC + struct.pack("<I", version))
    for h in headers:
        for key, raw in h.items():
            head += _attr_bytes(key, raw)
        head += b"\0"
    if multipart:
        head += b"\0"
    prefix_size = 4 if multipart else 0
    pos = len(head) + 8 * sum(len(c) for c in chunks)
    for part_chunks, order in zip(chunks, orders, strict=True):
        offsets = [0] * len(part_chunks)
        for k in order:
            offsets[k] = pos
            pos += prefix_size + _size(part_chunks, k)
        head += struct.pack(f"<{len(offsets)}Q", *offsets)
    out.write(head)
    for index, (part_chunks, order) in enumerate(zip(chunks, orders, strict=True)):
        prefix = struct.pack("<i", index) if multipart else b""
        if isinstance(part_chunks, _FileChunks):
            with open(part_chunks.path, "rb") as src:
                for k in order:
                    start, size = part_chunks.ranges[k]
                    src.seek(start)
                    out.write(prefix + src.read(size))
        else:
            for k in order:
                out.write(prefix)
                out.write(part_chunks[k])


def _size(chunks: Sequence[bytes | memoryview] | _FileChunks, k: int) -> int:
    return chunks.size(k) if isinstance(chunks, _FileChunks) else len(chunks[k])


def storage_name(header: dict[str, Any]) -> str:
    """'scanlineimage', 'tiledimage', ... of a part header (binding values)."""
    t = header.get("type")
    return (
        str(getattr(t, "name", "scanlineimage"))
        if t is not None
        else ("tiledimage" if "tiles" in header else "scanlineimage")
    )


def compression_name(header: dict[str, Any]) -> str:
    """'ZIP', 'DWAA', ... of a part header (binding values)."""
    c = header.get("compression")
    if c is None:
        return "NONE"
    return COMPRESSION_NAMES.get(int(c), str(c))


def window(
    header: dict[str, Any], key: str, channels: dict[str, Any] | None = None
) -> tuple[int, int, int, int]:
    """(xmin, ymin, xmax, ymax) of a box2i header value (``dataWindow``/``displayWindow``).

    Without the attribute (a part built in memory), the window at the origin of the first of
    ``channels`` (the binding's default), if given.
    """
    if key not in header and channels:
        first = next(iter(channels.values()))
        h, w = np.shape(getattr(first, "pixels", first))[:2]
        return 0, 0, int(w) - 1, int(h) - 1
    lo, hi = header[key]
    return int(lo[0]), int(lo[1]), int(hi[0]), int(hi[1])


def box2i(xmin: int, ymin: int, xmax: int, ymax: int) -> tuple[np.ndarray, np.ndarray]:
    """A box2i header value for the binding."""
    return (np.array([xmin, ymin], np.int32), np.array([xmax, ymax], np.int32))


__all__ = [
    "COMPRESSION_NAMES",
    "HARD_MAX_PIXELS",
    "LOSSY_COMPRESSIONS",
    "MAGIC",
    "PIXEL_TYPES",
    "ExrPassthrough",
    "FileLayout",
    "Limits",
    "PartLayout",
    "RawAttribute",
    "ReleasedChannel",
    "box2i",
    "compression_name",
    "read_layout",
    "read_parts",
    "release_pixels",
    "storage_name",
    "window",
    "write_parts",
]
