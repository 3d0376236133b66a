"""Benchmark: EXR read and write of a 1920x1080 G-buffer (12 half channels, ZIP).

Run: ``.venv/bin/python -m bench.bench_exr``. The frame holds Depict's canonical channels
(R G B A, N.XYZ, depth.Z, albedo.RGB, AO.X) of a shaded sphere. Timed: decoding the parts,
reading into a Frame (decode + preset mapping), a no-op write (unchanged parts are copied
chunk for chunk), a write with three new float outputs (the part is encoded again), and for
reference the OpenEXR binding's own write of the same channels and a copy of the file by
OpenImageIO's ``oiiotool`` (decode and encode again, in its own process).
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import OpenEXR

from bench.common import HD, Report
from gbuffer import exr, read, write


def frame_channels(shape: tuple[int, int] = HD) -> dict[str, np.ndarray]:
    h, w = shape
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    u, v = (x - w / 2) / (0.45 * h), -(y - h / 2) / (0.45 * h)
    r2 = u * u + v * v
    inside = r2 < 1.0
    nz = np.sqrt(np.clip(1.0 - r2, 0.0, 1.0))
    n = np.dstack([u, v, nz]) * inside[..., None]
    shade = np.clip(n @ np.array([0.3, 0.5, 0.8], np.float32), 0, None)
    albedo = np.dstack([0.2 + 0.6 * x / w, 0.5 + 0 * x, 0.8 - 0.5 * y / h]) * inside[..., None]
    ch = {c: (albedo[..., k] * shade) for k, c in enumerate("RGB")}
    ch["A"] = inside.astype(np.float32)
    ch.update({f"N.{c}": n[..., k] for k, c in enumerate("XYZ")})
    ch["depth.Z"] = np.where(inside, 5.0 - nz, np.inf)
    ch.update({f"albedo.{c}": albedo[..., k] for k, c in enumerate("RGB")})
    ch["AO.X"] = 0.5 + 0.5 * nz
    return {k: np.ascontiguousarray(a, dtype=np.float16) for k, a in ch.items()}


def main() -> None:
    report = Report("EXR I/O, 12 half channels, ZIP")
    channels = frame_channels()
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "frame.exr"
        header = {"compression": OpenEXR.ZIP_COMPRESSION}
        OpenEXR.File(dict(header), dict(channels)).write(str(src))
        out = Path(tmp) / "out.exr"
        report.time("read_parts (decode 12 channels)", lambda: exr.read_parts(src), repeat=5)
        report.time("gbuffer.read (decode + canonical preset)", lambda: read(src), repeat=5)
        frame = read(src)
        report.time("gbuffer.write, no outputs (chunk copy)", lambda: write(frame, out), repeat=5)
        outputs = read(src)
        h, w = HD
        for name in ("curvature.H", "curvature.k1", "curvature.k2"):
            outputs.outputs[name] = np.zeros((h, w), np.float32)
        report.time(
            "gbuffer.write, +3 float outputs (ZIP encode)", lambda: write(outputs, out), repeat=5
        )
        report.time(
            "OpenEXR.File.write of the 12 channels (reference)",
            lambda: OpenEXR.File(dict(header), dict(channels)).write(str(out)),
            repeat=5,
        )
        oiiotool = str(Path(sys.executable).with_name("oiiotool"))  # from the openimageio wheel
        report.time(
            "oiiotool src.exr -o out.exr (reference, with process start)",
            lambda: subprocess.run([oiiotool, str(src), "-o", str(out)], check=True),
            repeat=5,
        )


if __name__ == "__main__":
    main()
