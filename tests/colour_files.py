"""Real EXR files of one picture in two working spaces: linear Rec.709 (no chromaticities, as
renderers write it) and ACEScg (the colours converted by OpenColorIO, ``chromaticities`` set to
AP1), for the colour-management tests and the README's figures."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenEXR
import PyOpenColorIO as ocio

from ops.colorspace import ACES_AP1

#: OCIO's built-in studio config (what Depict uses without $OCIO).
CONFIG = "ocio://studio-config-latest"

#: The 24 patches of the ColorChecker Classic, 8-bit sRGB (BabelColor's averages), row by row.
MACBETH_SRGB = np.array(
    [
        [115, 82, 68], [194, 150, 130], [98, 122, 157], [87, 108, 67],
        [133, 128, 177], [103, 189, 170], [214, 126, 44], [80, 91, 166],
        [193, 90, 99], [94, 60, 108], [157, 188, 64], [224, 163, 46],
        [56, 61, 150], [70, 148, 73], [175, 54, 60], [231, 199, 31],
        [187, 86, 149], [8, 133, 161], [243, 243, 242], [200, 200, 200],
        [160, 160, 160], [122, 122, 121], [85, 85, 85], [52, 52, 52],
    ],
    np.float64,
)  # fmt: skip


def srgb_decode(values: np.ndarray) -> np.ndarray:
    """8-bit sRGB -> linear (IEC 61966-2-1)."""
    v = np.asarray(values, np.float64) / 255.0
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def ocio_convert(rgb: np.ndarray, src: str, dst: str) -> np.ndarray:
    """``rgb`` (..., 3) from OCIO space ``src`` to ``dst`` by OpenColorIO itself, float32."""
    proc = ocio.Config.CreateFromFile(CONFIG).getProcessor(src, dst).getDefaultCPUProcessor()
    x = np.ascontiguousarray(np.asarray(rgb, np.float32)).copy()
    proc.applyRGB(x)
    return x


def acescg_copy(src: str | Path, dst: str | Path) -> None:
    """Write ``src`` (linear Rec.709) as ACEScg: every RGB(A) layer converted (normals, depth
    and positions are stored as separate X/Y/Z channels and stay), chromaticities = AP1."""
    with OpenEXR.File(str(src)) as f:
        header = dict(f.header())
        channels = {name: np.array(c.pixels) for name, c in f.channels().items()}
    for name, pixels in channels.items():
        if pixels.ndim == 3 and pixels.shape[2] in (3, 4):
            out = pixels.astype(np.float32)
            out[..., :3] = ocio_convert(out[..., :3], "lin_rec709", "ACEScg")
            channels[name] = out
    header["chromaticities"] = ACES_AP1
    OpenEXR.File(header, channels).write(str(dst))


def chart(rgb: np.ndarray, path: str | Path, chroma: tuple[float, ...] | None = None) -> None:
    """A colour-chart frame: each colour of ``rgb`` (N, 3) a 16x16 patch on a row, at depth 2
    facing the camera, written as a canonical EXR (``chromaticities`` when given)."""
    n = len(rgb)
    beauty = np.repeat(np.repeat(np.asarray(rgb, np.float32)[None, :, :], 16, 0), 16, 1)
    header: dict[str, object] = {"compression": OpenEXR.ZIP_COMPRESSION}
    if chroma is not None:
        header["chromaticities"] = tuple(chroma)
    channels = {
        "R": beauty[..., 0].copy(),
        "G": beauty[..., 1].copy(),
        "B": beauty[..., 2].copy(),
        "Z": np.full((16, 16 * n), 2.0, np.float32),
    }
    OpenEXR.File(header, channels).write(str(path))
