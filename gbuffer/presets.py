"""Renderer presets: each renderer's channel names mapped to Depict's canonical buffers.

A preset is a table (canonical buffer -> the layer names a renderer uses for it, first found
wins) plus the renderer's conventions: the space of its normals and positions, whether its
depth is planar or the distance along the ray, and the depth value it writes on background.
:func:`detect` picks a preset from header attributes and channel names; :func:`to_frame` turns
the file's channels into a :class:`~gbuffer.frame.Frame` (float32, canonical conventions).

Channel names. Multi-part files (Karma/Houdini) often put the layer in the part name and keep
bare channel names; they are seen as ``<part name>.<channel>`` (the first part's channels also
by their bare names). A layer ``L`` of three components is found as ``L.R/G/B``, ``L.X/Y/Z``,
``L.r/g/b``, ``L.x/y/z`` or ``L.red/green/blue``; of one component as ``L`` itself or
``L.Z/X/R/V/Y/A`` (lower case too). Blender prefixes every pass with its view layer
(``ViewLayer.Normal.X``); the prefix is found automatically or given as ``ReadOptions.layer``.

Conventions applied (DESIGN.md): camera space is OpenGL's (+z towards the camera). World-space
normals are turned into camera space with the inverse transpose of the camera rotation,
left-handed camera spaces (RenderMan, +z forward) by flipping z. Normals are renormalised and
the **coverage** of a pixel is::

    coverage = min(clip(alpha, 0, 1), f(|n|)),
    f(l) = 1 if |l - 1| <= tol,  l / (1 - tol) if l < 1 - tol,  (1 + tol) / l if l > 1 + tol

(``tol`` = ``ReadOptions.normal_tolerance``, 0.1): a filtered normal shorter than one (Blender
averages normals with the background at anti-aliased edges, so its length is about the pixel's
coverage) or a non-unit one lowers the trust in the pixel; alpha < 1 does too, and ``min``
does not count the same edge twice. A file's own ``coverage`` channel (canonical) is used as
is. Background pixels (alpha 0, a depth that is not finite, <= 0 or >= the preset's background
value) get depth +inf, normal 0 and coverage 0. NaN/Inf elsewhere in a data channel is a
:class:`FrameError` naming the channel; in radiance (beauty, lobes, albedo: the fireflies of a
path tracer) it makes the pixel a hole (:mod:`gbuffer.holes`). When lobes are found,
``remainder`` = beauty minus their sum (emission, environment, coat, SSS, ...: what passes
through unchanged).
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import cv2
import numpy as np

from gbuffer.camera import Camera
from gbuffer.camera_solve import reprojection_fit, solve_camera, usable_pixels
from gbuffer.errors import FrameError, MissingCameraError, OptionError
from gbuffer.exr import ExrPassthrough, window
from gbuffer.frame import BUFFERS, LOBES, Frame, Passthrough
from gbuffer.holes import hole_warnings, mark_holes

Space = Literal["world", "camera", "camera-lh"]
DepthKind = Literal["planar", "distance"]
SPACES = ("world", "camera", "camera-lh")
DEPTH_KINDS = ("planar", "distance")

_SUFFIX3 = (
    ("R", "G", "B"),
    ("X", "Y", "Z"),
    ("r", "g", "b"),
    ("x", "y", "z"),
    ("red", "green", "blue"),
)
_SUFFIX1 = ("Z", "X", "R", "V", "Y", "A", "z", "x", "r", "v", "y", "a")


@dataclass(frozen=True)
class LobeSpec:
    """Where a lobe's radiance, light (without colour) and colour come from.

    Each of ``radiance`` and ``light`` lists alternatives; an alternative is a tuple of layers
    summed (those present). ``color`` lists single layers, first found wins. Missing parts are
    derived: radiance = light x colour (Blender), light = radiance / colour where colour > 0.
    """

    radiance: tuple[tuple[str, ...], ...] = ()
    light: tuple[tuple[str, ...], ...] = ()
    color: tuple[str, ...] = ()


@dataclass(frozen=True)
class Preset:
    """A renderer's names and conventions (see the module docstring)."""

    name: str
    description: str
    buffers: Mapping[str, tuple[str, ...]]
    normal: tuple[tuple[str, Space], ...] = ()
    position: tuple[tuple[str, Space], ...] = ()
    lobes: Mapping[str, LobeSpec] = field(default_factory=dict)
    depth_kind: DepthKind = "planar"
    depth_background: float = 1e10
    view_layer: bool = False


BLENDER = Preset(
    name="blender",
    description="Blender Cycles/EEVEE multilayer EXR (3.x-4.x pass names, Blender 5 aliases)",
    buffers={
        "beauty": ("Combined", "Image"),
        "alpha": ("Combined.A", "Alpha"),
        "depth": ("Depth", "Z"),
        "albedo": ("Denoising Albedo", "DiffCol", "Diffuse Color"),
        "ao": ("AO", "Ambient Occlusion"),
    },
    normal=(("Normal", "world"),),
    position=(("Position", "world"),),
    lobes={
        "diffuse": LobeSpec(
            light=(("DiffDir", "DiffInd"), ("Diffuse Direct", "Diffuse Indirect")),
            color=("DiffCol", "Diffuse Color"),
        ),
        "specular": LobeSpec(
            light=(("GlossDir", "GlossInd"), ("Glossy Direct", "Glossy Indirect")),
            color=("GlossCol", "Glossy Color"),
        ),
        "transmission": LobeSpec(
            light=(("TransDir", "TransInd"), ("Transmission Direct", "Transmission Indirect")),
            color=("TransCol", "Transmission Color"),
        ),
    },
    depth_kind="planar",
    depth_background=1e9,
    view_layer=True,
)

