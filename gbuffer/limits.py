"""Limits on what an EXR may claim, checked on its header (:func:`gbuffer.exr.read_layout`)
before any pixel is decoded: the pixels of a data window, the decoded size, the channels.

The service sets them from its settings (``DEPICT_MAX_PIXELS``, ``DEPICT_MAX_DECODED_MB``,
``DEPICT_MAX_CHANNELS``); the command line honours the same variables when they are set, and
otherwise refuses only what could not fit in the machine's memory.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Any, Protocol

from gbuffer.errors import LimitError, OptionError

#: Without a configured ``max_pixels``, a data window over this many pixels is still refused.
HARD_MAX_PIXELS = 1 << 30
#: Without a configured limit, at most this many channels (all parts together).
HARD_MAX_CHANNELS = 4096
#: A render's peak memory over its buffers' size (measured: about 640 bytes a pixel at 256²
#: and 1024², against 43 float channels, 172 bytes).
RENDER_WORKING = 4
#: Bytes per sample of the EXR pixel types (UINT, HALF, FLOAT).
_SAMPLE_BYTES = {0: 4, 1: 2, 2: 4}


class Layout(Protocol):
    """What the checks read of :class:`gbuffer.exr.FileLayout`."""

    parts: Any


def _physical_memory() -> int:
    try:
        return int(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError):
        return 1 << 36


def _env_number(name: str, scale: float = 1.0) -> int | None:
    text = os.environ.get(name, "").strip()
    if not text:
        return None
    try:
        value = float(text) * scale
    except ValueError:
        raise OptionError(f"{name}={text!r} is not a number") from None
    if not 0 < value < 2**62:
        raise OptionError(f"{name}={text!r} must be positive")
    return int(value)


@dataclass(frozen=True)
class Limits:
    """What an EXR may claim, checked on its header before any pixel is decoded.

    ``max_pixels``: width x height of any part's data window; ``max_bytes``: the decoded size,
    sum over every channel of every part of (width / x sampling) x (height / y sampling) x bytes
    per sample; ``max_channels``: channels of all parts together. ``None``: the hard ceilings
    (:data:`HARD_MAX_PIXELS`, the machine's physical memory, :data:`HARD_MAX_CHANNELS`).
    """

    max_pixels: int | None = None
    max_bytes: int | None = None
    max_channels: int | None = None

    @classmethod
    def from_env(cls) -> Limits:
        """The limits of ``DEPICT_MAX_PIXELS``, ``DEPICT_MAX_DECODED_MB`` (MiB) and
        ``DEPICT_MAX_CHANNELS`` when set (the service's settings, honoured by the CLI too)."""
        return cls(
            max_pixels=_env_number("DEPICT_MAX_PIXELS"),
            max_bytes=_env_number("DEPICT_MAX_DECODED_MB", 1024 * 1024),
            max_channels=_env_number("DEPICT_MAX_CHANNELS"),
        )

    def check(self, layout: Layout, where: str) -> None:
        """:class:`LimitError` naming the limit (and its setting) a file's header is over."""
        max_pixels = self.max_pixels or HARD_MAX_PIXELS
        max_bytes = self.max_bytes or _physical_memory()
        max_channels = self.max_channels or HARD_MAX_CHANNELS
        for i, part in enumerate(layout.parts):
            pixels = part.width * part.height
            if pixels > max_pixels:
                raise LimitError(
                    f"{where}: part {i} is {part.width}x{part.height} = {pixels} pixels, over "
                    f"the limit of {max_pixels} pixels (DEPICT_MAX_PIXELS); refused before "
                    "decoding"
                )
        channels = sum(len(part.channels) for part in layout.parts)
        if channels > max_channels:
            raise LimitError(
                f"{where}: {channels} channels, over the limit of {max_channels} "
                "(DEPICT_MAX_CHANNELS); refused before decoding"
            )
        decoded = decoded_bytes(layout)
        if decoded > max_bytes:
            raise LimitError(
                f"{where}: {channels} channels of {_sizes(layout)} decode to "
                f"{decoded / 2**20:.0f} MiB, over the limit of {max_bytes / 2**20:.0f} MiB "
                "(DEPICT_MAX_DECODED_MB); refused before decoding"
            )

    def check_render(self, width: int, height: int, where: str) -> None:
        """:class:`LimitError` when a render of ``width`` x ``height`` pixels is over the
        pixels or the decoded size an EXR may claim (its buffers, :data:`gbuffer.frame.
        RENDER_BUFFERS`, as float32), or, without a configured size, when rendering it would
        take more than the machine's memory (about :data:`RENDER_WORKING` times its buffers):
        a render is refused before it starts, as a file is before it is decoded."""
        from gbuffer.frame import BUFFERS, RENDER_BUFFERS

        pixels = width * height
        max_pixels = self.max_pixels or HARD_MAX_PIXELS
        if pixels > max_pixels:
            raise LimitError(
                f"{where}: {width}x{height} = {pixels} pixels, over the limit of {max_pixels} "
                "pixels (DEPICT_MAX_PIXELS); ask for a smaller size"
            )
        channels = sum(BUFFERS[name][0] for name in RENDER_BUFFERS)
        size = pixels * channels * 4
        if self.max_bytes is not None:
            if size > self.max_bytes:
                raise LimitError(
                    f"{where}: {width}x{height} pixels render {channels} float channels, "
                    f"{size / 2**20:.0f} MiB, over the limit of {self.max_bytes / 2**20:.0f} "
                    "MiB (DEPICT_MAX_DECODED_MB); ask for a smaller size"
                )
            return
        memory = _physical_memory()
        if size * RENDER_WORKING > memory:
            raise LimitError(
                f"{where}: {width}x{height} pixels would take about "
                f"{size * RENDER_WORKING / 2**30:.1f} GiB to render, more than this machine's "
                f"{memory / 2**30:.1f} GiB of memory; ask for a smaller size"
            )


def decoded_bytes(layout: Layout) -> int:
    """Bytes the pixels of every channel of every part take once decoded."""
    total = 0
    for part in layout.parts:
        w, h = max(part.width, 0), max(part.height, 0)
        for _, ptype, xs, ys, _ in part.channels:
            size = _SAMPLE_BYTES.get(ptype, 4)
            total += math.ceil(w / max(xs, 1)) * math.ceil(h / max(ys, 1)) * size
    return total


def _sizes(layout: Layout) -> str:
    sizes = sorted({f"{p.width}x{p.height}" for p in layout.parts})
    return ", ".join(sizes)
