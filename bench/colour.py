"""Colour management figures: the same frames as linear Rec.709 and as ACEScg enhance, score and
preview alike (``python -m bench.colour [--docs DIR]``).

For each corpus frame (CI set) an ACEScg copy is written (every RGB layer converted by
OpenColorIO, ``chromaticities`` = AP1) and read back. For each default operator the change it
makes to the beauty is compared, converted back to Rec.709 by OCIO: the disagreement is
Σ|Δ_ACEScg − Δ_709| / Σ|Δ_709| over covered pixels. The same is measured without colour
management (the ACEScg copy read with ``colorspace=lin_rec709``, as Depict read every file
before), and so are the congruence score and the preview (99th percentile of the 8-bit
difference through the config's default view). ``--docs DIR`` also writes
``colour_hdr_preview.png`` (a bright frame through the hard clip and through the ACES 2.0 view)
and ``colour_agreement.png`` (previews of a frame, of its ACEScg copy, and of the copy read
without colour management).
"""

from __future__ import annotations

import argparse
import json
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import OpenEXR
import PyOpenColorIO as ocio

import gbuffer
from analysis.score import score_frame
from bench import corpus
from bench.sheets import save, sheet
from gbuffer.colorspace import BUILTIN_CONFIG, View
from gbuffer.frame import Frame
from gbuffer.preview import picture
from ops.colorspace import ACES_AP1
from service import pipeline

OPS = ("radiance_scaling", "unsharp_masking", "light_alignment", "depth_unsharp_masking")
#: The corpus frame of the README's pictures.
DOCS_FRAME = "still_life_240p_16spp"
#: Stops above the frame's own exposure for the high-dynamic-range picture.
HDR_STOPS = 2.5


def ocio_convert(rgb: np.ndarray, src: str, dst: str) -> np.ndarray:
    """``rgb`` (..., 3) from OCIO space ``src`` to ``dst`` by OpenColorIO itself (its built-in
    config, not Depict's own matrices), float32."""
    proc = (
        ocio.Config.CreateFromFile(BUILTIN_CONFIG).getProcessor(src, dst).getDefaultCPUProcessor()
    )
    x = np.ascontiguousarray(np.asarray(rgb, np.float32)).copy()
    proc.applyRGB(x)
    return x


def space_copy(
    src: str | Path,
    dst: str | Path,
    convert: Callable[[np.ndarray], np.ndarray],
    chromaticities: Sequence[float],
) -> None:
    """Write ``src`` (linear Rec.709) in another space: every RGB(A) layer's colours through
    ``convert`` (normals, depth and positions are stored as separate X/Y/Z channels and stay),
    the header's ``chromaticities`` those of the space."""
    with OpenEXR.File(str(src)) as f:
        header = dict(f.header())
        channels = {name: np.array(c.pixels) for name, c in f.channels().items()}
    for name, pixels in channels.items():
        if pixels.ndim == 3 and pixels.shape[2] in (3, 4):
            out = pixels.astype(np.float32)
            out[..., :3] = convert(out[..., :3])
            channels[name] = out
    header["chromaticities"] = tuple(chromaticities)
    OpenEXR.File(header, channels).write(str(dst))


def acescg_copy(src: str | Path, dst: str | Path) -> None:
    """Write ``src`` (linear Rec.709) as ACEScg, every colour converted by OpenColorIO,
    chromaticities = AP1 (:func:`space_copy`)."""
    space_copy(src, dst, lambda rgb: ocio_convert(rgb, "lin_rec709", "ACEScg"), ACES_AP1)


def _rec709(frame: Frame, rgb: np.ndarray) -> np.ndarray:
    if frame.colorspace.is_rec709:
        return rgb
    return ocio_convert(rgb, "ACEScg", "lin_rec709")


def _change(frame: Frame, op: str, managed: bool) -> np.ndarray:
    after = pipeline.run(frame, [{"op": op}]).buffers["beauty"]
    if managed:
        return _rec709(frame, after) - _rec709(frame, frame.buffers["beauty"])
    return after - frame.buffers["beauty"]


def _preview(frame: Frame) -> np.ndarray:
    return np.round(picture(frame, "beauty", 0.0, View()) * 255.0)


