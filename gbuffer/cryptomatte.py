"""Cryptomatte: ID mattes by name, decoded per the open Cryptomatte specification.

A Cryptomatte layer ``<name>`` (e.g. Blender's ``ViewLayer.CryptoObject``) stores ranked
(id, coverage) pairs in the channels ``<name>00.r/g/b/a``, ``<name>01.r/g/b/a`` ... (``r``/``b``:
ids, ``g``/``a``: their coverage, rank 0 first). The header names the layer in
``cryptomatte/<key>/name`` and maps names to ids in ``cryptomatte/<key>/manifest`` (JSON: name ->
8 hex digits), or in a sidecar JSON file ``cryptomatte/<key>/manif_file`` beside the EXR.

An id is the 32-bit MurmurHash3 (seed 0) of the name's UTF-8 bytes, read as a float32, with one
bit of the exponent flipped when the exponent is all zeros or all ones (so no id is a
denormal, an infinity or a NaN): :func:`id_bits`. The matte of a set of names is the sum of the
coverages of every rank whose id is one of theirs (:func:`matte`): exact at anti-aliased edges.
"""

from __future__ import annotations

import fnmatch
import json
from dataclasses import dataclass
from pathlib import Path, PurePosixPath
from typing import Any

import mmh3
import numpy as np

from gbuffer import exr
from gbuffer.atomic import read_text
from gbuffer.errors import FrameError
from gbuffer.frame import Frame

#: Channel suffixes of one rank pair, per naming convention (OpenEXR, Nuke).
_SUFFIXES = (("r", "g", "b", "a"), ("R", "G", "B", "A"), ("red", "green", "blue", "alpha"))
#: Layers are tried in this order when a mask does not name one.
_KIND_ORDER = ("object", "material", "asset")


def id_bits(name: str) -> int:
    """The Cryptomatte id of ``name`` as its uint32 bit pattern (the float32 id's bits)."""
    bits = mmh3.hash(name.encode("utf-8"), 0, signed=False)
    exponent = (bits >> 23) & 0xFF
    if exponent in (0, 0xFF):
        bits ^= 1 << 23
    return int(bits)


def id_float(name: str) -> float:
    """The Cryptomatte id of ``name`` as the float32 stored in the id channels."""
    return float(np.array([id_bits(name)], np.uint32).view(np.float32)[0])


@dataclass(frozen=True)
class Layer:
    """One Cryptomatte layer of a file: its header key, name, manifest (name -> id bits), the
    (id channel, coverage channel) names of every rank, rank 0 first, and the part holding them."""

    key: str
    name: str
    manifest: dict[str, int]
    ranks: tuple[tuple[str, str], ...]
    part: int = 0

    @property
    def short(self) -> str:
        """The name without the view layer (``CryptoObject`` for ``ViewLayer.CryptoObject``)."""
        return self.name.rsplit(".", 1)[-1]

    def select(self, patterns: list[str]) -> dict[str, int]:
        """The manifest entries whose names match one of ``patterns`` (fnmatch wildcards)."""
        return {
            name: bits
            for name, bits in self.manifest.items()
            if any(fnmatch.fnmatchcase(name, p) for p in patterns)
        }


def _manifest(header: dict[str, Any], key: str, directory: Path | None) -> dict[str, int]:
    text = header.get(f"cryptomatte/{key}/manifest")
    sidecar = header.get(f"cryptomatte/{key}/manif_file")
    where = f"cryptomatte/{key}/manifest"
    if text is None and sidecar:
        if directory is None:
            return {}  # a sidecar is only read beside a file on this machine
        rel = PurePosixPath(str(sidecar))
        if "\\" in str(sidecar) or rel.is_absolute() or ".." in rel.parts:
            raise FrameError(f"cryptomatte/{key}/manif_file {sidecar!r}: not a relative path")
        path = directory / rel
        try:
            text = read_text(path)
        except OSError as exc:
            raise FrameError(
                f"cannot read the Cryptomatte manifest {path}: {exc.strerror}"
            ) from None
        where = str(path)
    if text is None:
        return {}
    try:
        entries = json.loads(text)
        return {str(name): int(str(value), 16) for name, value in entries.items()}
    except (ValueError, AttributeError) as exc:
        raise FrameError(f"{where}: not a Cryptomatte manifest ({exc})") from None


def _ranks(name: str, channels: dict[str, Any]) -> tuple[tuple[str, str], ...]:
    ranks: list[tuple[str, str]] = []
    for level in range(100):
        prefix = f"{name}{level:02d}."
        found = next(
            (s for s in _SUFFIXES if all(prefix + c in channels for c in s)),
            None,
        )
        if found is None:
            break
        ranks += [(prefix + found[0], prefix + found[1]), (prefix + found[2], prefix + found[3])]
    return tuple(ranks)


def _same_grid(frame: Frame, index: int) -> bool:
    """Whether part ``index`` of the frame's file has the primary part's data window."""
    parts, primary = frame.passthrough.parts, frame.passthrough.primary
    if index == primary:
        return True
    (header, channels), (main, main_channels) = parts[index], parts[primary]
    return exr.window(header, "dataWindow", channels) == exr.window(
        main, "dataWindow", main_channels
    )


