"""Picture-quality figures of an operator's result against its input frame, and the report.

An enhancement of a path-traced frame should keep what the renderer got right — the exposure,
the colours, the lighting the eye reads at a glance, the cleanliness of flat lit areas — and
only add shape detail. :func:`figures` measures exactly that on a frame (``before``) and an
operator's result (``after``), with the pixel classes of :func:`regions`:

================  ========================================================================  ======
figure            what                                                                      target
================  ========================================================================  ======
``lum_objects``   mean Rec. 709 luminance of the object pixels, after / before              ±13 %
``lum_covered``   the same over every covered pixel (objects and floor)                     –
``hot``           share of the frame's pixels where some channel is above both              ≤ 0.1 %
                  :data:`HOT_FACTOR` × its input and the input's maximum of that channel
``negatives``     pixels of the output with a channel < 0                                   0
``nonfinite``     pixels of the output with a NaN or infinite channel                       0
``floor_noise``   high-frequency noise of the flat, directly lit floor, after / before      ≤ 1.2
``lf_corr``       Pearson correlation of the strongly blurred luminance (σ =                ≥ 0.97
                  :data:`LF_SIGMA` of the image height) over the covered pixels
``detail``        RMS band-pass contrast of the object pixels (difference of Gaussians at   > 1
                  :data:`DETAIL_SIGMAS` of the image height), after / before
``cong_*``        congruence score (LLA Eq. 2) as ``depict score`` computes it, of the      rises
                  whole frame and of the objects alone, before and after; the result's
                  shading strength on the input's scale (two renderings of one frame)
================  ========================================================================  ======

Pixel classes come from the object index pass (Blender's ``IndexOB``; the corpus scenes give
the floor and backdrop index 1 and each object its own index from 2): *covered* pixels are
surfaces (coverage > 0.5), *objects* the covered pixels with index ≥ 2 (every covered pixel of a
frame without an index, such as Depict's mesh renders), *floor* index 1.

Noise, details and blurs:

- Floor noise: the beauty's luminance is divided by the albedo's (``DiffCol``) so the floor's
  texture (checkers, sand) does not count as noise; its high frequencies are the difference with
  a Gaussian blur of σ = :data:`NOISE_SIGMA_PX` pixels (Monte-Carlo noise is per pixel, whatever
  the resolution), relative to that local mean, and the figure is their RMS over the flat lit
  floor: floor pixels facing like the floor's median normal, whose blurred direct diffuse light
  (``DiffDir``) is above :data:`LIT_FRACTION` of its 90th percentile there, eroded by
  :data:`FLOOR_MARGIN` of the image height (away from objects, silhouettes, shadow boundaries
  and the image border). Frames without floor, direct light or albedo passes give NaN. A
  texture the operator leaves as it was does not count; texture edges it sharpens (halos) do,
  as added high frequencies of a flat area: at 512 samples, where little Monte-Carlo noise is
  left, they are most of what unsharp masking adds on the checker floor.
- Every blur is a normalised convolution over the pixels it concerns (``G*(f·m) / G*m``), so
  background and neighbouring objects do not leak into a region: the band-pass detail is
  interior relief and texture, not silhouettes.
- The detail band starts at σ = 1 px at 240p, above most of the per-pixel Monte-Carlo noise
  (15 % grain on the objects of a 240p frame moves ``detail`` by < 1 %); noise is what
  ``floor_noise`` measures.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from analysis.score import CONGRUENCE, score_image
from gbuffer.frame import Frame
from ops.color import luminance
from ops.colorspace import LINEAR_REC709, convert
from ops.congruence import CongruenceResult

F32 = NDArray[np.float32]
Mask = NDArray[np.bool_]

#: Floor and backdrop surfaces in the object index; objects count from 2, background is 0.
FLOOR_INDEX = 1
#: A channel above this factor of its input (and above the input's maximum) is "hot".
HOT_FACTOR = 2.0
#: σ of the low-frequency blur, relative to the image height (7 px at 240p, 32 px at 1080p).
LF_SIGMA = 0.03
#: σ of the two Gaussians of the detail band, relative to the image height (1 and 4 px at 240p).
DETAIL_SIGMAS = (1.0 / 240.0, 4.0 / 240.0)
#: σ in pixels of the blur the floor noise is measured against.
NOISE_SIGMA_PX = 1.5
#: Floor pixels count as directly lit above this fraction of the floor's 90th percentile of
#: blurred direct diffuse light.
LIT_FRACTION = 0.7
#: Margin eroded off the lit floor region, relative to the image height (at least 3 pixels).
FLOOR_MARGIN = 0.015
#: Floor pixels within this angle of the floor's median normal are flat floor (not a backdrop).
FLAT_DEGREES = 2.0


@dataclass(frozen=True)
class Regions:
    """Pixel classes of a frame (see the module docstring), each an (H, W) bool mask."""

    covered: Mask
    objects: Mask
    floor: Mask
    flat_floor: Mask


@dataclass(frozen=True)
class Figures:
    """The figures of one result (see the module docstring); NaN where undefined."""

    lum_objects: float
    lum_covered: float
    hot: float
    negatives: int
    nonfinite: int
    floor_noise: float
    lf_corr: float
    detail: float
    cong_before: float
    cong_after: float
    cong_objects_before: float
    cong_objects_after: float

    def as_dict(self) -> dict[str, float]:
        return {k: float(v) for k, v in asdict(self).items()}


# -- passes the figures read ---------------------------------------------------------------------


def file_channel(frame: Frame, suffix: str) -> F32 | None:
    """The file channel whose name is ``suffix`` or ends in ``.suffix`` (``"IndexOB.X"``
    finds ``ViewLayer.IndexOB.X``), as float32, or None."""
    if not frame.passthrough.parts:
        return None
    channels = frame.passthrough.parts[frame.passthrough.primary][1]
    for name, channel in channels.items():
        if name == suffix or name.endswith("." + suffix):
            return np.asarray(getattr(channel, "pixels", channel), np.float32)
    return None


def file_luminance(frame: Frame, layer: str) -> F32 | None:
    """Luminance (in the frame's working space) of the file's ``layer.R/G/B`` (e.g.
    ``DiffDir``), or None."""
    rgb = [file_channel(frame, f"{layer}.{c}") for c in "RGB"]
    planes = [c for c in rgb if c is not None]
    if len(planes) != 3:
        return None
    return luminance(np.dstack(planes), weights=frame.colorspace.weights)


# -- filters ---------------------------------------------------------------------------------------


def masked_blur(image: F32, mask: Mask, sigma: float) -> F32:
    """Gaussian blur of ``image`` (H, W) over the pixels of ``mask`` only (normalised
    convolution, σ in pixels); 0 where no masked pixel is near."""
    m = mask.astype(np.float32)
    num = cv2.GaussianBlur(np.where(mask, image, np.float32(0)).astype(np.float32), (0, 0), sigma)
    den = cv2.GaussianBlur(m, (0, 0), sigma)
    out = np.zeros(image.shape, np.float32)
    np.divide(num, den, out=out, where=den > 1e-3)
    return out


def _erode(mask: Mask, radius: int) -> Mask:
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
    eroded = cv2.erode(mask.astype(np.uint8), kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0)
    return eroded.astype(bool)


# -- pixel classes ---------------------------------------------------------------------------------


def _flat_lit_floor(frame: Frame, floor: Mask) -> Mask:
    direct = file_luminance(frame, "DiffDir")
    if direct is None or floor.sum() < 16 or "normal" not in frame.buffers:
        return np.zeros_like(floor)
    normal = frame.buffers["normal"]
    median = np.median(normal[floor], axis=0)
    median /= max(float(np.linalg.norm(median)), 1e-6)
    flat = floor & (normal @ median.astype(np.float32) > math.cos(math.radians(FLAT_DEGREES)))
    smooth = masked_blur(direct, flat, 2.0 * NOISE_SIGMA_PX)
    lit = flat & (smooth > LIT_FRACTION * float(np.percentile(smooth[flat], 90)))
    return _erode(lit, max(3, round(FLOOR_MARGIN * frame.image_height)))


def regions(frame: Frame) -> Regions:
    """The pixel classes of ``frame`` from its coverage and object index."""
    covered = np.asarray(frame.mask > 0.5)
    index = file_channel(frame, "IndexOB.X")
    if index is None:
        none = np.zeros_like(covered)
        return Regions(covered, covered, none, none)
    ids = np.rint(index).astype(np.int32)
    floor = covered & (ids == FLOOR_INDEX)
    objects = covered & (ids > FLOOR_INDEX)
    return Regions(covered, objects, floor, _flat_lit_floor(frame, floor))


# -- the figures -----------------------------------------------------------------------------------


def luminance_ratio(before: F32, after: F32, mask: Mask) -> float:
    """Mean Rec. 709 luminance of ``after`` over that of ``before`` on ``mask`` (NaN if empty)."""
    if not mask.any():
        return math.nan
    num = float(luminance(after)[mask].mean(dtype=np.float64))
    den = float(luminance(before)[mask].mean(dtype=np.float64))
    return num / den if den > 0 else math.nan


def hot_fraction(before: F32, after: F32, factor: float = HOT_FACTOR) -> float:
    """Share of pixels where some channel of ``after`` exceeds both ``factor`` × its value in
    ``before`` and ``before``'s maximum of that channel over the frame."""
    peak = before.reshape(-1, before.shape[-1]).max(axis=0)
    hot = (after > factor * before) & (after > peak)
    return float(hot.any(axis=-1).mean())


def bad_pixels(after: F32) -> tuple[int, int]:
    """(pixels with a negative channel, pixels with a NaN or infinite channel)."""
    finite = np.isfinite(after)
    negative = finite & (after < 0)
    return int(negative.any(axis=-1).sum()), int((~finite).any(axis=-1).sum())


def relative_noise(shading: F32, mask: Mask, sigma: float = NOISE_SIGMA_PX) -> float:
    """RMS of (S − G_σ*S) / G_σ*S over ``mask`` (the blur restricted to ``mask``); NaN if empty."""
    if mask.sum() < 16:
        return math.nan
    local = masked_blur(shading, mask, sigma)
    ok = mask & (local > 0)
    rel = (shading[ok] - local[ok]) / local[ok]
    return float(np.sqrt(np.mean(np.square(rel, dtype=np.float64))))


def floor_noise_ratio(before: F32, after: F32, albedo: F32 | None, region: Mask) -> float:
    """:func:`relative_noise` of the luminance over the albedo's, after / before, on the flat lit
    floor ``region`` (NaN without albedo or region)."""
    if albedo is None or not region.any():
        return math.nan
    inv = np.zeros_like(albedo)
    np.divide(1.0, albedo, out=inv, where=albedo > 1e-4)
    region = region & (albedo > 1e-4)
    n0 = relative_noise(luminance(before) * inv, region)
    n1 = relative_noise(luminance(after) * inv, region)
    return n1 / n0 if n0 > 0 else math.nan


def lf_correlation(before: F32, after: F32, mask: Mask, sigma: float) -> float:
    """Pearson correlation over ``mask`` of the two luminances blurred (over ``mask``) with a
    Gaussian of σ pixels: the lighting the eye reads at a glance."""
    if mask.sum() < 2:
        return math.nan
    a = masked_blur(luminance(before), mask, sigma)[mask].astype(np.float64)
    b = masked_blur(luminance(after), mask, sigma)[mask].astype(np.float64)
    a -= a.mean()
    b -= b.mean()
    den = math.sqrt(float(a @ a) * float(b @ b))
    return float(a @ b) / den if den > 0 else math.nan


def band_contrast(image: F32, mask: Mask, sigmas: tuple[float, float]) -> float:
    """RMS over ``mask`` of the band-pass contrast (G_σ1*Y − G_σ2*Y) / G_σ2*Y of the luminance
    (σ in pixels, blurs restricted to ``mask``)."""
    if not mask.any():
        return math.nan
    y = luminance(image)
    fine, coarse = (masked_blur(y, mask, s) for s in sigmas)
    ok = mask & (coarse > 0)
    rel = (fine[ok] - coarse[ok]) / coarse[ok]
    return float(np.sqrt(np.mean(np.square(rel, dtype=np.float64))))


def detail_gain(before: F32, after: F32, mask: Mask, height: int) -> float:
    """:func:`band_contrast` at :data:`DETAIL_SIGMAS` × ``height``, after / before."""
    sigmas = (DETAIL_SIGMAS[0] * height, DETAIL_SIGMAS[1] * height)
    c0 = band_contrast(before, mask, sigmas)
    return band_contrast(after, mask, sigmas) / c0 if c0 > 0 else math.nan


def frame_congruence(frame: Frame, shading_norm: float | None = None) -> CongruenceResult:
    """LLA Eq. 2 of the frame's beauty, with the parameters of ``depict score``
    (:func:`analysis.score.score_frame`: the shape flow of the normals); ``shading_norm``
    puts the shading strength on another rendering's scale (the input's, for a result)."""
    params = dict(CONGRUENCE)
    if shading_norm is not None:
        params["shading_norm"] = shading_norm
    return score_image(
        np.asarray(frame.buffers["beauty"], np.float32),
        np.asarray(frame.buffers["depth"], np.float32),
        frame.mask,
        frame.buffers.get("normal"),
        int(frame.image_height),
        weights=frame.colorspace.weights,
        **params,
    )


def masked_score(result: CongruenceResult, mask: Mask) -> float:
    """Eq. 2 restricted to ``mask``: Σ e_shape w s / Σ e_shape w over its pixels, from the
    full-resolution maps (score, shape strength, weight)."""
    weight = (result.shape_strength * result.weight)[mask].astype(np.float64)
    den = float(weight.sum())
    return float(weight @ result.score_map[mask]) / den if den > 0 else math.nan


@dataclass(frozen=True)
class Reference:
    """What :func:`figures` measures once per input frame."""

    frame: Frame
    regions: Regions
    albedo: F32 | None
    congruence: float
    congruence_objects: float
    shading_norm: float


def reference(frame: Frame) -> Reference:
    """Pixel classes, albedo and the input's congruence scores of ``frame``."""
    regs = regions(frame)
    result = frame_congruence(frame)
    albedo = file_luminance(frame, "DiffCol")
    return Reference(
        frame,
        regs,
        albedo,
        result.score,
        masked_score(result, regs.objects),
        result.shading_norm,
    )


def figures(ref: Reference, after: Frame) -> Figures:
    """Every figure of the result ``after`` of an operator on ``ref.frame``."""
    b = np.asarray(ref.frame.buffers["beauty"], np.float32)
    a = np.asarray(after.buffers["beauty"], np.float32)
    regs = ref.regions
    height = int(ref.frame.image_height)
    negatives, nonfinite = bad_pixels(a)
    clean = np.nan_to_num(a, nan=0.0, posinf=0.0, neginf=0.0)  # NaN would poison every mean
    scored = frame_congruence(_with_beauty(after, clean), ref.shading_norm)
    # the luminance figures are Rec. 709's: a frame in another working space is converted
    b, a, clean = (convert(x, ref.frame.colorspace, LINEAR_REC709) for x in (b, a, clean))
    return Figures(
        lum_objects=luminance_ratio(b, clean, regs.objects),
        lum_covered=luminance_ratio(b, clean, regs.covered),
        hot=hot_fraction(b, a),
        negatives=negatives,
        nonfinite=nonfinite,
        floor_noise=floor_noise_ratio(b, clean, ref.albedo, regs.flat_floor),
        lf_corr=lf_correlation(b, clean, regs.covered, LF_SIGMA * height),
        detail=detail_gain(b, clean, regs.objects, height),
        cong_before=ref.congruence,
        cong_after=scored.score,
        cong_objects_before=ref.congruence_objects,
        cong_objects_after=masked_score(scored, regs.objects),
    )


def _with_beauty(frame: Frame, beauty: F32) -> Frame:
    out = frame.copy()
    out.buffers["beauty"] = beauty
    return out


# -- targets and the report ------------------------------------------------------------------------

#: The targets of each figure: name -> (passes, as written in the report).
TARGETS: dict[str, tuple[Callable[[float], bool], str]] = {
    "lum_objects": (lambda v: abs(v - 1.0) <= 0.13, "1 ± 0.13"),
    "hot": (lambda v: v <= 0.001, "≤ 0.1 %"),
    "negatives": (lambda v: v == 0, "0"),
    "nonfinite": (lambda v: v == 0, "0"),
    "floor_noise": (lambda v: math.isnan(v) or v <= 1.2, "≤ 1.2"),
    "lf_corr": (lambda v: v >= 0.97, "≥ 0.97"),
    "detail": (lambda v: v > 1.0, "> 1"),
}
#: Operators the report runs by default, with their defaults.
DEFAULT_OPS = (
    "radiance_scaling",
    "light_alignment",
    "unsharp_masking",
    "apparent_relief",
    "depth_unsharp_masking",
)


#: A congruence score that changes by less than this has not changed (float rounding).
CONGRUENCE_TOLERANCE = 1e-4


def misses(fig: Figures) -> list[str]:
    """The figures of ``fig`` that miss their :data:`TARGETS`, and ``cong`` / ``cong_objects``
    where the congruence falls (by more than :data:`CONGRUENCE_TOLERANCE`)."""
    values = fig.as_dict()
    out = [k for k, (ok, _) in TARGETS.items() if not ok(values[k])]
    if fig.cong_after < fig.cong_before - CONGRUENCE_TOLERANCE:
        out.append("cong")
    if fig.cong_objects_after < fig.cong_objects_before - CONGRUENCE_TOLERANCE:
        out.append("cong_objects")
    return out


def run_operator(frame: Frame, op: str, lights: Sequence[str]) -> Frame:
    """``op`` with its defaults through :func:`service.pipeline.run`, given the frame's key
    ``lights`` when the operator takes lights and they are known."""
    from service import pipeline, registry

    params: dict[str, Any] = {}
    if lights and "lights" in registry.get(op).params.model_fields:
        params["lights"] = list(lights)
    return pipeline.run(frame, [{"op": op, "params": params}])


COLUMNS = (
    ("frame", "frame"),
    ("op", "operator"),
    ("lum_objects", "lum obj"),
    ("lum_covered", "lum all"),
    ("hot", "hot %"),
    ("negatives", "neg"),
    ("nonfinite", "non-fin"),
    ("floor_noise", "floor noise"),
    ("lf_corr", "LF corr"),
    ("detail", "detail"),
    ("cong", "congruence frame"),
    ("cong_objects", "congruence objects"),
)


def _cells(frame: str, op: str, fig: Figures, mark: Callable[[str], str]) -> list[str]:
    missed = set(misses(fig))
    v = fig.as_dict()

    def num(key: str, text: str) -> str:
        return mark(text) if key in missed else text

    return [
        frame,
        op,
        num("lum_objects", f"{fig.lum_objects:.3f}"),
        f"{fig.lum_covered:.3f}",
        num("hot", f"{100.0 * fig.hot:.2f}"),
        num("negatives", f"{fig.negatives}"),
        num("nonfinite", f"{fig.nonfinite}"),
        num("floor_noise", "–" if math.isnan(fig.floor_noise) else f"{fig.floor_noise:.2f}"),
        num("lf_corr", f"{fig.lf_corr:.3f}"),
        num("detail", f"{fig.detail:.2f}"),
        num("cong", f"{v['cong_before']:.3f} → {v['cong_after']:.3f}"),
        num("cong_objects", f"{v['cong_objects_before']:.3f} → {v['cong_objects_after']:.3f}"),
    ]


def table(rows: Sequence[tuple[str, str, Figures]], markdown: bool = False) -> str:
    """The report: one line per frame and operator; figures that miss their target are in bold
    (Markdown) or followed by ``*``."""
    head = [title for _, title in COLUMNS]
    if markdown:
        body = [_cells(f, op, fig, lambda t: f"**{t}**") for f, op, fig in rows]
        lines = ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] * 2 + ["---:"] * 10) + "|"]
        return "\n".join(lines + ["| " + " | ".join(r) + " |" for r in body])
    body = [_cells(f, op, fig, lambda t: t + "*") for f, op, fig in rows]
    widths = [max(len(r[i]) for r in [head, *body]) for i in range(len(head))]
    fmt = [(str.ljust if i < 2 else str.rjust) for i in range(len(head))]
    return "\n".join(
        "  ".join(f(c, w) for f, c, w in zip(fmt, r, widths, strict=True)) for r in [head, *body]
    )


def main(argv: Sequence[str] | None = None) -> int:
    from bench import corpus

    ap = argparse.ArgumentParser(description="Quality figures of operator defaults on the corpus")
    ap.add_argument(
        "--dir",
        type=Path,
        action="append",
        help="folder of corpus frames (repeatable; default: the committed subset, and "
        "corpus/frames when rendered)",
    )
    ap.add_argument("--frames", nargs="+", default=(), help="only frames whose name has one of")
    ap.add_argument("--op", action="append", help=f"operator (repeatable; default: {DEFAULT_OPS})")
    ap.add_argument("--markdown", action="store_true", help="print a Markdown table")
    args = ap.parse_args(argv)
    frames = corpus.gather(args.dir, args.frames)
    if not frames:
        raise SystemExit("quality: no corpus frames (see python -m bench.corpus --help)")
    rows = []
    for cf in frames:
        ref = reference(cf.read())
        for op in args.op or DEFAULT_OPS:
            out = run_operator(ref.frame, op, cf.light_strings())
            rows.append((cf.name, op, figures(ref, out)))
        print(f"{cf.name}: done", file=sys.stderr, flush=True)
    print(table(rows, args.markdown))
    return 0


if __name__ == "__main__":
    sys.exit(main())
