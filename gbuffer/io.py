"""Frames from and to EXR files: ``read``, ``write``, ``describe``.

``read`` = :func:`gbuffer.exr.read_parts` (every part, channel and attribute, with a pixel
limit checked on the header) + :func:`gbuffer.presets.to_frame` (the renderer's names mapped to
canonical buffers).

``write`` gives the file back with the frame's ``outputs`` and ``attributes`` in the place
``layout`` says (below; by default an added part, the input's parts copied as they are). In the
``same`` layout they become channels of the primary part (the part whose data window is the
frame grid) and attributes of its header:

* an output named like an existing channel replaces its pixels and keeps its pixel type
  (HALF stays HALF); a new output is a FLOAT channel;
* every part keeps its compression, lossy ones (DWAA/DWAB/B44/B44A/PXR24) included, so an
  output is about the size of its input; what re-encoding a changed part with a lossy codec
  costs is returned as a warning (:func:`_lossy_notes`: DWA re-quantises its R, G, B, Y
  channels, PXR24 rounds new 32-bit layers to 24 bits; B44 keeps 32-bit layers exact);
* parts and channels that did not change are copied chunk for chunk (bit-identical).

``layout`` (:data:`LAYOUTS`, default :data:`DEFAULT_LAYOUT`) chooses where new channels go:

* ``"same"``: into the primary part, as above (every channel of that part is encoded again);
* ``"part"`` (the default): into an added part of a multi-part file (named after
  ``depict/result``), with the header attributes (those OpenEXR requires every part to share,
  e.g. ``chromaticities``, go to every part); every part of the input is copied chunk for chunk,
  nothing is re-encoded
  but the new layers (when an output replaces a channel of the primary part, e.g. a second
  enhance of a ``part`` output, that part is re-encoded with every new layer, as ``"same"``);
* ``"sidecar"``: a file with only the outputs and the header attributes (one part, ZIP, the
  input's windows and the attributes OpenEXR has every part share: pixel aspect ratio, time
  code, chromaticities); the input stays where it is and holds the G-buffer.

A frame built in memory (no passthrough, e.g. a render) is written as one part with Depict's
canonical channel names (DESIGN.md): radiance (beauty, alpha, albedo, lobes) as HALF unless it
exceeds the half range, everything else (normals, depth, position, AO, coverage, outputs) as
FLOAT, ZIP compression, the camera as ``worldToCamera``/``worldToNDC`` + ``depict/*``.
"""

from __future__ import annotations

import dataclasses
import json
import struct
from pathlib import Path
from typing import Any, Final

import numpy as np
import OpenEXR

from gbuffer import cryptomatte, exr
from gbuffer.camera import Camera
from gbuffer.colorspace import resolve_leniently
from gbuffer.errors import FrameError
from gbuffer.frame import LOBES, Frame, Passthrough
from gbuffer.presets import (
    RESULT_ATTRIBUTE,
    ReadOptions,
    canonical_channels,
    detect,
    find_preset,
    read_options,
    to_frame,
)

#: Header keys an output attribute may not replace (they describe the pixels).
PROTECTED_ATTRIBUTES = frozenset(
    {"channels", "chunkCount", "dataWindow", "type", "tiles", "name", "lineOrder"}
)

_HALF_MAX = 65000.0

#: Where :func:`write` puts new channels (module docstring).
LAYOUTS = ("same", "part", "sidecar")
#: The default everywhere (CLI, HTTP, batch, Python): nothing of the input is encoded again.
DEFAULT_LAYOUT: Final = "part"


def _camera_arg(camera: Camera | dict[str, Any] | str | Path | None) -> Camera | None:
    if camera is None or isinstance(camera, Camera):
        return camera
    if isinstance(camera, dict):
        return Camera.from_dict(camera)
    if isinstance(camera, str | Path):
        return Camera.from_json_file(camera)
    raise FrameError(
        f"camera must be a Camera, a dict or a path to camera JSON, not {type(camera).__name__}"
    )


