"""A frame's buffers under Depict's canonical channel names, as Depict writes them (the
``canonical`` preset reads them back)."""

from __future__ import annotations

import numpy as np

from gbuffer.frame import LOBES, Frame

_RGB = ("R", "G", "B")
_XYZ = ("X", "Y", "Z")

#: Canonical buffer -> (layer, channel names of its components), in the order they are written
#: (DESIGN.md table); a one-component buffer (or an AO stored as RGB) gives the first name.
CANONICAL_NAMES: dict[str, tuple[str, tuple[str, ...]]] = {
    "beauty": ("", _RGB),
    "alpha": ("", ("A",)),
    "normal": ("N", _XYZ),
    "depth": ("depth", ("Z",)),
    "position": ("P", _XYZ),
    "albedo": ("albedo", _RGB),
    "ao": ("AO", ("X",)),
    "coverage": ("coverage", ("X",)),
    "roughness": ("roughness", ("X",)),
    **{key: (key, _RGB) for lobe in LOBES for key in (lobe, f"{lobe}.light", f"{lobe}.color")},
}


def canonical_channels(frame: Frame) -> dict[str, np.ndarray]:
    """The frame's buffers under Depict's canonical channel names (:data:`CANONICAL_NAMES`)."""
    out: dict[str, np.ndarray] = {}
    for buffer, (layer, suffixes) in CANONICAL_NAMES.items():
        arr = frame.buffers.get(buffer)
        if arr is None:
            continue
        names = [f"{layer}.{s}" if layer else s for s in suffixes]
        if arr.ndim == 2:
            out[names[0]] = arr
            continue
        for k, name in enumerate(names):
            out[name] = np.ascontiguousarray(arr[..., k])
    return out
