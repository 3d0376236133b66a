"""EXR headers read without the library: magic, version flags, every part's attributes as raw
bytes, data windows and chunk offset tables (:func:`read_layout`); header value helpers."""

from __future__ import annotations

import os
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
import OpenEXR

from gbuffer.atomic import special_kind
from gbuffer.errors import FrameError

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
        kind = special_kind(os.stat(path).st_mode)  # (before opening: a FIFO would block)
        if kind is not None:
            why = "" if kind == "a directory" else "; an EXR is read in several passes"
            raise FrameError(f"{where}: it is {kind}, not a regular file{why}")
        with open(path, "rb") as f:
            size = os.fstat(f.fileno()).st_size
            layout = _read_layout(f, size, where)
            if not any(p.storage.startswith("deep") for p in layout.parts):
                _read_offsets(f, layout, where)
    except OSError as exc:
        raise FrameError(f"{where}: cannot read ({exc.strerror or exc})") from None
    return layout


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
