"""Masks: Radiance Scaling and Light Alignment restricted to one object of a Blender frame.

``python -m bench.gallery_masks [--out DIR]`` reads the Blender Cycles render with Cryptomatte
passes (``tests/fixtures/blender/cryptomatte.exr``), runs each operator on the whole frame and
with ``mask: "cryptomatte:Suzanne"`` (through :func:`service.pipeline.run`), prints how many
pixels changed inside and outside the matte, and writes ``masks_blender.png`` (at least 800 px
wide) into DIR (default ``gallery/``; ``--out docs/images`` refreshes the README's picture):
the beauty, the Cryptomatte ids and the matte; then for each operator the whole frame, the
masked step and the lightness change of the masked step; last, Suzanne enlarged before and after
each masked step.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

import gbuffer
from bench.gallery import BLENDER, DEFAULT_OUT, apply, blender_lights
from bench.sheets import change_pic, crop, crop_box, rgb_pic, save, sheet
from gbuffer.frame import Frame
from gbuffer.preview import picture
from service.masks import matte

MASK = "cryptomatte:Suzanne"
#: Peak lightness change of the change pictures (sRGB-encoded luminance).
PEAK = 0.1


def steps(frame: Frame) -> dict[str, dict[str, Any]]:
    """The operators shown: Radiance Scaling of the lobes, Light Alignment (ratio form) with
    the shot's own lights."""
    return {
        "Radiance Scaling": {"op": "radiance_scaling"},
        "Light Alignment": {"op": "light_alignment", "lights": blender_lights(frame)},
    }


def figures(frame: Frame) -> tuple[dict[str, Any], list[list[tuple[np.ndarray, str]]]]:
    """Pixels changed by each step, whole frame and masked, and the picture rows."""
    m = matte(frame, MASK)
    before = picture(frame, "beauty")
    ids = picture(frame, "cryptomatte")
    result: dict[str, Any] = {
        "mask": MASK,
        "matte_inside_px": int(np.count_nonzero(m >= 1.0)),
        "matte_edge_px": int(np.count_nonzero((m > 0) & (m < 1))),
    }
    rows = [
        [
            (before, "Cycles beauty"),
            (ids, "Cryptomatte ids (CryptoObject)"),
            (np.repeat(m[..., None], 3, axis=2), f"mask {MASK}"),
        ]
    ]
    beauty = frame.buffers["beauty"]
    box = crop_box(m, margin=0.15)
    zoom = [(crop(before, box), "Suzanne, enlarged: before")]
    for label, step in steps(frame).items():
        op, params = step["op"], {k: v for k, v in step.items() if k != "op"}
        whole = apply(frame, op, **params).buffers["beauty"]
        masked = apply(frame, op, mask=MASK, **params).buffers["beauty"]
        changed = (masked != beauty).any(axis=-1)
        result[op] = {
            "changed_px_whole_frame": int(np.count_nonzero((whole != beauty).any(axis=-1))),
            "changed_px_masked": int(np.count_nonzero(changed)),
            "changed_px_outside_matte": int(np.count_nonzero(changed & (m == 0))),
        }
        after = rgb_pic(frame, masked)
        zoom.append((crop(after, box), f"{label}, masked"))
        rows.append(
            [
                (rgb_pic(frame, whole), f"{label}: whole frame"),
                (after, f"{label}: {MASK}"),
                (change_pic(before, after, m, PEAK), "change: blue darker, red lighter"),
            ]
        )
    return result, [*rows, zoom]


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="output folder")
    args = parser.parse_args(argv)
    exr = BLENDER / "cryptomatte.exr"
    if not exr.is_file():
        raise SystemExit(f"gallery_masks: the Blender fixture {exr} is absent (see its README)")
    frame = gbuffer.read(exr)
    result, rows = figures(frame)
    print(json.dumps(result, indent=2))
    title = "Masks: each step restricted to Suzanne by Cryptomatte; every other pixel bit-exact"
    kw: dict[str, Any] = {"gap": 2, "label_scale": 0.5, "title_scale": 0.55}
    heights = [300] * (len(rows) - 1) + [400]
    save(sheet(rows, title, height=heights, **kw), args.out / "masks_blender.png", [])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
