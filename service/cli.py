"""``depict``: the command line. Every command is a thin layer over gbuffer/ and the registry.

Bad input (a bad file, a missing buffer or camera, an unknown operator or parameter) prints one
line ``depict: error: ...`` on stderr and exits with code 2; no traceback.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from typing import Any

from service import allocator
from service.cli_analysis import add_analysis_commands
from service.cli_common import (
    UsageError,
    add_pipeline_options,
    add_read_options,
    add_server_option,
    bounded,
    pipeline_spec,
    printable,
    read_options,
)
from service.errors import DepictError
from service.version import version

EXIT_USAGE = 2


def read_frame(args: argparse.Namespace, path: str) -> Any:
    from service.jobs import read_frame as read

    return read(path, read_options(args))


def check_outputs(outputs: list[str | None], inputs: list[str | None]) -> None:
    """Refuse outputs that name an input, each other or a special file (before any work)."""
    from gbuffer.atomic import check_outputs as check

    check(outputs, inputs)


def warn(messages: list[str]) -> None:
    """Notes for the user (e.g. NaN/Inf pixels read as holes), one line each on stderr."""
    for message in messages:
        print(f"depict: warning: {printable(message)}", file=sys.stderr)


# -- commands ----------------------------------------------------------------------------------


def cmd_render(args: argparse.Namespace) -> int:
    check_outputs([args.output], [args.mesh, args.camera])
    if args.server:
        from service.client import Client

        if args.shading != "auto":
            raise UsageError("--shading is not sent to a server (it renders with auto)")

        with Client.from_env(args.server) as client:
            client.render(
                args.mesh,
                args.output,
                width=args.width,
                height=args.height,
                camera=args.camera,
                azimuth=args.azimuth,
                elevation=args.elevation,
                lights=args.light,
            )
        print(f"wrote {args.output} ({args.width}x{args.height})")
        return 0
    from gbuffer import write
    from gbuffer.camera import Camera
    from gbuffer.render import auto_camera, load_mesh, render
    from ops.shading import parse_light

    mesh = load_mesh(args.mesh)
    try:
        lights = [parse_light(text) for text in args.light] or None
    except ValueError as exc:
        raise UsageError(f"--light: {exc}") from None
    if args.camera:
        camera = Camera.from_json_file(args.camera)
    else:
        camera = auto_camera(
            mesh,
            width=args.width,
            height=args.height,
            azimuth_deg=args.azimuth,
            elevation_deg=args.elevation,
        )
    frame = render(
        mesh, args.width, args.height, camera=camera, lights=lights, shading=args.shading
    )
    write(frame, args.output)
    print(f"wrote {args.output} ({args.width}x{args.height})")
    return 0


def cmd_warmup(args: argparse.Namespace) -> int:
    from service.warmup import warm

    t0 = time.perf_counter()
    times = warm()
    for name, seconds in times.items():
        print(f"  {name:<24s} {seconds:6.2f} s")
    print(f"kernels ready ({time.perf_counter() - t0:.1f} s)")
    return 0


def _runnable(info: dict[str, Any]) -> dict[str, Any]:
    """Which operators can run on the inspected frame, and what the others lack."""
    from service.registry import operators

    have = set(info["buffers"])
    if "position" in have:
        have.add("depth")
    blocked = {}
    for op in operators().values():
        lacks = [b for b in op.needs if b not in have]
        if op.needs_camera and info["camera"] is None:
            lacks.append("camera")
        if lacks:
            blocked[op.name] = lacks
    return {"runnable": [n for n in operators() if n not in blocked], "not_runnable": blocked}


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
    lines.append("  buffers:")
    for name, buf in info["buffers"].items():
        lines.append(f"    {name:<20s} <- {buf['source']}")
    lines += _camera_lines(info)
    made = info.get("depict")
    if made:
        where = made.get("result") or "R,G,B,A"
        lines.append(
            f"  depict: result in {where} (original beauty: {made.get('original', '?')}), "
            f"version {made.get('version', '?')}, input {made.get('input', '?')}"
        )
        if "pipeline" in made:
            lines.append(f"  depict pipeline: {json.dumps(made['pipeline'])}")
    lines += [f"  missing: {line}" for line in info.get("missing", [])]
    ops = info["operators"]
    if not ops["not_runnable"]:
        lines.append("  operators: every one can run")
    for name, lacks in ops["not_runnable"].items():
        lines.append(f"  cannot run: {name} (needs {', '.join(lacks)})")
    for key in ("problems", "warnings"):
        lines += [f"  {key[:-1]}: {line}" for line in info.get(key, [])]
    return lines


def cmd_inspect(args: argparse.Namespace) -> int:
    from gbuffer.errors import FrameError, LimitError, OptionError
    from gbuffer.io import ReadOptions, inspect

    read = read_options(args)
    options = ReadOptions(mapping=read["mapping"], normal_space=read["normal_space"])
    try:
        info = inspect(args.file, read["preset"], read["camera"], options)
    except (LimitError, OptionError):
        raise
    except FrameError as exc:  # the pixels cannot be decoded: describe the header alone
        info = _describe_header(args.file, exc)
    info["operators"] = _runnable(info)
    if args.json:
        print(json.dumps(info, indent=2))
    else:
        print("\n".join(printable(line) for line in _inspection_lines(info)))
    return 0


def _describe_header(path: str, error: Exception) -> dict[str, Any]:
    """What ``inspect`` says of a file whose header reads but whose pixels do not."""
    from gbuffer.exr import read_layout
    from gbuffer.io import describe_layout

    info = describe_layout(read_layout(path))
    info["file"] = path
    info["warnings"].append(f"pixels not described: {error}")
    return info


def cmd_preview(args: argparse.Namespace) -> int:
    from gbuffer.preview import picture, write_png

    check_outputs([args.output], [args.file, args.camera])
    frame = read_frame(args, args.file)
    write_png(picture(frame, args.layer, exposure=args.exposure), args.output)
    print(f"wrote {args.output} ({args.layer})")
    return 0


def cmd_ops(args: argparse.Namespace) -> int:
    from service.registry import operators

    ops = operators()
    if args.json:
        print(json.dumps([op.schema() for op in ops.values()], indent=2))
        return 0
    for op in ops.values():
        print(f"{op.name}: {op.summary}")
        print(f"  needs: {', '.join(op.needs) or '-'}; writes: {', '.join(op.writes)}")
        for name, field in op.params.model_fields.items():
            default = field.default if field.default is not None else "-"
            print(f"    {name:<22s} = {default!s:<12s} {field.description or ''}")
    return 0


def cmd_enhance(args: argparse.Namespace) -> int:
    import gbuffer
    from service import pipeline

    check_outputs([args.output], [args.input, args.camera, args.pipeline])
    if args.server:
        from service.client import Client

        read = read_options(args)
        with Client.from_env(args.server) as client:
            client.enhance(
                args.input,
                args.output,
                pipeline=pipeline_spec(args, default=None),  # None: the server's default
                preset=read["preset"],
                camera=read["camera"],
                mapping=read["mapping"],
                normal_space=read["normal_space"],
                debug_layers=args.debug_layers,
                output_layer=args.output_layer,
            )
        print(f"wrote {args.output}")
        return 0
    spec = pipeline_spec(args, default=pipeline.DEFAULT_PIPELINE)
    frame = read_frame(args, args.input)
    out = pipeline.finish(
        pipeline.run(frame, spec, debug_layers=args.debug_layers), args.output_layer
    )
    warn(getattr(frame.passthrough, "warnings", []) + gbuffer.write(out, args.output))
    print(f"wrote {args.output}")
    return 0


# -- service: serve, batch (service/api.py, service/batch.py) --


def cmd_serve(args: argparse.Namespace) -> int:
    from service.api import serve
    from service.settings import Settings

    overrides = {"host": args.host, "port": args.port, "workers": args.workers}
    try:
        settings = Settings(**{k: v for k, v in overrides.items() if v is not None})
    except ValueError as exc:
        raise UsageError(str(exc).replace("\n", " ")) from None
    serve(settings)
    return 0


def cmd_batch(args: argparse.Namespace) -> int:
    from service.batch import BatchError
    from service.batch import cmd_batch as run

    try:
        return run(args)
    except BatchError as exc:
        raise UsageError(str(exc)) from None


def add_service_commands(sub: Any) -> None:
    p = sub.add_parser("serve", help="run the HTTP service (settings from DEPICT_* variables)")
    p.add_argument("--host", help="address to bind (DEPICT_HOST, default 127.0.0.1)")
    p.add_argument("--port", type=int, help="port (DEPICT_PORT, default 8000)")
    p.add_argument("--workers", type=int, help="parallel jobs (DEPICT_WORKERS, default 2)")
    p.set_defaults(func=cmd_serve)

    p = sub.add_parser("batch", help="enhance a frame sequence on a Dask cluster")
    p.add_argument("input", help="input pattern: shot.####.exr, shot.%%04d.exr or shot.@.exr")
    p.add_argument("-o", "--output", required=True, help="output pattern, same tokens")
    p.add_argument("--frames", help="frames: 1-100, 1-100x2, 1,5,9 (default: existing inputs)")
    add_pipeline_options(p)
    p.add_argument(
        "--scheduler", metavar="tcp://HOST:8786", help="Dask scheduler (default: local cluster)"
    )
    p.add_argument("--workers", type=int, help="local cluster worker processes (default: cores)")
    p.add_argument("--skip-existing", action="store_true", help="skip frames whose output exists")
    p.add_argument(
        "--pinned",
        metavar="STATS.json",
        help="pinned statistics: reused when the file exists, else measured and written there",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--debug-layers", action="store_true", help="also write intermediate layers")
    p.add_argument("--output-layer", metavar="NAME", help="write NAME.R/G/B/A instead of R,G,B,A")
    add_read_options(p)
    p.set_defaults(func=cmd_batch)


# -- parser ------------------------------------------------------------------------------------


class _Parser(argparse.ArgumentParser):
    """Command-line errors as one line ``depict: error: ...`` and exit code 2, like the others
    (subcommand parsers inherit the class). ``builder(parser)``, when given, adds the
    arguments only when the command is parsed: what they import (defaults, choices) costs
    ``depict --help`` nothing."""

    def __init__(self, *args: Any, builder: Any = None, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._builder = builder

    def parse_known_args(self, args: Any = None, namespace: Any = None) -> Any:
        if self._builder is not None:
            build, self._builder = self._builder, None
            build(self)
        return super().parse_known_args(args, namespace)

    def error(self, message: str) -> Any:
        self.exit(EXIT_USAGE, f"depict: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="depict",
        description="Depict shape in rendered images: EXR G-buffers in, enhanced EXR out.",
    )
    parser.add_argument("--version", action="version", version=f"depict {version()}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("render", help="render a mesh to a canonical G-buffer EXR")
    p.add_argument("mesh", help="OBJ, PLY, STL, GLB or GLTF")
    p.add_argument("-o", "--output", required=True, help="output EXR")
    p.add_argument("--width", type=int, default=960)
    p.add_argument("--height", type=int, default=720)
    p.add_argument("--camera", metavar="CAM.json", help="camera JSON (default: auto framing)")
    p.add_argument("--azimuth", type=float, default=30.0, help="auto framing azimuth, degrees")
    p.add_argument("--elevation", type=float, default=20.0, help="auto framing elevation, deg")
    p.add_argument(
        "--light",
        action="append",
        default=[],
        metavar="SPEC",
        help="light, camera space: X,Y,Z (directional, towards the light) or point:X,Y,Z; "
        "repeat for several",
    )
    p.add_argument(
        "--shading",
        choices=("auto", "smooth", "flat"),
        default="auto",
        help="normals: smooth across UV seams, flat facets, or auto (the file's normals, else "
        "smooth, with the creases of a creased mesh such as a box)",
    )
    add_server_option(p)
    p.set_defaults(func=cmd_render)

    p = sub.add_parser("inspect", help="what Depict sees in an EXR: preset, buffers, camera")
    p.add_argument("file")
    p.add_argument("--json", action="store_true", help="stable JSON for other tools")
    add_read_options(p)
    p.set_defaults(func=cmd_inspect)

    p = sub.add_parser("preview", help="an 8-bit PNG of any layer")
    p.add_argument("file")
    p.add_argument("-o", "--output", required=True, help="output PNG")
    p.add_argument("--layer", default="beauty", help="buffer or layer (beauty, normal, ...)")
    p.add_argument(
        "--exposure",
        type=bounded(float, -20.0, 20.0),
        default=0.0,
        help="exposure in stops (radiance), -20 to 20",
    )
    add_read_options(p)
    p.set_defaults(func=cmd_preview)

    p = sub.add_parser(
        "warmup", help="compile the per-pixel kernels now (image builds, new farm nodes)"
    )
    p.set_defaults(func=cmd_warmup)

    p = sub.add_parser("ops", help="list operators with their parameters and defaults")
    p.add_argument("--json", action="store_true", help="JSON schemas of every operator")
    p.set_defaults(func=cmd_ops)

    p = sub.add_parser("enhance", help="apply operators to an EXR frame")
    p.add_argument("input")
    p.add_argument("-o", "--output", required=True, help="output EXR")
    add_pipeline_options(p)
    p.add_argument("--debug-layers", action="store_true", help="also write intermediate layers")
    p.add_argument("--output-layer", metavar="NAME", help="write NAME.R/G/B/A instead of R,G,B,A")
    add_read_options(p)
    add_server_option(p)
    p.set_defaults(func=cmd_enhance)

    add_analysis_commands(sub)
    add_service_commands(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    allocator.tune()
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args))
    except (ValueError, DepictError) as exc:  # bad input, or a server that refused or is down
        # ValueError: FrameError, PipelineError, UsageError, and ops/' bad values
        return _fail(str(exc))
    except FileNotFoundError as exc:
        return _fail(f"no such file: {exc.filename or exc}")
    except OSError as exc:  # a file that cannot be read or written
        where = f"{exc.filename}: " if exc.filename else ""
        return _fail(f"{where}{exc.strerror or exc}")
    except RecursionError:
        return _fail("input nested too deeply")
    except KeyboardInterrupt:
        return 130


def _fail(message: str) -> int:
    """One line on stderr, control characters escaped; the exit code of bad input."""
    print(f"depict: error: {printable(message)}", file=sys.stderr)
    return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
