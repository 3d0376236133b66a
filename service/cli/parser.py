"""The parser of ``depict``: every command and its flags, without importing what the commands
run. Each command names its function as ``"module:function"`` (``command``, and ``remote`` for
its ``--server`` form); :func:`service.cli.main` imports that module only when the command runs,
so ``depict --help`` and ``depict --version`` import nothing heavy."""

from __future__ import annotations

import argparse
from typing import Any

from service.cli.args import (
    EXIT_USAGE,
    add_pipeline_options,
    add_read_options,
    add_server_option,
    add_write_options,
    bounded,
    named_path,
    not_blank,
)
from service.version import version


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
    sub = parser.add_subparsers(dest="name", required=True, metavar="COMMAND")
    add_frame_commands(sub)
    add_analysis_commands(sub)
    add_service_commands(sub)
    return parser


def add_frame_commands(sub: Any) -> None:
    _render_arguments(sub.add_parser("render", help="render a mesh to a canonical G-buffer EXR"))

    p = sub.add_parser(
        "inspect", help="what Depict sees in an EXR: preset, buffers, camera, colour space"
    )
    p.add_argument("file")
    p.add_argument("--json", action="store_true", help="stable JSON for other tools")
    add_read_options(p)
    p.set_defaults(command="service.cli.inspection:cmd_inspect")

    preview = "an 8-bit PNG of any layer, through an OCIO display and view"
    _preview_arguments(sub.add_parser("preview", help=preview))

    p = sub.add_parser("mask", help="write the matte of a step's mask as a PNG, to check it")
    p.add_argument("file")
    p.add_argument("spec", help="cryptomatte:NAME, index:LAYER=V, a layer; ! inverts (--help)")
    p.add_argument(
        "-o", "--output", required=True, type=named_path, help="output PNG (white: m = 1)"
    )
    p.add_argument("--feather", type=bounded(float, 0.0, 0.5), default=0.0, help="σ / image height")
    p.add_argument("--amount", type=bounded(float, 0.0, 1.0), default=1.0, help="m times this")
    add_read_options(p)
    p.set_defaults(command="service.cli.frames:cmd_mask")

    p = sub.add_parser(
        "warmup", help="compile the per-pixel kernels now (image builds, new farm nodes)"
    )
    p.set_defaults(command="service.cli.render:cmd_warmup")

    p = sub.add_parser("ops", help="list operators with their parameters and defaults")
    p.add_argument("--json", action="store_true", help="JSON schemas of every operator")
    p.set_defaults(command="service.cli.frames:cmd_ops")

    p = sub.add_parser(
        "enhance",
        help="apply operators to EXR frames",
        description="Enhance one EXR, or several in one process (each with its own statistics; "
        "`depict batch` pins them for a sequence).",
    )
    p.add_argument("input", nargs="+", help="EXR file(s)")
    p.add_argument(
        "-o",
        "--output",
        required=True,
        type=named_path,
        help="output EXR, or a folder for outputs named as their inputs (one that exists, or a "
        "name ending in /)",
    )
    add_pipeline_options(p)
    add_write_options(p)
    add_read_options(p)
    add_server_option(p)
    p.set_defaults(command="service.cli.frames:cmd_enhance", remote="service.cli.remote:enhance")


def _render_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("mesh", help="OBJ, PLY, STL, GLB or GLTF")
    p.add_argument("-o", "--output", required=True, type=named_path, help="output EXR")
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
    p.set_defaults(command="service.cli.render:cmd_render", remote="service.cli.remote:render")


def _preview_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file")
    p.add_argument("-o", "--output", required=True, type=named_path, help="output PNG")
    p.add_argument(
        "--layer",
        default="beauty",
        help="buffer or layer (beauty, normal, ...); cryptomatte[/LAYER]: the Cryptomatte ids",
    )
    p.add_argument(
        "--exposure",
        type=bounded(float, -20.0, 20.0),
        default=0.0,
        help="exposure in stops (radiance), -20 to 20",
    )
    p.add_argument(
        "--display",
        help="display of the OpenColorIO config to show radiance on (default: the config's, "
        "sRGB for the built-in config)",
    )
    p.add_argument(
        "--view",
        help="view of that display (default: the display's default, ACES 2.0 SDR for the "
        "built-in config); raw: exposure and a hard clip of the sRGB curve",
    )
    add_read_options(p)
    p.set_defaults(command="service.cli.frames:cmd_preview")


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
    p.set_defaults(command="service.cli.analysis:cmd_score", remote="service.cli.remote:score")

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
    p.set_defaults(
        command="service.cli.analysis:cmd_relief_pick", remote="service.cli.remote:relief_pick"
    )

    sub.add_parser(
        "arm",
        help="write an Apparent Relief Map template, or paint an ARM",
        builder=_arm_arguments,
    )


# Built only when their command is run (depict --help and --version import nothing heavy).


def _compare_arguments(p: argparse.ArgumentParser) -> None:
    from analysis.compare import ALBEDOS, N_DIRECTIONS
    from analysis.methods import METHODS

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
    p.add_argument(
        "--plot", metavar="OUT.png", type=named_path, help="scores vs direction (like LLA Fig. 13)"
    )
    p.add_argument(
        "--sheet", metavar="OUT.png", type=named_path, help="renderings and score maps (Fig. 12)"
    )
    p.add_argument("--width", type=int, help="mesh render width (512)")
    p.add_argument("--height", type=int, help="mesh render height (512)")
    p.add_argument("--azimuth", type=float, help="mesh framing azimuth, degrees (30)")
    p.add_argument("--elevation", type=float, help="mesh framing elevation, degrees (20)")
    add_read_options(p)
    add_server_option(p)
    p.set_defaults(command="service.cli.analysis:cmd_compare", remote="service.cli.remote:compare")


def _arm_arguments(p: argparse.ArgumentParser) -> None:
    from service.arm import SHIPPED_ARMS

    p.add_argument("-o", "--output", required=True, type=named_path, help="output PNG")
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
    p.set_defaults(command="service.cli.analysis:cmd_arm")


def add_service_commands(sub: Any) -> None:
    p = sub.add_parser("serve", help="run the HTTP service (settings from DEPICT_* variables)")
    p.add_argument("--host", help="address to bind (DEPICT_HOST, default 127.0.0.1)")
    p.add_argument("--port", type=int, help="port (DEPICT_PORT, default 8000)")
    p.add_argument("--workers", type=int, help="parallel jobs (DEPICT_WORKERS, default 2)")
    p.set_defaults(command="service.cli.serving:cmd_serve")

    p = sub.add_parser("batch", help="enhance a frame sequence on a Dask cluster")
    p.add_argument("input", help="input pattern: shot.####.exr, shot.%%04d.exr or shot.@.exr")
    p.add_argument(
        "-o", "--output", required=True, type=named_path, help="output pattern, same tokens"
    )
    p.add_argument("--frames", help="frames: 1-100, 1-100x2, 1,5,9 (default: existing inputs)")
    add_pipeline_options(p)
    p.add_argument(
        "--scheduler",
        metavar="tcp://HOST:8786",
        type=not_blank("give the scheduler's address, or leave --scheduler out for a local one"),
        help="Dask scheduler (default: local cluster)",
    )
    p.add_argument("--workers", type=int, help="local cluster worker processes (default: cores)")
    p.add_argument("--skip-existing", action="store_true", help="skip frames whose output exists")
    p.add_argument(
        "--pinned",
        metavar="STATS.json",
        help="pinned statistics: reused when the file exists, else measured and written there",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_write_options(p)
    add_read_options(p)
    p.set_defaults(command="service.cli.sequence:cmd_batch")
