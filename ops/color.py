"""Linear scene-referred RGB <-> CIELAB, float32, vectorised, HDR-safe.

Depict's radiance is linear RGB with Rec.709 / sRGB primaries and a D65 white (DESIGN.md). CIELAB
is taken relative to a *white level*: a linear value equal to ``white`` in all three channels maps
to L* = 100, a* = b* = 0. Values above the white level are not clipped: CIELAB's
f(t) = t^(1/3) extends above 1, so L* > 100 and the round trip stays exact for HDR radiance.

Why not ``cv2.cvtColor``: OpenCV's float ``COLOR_RGB2Lab`` applies the sRGB transfer curve, and
both it and the linear ``COLOR_LRGB2Lab`` clip the input to [0, 1] (RGB (4, 4, 4) comes back as
L* = 100 instead of 168.1; checked with OpenCV 5.0), and use a cube-root table with errors of
about 0.02 in L*. Here the matrix is ``cv2.transform`` and the cube root ``cv2.pow``, with the
CIE linear segment below (6/29)^3 written in closed form (no branches, no masks):

    f(t)    = cbrt(max(t, δ³)) + min(t − δ³, 0) / (3δ²),       δ = 6/29
    f⁻¹(u)  = max(u, δ)³ + 3δ² · min(u − δ, 0)

(for t ≥ δ³ the second term is 0; below, cbrt(δ³) + (t − δ³)/(3δ²) = t/(3δ²) + 4/29, CIE's
linear segment). Negative linear values (out of gamut) follow the linear segment, so they too
round-trip.

References
----------
CIE 15:2004 Colorimetry, §8.2.1 (CIELAB); IEC 61966-2-1 (sRGB primaries, D65).
"""

from __future__ import annotations

from typing import Any, Literal

import cv2
import numpy as np

_cv: Any = cv2  # OpenCV's stubs reject scalar operands (cv2.max(a, 0.0))

__all__ = [
    "RGB_TO_XYZ",
    "auto_white",
    "lab_phi_to_rgb",
    "lab_to_rgb",
    "luminance",
    "resolve_white",
    "rgb_to_lab",
    "rgb_to_lab_phi",
]

#: Linear Rec.709/sRGB (D65) to CIE XYZ (IEC 61966-2-1), column vectors.
RGB_TO_XYZ = np.array(
    [
        [0.4124564, 0.3575761, 0.1804375],
        [0.2126729, 0.7151522, 0.0721750],
        [0.0193339, 0.1191920, 0.9503041],
    ],
    dtype=np.float64,
)
#: The D65 white of that matrix (its row sums): XYZ of RGB (1, 1, 1).
_WHITE_XYZ = RGB_TO_XYZ.sum(axis=1)
#: Rec.709 luminance weights (the Y row).
_LUMA = RGB_TO_XYZ[1]

_DELTA = 6.0 / 29.0
_DELTA3 = _DELTA**3
_SLOPE = 1.0 / (3.0 * _DELTA * _DELTA)  # d f / d t on the linear segment

# φ = f − 4/29 -> (L*, a*, b*) and back (linear, no offset).
_PHI_TO_LAB = np.array(
    [[0.0, 116.0, 0.0], [500.0, -500.0, 0.0], [0.0, 200.0, -200.0]], dtype=np.float32
)
_LAB_TO_PHI = np.linalg.inv(_PHI_TO_LAB.astype(np.float64)).astype(np.float32)

White = float | Literal["auto"]


def _check_rgb(rgb: np.ndarray, name: str) -> np.ndarray:
    arr = np.asarray(rgb)
    if arr.ndim != 3 or arr.shape[2] != 3:
        raise ValueError(f"{name} must have shape (H, W, 3), got {arr.shape}")
    return np.ascontiguousarray(arr, dtype=np.float32)


def _check_white(white: float) -> float:
    w = float(white)
    if not np.isfinite(w) or w <= 0.0:
        raise ValueError(f"white must be a finite number > 0 (or 'auto'), got {white!r}")
    return w