ARNOLD = Preset(
    name="arnold",
    description="Arnold AOVs (N/P world space, Z = distance to the camera, AI_BIG background)",
    buffers={
        "beauty": ("", "RGBA", "beauty"),
        "alpha": ("A", "RGBA.A"),
        "depth": ("Z", "depth"),
        "albedo": ("diffuse_albedo", "albedo"),
        "ao": ("ao", "AO", "occlusion"),
    },
    normal=(("N", "world"),),
    position=(("P", "world"),),
    lobes={
        "diffuse": LobeSpec(
            radiance=(("diffuse_direct", "diffuse_indirect"), ("diffuse",)),
            color=("diffuse_albedo",),
        ),
        "specular": LobeSpec(
            radiance=(("specular_direct", "specular_indirect"), ("specular",)),
            color=("specular_albedo",),
        ),
        "transmission": LobeSpec(
            radiance=(("transmission_direct", "transmission_indirect"), ("transmission",)),
            color=("transmission_albedo",),
        ),
    },
    depth_kind="distance",
    depth_background=1e10,
)

VRAY = Preset(
    name="vray",
    description="V-Ray render elements (VRayNormals camera space, raw Z, cameraTransform)",
    buffers={
        "beauty": ("", "RGBA", "rgba"),
        "alpha": ("A", "VRayAlpha", "alpha"),
        "depth": ("Z",),
        "albedo": ("VRayDiffuseFilter", "diffuse"),
    },
    normal=(("VRayNormals", "camera"), ("normals", "camera"), ("Normals", "camera")),
    lobes={
        "diffuse": LobeSpec(
            radiance=(("VRayLighting", "VRayGlobalIllumination"), ("lighting", "gi")),
            light=(("VRayRawLighting", "VRayRawGlobalIllumination"), ("lighting_raw", "gi_raw")),
            color=("VRayDiffuseFilter", "diffuse"),
        ),
        "specular": LobeSpec(
            radiance=(("VRayReflection", "VRaySpecular"), ("reflection", "specular")),
            light=(("VRayRawReflection",), ("reflection_raw",)),
            color=("VRayReflectionFilter", "reflection_filter"),
        ),
        "transmission": LobeSpec(
            radiance=(("VRayRefraction",), ("refraction",)),
            light=(("VRayRawRefraction",), ("refraction_raw",)),
            color=("VRayRefractionFilter", "refraction_filter"),
        ),
    },
    depth_kind="planar",
    depth_background=1e10,
)

RENDERMAN = Preset(
    name="renderman",
    description="RenderMan RIS AOVs (Nn/P camera space left-handed, z planar, __Nworld/__Pworld)",
    buffers={
        "beauty": ("", "Ci", "beauty"),
        "alpha": ("A", "a", "Ci.a", "Ci.A"),
        "depth": ("z", "Z"),
        "albedo": ("albedo", "diffuseColor"),
        "ao": ("occlusion", "ao"),
    },
    normal=(("Nn", "camera-lh"), ("__Nworld", "world"), ("N", "camera-lh")),
    position=(("__Pworld", "world"), ("P", "camera-lh")),
    lobes={
        "diffuse": LobeSpec(
            radiance=(
                ("directDiffuse", "indirectDiffuse"),
                ("directDiffuseLobe", "indirectDiffuseLobe"),
            ),
            color=("albedo", "diffuseColor"),
        ),
        "specular": LobeSpec(
            radiance=(
                ("directSpecular", "indirectSpecular"),
                (
                    "directSpecularPrimaryLobe",
                    "indirectSpecularPrimaryLobe",
                    "directSpecularRoughLobe",
                    "indirectSpecularRoughLobe",
                ),
            ),
        ),
        "transmission": LobeSpec(
            radiance=(("transmissive",), ("transmissiveGlassLobe",)),
        ),
    },
    depth_kind="planar",
    depth_background=1e10,
)

KARMA = Preset(
    name="karma",
    description="Houdini Karma render vars (multi-part by layer name, N/P world space)",
    buffers={
        "beauty": ("C", "beauty", ""),
        "alpha": ("C.A", "A"),
        "depth": ("depth", "Pz", "Z", "z"),
        "albedo": ("albedo", "diffuse_albedo", "basecolor"),
        "ao": ("occlusion", "ao", "AO"),
    },
    normal=(("N", "world"),),
    position=(("P", "world"),),
    lobes={
        "diffuse": LobeSpec(
            radiance=(
                ("directdiffuse", "indirectdiffuse"),
                ("combineddiffuse",),
                ("diffuse_direct", "diffuse_indirect"),
                ("diffuse",),
            ),
            color=("albedo", "diffuse_albedo"),
        ),
        "specular": LobeSpec(
            radiance=(
                ("glossyreflection", "indirectglossyreflection"),
                ("combinedglossyreflection",),
                ("specular_direct", "specular_indirect"),
                ("specular",),
            ),
            color=("specular_albedo",),
        ),
        "transmission": LobeSpec(
            radiance=(("glossytransmission",), ("transmission",)),
            color=("transmission_albedo",),
        ),
    },
    depth_kind="planar",
    depth_background=1e10,
)

CANONICAL = Preset(
    name="canonical",
    description="Depict's own names (the table above): R G B A, N.XYZ, depth.Z, P.XYZ, lobes, AO.X",
    buffers={
        "beauty": ("",),
        "alpha": ("A",),
        "depth": ("depth",),
        "albedo": ("albedo",),
        "ao": ("AO",),
        "roughness": ("roughness",),
        "coverage": ("coverage",),
    },
    normal=(("N", "camera"),),
    position=(("P", "camera"),),
    lobes={
        lobe: LobeSpec(radiance=((lobe,),), light=((f"{lobe}.light",),), color=(f"{lobe}.color",))
        for lobe in LOBES
    },
    depth_kind="planar",
    depth_background=1e30,
)

