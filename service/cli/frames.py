"""``depict enhance``, ``preview``, ``mask``, ``ops``: run here (``--server``: :mod:`.remote`)."""

from __future__ import annotations

import argparse
import contextlib
import json
import os
from collections.abc import Callable

import numpy as np

from gbuffer.atomic import check_outputs
from gbuffer.colorspace import View
from gbuffer.preview import picture, write_png
from service.cli.args import say
from service.cli.common import (
    StoppedAfter,
    each_file,
    enhance_targets,
    read_request,
    report_written,
    steps,
)
from service.enhance import Enhanced, ReadAhead, WriteRequest, enhance
from service.masks import matte

# The operators (and Numba) are imported by the commands that run or list them, not by
# ``preview`` and ``mask``.


def cmd_enhance(args: argparse.Namespace) -> int:
    pairs = enhance_targets(args)
    read = read_request(args)
    write = WriteRequest(
        debug_layers=args.debug_layers, output_layer=args.output_layer, layout=args.layout
    )
    # the first input decodes while the operators (and Numba) are imported and the pipeline is
    # checked, then beside Numba's start-up; a pipeline refused is said once the decode has
    # given the terminal back (the reader captures what the OpenEXR library prints)
    ahead = ReadAhead(pairs[0][0], read, write, prepare=False)
    try:
        from service import pipeline

        compiled = steps(args) or pipeline.DEFAULT
    except Exception:
        ahead.wait()
        raise
    ahead.prepare()
    reads: list[ReadAhead | None] = [ahead] + [None] * (len(pairs) - 1)  # each input's, started
    position = iter(range(len(pairs)))

    def one(src: str, out: str) -> None:
        i = next(position)

        def read_next() -> None:  # the next input decodes while this one's result is written
            if i + 1 < len(pairs):
                reads[i + 1] = ReadAhead(pairs[i + 1][0], read, write, prepare=False)

        def next_read_done() -> None:  # (its decode has the terminal: nothing said before)
            following = reads[i + 1] if i + 1 < len(pairs) else None
            if following is not None:
                following.wait()

        # this input's read: started ahead, or now (``--layout same`` reads none ahead)
        started = reads[i] or ReadAhead(src, read, write, prepare=False)
        reads[i] = None

        def reads_done() -> None:  # this input's too (stopped while it decodes)
            started.wait()
            next_read_done()

        before = _file_id(out)
        result: Enhanced | None = None
        try:
            result = enhance(src, out, compiled, read, write, ahead=started, before_write=read_next)
            stop = _wait_through_stops(next_read_done)
        except Exception:
            late = _wait_through_stops(reads_done)
            if late is not None:
                raise late from None
            raise
        except BaseException as stopped:  # Ctrl-C, SIGTERM
            _wait_through_stops(reads_done)
            if _file_id(out) in (before, None):
                raise
            stop = stopped  # it came once the output was in place: said, then raised
        _said(out, result, stop)

    return each_file(pairs, one)


def _said(out: str, result: Enhanced | None, stop: BaseException | None) -> None:
    """:func:`report_written` of a file in place, then the stop that came meanwhile, if any, as
    :class:`StoppedAfter` (the file counts as enhanced)."""
    try:
        if result is None:
            say(f"wrote {out}")
        else:
            report_written(out, result["read_warnings"] + result["warnings"])
    except Exception:
        raise
    except BaseException as late:  # (stopped as it is said)
        raise StoppedAfter(stop or late) from None
    if stop is not None:
        raise StoppedAfter(stop) from None


def _file_id(path: str) -> tuple[int, int] | None:
    """The (device, inode) of the file at ``path``, None where there is none: an output written
    is a new file (renamed into place: :func:`gbuffer.atomic.atomic_path`)."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_dev, st.st_ino


def _wait_through_stops(wait: Callable[[], None]) -> BaseException | None:
    """``wait()`` to the end, and the stop (Ctrl-C, SIGTERM) that came meanwhile, if any: what is
    said after it must not go into the temporary file a decode points the terminal at
    (:mod:`gbuffer.capture`), and the decode ends within about a second. A second stop gives up
    waiting."""
    try:
        wait()
    except BaseException as stop:
        with contextlib.suppress(BaseException):
            wait()
        return stop
    return None


def cmd_preview(args: argparse.Namespace) -> int:
    check_outputs([args.output], [args.file, args.camera])
    view = View(args.display, args.view)
    if not view.raw:
        view.resolved()  # an unknown display or view is refused before the frame is read
    frame = read_request(args).read(args.file)
    write_png(picture(frame, args.layer, args.exposure, view), args.output)
    print(f"wrote {args.output} ({args.layer})")
    return 0


def cmd_mask(args: argparse.Namespace) -> int:
    check_outputs([args.output], [args.file, args.camera])
    frame = read_request(args).read(args.file)
    m = matte(frame, args.spec, args.feather, args.amount)
    write_png(np.repeat(m[..., None], 3, axis=2), args.output)
    inside, edge = int(np.count_nonzero(m >= 1.0)), int(np.count_nonzero((m > 0) & (m < 1)))
    print(f"wrote {args.output} ({args.spec}: {inside} pixels inside, {edge} partly)")
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
            default = field.get_default(call_default_factory=True)
            shown = "-" if default is None else default
            if isinstance(default, list | dict):
                shown = json.dumps(default, ensure_ascii=False)
            print(f"    {name:<22s} = {shown!s:<12s} {field.description or ''}")
    return 0