def _flat(a: np.ndarray) -> np.ndarray:
    """A single-channel (H, W*C) view, so that cv2 scalar ops apply to every channel."""
    return a.reshape(a.shape[0], -1)


def luminance(rgb: np.ndarray) -> np.ndarray:
    """Rec.709 relative luminance Y = 0.2127 R + 0.7152 G + 0.0722 B of linear RGB.

    ``rgb`` has shape (..., 3); the result has the leading shape, float32.
    """
    arr = np.asarray(rgb, dtype=np.float32)
    if arr.ndim == 0 or arr.shape[-1] != 3:
        raise ValueError(f"rgb must have shape (..., 3), got {arr.shape}")
    flat = np.ascontiguousarray(arr.reshape(-1, 1, 3))
    y = _cv.transform(flat, _LUMA[None, :].astype(np.float32))
    return np.asarray(y, dtype=np.float32).reshape(arr.shape[:-1])


def auto_white(rgb: np.ndarray, mask: np.ndarray | None = None, percentile: float = 99.0) -> float:
    """White level for CIELAB: the ``percentile`` of luminance over covered pixels.

    Computed on a strided subsample (every 4th row and column, at least 64k pixels kept where the
    image has them) for speed; a 99th percentile moves by well under 1 % from that. Pixels with
    ``mask <= 0`` or non-finite luminance are ignored. Returns 1.0 when nothing usable is left
    (an all-black or empty frame), so black stays black instead of dividing by zero.

    A sequence should pin the white level (pass a number to the operators) so that it does not
    flicker from frame to frame (DESIGN.md).
    """
    if not 0.0 < percentile <= 100.0:
        raise ValueError(f"percentile must be in (0, 100], got {percentile}")
    arr = _check_rgb(rgb, "rgb")
    h, w = arr.shape[:2]
    step = 4 if h * w >= 16 * 65536 else 1
    sub = np.ascontiguousarray(arr[::step, ::step])
    y = _cv.transform(sub, _LUMA[None, :].astype(np.float32))
    ok = np.isfinite(y) & (y > 0.0)
    if mask is not None:
        m = np.asarray(mask)
        if m.shape != (h, w):
            raise ValueError(f"mask must have shape {(h, w)}, got {m.shape}")
        ok &= m[::step, ::step] > 0
    vals = y[ok]
    if vals.size == 0:
        return 1.0
    white = float(np.percentile(vals, percentile))
    return white if white > 0.0 and np.isfinite(white) else 1.0


def resolve_white(white: White, rgb: np.ndarray, mask: np.ndarray | None = None) -> float:
    """``white`` as a number: ``"auto"`` -> :func:`auto_white`, a number -> itself (checked)."""
    if isinstance(white, str):
        if white != "auto":
            raise ValueError(f"white must be 'auto' or a number > 0, got {white!r}")
        return auto_white(rgb, mask)
    return _check_white(white)


def rgb_to_lab_phi(rgb: np.ndarray, white: float = 1.0) -> np.ndarray:
    """Linear RGB -> centred CIELAB cube-root coordinates φ = f(t) − 4/29, (H, W, 3) float32.

    With t = (X/Xn, Y/Yn, Z/Zn) of ``rgb / white``, φ = (f(t_x), f(t_y), f(t_z)) − 4/29, so that

        L* = 116 φ_y,   a* = 500 (φ_x − φ_y),   b* = 200 (φ_y − φ_z).

    CIELAB is linear in φ without offset, so scaling (L*, a*, b*) by a common factor k (what
    3D unsharp masking does to keep saturation, Ritschel et al. 2008 §4) is scaling φ by k.
    Computed as φ = cbrt(max(t, δ³)) + min(t, δ³)/(3δ²) − δ (the CIE linear segment below δ³).
    """
    arr = _check_rgb(rgb, "rgb")
    w = _check_white(white)
    m = (RGB_TO_XYZ / (_WHITE_XYZ[:, None] * w)).astype(np.float32)
    t = _cv.transform(arr, m)
    tf = _flat(t)
    if _cv.minMaxLoc(tf)[0] > _DELTA3:  # nothing on the linear segment: φ = cbrt(t) − 4/29
        _cv.pow(tf, 1.0 / 3.0, dst=tf)
        _cv.subtract(tf, 4.0 / 29.0, dst=tf)
        return t
    lo = _cv.min(tf, _DELTA3)
    _cv.max(tf, _DELTA3, dst=tf)
    _cv.pow(tf, 1.0 / 3.0, dst=tf)
    _cv.addWeighted(tf, 1.0, lo, _SLOPE, -_DELTA, dst=tf)
    return t


