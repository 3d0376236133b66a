"""The analysis commands of ``depict``: ``score``, ``compare``, ``relief-pick`` and ``arm``.

``score``, ``compare`` and ``relief-pick`` run the same job functions locally
(:mod:`service.jobs`) as the HTTP service does remotely (``--server URL``), and print their
answer with the same function, so both modes give the same output.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from service.cli_common import (
    UsageError,
    add_pipeline_options,
    add_read_options,
    add_server_option,
    parse_sets,
    pipeline_spec,
    read_options,
)

MESH_SUFFIXES = (".obj", ".ply", ".stl", ".glb", ".gltf", ".off")


# -- score -------------------------------------------------------------------------------------


def _score_options(args: argparse.Namespace) -> dict[str, float | str]:
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
    spec = pipeline_spec(args, default=None)
    options = _score_options(args)
    if args.server:
        from service.client import Client

        with Client.from_env(args.server) as client:
            data = client.score(
                args.file,
                pipeline=spec,
                preset=args.preset,
                camera=args.camera,
                mapping=read_options(args)["mapping"],
                normal_space=args.normal_space,
                **options,
            )
    else:
        from service.jobs import score_job

        data = score_job(
            args.file,
            None if spec is None else spec.model_dump_json(),
            read_options(args),
            options,
            files=True,
        )
    data.pop("op_s", None)
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


def cmd_compare(args: argparse.Namespace) -> int:
    from analysis.pictures import plot
    from analysis.result import ComparisonResult
    from gbuffer.atomic import check_outputs

    check_outputs([args.plot, args.sheet], [args.input, args.camera])

    is_mesh = Path(args.input).suffix.lower() in MESH_SUFFIXES
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    options: dict[str, Any] = {
        "methods": methods,
        "directions": args.directions,
        "params": parse_sets(args.set),
        "albedo": args.albedo,
        "label": Path(args.input).stem,
        "shading_norm": _shading_norm(args.shading_norm),
    }
    if is_mesh:
        options.update(
            width=args.width, height=args.height, azimuth=args.azimuth, elevation=args.elevation
        )
    if args.server:
        from service.client import Client

        with Client.from_env(args.server) as client:
            data = client.compare(
                args.input,
                options,
                mesh=is_mesh,
                sheet=args.sheet,
                preset=args.preset,
                camera=args.camera,
            )
    else:
        from service.jobs import compare_job

        read = None if is_mesh else read_options(args)
        data = compare_job(args.input, read, options, bool(args.sheet))
        png = data.pop("sheet_png", None)  # as the client does: the sheet goes to its file
        if args.sheet and png:
            import base64

            from gbuffer.atomic import atomic_path

            with atomic_path(args.sheet) as tmp:
                Path(tmp).write_bytes(base64.b64decode(png))
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


def cmd_relief_pick(args: argparse.Namespace) -> int:
    params: dict[str, Any] = {}
    for key in ("scale", "curvedness_norm"):
        if getattr(args, key) is not None:
            params[key] = getattr(args, key)
    if args.server:
        from service.client import Client

        with Client.from_env(args.server) as client:
            data = client.relief_pick(
                args.file, args.x, args.y, params, preset=args.preset, camera=args.camera
            )
    else:
        from service.jobs import pick_job

        data = pick_job(args.file, read_options(args), args.x, args.y, params)
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
    import cv2
    import numpy as np

    from gbuffer.atomic import atomic_path, check_outputs
    from ops import relief as rl

    check_outputs([args.output], [args.base if args.base not in rl.SHIPPED_ARMS else None])
    if args.paint:
        if args.base in rl.SHIPPED_ARMS:
            base = rl.make_arm(args.base, args.size)
        elif args.base:
            img = cv2.imread(args.base, cv2.IMREAD_UNCHANGED)
            if img is None:
                raise UsageError(f"--base {args.base!r}: not a shipped ARM nor a readable image")
            base = rl.arm_from_image(img)
        else:
            base = np.zeros((args.size, args.size), np.float32)
        for text in args.paint:
            s1, s2, value = _paint(text)
            try:
                base = rl.paint_arm(base, (s1, s2), value, args.radius, args.softness)
            except ValueError as exc:
                raise UsageError(f"--paint {text!r}: {exc}") from None
        out = np.clip(base * 255.0 + 0.5, 0, 255).astype(np.uint8)
        what = "ARM"
    else:
        try:
            tpl = rl.arm_template(args.size)
        except ValueError as exc:
            raise UsageError(f"--size: {exc}") from None
        out = cv2.cvtColor(np.clip(tpl * 255.0 + 0.5, 0, 255).astype(np.uint8), cv2.COLOR_RGB2BGR)
        what = "ARM template"
    suffix = Path(args.output).suffix.lower() or ".png"
    with atomic_path(args.output) as tmp:
        ok, buf = cv2.imencode(suffix, out)
        if not ok:
            raise UsageError(f"cannot write {args.output}: use .png")
        Path(tmp).write_bytes(buf.tobytes())
    print(f"wrote {args.output} ({what}, {out.shape[1]}x{out.shape[0]})")
    return 0


# -- parsers -----------------------------------------------------------------------------------


def add_analysis_commands(sub: Any) -> None:
    p = sub.add_parser("score", help="congruence score of a frame's beauty (LLA Eq. 2)")
    p.add_argument("file")
    p.add_argument("--json", action="store_true", help="stable JSON for other tools")
    p.add_argument("--gradient-scale", type=float, help="gradient σ / image height (0.002)")
    p.add_argument("--integration-scale", type=float, help="integration σ / image height (0.01)")
    p.add_argument("--percentile", type=float, help="strength normalisation percentile (95)")
    p.add_argument("--depth-jump", type=float, help="largest log-depth step of a surface (0.05)")
    p.add_argument(
        "--shading-norm", type=float, help="pinned shading strength scale (default: per image)"
    )
    p.add_argument(
        "--shape",
        choices=("normals", "depth"),
        help="shape flow from the normals' gradients (default) or the log depth's",
    )
    add_pipeline_options(p, "score the frame after these steps")
    add_read_options(p)
    add_server_option(p)
    p.set_defaults(func=cmd_score)

    sub.add_parser(
        "compare",
        help="score every depiction method under the 21 light directions (LLA §7)",
        builder=_compare_arguments,
    )

    p = sub.add_parser(
        "relief-pick", help="the Apparent Relief descriptor under a pixel, to paint an ARM there"
    )
    p.add_argument("file")
    p.add_argument("x", type=int, help="column, from the left")
    p.add_argument("y", type=int, help="row, from the top")
    p.add_argument("--scale", type=float, help="curvature scale / image height (0.006)")
    p.add_argument("--curvedness-norm", type=float, help="pinned curvedness norm (default auto)")
    p.add_argument("--json", action="store_true", help="stable JSON for other tools")
    add_read_options(p)
    add_server_option(p)
    p.set_defaults(func=cmd_relief_pick)

    sub.add_parser(
        "arm",
        help="write an Apparent Relief Map template, or paint an ARM",
        builder=_arm_arguments,
    )


# Built only when their command is run (depict --help and --version import nothing heavy).


def _compare_arguments(p: argparse.ArgumentParser) -> None:
    from analysis.compare import ALBEDOS
    from analysis.methods import METHODS
    from ops.directions import N_DIRECTIONS

    p.add_argument("input", help="a mesh (rendered with Depict) or an EXR with normals and depth")
    p.add_argument("--methods", default=",".join(METHODS), help="comma list of methods")
    p.add_argument(
        "--directions", type=int, default=N_DIRECTIONS, help="first N directions of the sweep"
    )
    p.add_argument("--albedo", choices=ALBEDOS, default="white", help="shade white or the albedo")
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="SECTION.KEY=VALUE",
        help="parameter override, e.g. light_alignment.gamma=2 or congruence.percentile=99",
    )
    p.add_argument(
        "--shading-norm",
        default="reference",
        metavar="MODE",
        help="scale of the shading strengths: reference (the frame's Lambert under #1, for "
        "every rendering), per_image, or a number",
    )
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.add_argument("--plot", metavar="OUT.png", help="scores vs direction (like LLA Fig. 13)")
    p.add_argument("--sheet", metavar="OUT.png", help="renderings and score maps (Fig. 12)")
    p.add_argument("--width", type=int, default=512, help="mesh render width")
    p.add_argument("--height", type=int, default=512, help="mesh render height")
    p.add_argument("--azimuth", type=float, default=30.0, help="mesh framing azimuth, degrees")
    p.add_argument("--elevation", type=float, default=20.0, help="mesh framing elevation, deg")
    add_read_options(p)
    add_server_option(p)
    p.set_defaults(func=cmd_compare)


def _arm_arguments(p: argparse.ArgumentParser) -> None:
    from ops.relief import SHIPPED_ARMS

    p.add_argument("-o", "--output", required=True, help="output PNG")
    p.add_argument("--size", type=int, default=256, help="side in pixels (64-4096)")
    p.add_argument(
        "--paint",
        action="append",
        default=[],
        metavar="S1,S2[=VALUE]",
        help="paint VALUE (default 1) around descriptor S (from relief-pick); repeatable",
    )
    p.add_argument(
        "--base", help=f"ARM to paint on: {', '.join(SHIPPED_ARMS)} or an image (default: black)"
    )
    p.add_argument("--radius", type=float, default=0.15, help="paint radius, descriptor units")
    p.add_argument("--softness", type=float, default=0.5, help="fraction of the radius that fades")
    p.set_defaults(func=cmd_arm)