def read(
    path: str | Path,
    preset: str = "auto",
    camera: Camera | dict[str, Any] | str | Path | None = None,
    options: ReadOptions | dict[str, Any] | None = None,
    max_pixels: int | None = None,
    limits: exr.Limits | None = None,
    *,
    release: bool = False,
) -> Frame:
    """Read an EXR G-buffer into a :class:`Frame`.

    Parameters
    ----------
    path : the EXR file.
    preset : "auto" (detected from the header and channel names) or the name of one of
        :data:`gbuffer.presets.PRESETS`.
    camera : a :class:`Camera`, its JSON dict, or a path to camera JSON; it overrides the
        file's camera.
    options : :class:`gbuffer.presets.ReadOptions` (or its dict): mapping and convention
        overrides.
    max_pixels : refuse (LimitError) a part whose data window is larger, before decoding.
    limits : pixels, decoded bytes and channels the header may claim
        (:class:`gbuffer.limits.Limits`; default: the ``DEPICT_MAX_*`` variables when set).
    release : let go of the file's decoded channels as the buffers are made, and of the rest
        after (:func:`gbuffer.exr.release_pixels`): for a frame written with the ``part`` or
        ``sidecar`` layout, whose input parts are copied, not encoded again.

    Raises
    ------
    FrameError (and its subclasses LimitError, MissingCameraError) with a one-line message.
    """
    cam = _camera_arg(camera)
    passthrough = exr.read_parts(path, max_pixels, limits=limits)
    frame = to_frame(passthrough, preset, cam, options, release=release)
    if release:
        exr.release_pixels(passthrough)
    return frame


def _grid_shape(pt: Passthrough) -> tuple[int, int]:
    header, channels = pt.parts[pt.primary]
    x0, y0, x1, y1 = exr.window(header, "dataWindow", channels)
    return (y1 - y0 + 1, x1 - x0 + 1)


def _output_array(name: str, arr: Any, shape: tuple[int, int]) -> np.ndarray:
    a = np.asarray(arr)
    if a.shape != shape:
        raise FrameError(
            f"output '{name}' has shape {a.shape}; outputs are (H, W) = {shape} on the frame grid"
        )
    if a.dtype.kind not in "fiub":
        raise FrameError(f"output '{name}' has dtype {a.dtype}; outputs are float32 arrays")
    # (HALF stays HALF: the input's own R, G, B, A kept beside a result, bit for bit)
    return np.ascontiguousarray(a, dtype=np.float16 if a.dtype == np.float16 else np.float32)


def _check_attributes(attributes: dict[str, Any]) -> None:
    bad = sorted(set(attributes) & PROTECTED_ATTRIBUTES)
    if bad:
        raise FrameError(
            f"frame.attributes may not set {bad}: they describe the pixels "
            f"(protected: {', '.join(sorted(PROTECTED_ATTRIBUTES))})"
        )


