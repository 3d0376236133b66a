"""``depict enhance``, ``preview`` and ``ops``: run locally (``--server``: :mod:`.remote`)."""

from __future__ import annotations

import argparse
import json

from gbuffer.atomic import check_outputs
from gbuffer.preview import picture, write_png
from service import pipeline
from service.cli.common import read_request, steps, warn
from service.enhance import WriteRequest, enhance
from service.registry import operators


def cmd_enhance(args: argparse.Namespace) -> int:
    check_outputs([args.output], [args.input, args.camera, args.pipeline])
    compiled = steps(args) or pipeline.DEFAULT
    write = WriteRequest(
        debug_layers=args.debug_layers, output_layer=args.output_layer, layout=args.layout
    )
    result = enhance(args.input, args.output, compiled, read_request(args), write)
    warn(result["read_warnings"] + result["warnings"])
    print(f"wrote {args.output}")
    return 0


def cmd_preview(args: argparse.Namespace) -> int:
    check_outputs([args.output], [args.file, args.camera])
    frame = read_request(args).read(args.file)
    write_png(picture(frame, args.layer, exposure=args.exposure), args.output)
    print(f"wrote {args.output} ({args.layer})")
    return 0


def cmd_ops(args: argparse.Namespace) -> int:
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
