"""Images users hand to operators: matcaps, environment maps, gain maps, Apparent Relief Maps.

Any format OpenImageIO reads (PNG, JPEG, TIFF, HDR, EXR, ...) is read with it, as float32.
Colour pictures (``srgb=True``: matcaps, environments) are converted into the frame's working
space (``space``) from the file's: 8- and 16-bit files are sRGB-encoded Rec.709 (decoded to
linear light); float files (EXR, HDR) are linear, in the space of their ``chromaticities``
attribute when they carry one, else linear Rec.709. Data maps (``srgb=False``: gain maps,
ARMs, toon textures) are numbers, not colours: integer files are scaled to [0, 1], nothing is
converted. An EXR's ``R,G,B`` (else ``X,Y,Z``, ``Y``, the first channels) are used. The result
is float32 (H, W, 3), or (H, W) with ``grey=True``.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from gbuffer.atomic import regular_file
from gbuffer.errors import FrameError
from ops.colorspace import LINEAR_REC709, ColorSpace, convert, from_chromaticities


def _srgb_to_linear(x: np.ndarray) -> np.ndarray:
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4).astype(np.float32)


def _pick(pixels: np.ndarray, names: list[str]) -> np.ndarray:
    """The colour channels of an (H, W, C) image by name: R,G,B, X,Y,Z, Y, else the first."""
    index = {n: i for i, n in enumerate(names)}
    for trio in (("R", "G", "B"), ("X", "Y", "Z")):
        if all(c in index for c in trio):
            return np.dstack([pixels[..., index[c]] for c in trio])
    if "Y" in index:
        return pixels[..., index["Y"]]
    return pixels[..., :3] if pixels.shape[2] >= 3 else pixels[..., 0]


def _read(path: Path) -> tuple[np.ndarray, bool, ColorSpace]:
    """(pixels as float32 (H, W[, 3]), whether the file stores integers, its linear space)."""
    import OpenImageIO as oiio  # (loaded where an image is read, not with the operators)

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        oiio.geterror()
        raise FrameError(f"cannot read image {path} (PNG, JPEG, TIFF, HDR or EXR expected)")
    try:
        spec = inp.spec()
        pixels = inp.read_image(0, 0, 0, spec.nchannels, "float")
        chroma = spec.getattribute("chromaticities")
    finally:
        inp.close()
    if pixels is None:
        raise FrameError(f"cannot read image {path}: {oiio.geterror() or 'no pixels'}")
    integer = spec.format.basetype in (oiio.UINT8, oiio.UINT16, oiio.INT8, oiio.INT16)
    space = LINEAR_REC709
    if chroma is not None and not integer:
        try:
            space = from_chromaticities(f"{path.name} chromaticities", chroma, "file")
        except ValueError as exc:
            raise FrameError(f"image {path}: unusable chromaticities ({exc})") from None
    img = _pick(
        np.asarray(pixels, np.float32).reshape(spec.height, spec.width, -1), list(spec.channelnames)
    )
    return np.ascontiguousarray(img, np.float32), integer, space


def load_image(
    path: str | Path,
    *,
    srgb: bool = True,
    grey: bool = False,
    space: ColorSpace = LINEAR_REC709,
) -> np.ndarray:
    """Read an image as float32: a colour picture (``srgb``) in ``space``, else data."""
    try:
        p = regular_file(path)
    except OSError as exc:
        raise FrameError(f"image {path}: {exc.strerror or exc}") from None
    img, integer, file_space = _read(p)
    if not np.all(np.isfinite(img)):
        raise FrameError(f"image {path} holds NaN or Inf values")
    if srgb:
        if integer:
            img = _srgb_to_linear(img)
        if img.ndim == 3:
            img = convert(img, file_space, space)
    if grey:
        return img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    return img if img.ndim == 3 else np.repeat(img[..., None], 3, axis=2)
