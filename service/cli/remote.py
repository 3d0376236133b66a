"""The commands of ``depict`` that run on a Depict server (``--server URL`` or
``DEPICT_SERVER``; the key from ``DEPICT_API_KEY``) through :class:`service.client.Client`,
with the same flags as locally and the same output (the printing is the local command's)."""

from __future__ import annotations

import argparse

from gbuffer.atomic import check_outputs
from service.cli.analysis import (
    compare_options,
    pick_params,
    print_comparison,
    print_pick,
    print_score,
    read_flags,
    score_options,
)
from service.cli.args import UsageError, mapping
from service.cli.common import (
    check_preset,
    each_file,
    enhance_targets,
    exr_name,
    report_written,
    steps,
    warn,
)
from service.client import Client


def _spec(args: argparse.Namespace) -> object:
    """The pipeline to send, validated here first (None: the server's default)."""
    compiled = steps(args)
    return None if compiled is None else compiled.spec


def render(args: argparse.Namespace) -> int:
    check_outputs([args.output], [args.mesh, args.camera])
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
        warn(exr_name(args.output) + client.warnings)
    print(f"wrote {args.output} ({args.width}x{args.height})")
    return 0


def enhance(args: argparse.Namespace) -> int:
    pairs = enhance_targets(args)
    check_preset(args)
    buffers, spec = mapping(args), _spec(args)
    with Client.from_env(args.server) as client:

        def one(src: str, out: str) -> None:
            client.enhance(
                src,
                out,
                pipeline=spec,
                preset=args.preset,
                camera=args.camera,
                mapping=buffers,
                normal_space=args.normal_space,
                colorspace=args.colorspace,
                view_layer=args.view_layer,
                debug_layers=args.debug_layers,
                output_layer=args.output_layer,
                layout=args.layout,
            )
            report_written(out, client.warnings)

        return each_file(pairs, one)


def score(args: argparse.Namespace) -> int:
    spec = _spec(args)
    options = score_options(args)
    with Client.from_env(args.server) as client:
        data = client.score(
            args.file,
            pipeline=spec,
            preset=args.preset,
            camera=args.camera,
            mapping=mapping(args),
            normal_space=args.normal_space,
            colorspace=args.colorspace,
            view_layer=args.view_layer,
            **options,
        )
    return print_score(args, data)


#: The flags of reading a frame that ``compare`` and ``relief-pick`` send to a server.
SENT_READ_FLAGS = ("--preset", "--camera")


def _unsent_read_flags(args: argparse.Namespace, command: str) -> None:
    """A UsageError for the flags of reading a frame that ``command``'s route does not take:
    they were dropped without a word (a different score than the same command here)."""
    unsent = [f for f, given in read_flags(args).items() if given and f not in SENT_READ_FLAGS]
    if unsent:
        raise UsageError(
            f"{', '.join(unsent)}: not sent to a server by {command} (its route reads the file "
            "with --preset and --camera only); run it here, without --server"
        )


def compare(args: argparse.Namespace) -> int:
    is_mesh, options = compare_options(args)
    if not is_mesh:
        _unsent_read_flags(args, "compare")
    with Client.from_env(args.server) as client:
        data = client.compare(
            args.input,
            options,
            mesh=is_mesh,
            sheet=args.sheet,
            preset=args.preset,
            camera=args.camera,
        )
    return print_comparison(args, data)


def relief_pick(args: argparse.Namespace) -> int:
    _unsent_read_flags(args, "relief-pick")
    with Client.from_env(args.server) as client:
        data = client.relief_pick(
            args.file, args.x, args.y, pick_params(args), preset=args.preset, camera=args.camera
        )
    return print_pick(args, data)
