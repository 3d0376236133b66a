"""Contact sheets: display pictures of a frame's layers, crops, signed-change pictures, labelled
tiles in rows under a title, written as PNG (:mod:`bench.gallery`, :mod:`bench.gallery_corpus`,
:mod:`bench.gallery_masks` and :mod:`bench.colour` lay out their sheets with these)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from gbuffer.colorspace import View
from gbuffer.frame import Frame
from gbuffer.preview import RAW, picture, srgb_encode
from ops.color import luminance

#: Render height of the mesh frames (square frames), pixels.
SIZE = 384
#: Linear grey the mesh renders are composited over (their background is empty).
BACKGROUND = 0.18
#: Display exposure (stops) of the mesh renders: their white surface under the default lights
#: reaches about 0.6 linear, washed out in sRGB; the same for every before / after.
MESH_EXPOSURE = -0.6

Tile = tuple[np.ndarray, str]


def is_render(frame: Frame) -> bool:
    """A mesh render of ours (no background of its own), as opposed to the Cycles fixture."""
    return "remainder" not in frame.buffers


def pic(
    frame: Frame,
    layer: str = "beauty",
    exposure: float = 0.0,
    *,
    styled: bool = False,
    view: View = RAW,
) -> np.ndarray:
    """A display picture of a layer through ``view`` (default: exposure and clip); mesh renders
    at :data:`MESH_EXPOSURE` (plus ``exposure``; not for ``styled`` pictures, whose values are
    display values already, like the Apparent Relief styles), on grey."""
    if not is_render(frame):
        return picture(frame, layer, exposure, view)
    rgb = picture(frame, layer, exposure + (0.0 if styled else MESH_EXPOSURE), view)
    a = np.clip(frame.mask, 0.0, 1.0)[..., None]
    grey = srgb_encode(np.full(3, BACKGROUND, np.float32))
    return (rgb * a + grey * (1.0 - a)).astype(np.float32)


def rgb_pic(frame: Frame, rgb: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """A display picture of a linear RGB image of ``frame`` (composited as :func:`pic`)."""
    out = frame.copy()
    out.buffers["beauty"] = np.asarray(rgb, np.float32)
    return pic(out, "beauty", exposure)


def change_pic(before: np.ndarray, after: np.ndarray, mask: np.ndarray, peak: float) -> np.ndarray:
    """Signed change of sRGB-encoded lightness (after − before) on a blue-white-red scale,
    ±``peak`` saturating; grey off the surface."""
    d = luminance(after) - luminance(before)
    t = np.clip(d / np.float32(peak), -1.0, 1.0)
    pos, neg = np.clip(t, 0.0, 1.0), np.clip(-t, 0.0, 1.0)
    img = np.dstack([1.0 - neg, 1.0 - pos - neg, 1.0 - pos]).astype(np.float32)
    return np.where((mask > 0)[..., None], img, np.float32(0.5)).astype(np.float32)


Box = tuple[int, int, int, int]


def crop_box(mask: np.ndarray, margin: float = 0.04, square: bool = True) -> Box:
    """(y0, y1, x0, x1) around the covered pixels with a margin, inside the image: a square
    (``square``), else the full height and the covered columns."""
    h, w = mask.shape
    ys, xs = np.nonzero(mask > 0)
    if ys.size == 0:
        return 0, h, 0, w
    cy, cx = (ys.min() + ys.max()) / 2.0, (xs.min() + xs.max()) / 2.0
    if not square:
        half = (xs.max() - xs.min()) / 2.0 + margin * h
        x0, x1 = max(0, int(cx - half)), min(w, int(cx + half) + 1)
        return 0, h, x0, x1
    side = max(ys.max() - ys.min(), xs.max() - xs.min()) * (1.0 + 2.0 * margin)
    side = int(min(max(side, 16), h, w))
    y0 = int(np.clip(round(cy - side / 2), 0, h - side))
    x0 = int(np.clip(round(cx - side / 2), 0, w - side))
    return y0, y0 + side, x0, x0 + side


def crop(img: np.ndarray, box: Box | None, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """``img`` cut to ``box`` (when it has the frame's ``shape``, if given)."""
    if box is None or (shape is not None and img.shape[:2] != shape[:2]):
        return img
    y0, y1, x0, x1 = box
    return img[y0:y1, x0:x1]


def to_u8(rgb: np.ndarray) -> np.ndarray:
    return (np.clip(rgb, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def put_label(img: np.ndarray, text: str, scale: float) -> None:
    """White text on a dark translucent box in the tile's top-left corner (uint8 RGB, in
    place); ``|`` starts a new line."""
    font = cv2.FONT_HERSHEY_SIMPLEX
    thick = 1
    lines = text.split("|")
    sizes = [cv2.getTextSize(line, font, scale, thick)[0] for line in lines]
    (_, th), base = cv2.getTextSize("Ag", font, scale, thick)
    step = th + base + 2
    w = min(img.shape[1], max(s[0] for s in sizes) + 8)
    h = min(img.shape[0], step * len(lines) + 4)
    box = img[:h, :w].astype(np.float32)
    img[:h, :w] = (box * 0.35).astype(np.uint8)
    y = th + 4
    for line in lines:
        cv2.putText(img, line, (4, y), font, scale, (255, 255, 255), thick, cv2.LINE_AA)
        y += step


def tile_image(rgb: np.ndarray, label: str, height: int, scale: float) -> np.ndarray:
    """A labelled uint8 tile ``height`` pixels high (nearest-neighbour when enlarging, so the
    pixels stay honest)."""
    h, w = rgb.shape[:2]
    width = max(1, round(w * height / h))
    interp = cv2.INTER_NEAREST if height > h else cv2.INTER_AREA
    img = to_u8(cv2.resize(np.ascontiguousarray(rgb), (width, height), interpolation=interp))
    put_label(img, label, scale)
    return img


def sheet(
    rows: Sequence[Sequence[Tile]],
    title: str,
    *,
    height: int | Sequence[int] = SIZE,
    frame: Frame | None = None,
    square: bool = False,
    gap: int = 4,
    label_scale: float | None = None,
    title_scale: float | None = None,
) -> np.ndarray:
    """Rows of labelled tiles under a title bar, as uint8 RGB. ``height``: of every row, or one
    per row. With a mesh-render ``frame``, its tiles are cut to the object (the full height and
    the covered columns, or a square around it)."""
    heights = [height] * len(rows) if isinstance(height, int) else list(height)
    box = crop_box(frame.mask, square=square) if frame is not None and is_render(frame) else None
    shape = frame.shape if frame is not None else None
    built: list[list[np.ndarray]] = []
    for row, rh in zip(rows, heights, strict=True):
        scale = label_scale if label_scale is not None else max(0.35, rh / 700.0)
        built.append([tile_image(crop(rgb, box, shape), label, rh, scale) for rgb, label in row])
    widths = [sum(t.shape[1] for t in r) + gap * (len(r) - 1) for r in built]
    width = max(widths)
    tscale = title_scale if title_scale is not None else max(0.4, min(0.6, width / 2000.0))
    font = cv2.FONT_HERSHEY_SIMPLEX
    (_, th), base = cv2.getTextSize(title, font, tscale, 1)
    bar = th + base + 10 if title else 0
    total = bar + sum(heights) + gap * (len(built) - 1)
    out = np.full((total, width, 3), 32, np.uint8)
    if title:
        cv2.putText(out, title, (6, th + 5), font, tscale, (235, 235, 235), 1, cv2.LINE_AA)
    y = bar
    for built_row, rh in zip(built, heights, strict=True):
        x = 0
        for t in built_row:
            out[y : y + rh, x : x + t.shape[1]] = t
            x += t.shape[1] + gap
        y += rh + gap
    return out


def save(img: np.ndarray, path: Path, written: list[Path]) -> None:
    """Write a uint8 RGB image as a maximally compressed PNG and print its path."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.tmp.png")
    bgr = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_RGB2BGR)
    if not cv2.imwrite(str(tmp), bgr, [cv2.IMWRITE_PNG_COMPRESSION, 9]):
        raise SystemExit(f"gallery: cannot write {path}")
    tmp.replace(path)
    written.append(path)
    print(f"wrote {path} ({img.shape[1]}x{img.shape[0]}, {path.stat().st_size // 1024} KB)")
