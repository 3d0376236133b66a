"""``depict enhance``, ``preview``, ``mask``, ``ops``: run here (``--server``: :mod:`.remote`)."""

from __future__ import annotations

import argparse
import json

import numpy as np

from gbuffer.atomic import check_outputs
from gbuffer.colorspace import View
from gbuffer.preview import picture, write_png
from service.cli.common import each_file, enhance_targets, exr_name, read_request, steps, warn
from service.enhance import ReadAhead, WriteRequest, enhance
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

        started, reads[i] = reads[i], None
        try:
            result = enhance(src, out, compiled, read, write, ahead=started, before_write=read_next)
        except Exception:
            next_read_done()
            raise
        next_read_done()
        warn(result["read_warnings"] + result["warnings"] + exr_name(out))
        print(f"wrote {out}")

    return each_file(pairs, one)


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
