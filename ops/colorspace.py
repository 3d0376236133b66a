"""Linear RGB working spaces: primaries and white -> RGB-to-XYZ, Y weights, conversions.

A linear RGB space is fixed by the chromaticities of its three primaries and its white (the
EXR ``chromaticities`` attribute holds exactly these eight numbers). Its RGB-to-XYZ matrix M
(SMPTE RP 177-1993 §3.3) is

    P = [[x_r/y_r, x_g/y_g, x_b/y_b], [1, 1, 1], [z_r/y_r, z_g/y_g, z_b/y_b]]   (z = 1 − x − y)
    S = P⁻¹ · W,   W = (x_w/y_w, 1, z_w/y_w)
    M = P · diag(S)

so that RGB (1, 1, 1) is the white at Y = 1. Its second row is the space's luminance weights
(0.2126, 0.7152, 0.0722 for Rec.709; 0.2722, 0.6741, 0.0537 for ACEScg) and its row sums are
the white CIELAB is taken relative to. Converting between spaces of different whites adapts
with the Bradford transform (as OpenColorIO's ACES configs do between D65 and the ACES white).

Depict's default space is linear Rec.709 / sRGB primaries with a D65 white; its matrix is the
rounded one of IEC 61966-2-1 (:data:`ops.color.RGB_TO_XYZ`), kept bit for bit so that
results on Rec.709 frames do not move.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

__all__ = [
    "ACES_AP0",
    "ACES_AP1",
    "KNOWN",
    "LINEAR_REC709",
    "P3_D65",
    "REC709",
    "REC709_RGB_TO_XYZ",
    "REC709_Y",
    "REC2020",
    "ColorSpace",
    "bradford",
    "conversion",
    "convert",
    "from_chromaticities",
    "rgb_to_xyz",
]

#: (x_r, y_r, x_g, y_g, x_b, y_b, x_w, y_w), the order of the EXR ``chromaticities`` attribute.
Chromaticities = tuple[float, float, float, float, float, float, float, float]

#: ITU-R BT.709 / sRGB primaries, D65 white.
REC709: Chromaticities = (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290)
#: ACES AP1 (ACEScg) primaries, ACES white (SMPTE ST 2065-1).
ACES_AP1: Chromaticities = (0.713, 0.293, 0.165, 0.830, 0.128, 0.044, 0.32168, 0.33767)
#: ACES AP0 (ACES2065-1) primaries, ACES white.
ACES_AP0: Chromaticities = (0.7347, 0.2653, 0.0, 1.0, 0.0001, -0.0770, 0.32168, 0.33767)
#: ITU-R BT.2020 primaries, D65 white.
REC2020: Chromaticities = (0.708, 0.292, 0.170, 0.797, 0.131, 0.046, 0.3127, 0.3290)
#: Display P3 / P3-D65 primaries, D65 white.
P3_D65: Chromaticities = (0.680, 0.320, 0.265, 0.690, 0.150, 0.060, 0.3127, 0.3290)

#: OpenColorIO's canonical names of the linear spaces whose chromaticities are standard.
KNOWN: dict[str, Chromaticities] = {
    "Linear Rec.709 (sRGB)": REC709,
    "ACEScg": ACES_AP1,
    "ACES2065-1": ACES_AP0,
    "Linear Rec.2020": REC2020,
    "Linear P3-D65": P3_D65,
}

#: Rec. 709 / sRGB luminance weights of linear RGB (ITU-R BT.709-6, item 3.3: Y = 0.2126 R +
#: 0.7152 G + 0.0722 B): the weights of the Rec.709 space (its matrix's Y row is the same to
#: four decimals).
REC709_Y = (0.2126, 0.7152, 0.0722)

#: IEC 61966-2-1's rounded Rec.709 matrix (the one Depict has always used).
REC709_RGB_TO_XYZ = np.array(
    [
        [0.4124564, 0.3575761, 0.1804375],
        [0.2126729, 0.7151522, 0.0721750],
        [0.0193339, 0.1191920, 0.9503041],
    ],
    dtype=np.float64,
)

#: Bradford cone response (Lam 1985), rows: ρ, γ, β of XYZ.
_BRADFORD = np.array(
    [[0.8951, 0.2664, -0.1614], [-0.7502, 1.7135, 0.0367], [0.0389, -0.0685, 1.0296]],
    dtype=np.float64,
)


def _xyz(x: float, y: float) -> np.ndarray:
    """XYZ of chromaticity (x, y) at X + Y + Z = 1 (a primary may have y = 0: the CIE XYZ
    space's blue is (0, 0))."""
    return np.array([x, y, 1.0 - x - y], dtype=np.float64)


def rgb_to_xyz(chroma: Sequence[float]) -> np.ndarray:
    """The 3×3 RGB-to-XYZ matrix (float64) of a space's chromaticities (SMPTE RP 177): the
    primaries' XYZ scaled so that RGB (1, 1, 1) is the white at Y = 1.

    Rec.709 within 1e-4 of its standard chromaticities gives IEC 61966-2-1's rounded matrix;
    the CIE XYZ primaries ((1, 0), (0, 1), (0, 0), white E (⅓, ⅓), as OpenEXR writes XYZ
    images) the identity.
    """
    c = tuple(float(v) for v in chroma)
    if len(c) != 8 or not all(np.isfinite(c)):
        raise ValueError(f"chromaticities must be 8 finite numbers, got {chroma!r}")
    if max(abs(a - b) for a, b in zip(c, REC709, strict=True)) < 1e-4:
        return REC709_RGB_TO_XYZ.copy()
    if c[7] <= 0.0:
        raise ValueError(f"chromaticities {c}: the white has a y of 0 (not a colour space)")
    p = np.stack([_xyz(c[0], c[1]), _xyz(c[2], c[3]), _xyz(c[4], c[5])], axis=1)
    if abs(np.linalg.det(p)) < 1e-9:
        raise ValueError(f"chromaticities {c}: the primaries are on one line")
    s = np.linalg.solve(p, _xyz(c[6], c[7]) / c[7])
    if not (s > 0.0).all():
        raise ValueError(f"chromaticities {c}: the white is outside the primaries' triangle")
    return np.asarray(p * s[None, :], np.float64)


def bradford(src_white: np.ndarray, dst_white: np.ndarray) -> np.ndarray:
    """XYZ -> XYZ chromatic adaptation from ``src_white`` to ``dst_white`` (XYZ), Bradford."""
    cone_src, cone_dst = _BRADFORD @ src_white, _BRADFORD @ dst_white
    return np.asarray(np.linalg.inv(_BRADFORD) @ np.diag(cone_dst / cone_src) @ _BRADFORD)


@dataclass(frozen=True, eq=False)
class ColorSpace:
    """A frame's linear RGB working space.

    ``name``: what the user or the file calls it; ``matrix``: RGB-to-XYZ (3×3 float64);
    ``source``: where it came from (``--colorspace``, ``chromaticities attribute``, ``preset
    default (blender)``, ``default``).
    """

    name: str
    matrix: np.ndarray
    source: str = "default"

    @property
    def weights(self) -> tuple[float, float, float]:
        """Luminance weights: the Y row of the matrix (Rec.709: :data:`REC709_Y`)."""
        if self.is_rec709:
            return REC709_Y
        w = self.matrix[1]
        return (float(w[0]), float(w[1]), float(w[2]))

    @property
    def white(self) -> np.ndarray:
        """XYZ of RGB (1, 1, 1) (the row sums)."""
        return np.asarray(self.matrix.sum(axis=1), np.float64)

    @property
    def chromaticities(self) -> Chromaticities:
        """(x, y) of the primaries and of the white, the order of the EXR attribute."""
        cols = [self.matrix[:, j] for j in range(3)] + [self.white]
        xy = [(float(c[0] / c.sum()), float(c[1] / c.sum())) for c in cols]
        r, g, b, w = xy
        return (*r, *g, *b, *w)

    @property
    def is_rec709(self) -> bool:
        return bool(np.array_equal(self.matrix, REC709_RGB_TO_XYZ))

    def describe(self) -> dict[str, object]:
        """The JSON form ``depict inspect`` shows."""
        return {
            "name": self.name,
            "source": self.source,
            "luminance_weights": [round(float(v), 6) for v in self.weights],
            "white_xy": [round(float(v), 5) for v in self.white[:2] / self.white.sum()],
            "rgb_to_xyz": [[round(float(v), 7) for v in row] for row in self.matrix],
        }


#: Linear Rec.709, D65: the space of frames that do not say otherwise.
LINEAR_REC709 = ColorSpace("Linear Rec.709 (sRGB)", REC709_RGB_TO_XYZ, "default")


def from_chromaticities(name: str, chroma: Sequence[float], source: str) -> ColorSpace:
    """The space of ``chroma`` (see :func:`rgb_to_xyz`)."""
    return ColorSpace(name, rgb_to_xyz(chroma), source)


def conversion(src: ColorSpace, dst: ColorSpace) -> np.ndarray:
    """The 3×3 linear RGB -> RGB matrix (float64) from ``src`` to ``dst``, Bradford-adapted
    when their whites differ; the identity for the same matrix."""
    if np.array_equal(src.matrix, dst.matrix):
        return np.eye(3)
    adapt = bradford(src.white, dst.white)
    return np.asarray(np.linalg.inv(dst.matrix) @ adapt @ src.matrix)


def convert(rgb: np.ndarray, src: ColorSpace, dst: ColorSpace) -> np.ndarray:
    """(..., 3) linear RGB in ``src`` -> the same colours in ``dst``, float32 (``rgb`` itself,
    as float32, when the spaces are the same)."""
    arr = np.asarray(rgb, np.float32)
    m = conversion(src, dst)
    if np.array_equal(m, np.eye(3)):
        return arr
    flat = np.ascontiguousarray(arr.reshape(-1, 1, 3))
    return np.asarray(cv2.transform(flat, m.astype(np.float32)), np.float32).reshape(arr.shape)