def write(frame: Frame, path: str | Path, layout: str = DEFAULT_LAYOUT) -> list[str]:
    """Write ``frame`` to ``path`` in ``layout`` (see the module docstring for what goes where).

    Returns
    -------
    Warnings (compression switched to lossless, mip-map levels dropped, ...).

    Raises
    ------
    FrameError
        An output of the wrong shape, an output over a UINT channel, a protected attribute,
        or an I/O error.
    """
    _check_attributes(frame.attributes)
    if layout not in LAYOUTS:
        raise FrameError(f"layout {layout!r} is not one of {', '.join(LAYOUTS)}")
    pt = frame.passthrough
    if not pt.parts or layout == "sidecar":
        return _write_fresh(frame, path, buffers=not pt.parts)
    warnings: list[str] = []
    parts = [(dict(h), dict(c)) for h, c in pt.parts]
    header, channels = parts[pt.primary]
    shape = _grid_shape(pt)
    added: dict[str, Any] = {}
    # a part that is re-encoded anyway (an output replaces one of its channels) takes the new
    # layers too, so that its header and theirs cannot disagree
    own_part = layout == "part" and not any(name in channels for name in frame.outputs)
    over_half: list[str] = []  # outputs into HALF channels with values half cannot hold
    for name, arr in frame.outputs.items():
        pixels = _output_array(name, arr, shape)
        old = channels.get(name)
        if old is not None:
            released = isinstance(old, exr.ReleasedChannel)
            old_type = old.dtype if released else getattr(old, "pixels", old).dtype
            if old_type == np.uint32:
                raise FrameError(f"output '{name}' would overwrite a UINT channel of the file")
            if getattr(old, "xSampling", 1) != 1 or getattr(old, "ySampling", 1) != 1:
                raise FrameError(f"output '{name}' would overwrite a subsampled channel")
            if old_type == np.float16:
                pixels, over = _to_half(pixels)
                over_half += [f"{name} ({over})"] if over else []
            channels[name] = OpenEXR.Channel(name, pixels, 1, 1, bool(getattr(old, "pLinear", 0)))
        else:
            (added if own_part else channels)[name] = OpenEXR.Channel(name, pixels)
    if over_half:
        warnings.append(
            f"values beyond HALF's largest, {HALF_MAX:g}, clamped to it in the input's HALF "
            f"channels: {', '.join(over_half)} (the part or sidecar layout writes the result "
            "as FLOAT)"
        )
    compression = header.get("compression")
    if not added and frame.outputs and compression is not None:
        if int(compression) in exr.LOSSY_COMPRESSIONS:
            new = [name for name in frame.outputs if name not in pt.parts[pt.primary][1]]
            floats = [name for name in new if channels[name].pixels.dtype == np.float32]
            warnings += _lossy_notes(pt.primary, exr.compression_name(header), new, floats)
    if added:  # the header attributes go with the added layers
        header = _added_part(parts, header, frame.attributes)
        parts.append((header, added))
    for key, value in frame.attributes.items():
        header[key] = value
    if added:
        _share_attributes(parts, header)
    new_pt = dataclasses.replace(pt, parts=parts)
    warnings += exr.write_parts(new_pt, path)
    return warnings


#: The largest finite HALF value.
HALF_MAX = float(np.finfo(np.float16).max)


def _to_half(pixels: np.ndarray) -> tuple[np.ndarray, int]:
    """``pixels`` as HALF, finite values beyond :data:`HALF_MAX` clamped to it (the cast made
    them inf), and how many were."""
    beyond = np.isfinite(pixels) & (np.abs(pixels) > HALF_MAX)
    over = int(np.count_nonzero(beyond))
    if over:
        pixels = np.where(beyond, np.copysign(np.float32(HALF_MAX), pixels), pixels)
    return pixels.astype(np.float16), over


def _added_part(
    parts: list[tuple[dict[str, Any], dict[str, Any]]],
    primary: dict[str, Any],
    attributes: dict[str, Any],
) -> dict[str, Any]:
    """The header of the part ``layout="part"`` adds: the primary part's windows, its compression
    when lossless (else ZIP), a name no other part has (the result layer's, else ``depict``)."""
    compression = primary.get("compression", OpenEXR.ZIP_COMPRESSION)
    if int(compression) in exr.LOSSY_COMPRESSIONS:
        compression = OpenEXR.ZIP_COMPRESSION
    data_window = primary.get("dataWindow")
    header: dict[str, Any] = {
        "compression": compression,
        "lineOrder": OpenEXR.INCREASING_Y,
        "type": OpenEXR.scanlineimage,
    }
    for key in _WINDOWS:
        if key in primary:
            header[key] = primary[key]
    if data_window is not None and "displayWindow" not in header:
        header["displayWindow"] = data_window
    taken = {str(h.get("name") or f"part{i}") for i, (h, _) in enumerate(parts)}
    base = str(attributes.get(RESULT_ATTRIBUTE) or "depict")
    name, n = base, 0
    while name in taken:
        n += 1
        name = f"{base}{n}"
    header["name"] = name
    return header


#: Attributes every part of a multi-part file must carry with one value (OpenEXR's rule).
SHARED_ATTRIBUTES = ("displayWindow", "pixelAspectRatio", "timeCode", "chromaticities")


def _share_attributes(
    parts: list[tuple[dict[str, Any], dict[str, Any]]], added: dict[str, Any]
) -> None:
    """Give every part the shared attributes of the added part (e.g. the chromaticities of
    ``--colorspace``), else the first value a part has: readers refuse a multi-part file whose
    parts disagree. Only headers change; the parts' chunks are still copied."""
    for key in SHARED_ATTRIBUTES:
        value = added.get(key)
        if value is None:
            value = next((h[key] for h, _ in parts if h.get(key) is not None), None)
        if value is not None:
            for h, _ in parts:
                h[key] = value


