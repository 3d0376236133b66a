"""Colour charts for the colour-management tests: the ColorChecker's sRGB values and chart
frames (the ACEScg copies of whole files are :func:`bench.colour.acescg_copy`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import OpenEXR

from bench.colour import acescg_copy, ocio_convert, space_copy

__all__ = ["MACBETH_SRGB", "acescg_copy", "chart", "ocio_convert", "space_copy", "srgb_decode"]

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
