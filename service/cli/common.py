"""What the commands of ``depict`` share once they run: the compiled pipeline and the read
request their flags describe, and warnings for the user. (Building the parser never imports
this module: see :mod:`service.cli.args`.)"""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

from gbuffer.camera import Camera
from gbuffer.presets import ReadOptions
from service.cli.args import UsageError, mapping, printable
from service.enhance import ReadRequest

if TYPE_CHECKING:  # the operators (and Numba) load when a pipeline is compiled
    from service import pipeline


def steps(args: argparse.Namespace) -> pipeline.Pipeline | None:
    """The pipeline of ``--pipeline`` or of the ``--op`` steps, compiled (validated before any
    pixel is read), or None when neither is given."""
    from service import pipeline

    ops = getattr(args, "steps", None)
    if args.pipeline and ops:
        raise UsageError("give either --pipeline or --op steps, not both")
    if args.pipeline:
        return pipeline.compile(pipeline.load(args.pipeline))
    if ops:
        return pipeline.compile(ops)
    return None


def read_request(args: argparse.Namespace) -> ReadRequest:
    """How ``--preset``, ``--map``, ``--normal-space``, ``--colorspace`` and ``--camera`` say
    to read a frame."""
    options = ReadOptions(
        mapping=dict(mapping(args)),
        normal_space=args.normal_space,
        colorspace=getattr(args, "colorspace", None),
    )
    camera = Camera.from_json_file(args.camera) if args.camera else None
    return ReadRequest(args.preset, camera, options)


def warn(messages: list[str]) -> None:
    """Notes for the user (e.g. NaN/Inf pixels read as holes), one line each on stderr."""
    for message in messages:
        print(f"depict: warning: {printable(message)}", file=sys.stderr)
