"""Apparent Relief Maps as pictures (``depict arm``): the template that shows where each shape
lands, or an ARM painted around descriptors picked with ``depict relief-pick``."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from gbuffer.atomic import atomic_path, regular_file
from ops.relief import SHIPPED_ARMS, arm_from_image, arm_template, make_arm, paint_arm

__all__ = [
    "SHIPPED_ARMS",
    "base_arm",
    "paint_arm",
    "template_picture",
    "to_picture",
    "write_picture",
]


def base_arm(base: str | None, size: int) -> np.ndarray:
    """The ARM to paint on: a shipped one by name, an image file, or black (``None``)."""
    if base in SHIPPED_ARMS:
        return make_arm(base, size)
    if base:
        try:
            img = cv2.imread(str(regular_file(base)), cv2.IMREAD_UNCHANGED)
        except OSError as exc:
            raise ValueError(f"--base {base!r}: {exc.strerror or exc}") from None
        if img is None:
            raise ValueError(f"--base {base!r}: not a shipped ARM nor a readable image")
        return arm_from_image(img)
    return np.zeros((size, size), np.float32)


def to_picture(arm: np.ndarray) -> np.ndarray:
    """An ARM in [0, 1] as 8-bit grey."""
    return np.clip(arm * 255.0 + 0.5, 0, 255).astype(np.uint8)


def template_picture(size: int) -> np.ndarray:
    """The ARM template as an 8-bit BGR picture (ValueError for a size out of range)."""
    rgb = arm_template(size)
    return cv2.cvtColor(to_picture(rgb), cv2.COLOR_RGB2BGR)


def write_picture(path: str | Path, pixels: np.ndarray) -> None:
    """Write an 8-bit picture in the format of ``path``'s suffix (PNG when none), atomically."""
    suffix = Path(path).suffix.lower() or ".png"
    try:  # (encoded first: nothing is written for a format OpenCV has no encoder of)
        ok, buf = cv2.imencode(suffix, pixels)
    except cv2.error:  # (no encoder for the suffix: .exr, .txt)
        ok = False
    if not ok:
        raise ValueError(f"cannot write {path}: no {suffix} encoder for an 8-bit picture; use .png")
    with atomic_path(path) as tmp:
        Path(tmp).write_bytes(buf.tobytes())
