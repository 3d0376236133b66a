"""Pictures of a comparison: the scores plotted like LLA Fig. 13, the renderings with their
score maps like Fig. 12."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from analysis.methods import LABELS
from analysis.result import ComparisonResult, direction_angles

F32 = NDArray[np.float32]

#: Directions shown by default on a contact sheet, like the rows of LLA Fig. 12 (from well lit
#: to grazing to behind): frontal, 60° and grazing from the right, 150° behind on the right,
#: grazing from above, 150° behind on the left (the paper's numbers differ from our sweep's).
SHEET_DIRECTIONS: tuple[int, ...] = (1, 3, 4, 6, 9, 16)


def plot(result: ComparisonResult, path: str | Path, title: str | None = None) -> Path:
    """Scores vs direction number, one line per method, means dashed (like LLA Fig. 13).

    Grazing directions (θ = 90°) are shaded light grey, those behind the object (θ > 90°)
    darker. Written with matplotlib's Agg backend, atomically; returns the path.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from gbuffer.atomic import atomic_path

    path = Path(path)
    n = result.n_directions
    x = np.arange(1, n + 1)
    fig, ax = plt.subplots(figsize=(10, 4.8), dpi=110)
    for k in range(n):
        theta, _ = direction_angles(result.directions[k])
        if theta > 90.5:
            ax.axvspan(k + 0.5, k + 1.5, color="0.86", lw=0)
        elif theta > 89.5:
            ax.axvspan(k + 0.5, k + 1.5, color="0.93", lw=0)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    means = result.means
    for i, m in enumerate(result.methods):
        c = colors[i % len(colors)]
        ax.plot(
            x,
            result.scores[i],
            "-o",
            color=c,
            ms=4,
            lw=1.6,
            label=f"{LABELS[m]} (mean {means[m]:.3f})",
        )
        ax.axhline(means[m], color=c, ls="--", lw=1.0, alpha=0.8)
    ax.set_xlim(0.5, n + 0.5)
    ax.set_xticks(x, [str(k) for k in result.numbers])
    ax.set_xlabel("light direction # (grey: grazing, darker: behind the object)")
    ax.set_ylabel("congruence score (LLA Eq. 2)")
    lo = float(result.scores.min())
    ax.set_ylim(max(0.0, lo - 0.05), min(1.0, float(result.scores.max()) + 0.05))
    ax.grid(axis="y", alpha=0.3)
    ax.legend(loc="lower left", fontsize=8, framealpha=0.9)
    ax.set_title(title or f"Congruence scores{' - ' + result.label if result.label else ''}")
    fig.tight_layout()
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format=plot_format(path))
    finally:
        plt.close(fig)
    return path


def plot_format(path: str | Path) -> str:
    """The format matplotlib writes ``path`` in, from its name's suffix; ValueError naming the
    ones it writes where the suffix is none of them (checked before a comparison runs)."""
    from matplotlib.backend_bases import FigureCanvasBase

    kinds = FigureCanvasBase.get_supported_filetypes()
    fmt = Path(path).suffix.lstrip(".").lower()
    if fmt not in kinds:
        raise ValueError(
            f"--plot {path}: a plot is written as {', '.join(sorted(kinds))}; name it so (e.g. "
            "scores.png)"
        )
    return fmt


def _crop_box(mask: NDArray[np.bool_], margin: float = 0.04) -> tuple[int, int, int, int]:
    """(r0, r1, c0, c1): the covered bounding box with a margin, squared off where it fits."""
    h, w = mask.shape
    rows = np.nonzero(mask.any(axis=1))[0]
    cols = np.nonzero(mask.any(axis=0))[0]
    if rows.size == 0:
        return 0, h, 0, w
    pad = round(margin * max(h, w))
    r0, r1 = max(0, rows[0] - pad), min(h, rows[-1] + 1 + pad)
    c0, c1 = max(0, cols[0] - pad), min(w, cols[-1] + 1 + pad)
    return int(r0), int(r1), int(c0), int(c1)


