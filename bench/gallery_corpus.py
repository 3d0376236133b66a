"""Before/after sheets of every operator's defaults on the corpus frames, with their figures.

``make gallery`` runs this (``.venv/bin/python -m bench.gallery_corpus``) before
:mod:`bench.gallery`. For each frame of the committed corpus subset (``tests/fixtures/corpus``)
and of ``corpus/frames`` when it has been rendered (``make corpus``), it runs each operator of
:data:`bench.quality.DEFAULT_OPS` with its defaults (and the frame's key lights) and writes
``gallery/corpus/FRAME.png``: one row per operator with

- the input and the result at full frame (100 % for 240p frames; larger ones scaled to
  :data:`ROW` pixels high) and the change of lightness (blue darker, red lighter);
- two crops enlarged by whole factors with nearest-neighbour (4× for 240p, 2× for larger
  frames), before and after: the object window with the most band-pass detail and the nearest
  window of flat, directly lit floor (where added noise shows), so the pixels can be judged
  one by one;
- the figures of :mod:`bench.quality` on the change picture's label (those that miss their
  target marked ``*``).

``--frames`` keeps the frames whose name contains one of the given strings, ``--op`` picks
operators, ``--dir`` other folders of frames. ``--docs DIR`` also writes the README's
``defaults_cycles.png`` (:func:`docs_defaults`).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from bench import corpus, quality
from bench.gallery import DEFAULT_OUT
from bench.sheets import Box, Tile, change_pic, pic, save, sheet
from gbuffer.colorspace import View
from gbuffer.frame import Frame
from ops.color import luminance

#: Height of every row of a sheet (a 240p frame at 100 %), pixels.
ROW = 240
#: Lightness change (sRGB-encoded luminance) that saturates the change picture.
CHANGE_PEAK = 0.15


def zoom_of(height: int) -> int:
    """Enlargement of the crops: 4× for frames up to 300 px high, else 2×."""
    return 4 if height <= 300 else 2


def best_window(score: np.ndarray, side: int) -> Box:
    """The ``side`` × ``side`` window (y0, y1, x0, x1) inside the image with the largest sum of
    ``score``."""
    h, w = score.shape
    side = min(side, h, w)
    sums = cv2.boxFilter(score.astype(np.float32), -1, (side, side), normalize=False)
    half = side // 2
    inner = sums[half : h - side + half + 1, half : w - side + half + 1]
    y, x = np.unravel_index(int(np.argmax(inner)), inner.shape)
    return int(y), int(y) + side, int(x), int(x) + side


def crop_windows(ref: quality.Reference) -> list[tuple[str, Box]]:
    """The most detailed object window and, when the frame has one, the flat lit floor's."""
    frame, regs = ref.frame, ref.regions
    h = frame.shape[0]
    side = ROW // zoom_of(h)
    y = luminance(np.asarray(frame.buffers["beauty"], np.float32))
    s1, s2 = (s * h for s in quality.DETAIL_SIGMAS)
    band = quality.masked_blur(y, regs.objects, s1) - quality.masked_blur(y, regs.objects, s2)
    coarse = quality.masked_blur(y, regs.objects, s2)
    detail = np.where(regs.objects & (coarse > 0), np.abs(band) / np.maximum(coarse, 1e-6), 0.0)
    out = [("detail", best_window(detail, side))]
    if regs.flat_floor.sum() > side * side // 2:
        # the nearest floor: its texture is not minified into aliasing, its noise is the frame's
        depth = np.asarray(frame.buffers["depth"], np.float32)
        near = np.where(regs.flat_floor, 1.0 / np.maximum(depth, 1e-6) ** 2, 0.0)
        out.append(("lit floor", best_window(near, side)))
    return out


def enlarge(img: np.ndarray, box: Box, zoom: int) -> np.ndarray:
    y0, y1, x0, x1 = box
    return np.repeat(np.repeat(img[y0:y1, x0:x1], zoom, axis=0), zoom, axis=1)


def figures_label(fig: quality.Figures) -> str:
    missed = set(quality.misses(fig))

    def m(key: str, text: str) -> str:
        return text + ("*" if key in missed else "")

    noise = "-" if np.isnan(fig.floor_noise) else f"{fig.floor_noise:.2f}"
    return "|".join(
        [
            m("lum_objects", f"lum {fig.lum_objects:.2f}")
            + " "
            + m("hot", f"hot {100 * fig.hot:.2f}%"),
            m("lf_corr", f"LF {fig.lf_corr:.3f}") + " " + m("detail", f"detail {fig.detail:.2f}"),
            m("floor_noise", f"noise {noise}") + " " + m("negatives", f"neg {fig.negatives}"),
            m("cong", f"cong {fig.cong_before:.2f}>{fig.cong_after:.2f}")
            + " "
            + m("cong_objects", f"obj {fig.cong_objects_before:.2f}>{fig.cong_objects_after:.2f}"),
        ]
    )


