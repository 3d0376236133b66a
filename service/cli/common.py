"""What the commands of ``depict`` share once they run: the compiled pipeline and the read
request their flags describe, and warnings for the user. (Building the parser never imports
this module: see :mod:`service.cli.args`.)"""

from __future__ import annotations

import argparse
import os
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from gbuffer.atomic import check_outputs
from gbuffer.camera import Camera
from gbuffer.capture import terminal
from gbuffer.presets import ReadOptions, find_preset
from service.cli.args import (
    EXIT_USAGE,
    UsageError,
    error_line,
    fail,
    mapping,
    note,
    printable,
    say,
)
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
    """How ``--preset``, ``--map``, ``--normal-space``, ``--view-layer``, ``--colorspace`` and
    ``--camera`` say to read a frame (an unknown preset is refused here, before any file is
    read)."""
    check_preset(args)
    options = ReadOptions(
        mapping=dict(mapping(args)),
        normal_space=args.normal_space,
        layer=getattr(args, "view_layer", None),
        colorspace=getattr(args, "colorspace", None),
    )
    camera = Camera.from_json_file(args.camera) if args.camera else None
    return ReadRequest(args.preset, camera, options)


def check_preset(args: argparse.Namespace) -> None:
    """A FrameError naming the valid presets where ``--preset`` is none of them."""
    if args.preset != "auto":
        find_preset(args.preset)


def warn(messages: list[str]) -> None:
    """Notes for the user (e.g. NaN/Inf pixels read as holes), one line each on stderr."""
    for message in messages:
        note(f"depict: warning: {printable(message)}")


def exr_name(out: str) -> list[str]:
    """A note when an OpenEXR output is named otherwise (``-o shot.png``): what it will be."""
    if Path(out).suffix.lower() == ".exr":
        return []
    return [f"{out} is written as OpenEXR (its name does not end in .exr)"]


def report_written(out: str, warnings: list[str]) -> None:
    """What ``depict enhance`` says of a file it wrote (here or on a server): the warnings of
    its run and of its name, then ``wrote OUT``."""
    warn(warnings + exr_name(out))
    say(f"wrote {out}")


def enhance_targets(args: argparse.Namespace) -> list[tuple[str, str]]:
    """(input, output) of each file ``depict enhance`` names: ``-o`` is the output of a single
    input, or a folder that receives each input's output under the input's name (one that
    exists, or a name ending in /, made as the first output is written). Every output is
    checked before anything is read (none may name an input or another)."""
    inputs: list[str] = list(args.input)
    folder = Path(args.output)
    if folder.is_dir() or args.output.endswith(("/", os.sep)):
        pairs = [(src, str(folder / Path(src).name)) for src in inputs]
    elif len(inputs) > 1:
        raise UsageError(
            f"-o {args.output}: with {len(inputs)} inputs, -o names a folder for their "
            "outputs (one that exists, or a name ending in /)"
        )
    else:
        pairs = [(inputs[0], args.output)]
    check_outputs([out for _, out in pairs], [*inputs, args.camera, args.pipeline])
    return pairs


class StoppedAfter(BaseException):
    """A stop (Ctrl-C, SIGTERM: :attr:`stop`) that came once a file was in place and said:
    :func:`each_file` counts the file, then stops."""

    def __init__(self, stop: BaseException) -> None:
        super().__init__(stop)
        self.stop = stop


def each_file(pairs: list[tuple[str, str]], one: Callable[[str, str], None]) -> int:
    """``one(input, output)`` for every pair, in this process. A single file's failure is the
    command's (one line, exit 2); with several, a file that fails says so on one line and the
    others go on; the exit code is 2 if any failed. Stopped (Ctrl-C, SIGTERM) among several,
    it says how many were enhanced before it ends."""
    failed = enhanced = 0
    for src, out in pairs:
        try:
            one(src, out)
        except Exception as exc:
            line = error_line(exc)
            if line is None or len(pairs) == 1:
                raise
            fail(line if src in line else f"{src}: {line}")
            failed += 1
            continue
        except StoppedAfter as after:
            enhanced += 1
            _stopped(enhanced, failed, len(pairs))
            raise after.stop from None
        except BaseException:
            _stopped(enhanced, failed, len(pairs))
            raise
        enhanced += 1
    if failed:
        say(_tally(enhanced, failed, len(pairs)))
    return EXIT_USAGE if failed else 0


def _stopped(enhanced: int, failed: int, count: int) -> None:
    """The stop line, once no read started ahead holds the terminal: a stop can come between a
    read's start and the point where the caller keeps it to wait for (:mod:`.frames`)."""
    if count > 1:
        with terminal():
            note(f"depict: stopped: {_tally(enhanced, failed, count)}")


def _tally(enhanced: int, failed: int, count: int) -> str:
    return f"{enhanced} of {count} files enhanced" + (f", {failed} failed" if failed else "")
