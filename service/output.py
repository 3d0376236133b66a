"""Where a pipeline's result goes in the output file, and what the output says about itself.

**The result layer** (:func:`result_layer`), in this order:

1. ``--output-layer NAME`` (``output_layer`` over HTTP): ``NAME.R/G/B/A``; refused when the input
   already has channels of that layer that are not an earlier Depict result;
2. the layer of an earlier Depict result in the input (its header's ``depict/result``): a second
   ``enhance`` of an output replaces the first result, never the renderer's original;
3. the renderer's convention (:attr:`gbuffer.Frame.result_layer`): a pass of the view layer for a
   Blender multilayer file (``ViewLayer.Depict.R/G/B/A``: Blender's compositor Image node lists it
   as the pass "Depict");
4. ``R,G,B,A`` otherwise (Nuke's ``rgba``, what a Read node shows first). The input's own
   ``R,G,B,A`` are kept, pixel type and all, under a fresh layer name: ``input``, or ``input1``,
   ``input2``, … when the file already uses it.

**The header** of the output's primary part gets (:func:`provenance`): ``depict/version``,
``depict/pipeline`` (``{"steps": [...]}`` with every parameter of every step, defaults included:
feed it back with ``--pipeline``), ``depict/input`` (the input's file name), ``depict/history``
(one entry per run, when the input was itself a Depict output), ``depict/result`` (the result
layer, "" for ``R,G,B,A``), ``depict/original`` (the layer holding the renderer's beauty) and the
camera the pipeline used, when it did not come from the file: ``worldToCamera``, ``worldToNDC``
(the OpenEXR standard attributes), ``depict/projection``, ``depict/fovYDeg`` /
``depict/orthoHeight`` and ``depict/cameraSource``; and the working space when the user named
it (``--colorspace``): ``chromaticities`` (the OpenEXR standard attribute). Reading an output
back therefore needs no flag: ``preview``, ``inspect``, ``score`` and ``enhance`` take the
result as the beauty, in its space.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import numpy as np

from gbuffer.errors import FrameError, OptionError
from gbuffer.frame import Frame
from gbuffer.io import DEFAULT_LAYOUT, header_json
from gbuffer.presets import RESULT_ATTRIBUTE
from service.version import version

#: A layer name: dot-separated words (letters, digits, ``_``, ``-``, spaces inside).
_WORD = r"[A-Za-z0-9_](?:[A-Za-z0-9_ -]*[A-Za-z0-9_])?"
LAYER_NAME = re.compile(rf"^{_WORD}(?:\.{_WORD})*$")
#: The same rule as a JSON-schema pattern (the HTTP form field).
LAYER_PATTERN = LAYER_NAME.pattern
ORIGINAL_ATTRIBUTE = "depict/original"
_RGBA = ("R", "G", "B", "A")


def _channels(frame: Frame) -> dict[str, Any]:
    pt = frame.passthrough
    return pt.parts[pt.primary][1] if pt.parts else {}


def _header(frame: Frame) -> dict[str, Any]:
    pt = frame.passthrough
    return pt.parts[pt.primary][0] if pt.parts else {}


def _earlier_result(frame: Frame) -> str | None:
    value = _header(frame).get(RESULT_ATTRIBUTE)
    return value if isinstance(value, str) else None


def check_layer_name(output_layer: str) -> None:
    """FrameError unless ``output_layer`` is a layer name (checked once for a whole sequence
    too: ``depict batch --output-layer ''`` failed each frame)."""
    if not LAYER_NAME.match(output_layer):
        raise FrameError(
            f"output layer {output_layer!r} is not a layer name: dot-separated words of letters, "
            "digits, '_', '-' (and spaces inside), e.g. Depict or ViewLayer.Depict"
        )


def result_layer(frame: Frame, output_layer: str | None) -> str:
    """The layer the result goes to ("" for ``R,G,B,A``); see the module docstring."""
    earlier = _earlier_result(frame)
    if output_layer is None:
        if earlier is not None:
            return earlier
        return frame.result_layer or ""
    check_layer_name(output_layer)
    taken = sorted(c for c in _channels(frame) if c.startswith(f"{output_layer}."))
    if taken and output_layer != earlier:  # (the request's name, not the file, is wrong)
        raise OptionError(
            f"output layer {output_layer!r} would overwrite the input's channels "
            f"{', '.join(taken[:4])}{', ...' if len(taken) > 4 else ''}; choose a name the file "
            "does not use"
        )
    return output_layer


def _fresh_layer(channels: dict[str, Any], base: str = "input") -> str:
    """``base``, or ``base1``, ``base2``, … : a layer with no channel in ``channels``."""
    n = 0
    while True:
        name = base if n == 0 else f"{base}{n}"
        if not any(c.startswith(f"{name}.") for c in channels):
            return name
        n += 1


def place_result(frame: Frame, layer: str, keep_original: bool = True) -> str | None:
    """Write the beauty and alpha to ``layer``'s R, G, B, A; keep the input's R,G,B,A under a
    fresh name when they are replaced and are the renderer's (and ``keep_original``). Returns
    where the original is."""
    beauty = frame.need("beauty", "the enhanced image")
    alpha = frame.buffers.get("alpha", frame.mask)
    prefix = f"{layer}." if layer else ""
    channels = _channels(frame)
    original = _header(frame).get(ORIGINAL_ATTRIBUTE)
    keep = keep_original and not layer and _earlier_result(frame) is None
    if keep and any(name in channels for name in _RGBA):
        original = _fresh_layer({**channels, **frame.outputs})
        for name in _RGBA:
            if name in channels:
                frame.outputs[f"{original}.{name}"] = channels[name].pixels
    for i, name in enumerate(_RGBA[:3]):
        frame.outputs[prefix + name] = np.ascontiguousarray(beauty[..., i], dtype=np.float32)
    frame.outputs[prefix + "A"] = np.asarray(alpha, np.float32)
    if original is None:
        source = frame.sources.get("beauty", "").split(" ")[0]
        if "." in source:
            original = source.rpartition(".")[0]
        elif source and layer:  # the file's own R,G,B, the result beside them
            original = ""
    return original if isinstance(original, str) else None


def provenance(frame: Frame, input_name: str | None) -> dict[str, Any]:
    """Header attributes: version, pipeline with every parameter, input name, history."""
    pipeline = json.dumps({"steps": frame.history}, separators=(",", ":"))
    entry = {"version": version(), "input": input_name, "pipeline": {"steps": frame.history}}
    attrs: dict[str, Any] = {"depict/version": version(), "depict/pipeline": pipeline}
    if input_name:
        attrs["depict/input"] = input_name
    header = _header(frame)
    earlier = header.get("depict/pipeline")
    if isinstance(earlier, str):  # (a history that is not a JSON list starts again from here)
        history = header_json(header.get("depict/history"))
        if not isinstance(history, list) or not history:
            pipeline_before = header_json(earlier)
            history = [
                {
                    "version": header.get("depict/version"),
                    "input": header.get("depict/input"),
                    "pipeline": earlier if pipeline_before is None else pipeline_before,
                }
            ]
        attrs["depict/history"] = json.dumps([*history, entry], separators=(",", ":"))
    return attrs


def colorspace_attributes(frame: Frame) -> dict[str, Any]:
    """``chromaticities`` of a working space the user named (the file's own stay as they are)."""
    space = frame.colorspace
    if space.source != "--colorspace":
        return {}
    return {"chromaticities": space.chromaticities}


def camera_attributes(frame: Frame) -> dict[str, Any]:
    """The camera's header attributes, unless it came from the file's header itself."""
    cam = frame.camera
    if cam is None or cam.world_to_camera is None or cam.source.startswith("file header"):
        return {}
    if not cam.has_intrinsics:
        return {}
    assert frame.display_size is not None
    return cam.to_header(frame.display_size)


def finish(
    frame: Frame,
    output_layer: str | None = None,
    input_name: str | None = None,
    layout: str = DEFAULT_LAYOUT,
) -> Frame:
    """A copy of ``frame`` ready to write in ``layout`` (:data:`gbuffer.io.LAYOUTS`): the result
    in its layer, the header attributes of the module docstring. ``input_name`` defaults to the
    name of the file read. In the ``part`` layout a result that would replace the input's
    ``R,G,B,A`` goes to a fresh layer ``Depict`` instead (the added part then holds every new
    channel and the input's parts are copied as they are); in the ``sidecar`` layout the input's
    ``R,G,B,A`` are not copied (they stay in the input)."""
    out = frame.copy()
    layer = result_layer(out, output_layer)
    if layout == "part" and not layer and output_layer is None and _earlier_result(out) is None:
        layer = _fresh_layer({**_channels(out), **out.outputs}, "Depict")
    original = place_result(out, layer, keep_original=layout != "sidecar")
    path = getattr(out.passthrough, "path", "")
    if input_name is None and path:
        input_name = Path(str(path)).name
    out.attributes.update(camera_attributes(out))
    out.attributes.update(colorspace_attributes(out))
    out.attributes.update(provenance(out, input_name))
    out.attributes[RESULT_ATTRIBUTE] = layer
    if original is not None:
        out.attributes[ORIGINAL_ATTRIBUTE] = original
    return out
