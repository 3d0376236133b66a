"""``depict render`` (a mesh to a canonical G-buffer EXR; ``--server``: :mod:`.remote`) and
``depict warmup`` (compile the kernels now)."""

from __future__ import annotations

import argparse
import time

from gbuffer.atomic import check_outputs
from gbuffer.camera import Camera
from gbuffer.limits import Limits
from service.cli.common import exr_name, warn
from service.scene import RenderRequest, render_to_file
from service.warmup import warm


def cmd_render(args: argparse.Namespace) -> int:
    check_outputs([args.output], [args.mesh, args.camera])
    # (the service checks its own settings' limits before a render reaches a worker)
    Limits.from_env().check_render(args.width, args.height, "render")
    scene = RenderRequest(
        width=args.width,
        height=args.height,
        camera=Camera.from_json_file(args.camera) if args.camera else None,
        azimuth=args.azimuth,
        elevation=args.elevation,
        lights=tuple(args.light),
        shading=args.shading,
    )
    done = render_to_file(args.mesh, args.output, scene)
    warn(exr_name(args.output) + done["warnings"])
    print(f"wrote {args.output} ({args.width}x{args.height})")
    return 0


def cmd_warmup(args: argparse.Namespace) -> int:
    t0 = time.perf_counter()
    times = warm()
    for name, seconds in times.items():
        print(f"  {name:<24s} {seconds:6.2f} s")
    print(f"kernels ready ({time.perf_counter() - t0:.1f} s)")
    return 0