#: Channel-name suffixes DWAA/DWAB quantise (OpenEXR's DWA rules, case-sensitive, HALF and FLOAT).
DWA_LOSSY_SUFFIXES = frozenset({"R", "G", "B", "Y", "BY", "RY"})


def _lossy_notes(part: int, codec: str, new: list[str], floats: list[str]) -> list[str]:
    """What re-encoding a changed part with its own lossy ``codec`` costs (one line, or none);
    ``new``: the layers added to it, of which ``floats`` are FLOAT (the others HALF, e.g. the
    input's own R, G, B, A moved aside).

    Measured with OpenEXR 3.4: B44/B44A and PXR24 give back exactly what they decode
    (idempotent) and B44 leaves FLOAT channels exact, so new 32-bit layers are exact; PXR24
    rounds new FLOAT layers to 24 bits; DWAA/DWAB re-quantise every R, G, B, Y, BY, RY channel
    again (about half the first encoding's error) and quantise new layers so named.
    """
    if codec in ("DWAA", "DWAB"):
        data = [n for n in new if n.rpartition(".")[2] in DWA_LOSSY_SUFFIXES - {"R", "G", "B"}]
        also = f"; new data layers it quantises: {', '.join(data[:6])}" if data else ""
        return [
            f"part {part} is written with {codec} as it was read: {codec} is lossy and not "
            "idempotent, so its R, G, B, Y channels lose a little more precision (re-save the "
            "input with ZIP or PIZ to avoid it, e.g. oiiotool IN.exr --compression zip -o "
            f"IN_zip.exr){also}"
        ]
    if codec == "PXR24" and floats:
        more = ", ..." if len(floats) > 6 else ""
        return [
            f"part {part} is written with PXR24 as it was read: its new 32-bit layers "
            f"({', '.join(floats[:6])}{more}) are rounded to 24 bits"
        ]
    return []


def _radiance_keys() -> set[str]:
    keys = {"beauty", "alpha", "albedo"}
    for lobe in LOBES:
        keys |= {lobe, f"{lobe}.light", f"{lobe}.color"}
    return keys


#: The header attributes that place a part's pixels (the part `layout="part"` adds: the input's).
_WINDOWS = ("dataWindow", "displayWindow", "pixelAspectRatio")


def _write_fresh(frame: Frame, path: str | Path, buffers: bool = True) -> list[str]:
    """One part, ZIP: the frame's buffers under canonical names (``buffers``) and its outputs."""
    warnings: list[str] = []
    channels = canonical_channels(frame) if buffers else {}
    radiance_names = (
        set(canonical_channels(_subframe(frame, _radiance_keys()))) if buffers else set()
    )
    shape = frame.shape
    pixels: dict[str, np.ndarray] = {}
    for name, arr in channels.items():
        a = np.ascontiguousarray(arr, dtype=np.float32)
        if name in radiance_names:
            finite = a[np.isfinite(a)]
            if finite.size == 0 or float(np.abs(finite).max()) < _HALF_MAX:
                a = a.astype(np.float16)
        pixels[name] = a
    for name, arr in frame.outputs.items():
        pixels[name] = _output_array(name, arr, shape)
    if not pixels:
        raise FrameError(f"{path}: the frame has no buffers or outputs to write")
    h, w = shape
    assert frame.display_size is not None
    dw, dh = frame.display_size
    ox, oy = frame.origin
    header: dict[str, Any] = {
        "compression": OpenEXR.ZIP_COMPRESSION,
        "dataWindow": exr.box2i(ox, oy, ox + w - 1, oy + h - 1),
        "displayWindow": exr.box2i(0, 0, dw - 1, dh - 1),
        "lineOrder": OpenEXR.INCREASING_Y,
        "type": OpenEXR.scanlineimage,
    }
    if frame.passthrough.parts:  # a sidecar: the input's windows as they are (the frame's own
        # are relative to the display window's corner, which a file may put anywhere), and what
        # OpenEXR has every part of a file share (the chromaticities its colours are in, ...)
        primary = frame.passthrough.parts[frame.passthrough.primary][0]
        header.update({k: primary[k] for k in ("dataWindow", *SHARED_ATTRIBUTES) if k in primary})
    cam = frame.camera
    if cam is not None:
        if cam.has_intrinsics:
            header.update(cam.to_header(frame.display_size))
        else:
            warnings.append("camera without field of view or ortho height: not written")
    for key, value in frame.attributes.items():
        header[key] = value
    chans = {name: OpenEXR.Channel(name, a) for name, a in pixels.items()}
    warnings += exr.write_parts(Passthrough(parts=[(header, chans)]), path)
    return warnings


