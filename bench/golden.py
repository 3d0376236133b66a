"""Golden pictures: every default's result on committed corpus frames, as 8-bit previews.

``tests/test_golden.py`` compares today's results with ``tests/golden/*.png`` within a tolerance,
so a change of look is deliberate: after one, look at the new pictures and regenerate them with

    python -m bench.golden          # rewrites tests/golden/*.png

Each picture is the operator's default through :func:`service.pipeline.run` (with the frame's key
lights where the operator takes lights), encoded like ``depict preview`` (sRGB, exposure so the
input's 99th percentile of covered luminance maps to 0.9).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from bench import corpus
from gbuffer.frame import Frame
from gbuffer.preview import srgb_encode
from ops.color import luminance
from service import pipeline, registry

ROOT = Path(__file__).resolve().parents[1]
GOLDEN_DIR = ROOT / "tests" / "golden"
#: (frame, operator) pairs held by golden pictures.
CASES: tuple[tuple[str, str], ...] = tuple(
    (frame, op)
    for frame in ("rock_240p_16spp", "still_life_240p_16spp", "metal_240p_16spp")
    for op in ("radiance_scaling", "light_alignment", "unsharp_masking")
)


def case_name(frame: str, op: str) -> str:
    return f"{frame}.{op}.png"


def exposure(frame: Frame) -> float:
    """The factor that maps the 99th percentile of the covered luminance to 0.9."""
    y = luminance(np.ascontiguousarray(frame.buffers["beauty"], np.float32))
    level = float(np.percentile(y[frame.mask > 0.5], 99))
    return 0.9 / level if level > 0 else 1.0


def picture(beauty: np.ndarray, scale: float) -> np.ndarray:
    """8-bit sRGB (H, W, 3) of ``beauty`` times ``scale``."""
    encoded = srgb_encode(np.clip(np.asarray(beauty, np.float32) * np.float32(scale), 0.0, None))
    return np.asarray(np.clip(encoded, 0.0, 1.0) * 255.0 + 0.5, np.uint8)


def render_case(frame_name: str, op: str) -> np.ndarray:
    """Today's picture of ``op``'s default on the committed corpus frame ``frame_name``."""
    found = {f.name: f for f in corpus.find_frames(corpus.CI_DIR)}
    source = found[frame_name]
    frame = source.read()
    params: dict[str, object] = {}
    if "lights" in registry.get(op).params.model_fields:
        params["lights"] = list(source.light_strings())
    out = pipeline.run(frame, [{"op": op, "params": params}])
    return picture(out.buffers["beauty"], exposure(frame))


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=GOLDEN_DIR, help="folder of the pictures")
    args = parser.parse_args(argv)
    from PIL import Image

    args.out.mkdir(parents=True, exist_ok=True)
    for frame, op in CASES:
        path = args.out / case_name(frame, op)
        Image.fromarray(render_case(frame, op)).save(path, optimize=True)
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
