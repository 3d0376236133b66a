"""What a renderer preset is made of: where each buffer is found, the renderer's conventions and
the clues that tell its files apart (:mod:`gbuffer.presets.table` holds the presets).

A preset is data: :class:`Preset` lists, for each canonical buffer, the layer names a renderer
writes it under (first found wins), the space of its normals and positions, its depth convention,
and a :class:`Detection` saying how :func:`gbuffer.presets.detect` recognises its files: header
attribute names that only it writes, words of the header's ``software`` value, and channel-name
clues (:class:`PassNames`, :class:`NamePrefix`, :class:`LayerNames`, :class:`PartName`,
:class:`HeaderMark`, :class:`ChannelSet`), each of which says why it matched.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, Literal

from gbuffer.presets.channels import flat_channels

Space = Literal["world", "camera", "camera-lh"]
DepthKind = Literal["planar", "distance"]


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


# -- what a file shows of itself ----------------------------------------------------------------


@dataclass(frozen=True)
class FileView:
    """A file as the clues look at it: its parts' headers and channels."""

    parts: Sequence[tuple[dict[str, Any], dict[str, Any]]]

    @cached_property
    def names(self) -> list[str]:
        """Channel names as presets see them (multi-part layers as ``<part name>.<channel>``,
        :func:`gbuffer.presets.channels.flat_channels`)."""
        return list(flat_channels(self.parts))

    @cached_property
    def keys(self) -> list[str]:
        """Header attribute names, part by part."""
        return [key for header, _ in self.parts for key in header]

    @cached_property
    def name_set(self) -> frozenset[str]:
        return frozenset(self.names)

    @cached_property
    def layers(self) -> frozenset[str]:
        """Channel names without their last component (``"diffuse_direct.R"`` ->
        ``"diffuse_direct"``; a bare ``"Ci"`` stays ``"Ci"``)."""
        return frozenset(n.rpartition(".")[0] or n for n in self.names)


@dataclass(frozen=True)
class PassNames:
    """Channels named ``<view layer>.<pass>.<component>`` with one of ``passes`` (Blender): the
    view layer is found from them too (:meth:`view_layer`)."""

    passes: tuple[str, ...]
    reason: str

    @cached_property
    def pattern(self) -> re.Pattern[str]:
        alternatives = "|".join(re.escape(p) for p in self.passes)
        return re.compile(rf"^(.+)\.({alternatives})\.[A-Za-z]+$")

    def view_layer(self, name: str) -> str | None:
        """The view layer of channel ``name`` when it is one of the passes, else None."""
        match = self.pattern.match(name)
        return match.group(1) if match else None

    def find(self, file: FileView) -> str | None:
        return self.reason if any(self.pattern.match(n) for n in file.names) else None


@dataclass(frozen=True)
class NamePrefix:
    """A channel whose name starts with one of ``prefixes`` (V-Ray's ``VRay*`` elements)."""

    prefixes: tuple[str, ...]
    reason: str

    def find(self, file: FileView) -> str | None:
        return self.reason if any(n.startswith(self.prefixes) for n in file.names) else None


@dataclass(frozen=True)
class LayerNames:
    """Layers (or bare channels) named like the renderer's AOVs, unless every channel of
    ``unless`` is there too (a file with Depict's canonical names that shares an AOV name)."""

    names: frozenset[str]
    label: str
    unless: frozenset[str] = frozenset()

    def find(self, file: FileView) -> str | None:
        found = file.layers & self.names
        if not found or (self.unless and self.unless <= file.name_set):
            return None
        return f"{self.label} ({', '.join(sorted(found))})"


@dataclass(frozen=True)
class PartName:
    """A multi-part file with a part called ``name`` (Karma's beauty part ``C``)."""

    name: str
    reason: str

    def find(self, file: FileView) -> str | None:
        names = {str(h.get("name")) for h, _ in file.parts if h.get("name")}
        return self.reason if len(file.parts) > 1 and self.name in names else None


@dataclass(frozen=True)
class HeaderMark:
    """A header attribute whose name starts with ``prefix`` (Depict marks the files it writes,
    renderer files it gives back too: a weaker clue than the renderers' own)."""

    prefix: str

    def find(self, file: FileView) -> str | None:
        key = next((k for k in file.keys if k.startswith(self.prefix)), None)
        return None if key is None else f"header attribute {key}"


@dataclass(frozen=True)
class ChannelSet:
    """Every channel of one of ``sets`` is in the file."""

    sets: tuple[frozenset[str], ...]
    reason: str

    def find(self, file: FileView) -> str | None:
        return self.reason if any(s <= file.name_set for s in self.sets) else None


Clue = PassNames | NamePrefix | LayerNames | PartName | HeaderMark | ChannelSet


@dataclass(frozen=True)
class Detection:
    """How :func:`gbuffer.presets.detect` recognises a renderer's files.

    Attributes
    ----------
    header_keys : a regular expression (full match) for header attribute names only this
        renderer writes: the strongest clue.
    software : words (lower case) of the header's software / writer / creator / dcc value.
    channels : clues in the channel names, weaker than any header clue; each preset's are tried
        in ``rank`` order (the most specific names first) after every header clue.
    rank : the order of this preset's channel clues among the presets'.
    """

    header_keys: str | None = None
    software: tuple[str, ...] = ()
    channels: tuple[Clue, ...] = ()
    rank: int = 0

    @cached_property
    def header_pattern(self) -> re.Pattern[str] | None:
        return None if self.header_keys is None else re.compile(self.header_keys, re.DOTALL)


@dataclass(frozen=True)
class Preset:
    """A renderer's names and conventions (:mod:`gbuffer.presets`).

    Attributes
    ----------
    name, description : what ``--preset`` takes and what the README's table says of it.
    buffers : canonical buffer -> layer names, first found wins (``""``: the bare R, G, B).
    normal, position : (layer, space) candidates, first found wins.
    lobes : lobe -> where its radiance, light and colour come from.
    depth_kind : "planar" (-z camera) or "distance" (along the ray).
    depth_background : depth values at or above this are background.
    view_layer : the passes that carry a view-layer prefix (``ViewLayer.Normal.X``, Blender);
        ``None`` when layers are named as they are.
    detection : how its files are recognised.
    colorspace : the working space its files are in when the header does not say (a name of
        the OpenColorIO config); ``None``: Depict's default, linear Rec.709.
    """

    name: str
    description: str
    buffers: Mapping[str, tuple[str, ...]]
    normal: tuple[tuple[str, Space], ...] = ()
    position: tuple[tuple[str, Space], ...] = ()
    lobes: Mapping[str, LobeSpec] = field(default_factory=dict)
    depth_kind: DepthKind = "planar"
    depth_background: float = 1e10
    view_layer: PassNames | None = None
    detection: Detection = field(default_factory=Detection)
    colorspace: str | None = None