def measure(source: corpus.CorpusFrame, folder: Path) -> dict[str, float]:
    """Disagreements (with and without colour management) of one frame's ACEScg copy."""
    copy = folder / f"{source.name}.acescg.exr"
    acescg_copy(source.exr, copy)
    rec709 = source.read()
    managed = gbuffer.read(copy, camera=source.camera)
    unmanaged = gbuffer.read(copy, camera=source.camera, options={"colorspace": "lin_rec709"})
    covered = rec709.mask > 0
    row: dict[str, float] = {}
    for op in OPS:
        d0 = _change(rec709, op, True)[covered]
        for key, frame, conv in (("with", managed, True), ("without", unmanaged, False)):
            d1 = _change(frame, op, conv)[covered]
            row[f"{op}.{key}"] = float(np.abs(d1 - d0).sum() / np.abs(d0).sum())
    s0 = score_frame(rec709)["score"]
    row["score.with"] = abs(score_frame(managed)["score"] - s0)
    row["score.without"] = abs(score_frame(unmanaged)["score"] - s0)
    p0 = _preview(rec709)
    row["preview_p99.with"] = float(np.percentile(np.abs(_preview(managed) - p0), 99))
    row["preview_p99.without"] = float(np.percentile(np.abs(_preview(unmanaged) - p0), 99))
    return row


def table(rows: dict[str, dict[str, float]]) -> str:
    """The figures as a Markdown table (per cent for the operators)."""
    cols = [*OPS, "score", "preview_p99"]
    head = "| frame | " + " | ".join(cols) + " |"
    lines = [head, "|" + " --- |" * (len(cols) + 1)]
    for name, row in rows.items():
        cells = []
        for c in cols:
            a, b = row[f"{c}.with"], row[f"{c}.without"]
            if c in OPS:
                cells.append(f"{100 * a:.2f} % ({100 * b:.1f} %)")
            elif c == "score":
                cells.append(f"{a:.4f} ({b:.4f})")
            else:
                cells.append(f"{a:.0f} ({b:.0f})")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def hdr_picture(source: corpus.CorpusFrame, path: Path, written: list[Path]) -> None:
    """A frame HDR_STOPS brighter through Depict's hard clip and through the config's default
    view (ACES 2.0 SDR), each 860 px wide."""
    frame = source.read()
    tiles = [
        (picture(frame, "beauty", HDR_STOPS, View(view="raw")), "--view raw: exposure, hard clip"),
        (picture(frame, "beauty", HDR_STOPS, View()), "default view: ACES 2.0 - SDR 100 nits"),
    ]
    h, w = frame.shape
    title = f"{source.name} at +{HDR_STOPS:g} stops: hard clip vs the view transform"
    save(sheet([tiles], title, height=round(860 * h / w)), path, written)


def agreement_picture(
    source: corpus.CorpusFrame, copy: Path, path: Path, written: list[Path]
) -> None:
    """Previews through the default view: the Rec.709 file, its ACEScg copy, and the ACEScg
    copy read as if it were Rec.709 (no colour management)."""
    frames = [
        (source.read(), "Rec.709 file"),
        (gbuffer.read(copy, camera=source.camera), "ACEScg copy (chromaticities)"),
        (
            gbuffer.read(copy, camera=source.camera, options={"colorspace": "lin_rec709"}),
            "ACEScg copy read as Rec.709",
        ),
    ]
    tiles = [(picture(f, "beauty", 0.0, View()), label) for f, label in frames]
    h, w = frames[0][0].shape
    title = f"{source.name}: the same picture in two working spaces, previewed"
    save(sheet([tiles], title, height=round(600 * h / w)), path, written)


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("--docs", type=Path, default=None, help="also write the README picture here")
    ap.add_argument("--json", action="store_true", help="the figures as JSON")
    args = ap.parse_args(argv)
    frames = corpus.find_frames(corpus.CI_DIR)
    with tempfile.TemporaryDirectory() as tmp:
        rows = {f.name: measure(f, Path(tmp)) for f in frames}
        print(json.dumps(rows, indent=2) if args.json else table(rows))
        if args.docs is not None:
            written: list[Path] = []
            still = {f.name: f for f in frames}[DOCS_FRAME]
            hdr_picture(still, args.docs / "colour_hdr_preview.png", written)
            copy = Path(tmp) / f"{DOCS_FRAME}.acescg.exr"
            agreement_picture(still, copy, args.docs / "colour_agreement.png", written)
            print("\n".join(str(p) for p in written))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
