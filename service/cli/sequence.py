"""``depict batch``: a frame sequence on a Dask cluster (:mod:`service.batch`), each frame
through the one enhance path (:func:`service.enhance.enhance`)."""

from __future__ import annotations

import argparse
import os
import sys

from service import pipeline
from service.batch import BatchError, Summary, parse_frames, run_batch
from service.cli.args import printable
from service.cli.common import read_request, steps
from service.enhance import WriteRequest
from service.output import check_layer_name


def cmd_batch(args: argparse.Namespace) -> int:
    """Exit 1 when a frame failed, so a farm retries the chunk."""
    compiled = steps(args) or pipeline.DEFAULT
    if args.camera and not os.path.isfile(args.camera):
        raise BatchError(f"--camera {args.camera}: no such file")
    read = read_request(args)  # the camera is read here: workers may run in another folder
    write = WriteRequest(
        debug_layers=args.debug_layers, output_layer=args.output_layer, layout=args.layout
    )
    frames = None if args.frames is None else parse_frames(args.frames)  # ("": every frame)
    if args.output_layer is not None:
        check_layer_name(args.output_layer)
    cores = os.cpu_count() or 1
    if args.workers is not None and not 1 <= args.workers <= 4 * cores:  # (1000: 1000 processes)
        raise BatchError(
            f"--workers {args.workers}: give 1 to {4 * cores} (this machine has {cores} cores; "
            "a farm's nodes join with --scheduler)"
        )
    summary = run_batch(
        os.path.abspath(args.input),
        os.path.abspath(args.output),
        steps=compiled,
        frames=frames,
        read=read,
        write=write,
        scheduler=args.scheduler,
        workers=args.workers,
        skip_existing=args.skip_existing,
        pinned_file=args.pinned,
        progress=not args.no_progress,
    )
    total = len(summary.done) + len(summary.skipped) + len(summary.failed)
    print_summary(summary, total)
    return 0 if summary.ok else 1


def print_summary(summary: Summary, total: int) -> None:
    """The end-of-run report: counts, pinned statistics and one line per failed frame."""
    print(
        f"batch: {len(summary.done)} done, {len(summary.skipped)} skipped, "
        f"{len(summary.failed)} failed (of {total} frames) in {summary.seconds:.1f} s"
    )
    if summary.pinned:
        pins = ", ".join(f"{k}={v:.6g}" for k, v in sorted(summary.pinned.items()))
        print(f"  pinned: {pins}")
    for frame, error in summary.failed.items():
        print(f"  frame {frame} failed: {printable(error)}")
    for warning, frames in summary.warnings.items():
        print(f"depict: warning ({len(frames)} frames): {printable(warning)}", file=sys.stderr)