def layers(frame: Frame, sidecars: bool = True) -> list[Layer]:
    """The Cryptomatte layers of the frame's file (in any part on the frame's pixel grid),
    object layers first. ``sidecars``: read sidecar manifests beside the file (not for a file
    uploaded to the HTTP service)."""
    path = getattr(frame.passthrough, "path", "")
    directory = Path(path).parent if path and sidecars else None
    found: dict[str, Layer] = {}
    for index, (header, channels) in enumerate(frame.passthrough.parts):
        if not _same_grid(frame, index):
            continue
        for attr, value in header.items():
            key = attr.split("/")
            if len(key) != 3 or key[0] != "cryptomatte" or key[2] != "name" or value in found:
                continue
            ranks = _ranks(str(value), channels)
            if ranks:
                manifest = _manifest(header, key[1], directory)
                found[str(value)] = Layer(key[1], str(value), manifest, ranks, index)

    def order(layer: Layer) -> int:
        kinds = [k for k in _KIND_ORDER if k in layer.short.lower()]
        return _KIND_ORDER.index(kinds[0]) if kinds else len(_KIND_ORDER)

    return sorted(found.values(), key=order)


def _pixels(frame: Frame, layer: Layer, channel: str) -> np.ndarray:
    value = frame.passthrough.parts[layer.part][1][channel]
    return np.asarray(getattr(value, "pixels", value))


def _coverage(frame: Frame, layer: Layer, channel: str) -> np.ndarray:
    """A coverage channel as float32, NaN or Inf read as 0 (a damaged file's: they made every
    pixel a mask touched NaN)."""
    coverage = _pixels(frame, layer, channel).astype(np.float32)
    return np.where(np.isfinite(coverage), coverage, np.float32(0.0))


def matte(frame: Frame, layer: Layer, ids: list[int]) -> np.ndarray:
    """(H, W) float32: the coverage of the ids (uint32 bit patterns) in ``layer``, in [0, 1]."""
    wanted = np.asarray(sorted(set(ids)), np.uint32)
    out = np.zeros(frame.shape, np.float32)
    for id_channel, coverage_channel in layer.ranks:
        bits = np.ascontiguousarray(_pixels(frame, layer, id_channel), np.float32).view(np.uint32)
        hit = np.isin(bits, wanted)
        out += np.where(hit, _coverage(frame, layer, coverage_channel), np.float32(0))
    return np.clip(out, 0.0, 1.0)


def named_layers(frame: Frame, layer_name: str | None, sidecars: bool = True) -> list[Layer]:
    """The layers named ``layer_name`` (full or short name; ``None``: every layer, object
    layers first); FrameError naming what the file has when there is none."""
    found = layers(frame, sidecars)
    if not found:
        raise FrameError(
            "the file has no Cryptomatte layer (no cryptomatte/<key>/name in its header)"
        )
    named = [x for x in found if layer_name in (None, x.name, x.short)]
    if not named:
        have = ", ".join(x.name for x in found)
        raise FrameError(f"no Cryptomatte layer {layer_name!r}; the file has: {have}")
    return named


def find_layer(
    frame: Frame, layer_name: str | None, patterns: list[str], sidecars: bool = True
) -> tuple[Layer, dict[str, int]]:
    """The layer named ``layer_name`` (:func:`named_layers`; ``None``: the first whose manifest
    has a name matching ``patterns``) and the matching manifest entries; FrameError naming what
    the file has when nothing matches."""
    found = named_layers(frame, layer_name, sidecars)
    for candidate in found:
        chosen = candidate.select(patterns)
        if chosen:
            return candidate, chosen
    names = sorted({n for x in found for n in x.manifest})
    listed = ", ".join(names[:40]) + (" ..." if len(names) > 40 else "")
    raise FrameError(
        f"no Cryptomatte name matches {','.join(patterns)!r} in "
        f"{', '.join(x.name for x in found)}; names: {listed or 'none (no manifest)'}"
    )


def coverage_by_name(frame: Frame, layer: Layer) -> dict[str, float]:
    """Pixels covered by each manifest name (summed coverage over every rank), largest first."""
    totals: dict[int, float] = {}
    for id_channel, coverage_channel in layer.ranks:
        bits = np.ascontiguousarray(_pixels(frame, layer, id_channel), np.float32).view(np.uint32)
        values, inverse = np.unique(bits.ravel(), return_inverse=True)
        sums = np.bincount(inverse, weights=_coverage(frame, layer, coverage_channel).ravel())
        for value, total in zip(values.tolist(), sums.tolist(), strict=True):
            totals[value] = totals.get(value, 0.0) + total
    named = {name: round(totals.get(bits, 0.0), 2) for name, bits in layer.manifest.items()}
    return dict(sorted(named.items(), key=lambda kv: -kv[1]))


def describe(frame: Frame) -> list[dict[str, Any]]:
    """Every Cryptomatte layer: name, ranks and the pixels each manifest name covers."""
    return [
        {"name": x.name, "ranks": len(x.ranks), "names": coverage_by_name(frame, x)}
        for x in layers(frame)
    ]


def id_picture(frame: Frame, layer: Layer) -> np.ndarray:
    """(H, W, 3) float32 false-colour view of ``layer``: each id's colour (from its bits)
    weighted by its coverage, summed over the ranks."""
    out = np.zeros((*frame.shape, 3), np.float32)
    for id_channel, coverage_channel in layer.ranks:
        bits = np.ascontiguousarray(_pixels(frame, layer, id_channel), np.float32).view(np.uint32)
        rgb = np.dstack([(bits >> s) & 0xFF for s in (0, 8, 16)]).astype(np.float32) / 255.0
        coverage = _coverage(frame, layer, coverage_channel)[..., None]
        out += (0.25 + 0.75 * rgb) * np.where(bits[..., None] == 0, 0.0, coverage)
    return np.clip(out, 0.0, 1.0)
