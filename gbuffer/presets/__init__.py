"""Renderer presets: each renderer's channel names mapped to Depict's canonical buffers.

A preset is data (:class:`Preset`, the six of :data:`PRESETS` in :mod:`.table`): a table
(canonical buffer -> the layer names a renderer uses for it, first found wins), the renderer's
conventions (the space of its normals and positions, whether its depth is planar or the
distance along the ray, the depth value it writes on background) and the clues its files show
(:class:`Detection`). :func:`detect` weighs those clues (:mod:`.detect`); :func:`to_frame`
turns the file's channels into a :class:`~gbuffer.frame.Frame` (float32, canonical
conventions) in steps (:mod:`.convert`).

Modules: :mod:`.spec` (what a preset is made of), :mod:`.table` (the presets),
:mod:`.detect`, :mod:`.options` (:class:`ReadOptions`), :mod:`.channels` (channel names and
pixels), :mod:`.geometry` (camera space, the camera), :mod:`.convert` (:func:`to_frame`),
:mod:`.canonical` (the names Depict writes).

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

from gbuffer.presets.canonical import canonical_channels
from gbuffer.presets.channels import flat_channels
from gbuffer.presets.convert import RESULT_ATTRIBUTE, to_frame
from gbuffer.presets.detect import detect
from gbuffer.presets.geometry import CAMERA_DISAGREES_PX
from gbuffer.presets.options import DEPTH_KINDS, SPACES, ReadOptions, read_options
from gbuffer.presets.spec import DepthKind, Detection, LobeSpec, Preset, Space
from gbuffer.presets.table import PRESETS, find_preset, preset_help, preset_names

__all__ = [
    "CAMERA_DISAGREES_PX",
    "DEPTH_KINDS",
    "PRESETS",
    "RESULT_ATTRIBUTE",
    "SPACES",
    "DepthKind",
    "Detection",
    "LobeSpec",
    "Preset",
    "ReadOptions",
    "Space",
    "canonical_channels",
    "detect",
    "find_preset",
    "flat_channels",
    "preset_help",
    "preset_names",
    "read_options",
    "to_frame",
]
