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

from gbuffer.exr.layout import (
    COMPRESSION_NAMES,
    EXR_THREADS,
    LOSSY_COMPRESSIONS,
    MAGIC,
    PIXEL_TYPES,
    STORAGES,
    FileLayout,
    PartLayout,
    RawAttribute,
    box2i,
    compression_name,
    read_layout,
    storage_name,
    window,
)
from gbuffer.exr.read import ExrPassthrough, ReleasedChannel, read_parts, release_pixels
from gbuffer.exr.write import write_parts
from gbuffer.limits import HARD_MAX_PIXELS, Limits

__all__ = [
    "COMPRESSION_NAMES",
    "EXR_THREADS",
    "HARD_MAX_PIXELS",
    "LOSSY_COMPRESSIONS",
    "MAGIC",
    "PIXEL_TYPES",
    "STORAGES",
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