def lab_phi_to_rgb(
    phi: np.ndarray, white: float = 1.0, out: np.ndarray | None = None
) -> np.ndarray:
    """Centred cube-root coordinates φ (see :func:`rgb_to_lab_phi`) -> linear RGB, float32.

    f = φ + 4/29; t = f³ for f > 6/29, 3 (6/29)² (f − 4/29) below;
    rgb = white · M⁻¹ · ((Xn, Yn, Zn) ∘ t). ``phi`` is not modified. ``out``: an (H, W, 3)
    float32 array (or view) to write the result into; the result is returned either way.
    """
    arr = _check_rgb(phi, "phi")
    w = _check_white(white)
    knee = _DELTA - 4.0 / 29.0  # φ at the knee t = δ³ (2/29)
    af = _flat(arr)
    if _cv.minMaxLoc(af)[0] >= knee:  # nothing on the linear segment: t = (φ + 4/29)³
        cube = _cv.add(af, 4.0 / 29.0)
        _cv.pow(cube, 3, dst=cube)
    else:
        cube = _cv.max(af, knee)
        _cv.add(cube, 4.0 / 29.0, dst=cube)
        _cv.pow(cube, 3, dst=cube)
        lo = _cv.min(af, knee)
        s = 3.0 * _DELTA * _DELTA
        _cv.addWeighted(cube, 1.0, lo, s, -s * knee, dst=cube)
    m_inv = (np.linalg.inv(RGB_TO_XYZ) * (_WHITE_XYZ[None, :] * w)).astype(np.float32)
    res = _cv.transform(cube.reshape(arr.shape), m_inv, dst=out)
    if out is not None and not np.shares_memory(res, out):
        out[...] = res  # OpenCV allocated anew (a view it cannot write through)
        return out
    return res


def rgb_to_lab(rgb: np.ndarray, white: float = 1.0) -> np.ndarray:
    """Linear RGB (Rec.709 primaries, D65) -> CIELAB relative to the white level ``white``.

    X, Y, Z = M · rgb / white, each divided by the D65 white (Xn, Yn, Zn);
    L* = 116 f(Y/Yn) − 16, a* = 500 (f(X/Xn) − f(Y/Yn)), b* = 200 (f(Y/Yn) − f(Z/Zn)),
    f(t) = t^(1/3) for t > (6/29)³, t / (3 (6/29)²) + 4/29 below (CIE 15:2004 §8.2.1).
    No clipping: linear values above ``white`` give L* > 100.

    Parameters
    ----------
    rgb : (H, W, 3) float32
        Linear scene-referred radiance.
    white : float
        Linear value that maps to L* = 100 (> 0).

    Returns
    -------
    (H, W, 3) float32 ``(L*, a*, b*)``.
    """
    return _cv.transform(rgb_to_lab_phi(rgb, white), _PHI_TO_LAB)


def lab_to_rgb(lab: np.ndarray, white: float = 1.0) -> np.ndarray:
    """CIELAB relative to the white level ``white`` -> linear RGB; inverse of :func:`rgb_to_lab`.

    f_y = (L* + 16)/116, f_x = f_y + a*/500, f_z = f_y − b*/200;
    t = f³ above 6/29, 3 (6/29)² (f − 4/29) below; rgb = white · M⁻¹ · (Xn, Yn, Zn) ∘ t.

    Parameters
    ----------
    lab : (H, W, 3) float32
    white : float
        The white level the Lab values are relative to (> 0).

    Returns
    -------
    (H, W, 3) float32 linear RGB.
    """
    arr = _check_rgb(lab, "lab")
    return lab_phi_to_rgb(_cv.transform(arr, _LAB_TO_PHI), white)