def _score_colors(smap: F32, weight: F32) -> F32:
    """Per-pixel score in false colour (red = 0, blue = 1, LLA Fig. 12), dark grey off it."""
    import matplotlib

    cmap = matplotlib.colormaps["RdYlBu"]
    rgb = np.asarray(cmap(np.clip(smap, 0.0, 1.0))[..., :3], np.float32)
    bg = np.float32(0.15)
    wgt = np.clip(weight, 0.0, 1.0)[..., None]
    return np.asarray(rgb * wgt + bg * (1.0 - wgt), np.float32)


def _put_text(img: np.ndarray, text: str, org: tuple[int, int], scale: float) -> None:
    """White text with a black outline on an (H, W, 3) uint8 image, in place."""
    font = cv2.FONT_HERSHEY_SIMPLEX
    thick = max(1, round(scale * 1.6))
    cv2.putText(img, text, org, font, scale, (0, 0, 0), thick + 2, cv2.LINE_AA)
    cv2.putText(img, text, org, font, scale, (255, 255, 255), thick, cv2.LINE_AA)


def contact_sheet(
    result: ComparisonResult,
    path: str | Path,
    directions: Sequence[int] | None = None,
    *,
    tile: int = 200,
) -> Path:
    """Renderings with their per-pixel score maps, one row per direction (like LLA Fig. 12).

    Each method gets two columns: its rendering (sRGB-encoded) and its score map (red = low,
    blue = high; dark grey where nothing is scored), the mean score in the corner. Tiles are
    cropped to the object and ``tile`` pixels high. Directions default to those of
    :data:`SHEET_DIRECTIONS` that were kept, else all kept ones. Returns the path.
    """
    from gbuffer.preview import srgb_encode, write_png

    if directions is None:
        kept = set.intersection(*(set(result.images[m]) for m in result.methods))
        directions = [k for k in SHEET_DIRECTIONS if k in kept] or sorted(kept)
    directions = [int(k) for k in directions]
    if not directions:
        raise ValueError("contact_sheet: no direction to show (no rendering was kept)")
    if not (16 <= tile <= 2048):
        raise ValueError(f"tile must be in [16, 2048] pixels, got {tile!r}")
    first = result.results[result.methods[0]][0]
    mask = np.asarray(first.weight) > 0
    any_img = result.image(result.methods[0], directions[0])
    cover = np.any(any_img != 0, axis=-1) if any_img.ndim == 3 else any_img != 0
    r0, r1, c0, c1 = _crop_box(mask | cover)
    th = int(tile)
    tw = max(16, round(th * (c1 - c0) / max(1, r1 - r0)))

    def fit(rgb: np.ndarray) -> np.ndarray:
        crop = np.ascontiguousarray(rgb[r0:r1, c0:c1])
        return np.asarray(cv2.resize(crop, (tw, th), interpolation=cv2.INTER_AREA), np.float32)

    label_w = max(48, th // 3)
    head_h = max(28, th // 7)
    ncols = 2 * len(result.methods)
    sheet = np.full((head_h + th * len(directions), label_w + tw * ncols, 3), 0.0, np.float32)
    tiles_txt: list[tuple[str, tuple[int, int]]] = []
    for r, k in enumerate(directions):
        y = head_h + r * th
        for i, m in enumerate(result.methods):
            img = result.image(m, k)
            rgb = img if img.ndim == 3 else np.dstack([img, img, img])
            x = label_w + 2 * i * tw
            sheet[y : y + th, x : x + tw] = fit(srgb_encode(rgb))
            res = result.results[m][result._col(k)]
            sheet[y : y + th, x + tw : x + 2 * tw] = fit(_score_colors(res.score_map, res.weight))
            tiles_txt.append((f"{result.score(m, k):.3f}", (x + tw + 4, y + 4)))
        tiles_txt.append((f"#{k}", (6, y + th // 2)))
    out = (np.clip(sheet, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    # separators between method pairs
    for i in range(1, len(result.methods)):
        x = label_w + 2 * i * tw
        out[:, x : x + 1] = 90
    scale = max(0.35, th / 400.0)
    for i, m in enumerate(result.methods):
        x = label_w + 2 * i * tw
        _put_text(out, LABELS[m], (x + 4, head_h - 8), scale)
    for text, (x, y) in tiles_txt:
        _put_text(out, text, (x, y + int(22 * scale)), scale)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_png(out.astype(np.float32) / 255.0, path)
    return path