def operator_row(
    ref: quality.Reference, op: str, out: Frame, windows: list[tuple[str, Box]], view: View
) -> list[Tile]:
    before, after = pic(ref.frame, view=view), pic(out, view=view)
    fig = quality.figures(ref, out)
    zoom = zoom_of(ref.frame.shape[0])
    row: list[Tile] = [
        (before, "input"),
        (after, op),
        (
            change_pic(before, after, ref.regions.covered, CHANGE_PEAK),
            f"change +-{CHANGE_PEAK:g}|{figures_label(fig)}",
        ),
    ]
    for name, box in windows:
        row.append((enlarge(before, box, zoom), f"{name} x{zoom}: input"))
        row.append((enlarge(after, box, zoom), f"{name} x{zoom}: {op}"))
    return row


def frame_sheet(cf: corpus.CorpusFrame, ops: Sequence[str], view: View) -> np.ndarray:
    ref = quality.reference(cf.read())
    windows = crop_windows(ref)
    lights = cf.light_strings()
    rows = [
        operator_row(ref, op, quality.run_operator(ref.frame, op, lights), windows, view)
        for op in ops
    ]
    h, w = ref.frame.shape
    title = (
        f"{cf.name} ({w}x{h}): each operator's defaults; crops x{zoom_of(h)} nearest-neighbour; "
        "* = misses its target (bench/quality.py)"
    )
    return sheet(rows, title, height=ROW, label_scale=0.36)


#: The corpus frame of the README's picture of the defaults: the largest rendered rock frame.
DOCS_SCENE = "rock"
#: Operators of that picture.
DOCS_OPS = ("radiance_scaling", "light_alignment", "unsharp_masking")


def docs_defaults(out: Path, written: list[Path]) -> None:
    """``defaults_cycles.png`` for the README: a Blender Cycles corpus frame (the largest rock
    frame rendered, else the committed 240p one), its input and each default of
    :data:`DOCS_OPS` at 800 px wide, and the same crop of each enlarged with nearest-neighbour."""
    rocks = [f for f in corpus.gather(None, [DOCS_SCENE]) if f.name.startswith(DOCS_SCENE)]
    cf = max(rocks, key=lambda f: (corpus.SIZES.get(f.name.split("_")[1], (0, 0))[1], f.name))
    ref = quality.reference(cf.read())
    lights = cf.light_strings()
    results = [(pic(quality.run_operator(ref.frame, op, lights)), op) for op in DOCS_OPS]
    h, w = ref.frame.shape
    _, box = crop_windows(ref)[0]
    zoom = max(1, round(800 / 2 / (box[1] - box[0])))
    full = [(pic(ref.frame), "Cycles input"), *results]
    crops = [(enlarge(img, box, zoom), f"{label} x{zoom}") for img, label in full]
    title = f"Each default on a Blender Cycles frame ({cf.name}, {w}x{h}), and a crop x{zoom}"
    height = round(800 * h / w)
    rows = [full[:2], full[2:], crops]
    save(sheet(rows, title, height=[height, height, 400], gap=4), out, written)


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("out", nargs="?", type=Path, default=DEFAULT_OUT / "corpus")
    ap.add_argument("--dir", type=Path, action="append", help="folder of frames (repeatable)")
    ap.add_argument("--frames", nargs="+", default=(), help="only frames whose name has one of")
    ap.add_argument("--op", action="append", help="operator (repeatable)")
    ap.add_argument("--docs", type=Path, default=None, help="also write the README's picture here")
    ap.add_argument("--display", help="OCIO display of the sheets (default: the config's)")
    ap.add_argument("--view", help="OCIO view (default: the display's); raw: exposure and clip")
    args = ap.parse_args(argv)
    view = View(args.display, args.view)
    frames = corpus.gather(args.dir, args.frames)
    if not frames:
        print("gallery: no corpus frames (see python -m bench.corpus --help)", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    written: list[Path] = []
    for cf in frames:
        sheet_ = frame_sheet(cf, args.op or quality.DEFAULT_OPS, view)
        save(sheet_, args.out / f"{cf.name}.png", written)
    if args.docs is not None:
        docs_defaults(args.docs / "defaults_cycles.png", written)
    print(f"gallery: {len(written)} corpus sheets in {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
