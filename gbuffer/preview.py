"""8-bit pictures of any layer, for people: the only place Depict tone-maps.

* radiance (beauty, lobes): exposure in stops, then a display/view of the OpenColorIO config
  (:class:`gbuffer.colorspace.View`: e.g. the sRGB display's ACES 2.0 SDR view), from the
  frame's working space; or, with the ``raw`` view (the default of :func:`picture`), the
  colours in Rec.709 primaries, the sRGB transfer function and a hard clip;
* normals: ``0.5 * n + 0.5`` as RGB (camera space: +x red, +y green, +z blue);
* depth: near bright, far dark, normalised over the covered range; background black;
* one-channel data in [0, 1] (AO, coverage, alpha) as grey; signed data (curvature) on a
  blue-white-red scale symmetric about 0.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from gbuffer import cryptomatte
from gbuffer.atomic import atomic_path
from gbuffer.colorspace import RAW_VIEW, View, display_processor
from gbuffer.errors import FrameError
from gbuffer.frame import BUFFERS, Frame
from ops.colorspace import LINEAR_REC709, ColorSpace, convert

RADIANCE = {
    "beauty",
    "ambient",
    "diffuse",
    "specular",
    "transmission",
    "remainder",
    *(n for n in BUFFERS if n.endswith(".light") or n.endswith(".color")),
    "albedo",
}


def srgb_encode(linear: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """Linear radiance -> sRGB-encoded float in [0, 1] (IEC 61966-2-1), after ``2**exposure``."""
    x = np.asarray(np.clip(linear * np.float32(2.0**exposure), 0.0, 1.0), np.float32)
    # the same float32 operations as np.where(x <= 0.0031308, 12.92 x, 1.055 x^(1/2.4) − 0.055),
    # each only where it is taken: NumPy's power is six times slower on zeros (a render's
    # background), and np.where's two branches and temporaries took as long again
    low = x <= 0.0031308
    out = np.zeros(x.shape, np.float32)
    np.power(x, 1 / 2.4, out=out, where=~low)
    out *= np.float32(1.055)
    out -= np.float32(0.055)
    np.multiply(x, np.float32(12.92), out=out, where=low)
    return out


#: Depict's own exposure and clip (:func:`srgb_encode`), the default of :func:`picture`.
RAW = View(view=RAW_VIEW)


def display_encode(
    linear: np.ndarray, space: ColorSpace, view: View = RAW, exposure: float = 0.0
) -> np.ndarray:
    """Scene-linear radiance in ``space`` -> display-encoded float RGB in [0, 1] through
    ``view`` (the OCIO display/view transform; ``raw``: Rec.709 primaries, then
    :func:`srgb_encode`), after ``2**exposure``."""
    if view.raw:
        return srgb_encode(convert(linear, space, LINEAR_REC709), exposure)
    proc, pre = display_processor(space, view)
    x = np.ascontiguousarray(linear * np.float32(2.0**exposure), np.float32)
    if pre is not None:
        x = np.ascontiguousarray(cv2.transform(x, pre), np.float32)
    x = np.nan_to_num(x, nan=0.0, posinf=65504.0, neginf=0.0)
    proc.applyRGB(x)
    return np.clip(x, 0.0, 1.0)


def _depth_picture(depth: np.ndarray) -> np.ndarray:
    finite = np.isfinite(depth)
    out = np.zeros(depth.shape, np.float32)
    if finite.any():
        near, far = float(depth[finite].min()), float(depth[finite].max())
        span = far - near if far > near else 1.0
        out[finite] = 1.0 - 0.8 * (depth[finite] - near) / span
    return out


def _signed_picture(values: np.ndarray) -> np.ndarray:
    finite = np.nan_to_num(values, nan=0.0, posinf=0.0, neginf=0.0)
    peak = float(np.percentile(np.abs(finite), 99.5)) or 1.0
    t = np.clip(finite / peak, -1.0, 1.0)
    pos, neg = np.clip(t, 0, 1), np.clip(-t, 0, 1)
    return np.dstack([1.0 - neg, 1.0 - pos - neg, 1.0 - pos]).astype(np.float32)


def _grey_or_signed(values: np.ndarray) -> np.ndarray:
    """A one-channel field in grey (signed: blue below 0, red above), a three-component one
    (positions, vectors) as its components in RGB, around mid-grey when signed (as normals)."""
    v = np.nan_to_num(values, nan=0.0, posinf=0.0, neginf=0.0)
    if v.ndim == 3:  # (each signed component went through _signed_picture: 9 channels)
        if v.min() < 0.0:
            peak = float(np.percentile(np.abs(v), 99.5)) or 1.0
            return np.clip(0.5 + 0.5 * v / peak, 0.0, 1.0).astype(np.float32)
        return (v / max(float(v.max()), 1.0)).astype(np.float32)
    if v.min() < 0.0:
        return _signed_picture(v)
    hi = max(float(v.max()), 1.0)
    return np.repeat((v / hi)[..., None], 3, axis=2)


def picture(
    frame: Frame, layer: str = "beauty", exposure: float = 0.0, view: View = RAW
) -> np.ndarray:
    """An (H, W, 3) float32 RGB picture in [0, 1] of a canonical buffer or a file layer;
    radiance through ``view`` from the frame's working space (:func:`display_encode`);
    ``cryptomatte`` (or ``cryptomatte/LAYER``): a false-colour view of the Cryptomatte ids."""
    if layer == "cryptomatte" or layer.startswith("cryptomatte/"):
        chosen = cryptomatte.named_layers(frame, layer.partition("/")[2] or None)[0]
        return cryptomatte.id_picture(frame, chosen)
    if layer in frame.buffers:
        data = frame.buffers[layer]
        if layer == "normal":
            return np.clip(0.5 * data + 0.5, 0.0, 1.0) * (frame.mask[..., None] > 0)
        if layer == "depth":
            return np.repeat(_depth_picture(data)[..., None], 3, axis=2)
        if layer in RADIANCE:
            return display_encode(data, frame.colorspace, view, exposure)
        return _grey_or_signed(data)
    channels = frame.layer(layer)
    if not channels:
        raise FrameError(f"no layer '{layer}' in the frame; {_what_there_is(frame)}")
    names = list(channels)
    for trio in (("R", "G", "B"), ("X", "Y", "Z")):
        if all(c in channels for c in trio):
            rgb = np.dstack([channels[c] for c in trio])
            if trio[0] == "R":
                return display_encode(rgb, frame.colorspace, view, exposure)
            return _grey_or_signed(rgb)
    return _grey_or_signed(channels[names[0]])


#: cv2.imencode's settings of :func:`quick_png`: zlib level 1, every row as its difference to the
#: row above (libpng's UP filter) and run-length matching only.
QUICK_PNG = [
    cv2.IMWRITE_PNG_COMPRESSION,
    1,
    cv2.IMWRITE_PNG_FILTER,
    cv2.IMWRITE_PNG_FILTER_UP,
    cv2.IMWRITE_PNG_STRATEGY,
    cv2.IMWRITE_PNG_STRATEGY_RLE,
]


def _eight_bit(rgb: np.ndarray) -> np.ndarray:
    """An (H, W, 3) float picture in [0, 1] as uint8 (rounded, clipped)."""
    return np.ascontiguousarray((np.clip(rgb, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8))


def quick_png(rgb: np.ndarray) -> bytes:
    """An (H, W, 3) float picture in [0, 1] as an 8-bit PNG made for a browser nearby, fast
    (:data:`QUICK_PNG`). At 960x540 it takes a third of the time of zlib's level 1 with
    libpng's adaptive filters, for about the same size (measured: a render of Depict 3.6 ms and
    43 kB against 11.5 ms and 49 kB; a Cycles render, noisy, 14 ms and 959 kB against 43 ms and
    914 kB); the same pixels as :func:`write_png`."""
    ok, buf = cv2.imencode(".png", cv2.cvtColor(_eight_bit(rgb), cv2.COLOR_RGB2BGR), QUICK_PNG)
    if not ok:
        raise FrameError(f"cannot encode a {rgb.shape} picture as PNG")
    return bytes(buf)


def write_png(rgb: np.ndarray, path: str | Path, quick: bool = False) -> None:
    """Write an (H, W, 3) float picture in [0, 1] as an 8-bit PNG, atomically: with OpenImageIO
    at its default zlib level (6, adaptive filters: the smallest file), or ``quick``
    (:func:`quick_png`)."""
    if quick:
        with atomic_path(path) as tmp:
            tmp.write_bytes(quick_png(rgb))
        return
    import OpenImageIO as oiio  # (its 17 MiB and 30 ms only where a PNG is written)

    img = _eight_bit(rgb)
    if oiio.ImageOutput.create(str(path)) is None:  # (the error named the temporary file)
        oiio.geterror()  # (taken: else OpenImageIO prints it as the process ends)
        suffix = Path(path).suffix or "(no suffix)"
        raise FrameError(f"cannot write {path}: no picture format for {suffix}; use .png")
    with atomic_path(path) as tmp:
        out = oiio.ImageOutput.create(str(tmp))
        spec = oiio.ImageSpec(img.shape[1], img.shape[0], img.shape[2], oiio.UINT8)
        if out is None or not out.open(str(tmp), spec):
            raise FrameError(f"cannot write PNG {path}: {oiio.geterror()}")
        ok = out.write_image(img)
        out.close()
        if not ok:
            raise FrameError(f"cannot write PNG {path}: {oiio.geterror()}")


def _what_there_is(frame: Frame) -> str:
    """The buffers and layers a picture can be made of, for an error naming one that is not:
    the buffers Depict mapped, else the file's layers (a luminance-only or luminance/chroma
    image maps none: ``--layer Y`` shows its Y)."""
    have = sorted(set(frame.buffers) | {c.split(".")[0] for c in frame.outputs})
    if have:
        return f"available: {', '.join(have)}"
    layers = {c.rpartition(".")[0] or c for _, chans in frame.passthrough.parts for c in chans}
    if not layers:
        return "it holds no channel"
    return f"no buffer mapped; the file's layers: {', '.join(sorted(layers))} (--layer NAME)"
