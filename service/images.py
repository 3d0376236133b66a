"""Images users hand to operators: matcaps, environment maps, gain maps, Apparent Relief Maps.

PNG/JPEG/TIFF are read with OpenCV; 8- and 16-bit files are scaled to [0, 1] and, where they are
colour pictures (``srgb=True``: matcaps, environments), decoded from sRGB to linear. EXR files
are read with the OpenEXR package (``R,G,B`` / ``Y`` / the first channels) and are already
linear. The result is float32 (H, W, 3), or (H, W) with ``grey=True``.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import OpenEXR

from gbuffer.errors import FrameError


def _srgb_to_linear(x: np.ndarray) -> np.ndarray:
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4).astype(np.float32)


def _read_exr(path: Path) -> np.ndarray:
    try:
        with OpenEXR.File(str(path), separate_channels=True) as f:
            channels = {name: np.asarray(c.pixels, np.float32) for name, c in f.channels().items()}
    except Exception as exc:  # the binding raises bare exceptions for bad files
        raise FrameError(f"cannot read image {path}: not a readable EXR ({exc})") from None
    for trio in (("R", "G", "B"), ("X", "Y", "Z")):
        if all(c in channels for c in trio):
            return np.dstack([channels[c] for c in trio])
    if "Y" in channels:
        return channels["Y"]
    first = sorted(channels)[:3]
    return np.dstack([channels[c] for c in first]) if len(first) == 3 else channels[first[0]]


def load_image(path: str | Path, *, srgb: bool = True, grey: bool = False) -> np.ndarray:
    """Read an image as float32; ``srgb`` decodes 8/16-bit files to linear light."""
    p = Path(path)
    if not p.is_file():
        raise FrameError(f"image {path} does not exist")
    if p.suffix.lower() == ".exr":
        img = _read_exr(p)
    else:
        raw = cv2.imread(str(p), cv2.IMREAD_UNCHANGED | cv2.IMREAD_ANYDEPTH)
        if raw is None:
            raise FrameError(f"cannot read image {path} (PNG, JPEG, TIFF, HDR or EXR expected)")
        if raw.ndim == 3:
            raw = cv2.cvtColor(raw[..., :3], cv2.COLOR_BGR2RGB)
        if raw.dtype == np.uint8:
            img = raw.astype(np.float32) / 255.0
        elif raw.dtype == np.uint16:
            img = raw.astype(np.float32) / 65535.0
        else:
            img = raw.astype(np.float32)
        if srgb and raw.dtype in (np.uint8, np.uint16):
            img = _srgb_to_linear(img)
    if not np.all(np.isfinite(img)):
        raise FrameError(f"image {path} holds NaN or Inf values")
    if grey:
        return img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    return img if img.ndim == 3 else np.repeat(img[..., None], 3, axis=2)
