"""Which preset fits a file: the clues every preset declares (its
:class:`~gbuffer.presets.spec.Detection`), tried from the strongest to the weakest."""

from __future__ import annotations

from typing import Any

from gbuffer.frame import Passthrough
from gbuffer.presets.spec import FileView, Preset
from gbuffer.presets.table import FALLBACK, PRESETS

#: Header attributes whose value names the software that wrote the file.
SOFTWARE_KEYS = ("software", "Software", "writer", "creator", "dcc")


def detect(parts: Any) -> tuple[str, str]:
    """The preset that fits a file, and why.

    Parameters
    ----------
    parts : a :class:`Passthrough` or its list of ``(header, channels)``.

    Returns
    -------
    (preset name, one-line reason), e.g. ``("blender", "header attribute BlenderMultiChannel")``.
    Renderer header signatures (attribute names, then the software value) are checked first,
    then the presets' channel clues by rank (renderer channel names, then Depict's own
    ``depict/*`` attributes: Depict also writes them into renderer files it gives back, then
    canonical names); the fallback is ``canonical``.
    """
    plist = list(parts.parts) if isinstance(parts, Passthrough) else list(parts)
    file = FileView(plist)
    found = _by_header_key(file) or _by_software(file) or _by_channels(file)
    if found is None:
        return FALLBACK.name, "no renderer signature found; using Depict's canonical names"
    preset, reason = found
    return preset.name, reason


def _by_header_key(file: FileView) -> tuple[Preset, str] | None:
    """The first header attribute (part by part) that a renderer's signature names."""
    for key in file.keys:
        for preset in PRESETS.values():
            pattern = preset.detection.header_pattern
            if pattern is not None and pattern.fullmatch(key):
                return preset, f"header attribute {key}"
    return None


def _by_software(file: FileView) -> tuple[Preset, str] | None:
    """A renderer's word in a header's software value (part by part, key by key)."""
    for header, _ in file.parts:
        for key in SOFTWARE_KEYS:
            value = header.get(key)
            if not isinstance(value, str):
                continue
            low = value.lower()
            for preset in PRESETS.values():
                if any(word in low for word in preset.detection.software):
                    return preset, f"header {key}={value!r}"
    return None


def _by_channels(file: FileView) -> tuple[Preset, str] | None:
    """The first channel clue that matches, presets by rank."""
    for preset in sorted(PRESETS.values(), key=lambda p: p.detection.rank):
        for clue in preset.detection.channels:
            reason = clue.find(file)
            if reason is not None:
                return preset, reason
    return None
