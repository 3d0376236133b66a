"""``depict inspect``: what Depict sees in an EXR (preset and why, buffers and their channels,
camera and where it came from, which operators can run), as text or stable JSON."""

from __future__ import annotations

import argparse
import json
from typing import Any

from gbuffer.errors import FrameError, LimitError, OptionError
from gbuffer.exr import read_layout
from gbuffer.io import describe_layout, inspect
from service.cli.args import printable
from service.cli.common import read_request
from service.registry import runnable


def _camera_lines(info: dict[str, Any]) -> list[str]:
    cam = info["camera"]
    lines = [f"  camera: {json.dumps(cam) if cam else 'none'}"]
    if cam:
        lines.append(f"  camera source: {info.get('camera_source') or 'unknown'}")
        fit = info.get("camera_fit")
        if fit and fit.get("pixels"):
            outliers = f" ({fit['outliers']} outliers left out)" if fit["outliers"] else ""
            lines.append(
                f"  camera reprojection error against the position pass: RMS "
                f"{fit['rms_px']:.2g} px, max {fit['max_px']:.2g} px over {fit['pixels']} "
                f"pixels{outliers}"
            )
    return lines


def _inspection_lines(info: dict[str, Any]) -> list[str]:
    lines = [f"{info['file']}: {info['size'][0]}x{info['size'][1]}, preset {info['preset']}"]
    lines.append(f"  preset: {info['preset_reason']}")
    lines.append(f"  display window {info['display_window']}, data window {info['data_window']}")
    for part in info["parts"]:
        lines.append(
            f"  part {part['name'] or '(unnamed)'}: {len(part['channels'])} channels, "
            f"{part['compression']}{', tiled' if part['tiled'] else ''}"
        )
    space = info.get("colorspace")
    if space:
        weights = ", ".join(f"{w:.4f}" for w in space["luminance_weights"])
        lines.append(
            f"  colour space: {space['name']} (from {space['source']}; luminance weights "
            f"{weights}, white xy {space['white_xy'][0]:.4f} {space['white_xy'][1]:.4f})"
        )
    lines.append("  buffers:")
    for name, buf in info["buffers"].items():
        lines.append(f"    {name:<20s} <- {buf['source']}")
    lines += _camera_lines(info)
    made = info.get("depict")
    if made:
        where = made.get("result") or "R,G,B,A"
        original = made.get("original", "?") or "R,G,B"
        lines.append(
            f"  depict: result in {where} (original beauty: {original}), "
            f"version {made.get('version', '?')}, input {made.get('input', '?')}"
        )
        if "pipeline" in made:
            lines.append(f"  depict pipeline: {json.dumps(made['pipeline'])}")
    for layer in info.get("cryptomatte", []):
        names = ", ".join(f"{name} ({px:g} px)" for name, px in layer["names"].items())
        lines.append(f"  cryptomatte {layer['name']} ({layer['ranks']} ranks): {names}")
    lines += [f"  missing: {line}" for line in info.get("missing", [])]
    ops = info["operators"]
    if info.get("undecoded"):  # (what the buffers would be is not known: none are listed)
        lines.append("  operators: none can run, the pixels could not be decoded (below)")
    elif not ops["not_runnable"]:
        lines.append("  operators: every one can run")
    else:
        for name, lacks in ops["not_runnable"].items():
            lines.append(f"  cannot run: {name} (needs {', '.join(lacks)})")
    for key in ("problems", "warnings"):
        lines += [f"  {key[:-1]}: {line}" for line in info.get(key, [])]
    return lines


def cmd_inspect(args: argparse.Namespace) -> int:
    read = read_request(args)
    try:
        info = inspect(args.file, read.preset, read.camera, read.options)
    except (LimitError, OptionError):
        raise
    except FrameError as exc:  # the pixels cannot be decoded: describe the header alone
        info = _describe_header(args.file, exc)
    info["operators"] = runnable(info)
    if args.json:
        print(json.dumps(info, indent=2))
    else:
        print("\n".join(printable(line) for line in _inspection_lines(info)))
    return 0


def _describe_header(path: str, error: Exception) -> dict[str, Any]:
    """What ``inspect`` says of a file whose header reads but whose pixels do not."""
    info = describe_layout(read_layout(path))
    info["file"] = path
    info["undecoded"] = str(error)
    info["warnings"].append(f"pixels not described: {error}")
    return info