def _subframe(frame: Frame, keys: set[str]) -> Frame:
    sub = frame.copy()
    sub.buffers = {k: v for k, v in frame.buffers.items() if k in keys}
    return sub


def inspect(
    path: str | Path,
    preset: str = "auto",
    camera: Camera | dict[str, Any] | str | Path | None = None,
    options: ReadOptions | dict[str, Any] | None = None,
    max_pixels: int | None = None,
) -> dict[str, Any]:
    """:func:`describe` of any readable file (``depict inspect``): world-space normals with no
    camera are left out (``missing`` says so) and a file whose buffers cannot be mapped (a NaN in
    a data channel, ...) is still described, the reason in ``problems``. An unreadable file, an
    unknown preset or a bad explicit mapping still raise :class:`FrameError`."""
    cam = _camera_arg(camera)
    opts = dataclasses.replace(read_options(options), require_camera=False, strict=False)
    if preset != "auto":
        find_preset(preset)  # an unknown name is refused before the file is read
    passthrough = exr.read_parts(path, max_pixels)
    try:
        frame = to_frame(passthrough, preset, cam, opts)
        problems: list[str] = []
    except FrameError as exc:
        if opts.mapping:
            raise
        header = passthrough.parts[0][0]
        x0, y0, x1, y1 = exr.window(header, "displayWindow", passthrough.parts[0][1])
        name = preset if preset != "auto" else detect(passthrough)[0]
        size = (x1 - x0 + 1, y1 - y0 + 1)
        frame = Frame(buffers={}, display_size=size, preset=name, passthrough=passthrough)
        problems = [str(exc)]
        default = find_preset(name).colorspace
        frame.colorspace = resolve_leniently(opts.colorspace, header, name, default, problems)
    info = describe(frame)
    info["problems"] = problems
    return info


#: Buffers most operators need, and what their absence means.
_KEY_BUFFERS = {
    "beauty": "the image to enhance (operators that rebuild it from lobes or shade the G-buffer "
    "still run)",
    "normal": "curvature, Radiance Scaling, Light Alignment, Apparent Relief need it",
    "depth": "every operator needs it (or a position pass)",
}


def _missing(frame: Frame) -> list[str]:
    """What the frame lacks that operators need, one line each."""
    out = [f"{name}: {why}" for name, why in _KEY_BUFFERS.items() if name not in frame.buffers]
    if frame.camera is None:
        out.append(
            "camera: none in the file, none given, none solved (no world-space position pass); "
            "world-space normals and sizes in scene units need one (--camera CAM.json)"
        )
    return out


def header_json(text: object) -> Any:
    """The JSON a ``depict/*`` header attribute holds, or None where it holds none (not text,
    not JSON, nested past Python's recursion limit: another tool's or a damaged file's)."""
    if not isinstance(text, str):
        return None
    try:
        return json.loads(text)
    except (ValueError, RecursionError):
        return None


def _provenance(header: dict[str, Any]) -> dict[str, Any] | None:
    """What Depict wrote about an output it made (version, pipeline, input, result layer); a
    pipeline or history that is not JSON as its text."""
    keys = ("version", "input", "pipeline", "result", "original", "history")
    found = {k: header[f"depict/{k}"] for k in keys if isinstance(header.get(f"depict/{k}"), str)}
    for key in ("pipeline", "history"):
        if key in found:
            parsed = header_json(found[key])
            found[key] = found[key] if parsed is None else parsed
    return found or None


