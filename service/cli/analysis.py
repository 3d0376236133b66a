"""The analysis commands of ``depict``: ``score``, ``compare``, ``relief-pick`` and ``arm``.

``score``, ``compare`` and ``relief-pick`` run the same job functions locally
(:mod:`service.jobs`) as the HTTP service does remotely (``--server URL``: :mod:`.remote`), and
print their answer with the same function (:func:`print_score`, ...), so both modes give the same
output.
"""

from __future__ import annotations

import argparse
import base64
import json
from pathlib import Path
from typing import Any

from analysis.pictures import plot, plot_format
from analysis.result import ComparisonResult
from gbuffer.atomic import atomic_path, check_outputs
from service import arm
from service.cli.args import UsageError, parse_sets
from service.cli.common import read_request, steps, warn
from service.jobs import compare_job, pick_job, score_job

MESH_SUFFIXES = (".obj", ".ply", ".stl", ".glb", ".gltf", ".off")


# -- score -------------------------------------------------------------------------------------


def score_options(args: argparse.Namespace) -> dict[str, float | str]:
    """The congruence options given on the command line."""
    given = {
        "gradient_scale": args.gradient_scale,
        "integration_scale": args.integration_scale,
        "percentile": args.percentile,
        "depth_jump": args.depth_jump,
        "shading_norm": args.shading_norm,
        "shape": args.shape,
    }
    return {k: v for k, v in given.items() if v is not None}


def cmd_score(args: argparse.Namespace) -> int:
    compiled = steps(args)
    data = score_job(args.file, compiled, read_request(args), score_options(args), files=True)
    return print_score(args, data)


def print_score(args: argparse.Namespace, data: dict[str, Any]) -> int:
    data.pop("op_s", None)
    warn(data.get("warnings", []))
    if args.json:
        print(json.dumps(data, indent=2))
    else:
        h, w = data["analysis_shape"]
        print(f"{args.file}: congruence score {data['score']:.4f} (evaluated at {w}x{h})")
    return 0


# -- compare -----------------------------------------------------------------------------------


def _shading_norm(text: str) -> str | float:
    if text in ("reference", "per_image"):
        return text
    try:
        return float(text)
    except ValueError:
        raise UsageError(
            f"--shading-norm {text!r}: expected reference, per_image or a number"
        ) from None


def compare_options(args: argparse.Namespace) -> tuple[bool, dict[str, Any]]:
    """Whether the input is a mesh, and the comparison options given (outputs checked)."""
    check_outputs([args.plot, args.sheet], [args.input, args.camera])
    if args.plot:
        plot_format(args.plot)  # (it failed after the whole comparison, the sheet written)
    if args.sheet and Path(args.sheet).suffix.lower() != ".png":
        warn([f"{args.sheet} is written as PNG (its name does not end in .png)"])
    is_mesh = Path(args.input).suffix.lower() in MESH_SUFFIXES
    options: dict[str, Any] = {
        "methods": [m.strip() for m in args.methods.split(",") if m.strip()],
        "directions": args.directions,
        "params": parse_sets(args.set),
        "albedo": args.albedo,
        "label": Path(args.input).stem,
        "shading_norm": _shading_norm(args.shading_norm),
    }
    if not options["methods"]:  # (an empty list ran every method)
        raise UsageError(f"--methods {args.methods!r}: name at least one method")
    framing = {k: getattr(args, k) for k in MESH_FRAMING if getattr(args, k) is not None}
    reading = [flag for flag, given in read_flags(args).items() if given]
    if is_mesh:
        options.update({**MESH_FRAMING, **framing})
        if min(options["width"], options["height"]) < 3:  # (the score's "depth must be 3x3")
            raise UsageError("--width and --height: a comparison renders at least 3x3 pixels")
    ignored = reading if is_mesh else [f"--{k}" for k in framing]  # (ignored without a word)
    if ignored:
        what = "an EXR input; it is a mesh" if is_mesh else "a mesh input; it is a frame"
        warn([f"{', '.join(ignored)}: for {what} ({args.input}): ignored"])
    return is_mesh, options


