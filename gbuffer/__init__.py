"""The frame model, EXR I/O with passthrough, renderer presets and the camera."""

from gbuffer.camera import Camera
from gbuffer.errors import FrameError, LimitError, MissingBufferError, MissingCameraError
from gbuffer.frame import BUFFERS, LOBES, Frame, Passthrough
from gbuffer.io import describe, read, write
from gbuffer.presets import PRESETS, ReadOptions, detect

__all__ = [
    "BUFFERS",
    "LOBES",
    "PRESETS",
    "Camera",
    "Frame",
    "FrameError",
    "LimitError",
    "MissingBufferError",
    "MissingCameraError",
    "Passthrough",
    "ReadOptions",
    "describe",
    "detect",
    "read",
    "write",
]