def describe(frame: Frame) -> dict[str, Any]:
    """The stable JSON form of a frame (``depict inspect --json``).

    Keys: ``file``, ``preset``, ``preset_reason``, ``size`` ([w, h] of the grid),
    ``display_window`` and ``data_window`` ([xmin, ymin, xmax, ymax], inclusive), ``parts``
    (name, channels, type, compression, tiled), ``buffers`` (name -> source, shape),
    ``camera`` (camera JSON or null), ``camera_source`` (where it came from: given, file header,
    solved from a position pass), ``camera_fit`` (its reprojection error against the world-space
    position pass: rms_px, max_px, pixels, outliers; null without one), ``missing`` (what
    operators need and the frame lacks), ``depict`` (what Depict wrote into a file it made:
    version, input, pipeline, result layer, original layer, history; null otherwise),
    ``colorspace`` (the working space of the radiance: name, source, luminance weights, white,
    RGB-to-XYZ; :mod:`gbuffer.colorspace`), ``cryptomatte`` (each Cryptomatte layer: name, ranks,
    the pixels each manifest name covers), ``warnings``.
    """
    pt = frame.passthrough
    assert frame.display_size is not None
    dw, dh = frame.display_size
    parts = []
    if pt.parts:
        header, primary_channels = pt.parts[pt.primary]
        x0, y0, x1, y1 = exr.window(header, "dataWindow", primary_channels)
        if "displayWindow" in header:
            display = list(exr.window(header, "displayWindow"))
        else:
            display = [0, 0, dw - 1, dh - 1]
        data = [x0, y0, x1, y1]
        size = [x1 - x0 + 1, y1 - y0 + 1]
        for i, (h, channels) in enumerate(pt.parts):
            kind = exr.storage_name(h)
            parts.append(
                {
                    "name": h.get("name") or (f"part{i}" if len(pt.parts) > 1 else None),
                    "channels": sorted(channels),
                    "type": kind,
                    "compression": exr.compression_name(h),
                    "tiled": kind == "tiledimage",
                }
            )
    else:
        hh, ww = frame.shape
        ox, oy = frame.origin
        display = [0, 0, dw - 1, dh - 1]
        data = [ox, oy, ox + ww - 1, oy + hh - 1]
        size = [ww, hh]
    buffers = {
        name: {"source": frame.sources.get(name, ""), "shape": list(arr.shape)}
        for name, arr in sorted(frame.buffers.items())
    }
    return {
        "file": getattr(pt, "path", None) or None,
        "preset": frame.preset,
        "preset_reason": getattr(pt, "preset_reason", "") or "",
        "size": size,
        "display_window": display,
        "data_window": data,
        "parts": parts,
        "buffers": buffers,
        "camera": None if frame.camera is None else frame.camera.to_dict(),
        "camera_source": None if frame.camera is None else frame.camera.source or None,
        "camera_fit": None if frame.camera is None else frame.camera.fit,
        "colorspace": frame.colorspace.describe(),
        "missing": _missing(frame),
        "depict": _provenance(pt.parts[pt.primary][0]) if pt.parts else None,
        "cryptomatte": cryptomatte.describe(frame),
        "warnings": list(getattr(pt, "warnings", [])),
    }


def describe_layout(layout: exr.FileLayout) -> dict[str, Any]:
    """:func:`describe`'s form for a file whose header reads but whose pixels could not be
    decoded: windows and parts from the header, no buffers, no camera."""
    parts = []
    for i, part in enumerate(layout.parts):
        parts.append(
            {
                "name": part.name or (f"part{i}" if len(layout.parts) > 1 else None),
                "channels": sorted(name for name, *_ in part.channels),
                "type": part.storage,
                "compression": exr.COMPRESSION_NAMES.get(part.compression, str(part.compression)),
                "tiled": part.storage == "tiledimage",
            }
        )
    first = layout.parts[0]
    display = first.attributes.get("displayWindow")
    return {
        "file": None,
        "preset": "none",
        "preset_reason": "the pixels could not be decoded",
        "size": [first.width, first.height],
        "display_window": list(struct.unpack("<4i", display.data)) if display else None,
        "data_window": list(first.data_window),
        "parts": parts,
        "buffers": {},
        "camera": None,
        "warnings": [],
    }
