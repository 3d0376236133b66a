"""Write the shipped Apparent Relief Maps (``ops/data/arm/<name>.png``, 8-bit grey).

Run: ``.venv/bin/python -m bench.make_arms`` (add ``--template FILE.png`` to also write the
colour-coded template an artist paints on). The images are :func:`ops.relief.make_arm`,
quantised to 8 bits; ``tests/test_relief.py`` checks the files still match the generator.
"""

from __future__ import annotations

import argparse
import pathlib

import cv2
import numpy as np

from ops.relief import SHIPPED_ARMS, arm_template, make_arm, shipped_arm_path


def to_u8(img: np.ndarray) -> np.ndarray:
    """[0, 1] float -> uint8 (round to nearest)."""
    return np.clip(np.rint(img * 255.0), 0, 255).astype(np.uint8)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--template", type=pathlib.Path, help="also write the ARM template PNG here")
    args = ap.parse_args()
    for name in SHIPPED_ARMS:
        path = shipped_arm_path(name)
        path.parent.mkdir(parents=True, exist_ok=True)
        if not cv2.imwrite(str(path), to_u8(make_arm(name))):
            raise SystemExit(f"could not write {path}")
        print(f"wrote {path}")
    if args.template is not None:
        rgb = to_u8(arm_template(512))
        if not cv2.imwrite(str(args.template), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)):
            raise SystemExit(f"could not write {args.template}")
        print(f"wrote {args.template}")


if __name__ == "__main__":
    main()
