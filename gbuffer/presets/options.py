"""User overrides of a preset when reading a file (``--map``, ``--normal-space``, ...)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from gbuffer.colorspace import named
from gbuffer.errors import FrameError, OptionError
from gbuffer.frame import BUFFERS

SPACES = ("world", "camera", "camera-lh")
DEPTH_KINDS = ("planar", "distance")

_MAPPABLE = tuple(n for n in BUFFERS if n != "remainder")


@dataclass
class ReadOptions:
    """User overrides of a preset.

    Attributes
    ----------
    mapping : canonical buffer -> a layer prefix (``"MyLayer.N"``) or an explicit channel
        list (``["n.x", "n.y", "n.z"]``, or one string with commas). Lobe parts are mappable
        too (``"diffuse.light"``, ``"diffuse.color"``).
    normal_space, position_space : "world", "camera" or "camera-lh" (left-handed, +z forward);
        ``None`` keeps the preset's.
    depth : "planar" (-z camera) or "distance" (along the ray; converted with the camera).
    depth_background : depth values >= this are background (default: the preset's).
    layer : view/render-layer prefix to use (Blender ``"ViewLayer"``); found when ``None``.
    normal_encoding : "signed" (-1..1) or "unsigned" (stored as 0.5 n + 0.5).
    normal_tolerance : |n| within 1 +- this is trusted fully (see the coverage formula).
    require_camera : world-space normals without a camera raise :class:`MissingCameraError`
        when True; when False they are left out with a warning (e.g. for inspection).
    colorspace : the working space of the radiance, a colour space of the OpenColorIO config
        (:mod:`gbuffer.colorspace`); ``None``: the file's ``chromaticities``, else the preset's.
    strict : NaN/Inf in a data channel (normals, depth, position, AO, ...) on covered pixels
        raise :class:`FrameError` when True; when False (inspection) those pixels become holes
        with a warning. Radiance (beauty, lobes, albedo) is never refused: see
        :mod:`gbuffer.holes`.
    """

    mapping: dict[str, str | list[str]] = field(default_factory=dict)
    normal_space: str | None = None
    position_space: str | None = None
    depth: str | None = None
    depth_background: float | None = None
    layer: str | None = None
    normal_encoding: str = "signed"
    normal_tolerance: float = 0.1
    require_camera: bool = True
    strict: bool = True
    colorspace: str | None = None

    def __post_init__(self) -> None:
        for key, channels in self.mapping.items():
            if key not in _MAPPABLE:
                raise OptionError(
                    f"mapping key '{key}' is not a buffer; valid keys: {', '.join(_MAPPABLE)}"
                )
            listed = [channels] if isinstance(channels, str) else list(channels)
            if not listed or any(not str(c).strip(" ,") for c in listed):
                raise OptionError(
                    f"mapping of '{key}' names no channel ({channels!r}); give a layer or "
                    "channels, e.g. normal=MyLayer.N or normal=n.x,n.y,n.z"
                )
        for name in ("normal_space", "position_space"):
            value = getattr(self, name)
            if value is not None and value not in SPACES:
                raise FrameError(f"{name}={value!r} must be one of {', '.join(SPACES)}")
        if self.depth is not None and self.depth not in DEPTH_KINDS:
            raise FrameError(f"depth={self.depth!r} must be one of {', '.join(DEPTH_KINDS)}")
        if self.depth_background is not None and not self.depth_background > 0:
            raise FrameError(f"depth_background={self.depth_background} must be > 0")
        if self.normal_encoding not in ("signed", "unsigned"):
            raise FrameError(
                f"normal_encoding={self.normal_encoding!r} must be 'signed' or 'unsigned'"
            )
        if not 0.0 <= self.normal_tolerance < 1.0:
            raise FrameError(f"normal_tolerance={self.normal_tolerance} must be in [0, 1)")
        if self.colorspace is not None:
            named(self.colorspace)  # an unknown or non-linear space is refused before reading

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ReadOptions:
        known = set(cls.__dataclass_fields__)
        unknown = sorted(set(data) - known)
        if unknown:
            raise FrameError(f"unknown read options {unknown}; valid: {sorted(known)}")
        return cls(**dict(data))


def read_options(overrides: ReadOptions | Mapping[str, Any] | None) -> ReadOptions:
    """``overrides`` as :class:`ReadOptions` (its dict form is checked)."""
    if isinstance(overrides, ReadOptions):
        return overrides
    return ReadOptions.from_dict(overrides or {})