#: Presets by name.
PRESETS: dict[str, Preset] = {
    p.name: p for p in (BLENDER, ARNOLD, VRAY, RENDERMAN, KARMA, CANONICAL)
}

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

    def __post_init__(self) -> None:
        for key in self.mapping:
            if key not in _MAPPABLE:
                raise OptionError(
                    f"mapping key '{key}' is not a buffer; valid keys: {', '.join(_MAPPABLE)}"
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

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ReadOptions:
        known = set(cls.__dataclass_fields__)
        unknown = sorted(set(data) - known)
        if unknown:
            raise FrameError(f"unknown read options {unknown}; valid: {sorted(known)}")
        return cls(**dict(data))


# -- channel namespace --------------------------------------------------------------------------


def flat_channels(
    parts: Sequence[tuple[dict[str, Any], dict[str, Any]]],
) -> dict[str, tuple[int, str]]:
    """Channel name as presets see it -> (part index, channel name in that part)."""
    flat: dict[str, tuple[int, str]] = {}
    multi = len(parts) > 1
    for i, (header, channels) in enumerate(parts):
        part_name = header.get("name") if multi else None
        for c in channels:
            if part_name and "." not in c:
                flat.setdefault(f"{part_name}.{c}", (i, c))
    for i, (_header, channels) in enumerate(parts):
        for c in channels:
            flat.setdefault(c, (i, c))
    return flat


def _resolve(flat: Mapping[str, Any], layer: str, n: int) -> list[str] | None:
    """Channel names of ``layer`` with ``n`` components, or None."""
    if n == 1:
        if layer and layer in flat:
            return [layer]
        for s in _SUFFIX1:
            name = f"{layer}.{s}" if layer else s
            if name in flat:
                return [name]
        return None
    for suffixes in _SUFFIX3:
        names = [f"{layer}.{s}" if layer else s for s in suffixes]
        if all(name in flat for name in names):
            return names
    return None


def _describe(names: Sequence[str]) -> str:
    """``["L.N.X", "L.N.Y", "L.N.Z"]`` -> ``"L.N.X,Y,Z"``."""
    heads = {n.rpartition(".")[0] for n in names}
    if len(names) > 1 and len(heads) == 1 and next(iter(heads)):
        head = next(iter(heads))
        return f"{head}." + ",".join(n.rpartition(".")[2] for n in names)
    return ",".join(names)


# -- detection ----------------------------------------------------------------------------------

_BLENDER_PASS = re.compile(
    r"^(.+)\.(Combined|Depth|Normal|Position|DiffDir|DiffInd|DiffCol|GlossDir|GlossCol|"
    r"TransDir|TransCol|Emit|Env|AO|Diffuse Direct|Diffuse Color|Glossy Direct|Glossy Color|"
    r"Ambient Occlusion|Emission|Environment)\.[A-Za-z]+$"
)
_SOFTWARE = (
    ("blender", "blender"),
    ("arnold", "arnold"),
    ("v-ray", "vray"),
    ("vray", "vray"),
    ("renderman", "renderman"),
    ("prman", "renderman"),
    ("karma", "karma"),
    ("houdini", "karma"),
    ("depict", "canonical"),
)


def _parts_of(parts: Any) -> list[tuple[dict[str, Any], dict[str, Any]]]:
    if isinstance(parts, Passthrough):
        return list(parts.parts)
    return list(parts)


def detect(parts: Any) -> tuple[str, str]:
    """The preset that fits a file, and why.

    Parameters
    ----------
    parts : a :class:`Passthrough` or its list of ``(header, channels)``.

    Returns
    -------
    (preset name, one-line reason), e.g. ``("blender", "header attribute BlenderMultiChannel")``.
    Renderer header signatures are checked first, then renderer channel names, then Depict's
    own ``depict/*`` attributes (Depict also writes them into renderer files it gives back),
    then canonical names; ``canonical`` is the fallback.
    """
    plist = _parts_of(parts)
    keys = [k for header, _ in plist for k in header]
    for key in keys:
        if key == "BlenderMultiChannel":
            return "blender", "header attribute BlenderMultiChannel"
        if key.lower().startswith("arnold/"):
            return "arnold", f"header attribute {key}"
        if key.startswith("vrayInfo/") or key == "cameraTransform":
            return "vray", f"header attribute {key}"
        if key.lower().startswith(("karma", "houdini")):
            return "karma", f"header attribute {key}"
        if key.lower().startswith(("renderman", "prman", "pixar")):
            return "renderman", f"header attribute {key}"
    for header, _ in plist:
        for key in ("software", "Software", "writer", "creator", "dcc"):
            value = header.get(key)
            if isinstance(value, str):
                low = value.lower()
                for word, name in _SOFTWARE:
                    if word in low:
                        return name, f"header {key}={value!r}"
    flat = flat_channels(plist)
    names = list(flat)
    if any(_BLENDER_PASS.match(n) for n in names):
        return "blender", "Blender pass names (<ViewLayer>.<pass>.<channel>)"
    if any(n.startswith(("VRay", "vray")) for n in names):
        return "vray", "V-Ray render element names (VRay*)"
    rman = {"Nn", "__Nworld", "__Pworld", "Ci", "directDiffuse", "directSpecular"}
    heads = {n.rpartition(".")[0] or n for n in names}
    if heads & rman:
        return "renderman", f"RenderMan AOV names ({', '.join(sorted(heads & rman))})"
    arnold = {
        "diffuse_direct",
        "diffuse_indirect",
        "diffuse_albedo",
        "specular_direct",
        "specular_albedo",
        "transmission_direct",
        "coat_direct",
        "sss_direct",
    }
    if heads & arnold and not {"N.X", "depth.Z"} <= set(names):
        return "arnold", f"Arnold AOV names ({', '.join(sorted(heads & arnold))})"
    part_names = {str(h.get("name")) for h, _ in plist if h.get("name")}
    if len(plist) > 1 and "C" in part_names:
        return "karma", "multi-part file with a part named 'C' (Karma beauty)"
    depict = next((k for k in keys if k.startswith("depict/")), None)
    if depict is not None:  # after the renderers: Depict marks the files it writes back too
        return "canonical", f"header attribute {depict}"
    if {"N.X", "N.Y", "N.Z"} <= set(names) or "depth.Z" in names:
        return "canonical", "Depict canonical channel names (N.X/Y/Z, depth.Z)"
    return "canonical", "no renderer signature found; using Depict's canonical names"


# -- conversion ---------------------------------------------------------------------------------


class _Reader:
    """Loads channels of a passthrough as float32 arrays on the primary part's grid."""

    def __init__(
        self, pt: Passthrough, flat: dict[str, tuple[int, str]], where: str, strict: bool = True
    ) -> None:
        self.pt = pt
        self.flat = flat
        self.where = where
        self.strict = strict
        self.primary = 0
        self.grid = (0, 0, 0, 0)
        #: pixels with NaN/Inf radiance (or, when not strict, data): holes of the frame
        self.holes: np.ndarray | None = None
        self.hole_channels: dict[str, int] = {}  # channel -> non-finite values there
        self.masked_channels: dict[str, int] = {}  # data channels, when not strict

    def add_holes(self, name: str, bad: np.ndarray, radiance: bool) -> None:
        """Make ``bad`` pixels holes; count the channel's non-finite values."""
        self.holes = bad.copy() if self.holes is None else self.holes | bad
        counts = self.hole_channels if radiance else self.masked_channels
        counts[name] = counts.get(name, 0) + int(bad.sum())

    def set_primary(self, index: int) -> None:
        self.primary = index
        header, channels = self.pt.parts[index]
        self.grid = window(header, "dataWindow", channels)

    @property
    def shape(self) -> tuple[int, int]:
        x0, y0, x1, y1 = self.grid
        return (y1 - y0 + 1, x1 - x0 + 1)

    def _pixels(
        self, name: str, buffer: str
    ) -> tuple[int, dict[str, Any], dict[str, Any], np.ndarray]:
        part, cname = self.flat[name]
        header, channels = self.pt.parts[part]
        ch = channels[cname]
        pixels = getattr(ch, "pixels", ch)
        if getattr(ch, "xSampling", 1) != 1 or getattr(ch, "ySampling", 1) != 1:
            raise FrameError(
                f"{self.where}: channel '{name}' is subsampled; the {buffer} buffer needs a "
                "full-resolution channel"
            )
        if pixels.dtype == np.uint32:
            raise FrameError(
                f"{self.where}: channel '{name}' is UINT; the {buffer} buffer needs a HALF or "
                "FLOAT channel (map another channel with --map)"
            )
        return part, header, channels, pixels

    def plane(self, name: str, buffer: str, fill: float = 0.0) -> np.ndarray:
        """One channel as a new float32 (H, W) array on the grid (``fill`` outside its window)."""
        part, header, channels, pixels = self._pixels(name, buffer)
        src = self.grid if part == self.primary else window(header, "dataWindow", channels)
        if pixels.dtype == np.float16:  # cv2 converts 16F -> 32F several times faster
            half = cv2.multiply(pixels, 1.0, dtype=cv2.CV_32F)  # type: ignore[call-overload]
            arr = np.asarray(half, np.float32)
        else:
            arr = np.array(pixels, dtype=np.float32)
        if src == self.grid:
            return arr
        out = np.full(self.shape, fill, np.float32)
        gx0, gy0, gx1, gy1 = self.grid
        x0, y0 = max(src[0], gx0), max(src[1], gy0)
        x1, y1 = min(src[2], gx1), min(src[3], gy1)
        if x1 >= x0 and y1 >= y0:
            out[y0 - gy0 : y1 - gy0 + 1, x0 - gx0 : x1 - gx0 + 1] = arr[
                y0 - src[1] : y1 - src[1] + 1, x0 - src[0] : x1 - src[0] + 1
            ]
        return out

    def stack(self, names: Sequence[str], buffer: str, fill: float = 0.0) -> np.ndarray:
        """Channels ``names`` as one new float32 (H, W) or (H, W, C) array on the grid."""
        planes = [self.plane(name, buffer, fill) for name in names]
        if len(planes) == 1:
            return planes[0]
        return np.asarray(cv2.merge(planes), np.float32)


def _find(
    reader: _Reader,
    buffer: str,
    layers: Sequence[str],
    prefix: str,
    opts: ReadOptions,
    n: int | None = None,
) -> list[str] | None:
    """Channels of ``buffer``: the user's mapping, else the first layer found."""
    n = n if n is not None else BUFFERS[buffer][0]
    flat = reader.flat
    if buffer in opts.mapping:
        spec = opts.mapping[buffer]
        names = [s.strip() for s in spec.split(",")] if isinstance(spec, str) else list(spec)
        if len(names) == 1 and (n > 1 or names[0] not in flat):
            found = _resolve(flat, names[0], n)
            if found is None:
                raise OptionError(
                    f"{reader.where}: --map {buffer}={names[0]}: no layer '{names[0]}' with {n} "
                    f"component(s); channels: {_channel_list(flat)}"
                )
            return found
        missing = [c for c in names if c not in flat]
        if missing or len(names) != n:
            raise OptionError(
                f"{reader.where}: --map {buffer}: needs {n} existing channel(s), got {names}; "
                f"channels: {_channel_list(flat)}"
            )
        return names
    for layer in layers:
        full = f"{prefix}.{layer}" if prefix and layer else (layer or prefix)
        found = _resolve(flat, full, n)
        if found is not None:
            return found
    return None


def _channel_list(flat: Mapping[str, Any], limit: int = 24) -> str:
    names = list(flat)
    more = f", ... ({len(names) - limit} more)" if len(names) > limit else ""
    return ", ".join(names[:limit]) + more


def _blender_prefix(flat: Mapping[str, Any], opts: ReadOptions, warnings: list[str]) -> str:
    prefixes: list[str] = []
    for name in flat:
        m = _BLENDER_PASS.match(name)
        if m and m.group(1) not in prefixes:
            prefixes.append(m.group(1))
    if opts.layer is not None:
        if opts.layer not in prefixes and prefixes:
            raise FrameError(
                f"view layer '{opts.layer}' not in the file; layers: {', '.join(prefixes)}"
            )
        return opts.layer
    if not prefixes:
        return ""
    # the layer with the most passes: not the "Composite" layer (Combined alone) that Blender
    # adds to a render saved with the compositor on
    passes = {
        p: sum(1 for n in flat if n.startswith(f"{p}.") and _BLENDER_PASS.match(n))
        for p in prefixes
    }
    chosen = max(prefixes, key=lambda p: (passes[p], f"{p}.Combined.R" in flat))
    if len(prefixes) > 1:
        warnings.append(
            f"view layers {', '.join(prefixes)}: using '{chosen}' (choose with layer=...)"
        )
    return chosen


def _check_finite(
    reader: _Reader,
    names: Sequence[str],
    arr: np.ndarray,
    background: np.ndarray | None,
    radiance: bool = False,
) -> None:
    """NaN/Inf on covered pixels: a hole for radiance (and, when the reader is not strict, for
    data), else a FrameError naming the channel; the values become 0 either way."""
    if np.isfinite(arr).all():
        return
    bad = ~np.isfinite(arr)
    for k, name in enumerate(names):
        bad_k = bad if arr.ndim == 2 else bad[..., k]
        if background is not None:
            bad_k = bad_k & ~background
        if not bad_k.any():
            continue
        if radiance or not reader.strict:
            reader.add_holes(name, bad_k, radiance)
            continue
        ys, xs = np.nonzero(bad_k)
        raise FrameError(
            f"{reader.where}: channel '{name}' has {len(ys)} NaN/Inf value(s) on covered "
            f"pixels (first at x={xs[0]}, y={ys[0]} of the data window)"
        )
    arr[bad] = 0.0


def _sum(arrays: Sequence[np.ndarray]) -> np.ndarray:
    """Σ arrays, accumulated into the first (the caller's own new array: no copy)."""
    out = arrays[0]
    for a in arrays[1:]:
        cv2.add(out, a, dst=out)
    return out


def _trust(length: np.ndarray, tol: float) -> np.ndarray:
    """f(|n|) of the coverage formula (module docstring)."""
    low = np.float32(1.0 - tol)
    high = np.float32(1.0 + tol)
    f = np.ones_like(length)
    short = length < low
    f[short] = length[short] / low
    long_ = length > high
    f[long_] = high / length[long_]
    return f


def _camera_error(where: str, what: str, src: str, camera: Camera | None) -> MissingCameraError:
    have = "the camera given has no world_to_camera matrix" if camera else "the file has none"
    return MissingCameraError(
        f"{where}: the {what} ({src}) are in world space and no camera is known ({have}, and "
        "no world-space position pass to solve it from); give a camera JSON (--camera "
        'CAM.json on the command line, the camera form field over HTTP) with {"world_to_camera": '
        '[[4 numbers], [4], [4], [4]], "fov_y_deg": 40} (OpenGL camera looking down -z), or '
        "declare them camera-space (--normal-space camera, normal_space=camera)"
    )


def _to_camera_normals(n: np.ndarray, space: str, camera: Camera | None) -> np.ndarray:
    if space == "camera":
        return n
    if space == "camera-lh":
        n[..., 2] *= -1.0
        return n
    assert camera is not None and camera.world_to_camera is not None
    rot = camera.world_to_camera[:3, :3]
    normal_matrix = np.linalg.inv(rot).T.astype(np.float32)
    return np.asarray(cv2.transform(n, normal_matrix), dtype=np.float32)


def _to_camera_points(p: np.ndarray, space: str, camera: Camera | None) -> np.ndarray:
    if space == "camera":
        return p
    if space == "camera-lh":
        p[..., 2] *= -1.0
        return p
    assert camera is not None and camera.world_to_camera is not None
    m = camera.world_to_camera[:3, :].astype(np.float32)
    return np.asarray(cv2.transform(p, m), dtype=np.float32)


def _camera_from_positions(
    camera: Camera | None,
    points: np.ndarray,
    covered: np.ndarray,
    display_size: tuple[int, int],
    origin: tuple[int, int],
    depth: np.ndarray | None,
    found: Mapping[str, list[str]],
    warnings: list[str],
) -> Camera | None:
    """The camera solved from world-space positions when none is known; else the known one
    with its reprojection error against them (a wrong field of view shows up in pixels)."""
    src = _describe(found["position"])
    if camera is not None and camera.world_to_camera is not None:
        if camera.fov_y_deg is None and camera.ortho_height is None:
            return camera
        fit = reprojection_fit(camera, points, usable_pixels(points, covered), display_size, origin)
        if fit.rms_px > CAMERA_DISAGREES_PX:
            warnings.append(
                f"the camera ({camera.source or 'given'}) puts the points of {src} "
                f"{fit.rms_px:.3g} px (RMS) away from their pixels: check its field of view and "
                "pose (a Blender camera's angle_y is the sensor's, not the image's), or give no "
                "camera and let Depict solve it from the position pass"
            )
        return dataclasses.replace(camera, fit=fit.as_dict())
    if camera is not None:  # intrinsics only: camera-space buffers, nothing to solve
        return camera
    finite_depth = None if depth is None else np.where(covered, depth, np.inf)
    try:
        solved, fit = solve_camera(points, covered, display_size, origin, finite_depth)
    except FrameError as exc:
        warnings.append(f"no camera solved from {src}: {exc}")
        return None
    return dataclasses.replace(
        solved, source=f"solved from {src} (world positions)", fit=fit.as_dict()
    )


#: A camera whose points land further than this from their pixels (RMS) gets a warning.
CAMERA_DISAGREES_PX = 0.5

#: Header attribute naming the layer of Depict's result in the files it writes ("" for R,G,B,A).
RESULT_ATTRIBUTE = "depict/result"


def _marked_result(pt: Passthrough, flat: Mapping[str, Any], warnings: list[str]) -> str | None:
    """The layer of an earlier Depict result (``depict/result``; "" for R,G,B,A), if the file
    has one whose channels are all there."""
    for header, _ in pt.parts:
        layer = header.get(RESULT_ATTRIBUTE)
        if isinstance(layer, str):
            if _resolve(flat, layer, 3) is not None:
                return layer
            warnings.append(f"{RESULT_ATTRIBUTE}={layer!r} names no RGB layer of the file")
    return None


def _file_camera(header: dict[str, Any], warnings: list[str]) -> Camera | None:
    try:
        return Camera.from_header(header)
    except Exception as exc:
        warnings.append(f"camera in the file ignored ({exc})")
        return None


def to_frame(
    passthrough: Passthrough,
    preset: str | Preset = "auto",
    camera: Camera | None = None,
    overrides: ReadOptions | Mapping[str, Any] | None = None,
) -> Frame:
    """Map a file's channels to canonical buffers (see the module docstring).

    Parameters
    ----------
    passthrough : the file as read (:func:`gbuffer.exr.read_parts`).
    preset : a preset name, a :class:`Preset`, or ``"auto"`` (:func:`detect`).
    camera : a camera that overrides the file's (``None``: the file's, if any).
    overrides : :class:`ReadOptions` (or its dict form).

    Returns
    -------
    Frame on the primary part's data window (the part holding the beauty, else the normals,
    else the depth), with ``sources`` naming the channels of each buffer and the passthrough
    kept for writing. Its ``passthrough.warnings`` (when an :class:`ExrPassthrough`) lists
    what the user should know (dropped layers, approximations).

    Raises
    ------
    FrameError
        NaN/Inf in a data channel, a bad mapping, a UINT channel for a float buffer.
    MissingCameraError
        World-space normals and no camera (unless ``require_camera`` is False).
    """
    opts = (
        overrides if isinstance(overrides, ReadOptions) else ReadOptions.from_dict(overrides or {})
    )
    where = passthrough.path if isinstance(passthrough, ExrPassthrough) else "frame"
    warnings: list[str] = passthrough.warnings if isinstance(passthrough, ExrPassthrough) else []
    if not passthrough.parts:
        raise FrameError(f"{where}: the file has no parts")
    reason = ""
    if isinstance(preset, str):
        if preset == "auto":
            preset, reason = detect(passthrough)
        elif preset not in PRESETS:
            raise FrameError(f"preset={preset!r} is not known; valid: auto, {', '.join(PRESETS)}")
        else:
            reason = "chosen by the user"
        p = PRESETS[preset]
    else:
        p, reason = preset, "chosen by the user"
    if isinstance(passthrough, ExrPassthrough):
        passthrough.preset_reason = reason

    flat = flat_channels(passthrough.parts)
    reader = _Reader(passthrough, flat, where, strict=opts.strict)
    prefix = opts.layer or ""
    if p.view_layer:
        prefix = _blender_prefix(flat, opts, warnings)
    result_layer = f"{prefix}.Depict" if p.view_layer and prefix else None
    marked = _marked_result(passthrough, flat, warnings)
    if marked is not None:
        result_layer = marked or None
        if "beauty" not in opts.mapping:  # an output of Depict: its result is the beauty
            opts = dataclasses.replace(opts, mapping={**opts.mapping, "beauty": marked or "R,G,B"})

    found: dict[str, list[str]] = {}
    spaces: dict[str, str] = {}
    for buffer, layers in p.buffers.items():
        names = _find(reader, buffer, layers, prefix, opts)
        if names is not None:
            found[buffer] = names
    for buffer, candidates in (("normal", p.normal), ("position", p.position)):
        override_space = opts.normal_space if buffer == "normal" else opts.position_space
        if buffer in opts.mapping:
            names = _find(reader, buffer, (), prefix, opts)
            space = override_space or (candidates[0][1] if candidates else "camera")
        else:
            names, space = None, ""
            for layer, sp in candidates:
                names = _find(reader, buffer, (layer,), prefix, opts)
                if names is not None:
                    space = override_space or sp
                    break
        if names is not None:
            found[buffer] = names
            spaces[buffer] = space
    for key in ("coverage", "roughness"):
        if key in opts.mapping and key not in found:
            names = _find(reader, key, (), prefix, opts)
            if names is not None:
                found[key] = names

    # The grid: the part that holds the beauty, else the normals, else the depth.
    primary = 0
    for key in ("beauty", "normal", "depth", "alpha"):
        if key in found:
            primary = flat[found[key][0]][0]
            break
    passthrough.primary = primary
    reader.set_primary(primary)
    header = passthrough.parts[primary][0]
    dx0, dy0, dx1, dy1 = (
        window(header, "displayWindow") if "displayWindow" in header else reader.grid
    )
    display_size = (dx1 - dx0 + 1, dy1 - dy0 + 1)
    origin = (reader.grid[0] - dx0, reader.grid[1] - dy0)

    if camera is None:
        camera = _file_camera(header, warnings)
    elif not camera.source:
        camera = dataclasses.replace(camera, source="given")

    buffers: dict[str, np.ndarray] = {}
    sources: dict[str, str] = {}
    depth_bg_value = opts.depth_background or p.depth_background

    # Background: alpha 0, or a depth sentinel.
    alpha = None
    background = np.zeros(reader.shape, bool)
    if "alpha" in found:
        alpha = reader.stack(found["alpha"], "alpha")
        _check_finite(reader, found["alpha"], alpha, None)
        background |= alpha <= 0.0
        buffers["alpha"] = alpha
        sources["alpha"] = found["alpha"][0]
    depth = None
    if "depth" in found:
        depth = reader.stack(found["depth"], "depth", fill=np.inf)
        nan = np.isnan(depth)
        if nan.any() and (nan & ~background).any() and not opts.strict:
            reader.add_holes(found["depth"][0], nan & ~background, radiance=False)
        elif nan.any() and (nan & ~background).any():
            ys, xs = np.nonzero(nan & ~background)
            raise FrameError(
                f"{where}: channel '{found['depth'][0]}' has {len(ys)} NaN value(s) on covered "
                f"pixels (first at x={xs[0]}, y={ys[0]} of the data window)"
            )
        with np.errstate(invalid="ignore"):
            background |= ~(np.isfinite(depth) & (depth > 0.0) & (depth < depth_bg_value))

    def load_checked(buffer: str, names: list[str]) -> np.ndarray:
        arr = reader.stack(names, buffer)
        _check_finite(reader, names, arr, background, radiance=buffer in ("beauty", "albedo"))
        return arr

    any_bg = bool(background.any())

    position = None
    if "position" in found:
        position = load_checked("position", found["position"])
        if spaces["position"] == "world":
            camera = _camera_from_positions(
                camera, position, ~background, display_size, origin, depth, found, warnings
            )

    if depth is not None:
        kind = opts.depth or p.depth_kind
        src = found["depth"][0]
        depth[background] = np.inf
        if kind == "distance":
            if camera is not None and (camera.fov_y_deg is not None or camera.ortho_height):
                vz = camera.view_vectors(reader.shape, display_size, origin)[..., 2]
                depth *= vz
                src += " (distance along the ray -> planar)"
            else:
                warnings.append(
                    f"depth {src} is the distance along the ray and no camera field of view is "
                    "known: used as planar depth (pass a camera to convert)"
                )
        buffers["depth"] = depth
        sources["depth"] = src

    if "beauty" in found:
        buffers["beauty"] = load_checked("beauty", found["beauty"])
        sources["beauty"] = _describe(found["beauty"])
    for key in ("albedo", "ao", "roughness"):
        if key in found:
            buffers[key] = load_checked(key, found[key])
            sources[key] = _describe(found[key])

    # Normals: decode, to camera space, renormalise, coverage.
    trust = None
    if "normal" in found:
        names = found["normal"]
        space = spaces["normal"]
        src = _describe(names)
        n = load_checked("normal", names)
        if opts.normal_encoding == "unsigned":
            n = n * np.float32(2.0) - np.float32(1.0)
        usable = True
        if space == "world" and (camera is None or camera.world_to_camera is None):
            if opts.require_camera:
                raise _camera_error(where, "normals", src, camera)
            warnings.append(f"normals {src} left out: world space and no camera")
            usable = False
        if usable:
            n = _to_camera_normals(n, space, camera)
            length = np.sqrt(cv2.transform(n * n, np.ones((1, 3), np.float32)))
            length = np.asarray(length, np.float32).reshape(reader.shape)
            empty = length < 1e-6
            # one pass: n * (1 / |n|), 0 where empty or background
            inv = np.zeros_like(length)
            np.divide(np.float32(1.0), length, out=inv, where=~(empty | background))
            n *= inv[..., None]
            trust = _trust(length, opts.normal_tolerance)
            trust[empty] = 0.0
            buffers["normal"] = n
            sources["normal"] = src + (f" ({space} -> camera)" if space != "camera" else "")
            if space == "world":
                _check_facing(n, camera, reader.shape, display_size, origin, src, warnings)

    if position is not None:
        names = found["position"]
        space = spaces["position"]
        src = _describe(names)
        pos = position
        if space == "world" and (camera is None or camera.world_to_camera is None):
            warnings.append(f"position {src} left out: world space and no camera")
        else:
            pos = _to_camera_points(pos, space, camera)
            pos[background] = 0.0
            buffers["position"] = pos
            sources["position"] = src + (f" ({space} -> camera)" if space != "camera" else "")
            if "depth" not in buffers:
                d = -pos[..., 2].copy()
                d[background | ~(d > 0)] = np.inf
                buffers["depth"] = d
                sources["depth"] = f"-z of position {src}"

    # Coverage.
    if "coverage" in found:
        cov = np.clip(load_checked("coverage", found["coverage"]), 0.0, 1.0)
        sources["coverage"] = _describe(found["coverage"])
    elif trust is not None or alpha is not None or depth is not None:
        parts = []
        if alpha is not None:
            parts.append("alpha")
        if trust is not None:
            parts.append("normal length")
        cov = np.ones(reader.shape, np.float32)
        if alpha is not None:
            np.minimum(cov, np.clip(alpha, 0.0, 1.0), out=cov)
        if trust is not None:
            np.minimum(cov, trust, out=cov)
        sources["coverage"] = f"min({', '.join(parts)})" if parts else "finite depth"
    else:
        cov = None
    if cov is not None:
        cov = cov.astype(np.float32, copy=False)
        if any_bg:
            cov[background] = 0.0
        buffers["coverage"] = cov

    # Lobes.
    lobe_sum = None
    for lobe in LOBES:
        spec = p.lobes.get(lobe, LobeSpec())
        parts_src: dict[str, str] = {}
        rad = _lobe_part(reader, f"{lobe}", spec.radiance, prefix, opts, background, parts_src)
        light = _lobe_part(reader, f"{lobe}.light", spec.light, prefix, opts, background, parts_src)
        color = _lobe_part(
            reader,
            f"{lobe}.color",
            tuple((c,) for c in spec.color),
            prefix,
            opts,
            background,
            parts_src,
            single=True,
        )
        if rad is None and light is not None and color is not None:
            rad = light * color
            parts_src[lobe] = f"({parts_src[lobe + '.light']}) * {parts_src[lobe + '.color']}"
        if rad is not None and light is None and color is not None:
            safe = np.where(color > 1e-6, color, np.float32(1.0))
            light = np.where(color > 1e-6, rad / safe, np.float32(0.0)).astype(np.float32)
            parts_src[lobe + ".light"] = f"{parts_src[lobe]} / {parts_src[lobe + '.color']}"
        for key, arr in ((lobe, rad), (f"{lobe}.light", light), (f"{lobe}.color", color)):
            if arr is not None:
                buffers[key] = arr
                sources[key] = parts_src[key]
        if rad is None and (light is not None or color is not None):
            warnings.append(f"{lobe}: light or colour found without the other; no {lobe} lobe")
        if rad is not None:
            lobe_sum = rad.copy() if lobe_sum is None else cv2.add(lobe_sum, rad)
    if lobe_sum is not None and "beauty" in buffers:
        buffers["remainder"] = cv2.subtract(buffers["beauty"], lobe_sum)
        present = [lobe for lobe in LOBES if lobe in buffers]
        sources["remainder"] = "beauty - (" + " + ".join(present) + ")"

    if not buffers:
        warnings.append(
            "no buffer recognised with preset "
            f"'{p.name}'; channels: {_channel_list(flat)} (choose --preset or --map)"
        )
    if marked is not None and "beauty" in sources:
        sources["beauty"] += " (Depict's result: depict/result)"
    frame = Frame(
        buffers=buffers,
        camera=camera,
        display_size=display_size,
        origin=origin,
        preset=p.name,
        sources=sources,
        passthrough=passthrough,
        result_layer=result_layer,
    )
    if reader.holes is not None:
        original = reader.stack(found["beauty"], "beauty") if "beauty" in found else None
        notes = mark_holes(frame, reader.holes, original)
        warnings += hole_warnings(reader.hole_channels, reader.masked_channels, notes)
    return frame


def _lobe_part(
    reader: _Reader,
    key: str,
    alternatives: Sequence[tuple[str, ...]],
    prefix: str,
    opts: ReadOptions,
    background: np.ndarray,
    sources: dict[str, str],
    single: bool = False,
) -> np.ndarray | None:
    """Sum of the layers of the first alternative with any layer present (3 components)."""
    if key in opts.mapping:
        names = _find(reader, key, (), prefix, opts, n=3)
        if names is None:
            return None
        arr = reader.stack(names, key)
        _check_finite(reader, names, arr, background, radiance=True)
        sources[key] = _describe(names)
        return arr
    for alt in alternatives:
        layers = []
        for layer in alt:
            names = _find(reader, key, (layer,), prefix, opts, n=3)
            if names is not None:
                layers.append(names)
        if not layers:
            continue
        total = []
        for names in layers:
            arr = reader.stack(names, key)
            _check_finite(reader, names, arr, background, radiance=True)
            total.append(arr)
        sources[key] = " + ".join(_describe(n) for n in layers)
        if single:
            return total[0]
        return _sum(total)
    return None


def _check_facing(
    n: np.ndarray,
    camera: Camera | None,
    shape: tuple[int, int],
    display_size: tuple[int, int],
    origin: tuple[int, int],
    src: str,
    warnings: list[str],
) -> None:
    """Warn when most converted normals face away from the camera (a convention mix-up)."""
    if camera is None:
        return
    try:
        view = camera.view_vectors(shape, display_size, origin)
    except FrameError:
        view = np.zeros((*shape, 3), np.float32)
        view[..., 2] = 1.0
    facing = np.einsum("ijk,ijk->ij", n, view)
    covered = np.abs(facing) > 1e-3
    if covered.sum() > 16 and (facing[covered] < 0).mean() > 0.5:
        warnings.append(
            f"most normals from {src} face away from the camera after the world -> camera "
            "conversion: check the camera matrix (world_to_camera, OpenGL convention)"
        )


def canonical_channels(frame: Frame) -> dict[str, np.ndarray]:
    """The frame's buffers under Depict's canonical channel names (DESIGN.md table)."""
    out: dict[str, np.ndarray] = {}
    b = frame.buffers

    def put(layer: str, arr: np.ndarray, suffixes: Sequence[str]) -> None:
        if arr.ndim == 2:
            out[f"{layer}.{suffixes[0]}" if layer else suffixes[0]] = arr
            return
        for k, s in enumerate(suffixes):
            out[f"{layer}.{s}" if layer else s] = np.ascontiguousarray(arr[..., k])

    if "beauty" in b:
        put("", b["beauty"], ("R", "G", "B"))
    if "alpha" in b:
        out["A"] = b["alpha"]
    if "normal" in b:
        put("N", b["normal"], ("X", "Y", "Z"))
    if "depth" in b:
        out["depth.Z"] = b["depth"]
    if "position" in b:
        put("P", b["position"], ("X", "Y", "Z"))
    if "albedo" in b:
        put("albedo", b["albedo"], ("R", "G", "B"))
    if "ao" in b:
        out["AO.X"] = b["ao"] if b["ao"].ndim == 2 else np.ascontiguousarray(b["ao"][..., 0])
    for key in ("coverage", "roughness"):
        if key in b:
            out[f"{key}.X"] = b[key]
    for lobe in LOBES:
        for key in (lobe, f"{lobe}.light", f"{lobe}.color"):
            if key in b:
                put(key, b[key], ("R", "G", "B"))
    return out