def read_flags(args: argparse.Namespace) -> dict[str, bool]:
    """Whether each flag of reading a frame was given."""
    return {
        "--preset": args.preset != "auto",
        "--camera": args.camera is not None,
        "--map": bool(args.map),
        "--normal-space": args.normal_space is not None,
        "--view-layer": args.view_layer is not None,
        "--colorspace": args.colorspace is not None,
    }


#: How ``depict compare`` renders a mesh input, unless its flags say otherwise.
MESH_FRAMING: dict[str, Any] = {"width": 512, "height": 512, "azimuth": 30.0, "elevation": 20.0}


def cmd_compare(args: argparse.Namespace) -> int:
    is_mesh, options = compare_options(args)
    read = None if is_mesh else read_request(args)
    data = compare_job(args.input, read, options, bool(args.sheet), files=True)
    png = data.pop("sheet_png", None)  # as the client does: the sheet goes to its file
    if args.sheet and png:
        with atomic_path(args.sheet) as tmp:
            Path(tmp).write_bytes(base64.b64decode(png))
    return print_comparison(args, data)


def print_comparison(args: argparse.Namespace, data: dict[str, Any]) -> int:
    warn(data.get("warnings", []))
    result = ComparisonResult.from_dict(data)
    if args.plot:
        plot(result, args.plot)
    if args.json:
        print(json.dumps(data, indent=2))
    else:
        print(result.table_markdown())
    for path in (args.plot, args.sheet):
        if path and not args.json:
            print(f"wrote {path}")
    return 0


# -- Apparent Relief: pick a feature, paint an ARM -----------------------------------------------


def pick_params(args: argparse.Namespace) -> dict[str, Any]:
    """The ``apparent_relief`` parameters given on the command line."""
    return {
        k: getattr(args, k) for k in ("scale", "curvedness_norm") if getattr(args, k) is not None
    }


def cmd_relief_pick(args: argparse.Namespace) -> int:
    data = pick_job(args.file, read_request(args), args.x, args.y, pick_params(args))
    return print_pick(args, data)


def print_pick(args: argparse.Namespace, data: dict[str, Any]) -> int:
    if args.json:
        print(json.dumps(data, indent=2))
    else:
        s1, s2 = data["s"]
        u, v = data["uv"]
        print(
            f"pixel ({data['x']}, {data['y']}): S = ({s1:+.4f}, {s2:+.4f}), {data['region']}; "
            f"ARM texel u = {u:.4f}, v = {v:.4f}; r = {data['r']:.4f}"
        )
        print(f"  paint it: depict arm -o my_arm.png --paint {s1:.4f},{s2:.4f}=1")
    return 0


def _paint(text: str) -> tuple[float, float, float]:
    where, sep, value = text.partition("=")
    try:
        s1, s2 = (float(v) for v in where.split(","))
        return s1, s2, float(value) if sep else 1.0
    except ValueError:
        raise UsageError(f"--paint {text!r}: expected S1,S2[=VALUE]") from None


def cmd_arm(args: argparse.Namespace) -> int:
    check_outputs([args.output], [args.base if args.base not in arm.SHIPPED_ARMS else None])
    if not 64 <= args.size <= 4096:  # (the --paint path made an ARM of any size)
        raise UsageError(f"--size {args.size}: outside the allowed range [64, 4096]")
    if args.base is not None and not args.paint:
        raise UsageError("--base is the ARM --paint paints on; give --paint S1,S2 too")
    if args.paint:
        painted = arm.base_arm(args.base, args.size)
        for text in args.paint:
            s1, s2, value = _paint(text)
            try:
                painted = arm.paint_arm(painted, (s1, s2), value, args.radius, args.softness)
            except ValueError as exc:
                raise UsageError(f"--paint {text!r}: {exc}") from None
        out, what = arm.to_picture(painted), "ARM"
    else:
        try:
            out, what = arm.template_picture(args.size), "ARM template"
        except ValueError as exc:
            raise UsageError(f"--size: {exc}") from None
    arm.write_picture(args.output, out)
    print(f"wrote {args.output} ({what}, {out.shape[1]}x{out.shape[0]})")
    return 0
