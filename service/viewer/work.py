"""The viewer's work on the service's worker processes (:meth:`service.http.deps.Services.run`,
so within its queue and time limits): what a frame holds, pictures of its layers, and previews.

Previews run on a copy of the frame shrunk by a whole number near the ratio of its height to the
preview height (:func:`shrink_factor`, :func:`downscale`), made once per frame and factor and
kept in the frame's folder (``small_<factor>.pkl``, with the score of the input at that size),
and in the memory of the worker that last read it (:func:`_load`). The copy at the page's
preview height is made as the upload is inspected, from the same decode (:func:`inspect_job`).
Every size of the operators is relative to the image height, so a look tuned on the preview
carries to the full-resolution frame, which
``GET /v1/frames/{id}/enhanced.exr`` enhances exactly as ``depict enhance`` does
(:func:`service.http.worker.enhance_job`).
"""

from __future__ import annotations

import base64
import json
import pickle
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from analysis.score import frame_shape, score_frame
from gbuffer.atomic import atomic_path
from gbuffer.errors import FrameError
from gbuffer.exr import read_layout
from gbuffer.frame import MASK_SOURCES, Frame, Passthrough
from gbuffer.io import describe, inspect
from gbuffer.preview import picture, quick_png, write_png
from service import pipeline
from service.enhance import ReadRequest
from service.memo import Memo
from service.registry import Context, runnable

#: The layer name of the per-pixel congruence score (LLA Eq. 2) in pictures.
SCORE_MAP = "score_map"
#: The geometry buffers: each preview pixel keeps one source pixel's depth, position, normal and
#: coverage together, as a renderer's centre sample does (averaging them across a silhouette
#: would invent surfaces between the object and what lies behind it, and averaged normals are
#: not what the operators' surface filters expect); the radiance buffers are block averages.
_GEOMETRY = ("depth", "position", "normal", "coverage")

#: Parameters that may name a layer of the file (a mask, a gain map, an ARM, ...): a preview
#: whose steps set one also loads the file's channels.
FILE_PARAMETERS = frozenset({"mask", "gain_map", "unlit", "arm", "toon"})


def reads_file_layers(steps: pipeline.Pipeline) -> bool:
    """Whether a step sets a parameter of :data:`FILE_PARAMETERS`."""
    return any(FILE_PARAMETERS & set(step.params) for step in steps.spec.steps)


def shrink_factor(size: Sequence[int], height: int) -> int:
    """The whole number a frame of ``size`` (width, height) is divided by for a preview about
    ``height`` rows high: the nearest to the ratio (a whole number, so that the geometry is
    sampled at the same place of every block: a fractional step would alternate between two
    spacings, and the operators' derivatives would show the pattern), and no more than its
    narrower side (a block of the preview holds pixels of the frame)."""
    width, frame_height = size
    return max(1, min(round(frame_height / max(1, height)), width, frame_height))


def _centres(pixels: np.ndarray, factor: int) -> np.ndarray:
    """The pixel at the centre of each whole factor × factor block (a view)."""
    rows, cols = (max(1, n // factor) for n in pixels.shape[:2])
    c = factor // 2
    return pixels[c : rows * factor : factor, c : cols * factor : factor]


def downscale(frame: Frame, factor: int) -> Frame:
    """``frame`` shrunk by ``factor`` (blocks of factor × factor pixels: the centre pixel of
    :data:`_GEOMETRY`, the mean of the rest), its display window and origin with it, without
    the file's passthrough; the same buffers when ``factor`` is 1."""
    if factor <= 1:
        return replace(frame, passthrough=Passthrough(), holes=None, hole_beauty=None)
    rows, cols = (max(1, n // factor) for n in frame.shape)
    buffers = {}
    for name, data in frame.buffers.items():
        if name in _GEOMETRY:
            small = _centres(data, factor)
        else:
            block = data[: rows * factor, : cols * factor]
            small = cv2.resize(block, (cols, rows), interpolation=cv2.INTER_AREA)
        buffers[name] = np.ascontiguousarray(small, np.float32).reshape(rows, cols, *data.shape[2:])
    assert frame.display_size is not None
    dw, dh = frame.display_size
    return replace(
        frame,
        buffers=buffers,
        display_size=(max(1, dw // factor), max(1, dh // factor)),
        origin=(frame.origin[0] // factor, frame.origin[1] // factor),
        outputs={},
        passthrough=Passthrough(),
        holes=None,
        hole_beauty=None,
    )


#: Primaries and white point (x, y each: red, green, blue, white) of the usual colour spaces.
_PRIMARIES = {
    "Rec.709 / sRGB primaries": (0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290),
    "ACES2065-1 (AP0)": (0.7347, 0.2653, 0.0, 1.0, 0.0001, -0.077, 0.32168, 0.33767),
    "ACEScg (AP1)": (0.713, 0.293, 0.165, 0.830, 0.128, 0.044, 0.32168, 0.33767),
    "Rec.2020": (0.708, 0.292, 0.170, 0.797, 0.131, 0.046, 0.3127, 0.3290),
}
#: String attributes where renderers and tools name the colour space.
_COLOUR_NAMES = ("colorSpace", "colorspace", "oiio:ColorSpace", "interpretation")


def colour_space(source: str) -> str:
    """The colour space the header states: its ``chromaticities`` matched against the usual
    primaries, or a colour space name; OpenEXR's default (Rec.709 primaries) when none."""
    attributes = read_layout(source).parts[0].attributes
    for name in _COLOUR_NAMES:
        raw = attributes.get(name)
        if raw is not None and raw.type == "string":
            return f"{raw.data.decode('utf-8', 'replace')} ({name} attribute)"
    raw = attributes.get("chromaticities")
    if raw is None or len(raw.data) != 32:
        return "not stated: linear Rec.709 primaries assumed (OpenEXR's default)"
    values = np.frombuffer(raw.data, "<f4")
    for label, primaries in _PRIMARIES.items():
        if np.allclose(values, primaries, atol=2e-3):
            return f"{label} (chromaticities attribute)"
    return "chromaticities " + ", ".join(f"{v:.4g}" for v in values)


def inspect_job(source: str, read: ReadRequest, height: int) -> dict[str, Any]:
    """What ``depict inspect --json`` says of the uploaded frame, with the layers the viewer
    can show (its buffers and the score map). The file is decoded once: where it reads as the
    previews read it, its copy at the preview ``height`` is made from the same decode
    (:func:`_small`), so that the first picture and preview do not decode it again; where it
    does not, it is described as ``depict inspect`` describes it, with what is wrong, and its
    previews say what that is."""
    try:
        frame = read.read(source)
    except FrameError:
        info = inspect(source, read.preset, read.camera, read.options)
    else:
        info = {**describe(frame), "problems": []}
        if frame.buffers:  # (a luminance-only image has none: it is described, not shrunk)
            _shrink(Path(source).parent, shrink_factor(info["size"], height), frame)
    info["operators"] = runnable(info)
    info["colour_space"] = colour_space(source)
    scored = "depth" in info["buffers"] and min(info["size"]) >= 3  # (_score)
    info["layers"] = [*info["buffers"], *([SCORE_MAP] if scored else [])]
    return {"info": info}


def _small(folder: Path, factor: int, read: ReadRequest) -> tuple[Frame, dict[str, Any] | None]:
    """The frame shrunk by ``factor`` and the score of its beauty (None without depth), made on
    first use (:func:`_shrink`) and kept in the frame's folder, with the file's channels shrunk
    beside them (:func:`_file_layers`)."""
    cache = _copy_path(folder, factor)
    if cache.is_file():
        loaded: tuple[Frame, dict[str, Any] | None] = _load(cache)
        return loaded
    return _shrink(folder, factor, read.read(folder / "in.exr"))


def _shrink(folder: Path, factor: int, frame: Frame) -> tuple[Frame, dict[str, Any] | None]:
    """:func:`_small` of the frame read from the folder's file: made, written and kept."""
    if not frame.buffers:
        raise FrameError(
            "the file holds no buffer Depict reads (no beauty, normals, depth or lobes): there "
            "is nothing to preview; `inspect` lists its channels"
        )
    small = downscale(frame, factor)
    score = _score(small)
    cache = _copy_path(folder, factor)
    made = ((_layers_path(cache), shrink_passthrough(frame, factor)), (cache, (small, score)))
    for path, data in made:
        with atomic_path(path) as tmp, open(tmp, "wb") as f:
            pickle.dump(data, f, protocol=pickle.HIGHEST_PROTOCOL)
        _keep(path, data)
    return small, score


def _copy_path(folder: Path, factor: int) -> Path:
    """Where the frame's copy shrunk by ``factor`` is kept, with its score."""
    return folder / f"small_{factor}.pkl"


def _layers_path(copy: Path) -> Path:
    """Where the file's channels shrunk as the ``copy`` are kept."""
    return copy.with_suffix(".layers.pkl")


def _file_layers(folder: Path, factor: int, small: Frame) -> Frame:
    """``small`` with the file's channels (shrunk by ``factor``), for the steps that read a
    layer of the file (:data:`FILE_PARAMETERS`)."""
    passthrough: Passthrough = _load(_layers_path(_copy_path(folder, factor)))
    return replace(small, passthrough=passthrough)


#: What a worker keeps in memory of the files :func:`_load` reads (the last ones read): at most
#: this many files and bytes (a 1080p render's shrunk copy for a 540-row preview and its file's
#: channels: 95 and 89 MB; at full size, 363 and 340 MB: then the copy alone is kept). A file
#: larger than the bytes is not kept; what its previews keep (:func:`_memo`) counts in the bytes,
#: and goes first; files deleted since (a frame forgotten or expired) are let go in the worker's
#: next pause (:func:`forget_deleted`).
KEEP_LOADED = 2
KEEP_LOADED_BYTES = 512 << 20
_loaded: dict[Path, tuple[tuple[int, int, int], Any, int, Memo]] = {}


def _load(path: Path) -> Any:
    """Our own pickle ``path``, kept in this worker's memory for the next preview (every slider
    move asks for the same frame: 95 MB of a 1080p render's shrunk copy unpickled took 12 ms
    a preview, more in a worker whose memory had been given back). Its arrays are shared with
    every preview: no operator writes into the frame it is given (``tests/test_viewer_work.py``
    holds them to it); they are not made read-only, which would make Numba compile another
    version of every kernel that reads them. A file written again (another inode, time or
    size) is read again."""
    kept = _loaded.get(path)
    if kept is not None and kept[0] == _stamp(path):
        _loaded[path] = _loaded.pop(path)  # (the last one used last: the first is the oldest)
        return kept[1]
    with open(path, "rb") as f:
        value = pickle.load(f)  # our own file
    return _keep(path, value)


def _keep(path: Path, value: Any) -> Any:
    """``value``, read from or written to ``path``, kept as :func:`_load`'s (within
    :data:`KEEP_LOADED` and :data:`KEEP_LOADED_BYTES`, the oldest let go first)."""
    _loaded.pop(path, None)
    arrays = _arrays(value)
    _loaded[path] = (_stamp(path), value, sum(a.nbytes for a in arrays), Memo(stable=arrays))
    _within_bounds()
    return value


def _within_bounds() -> None:
    """What :func:`_load` keeps, within :data:`KEEP_LOADED` and :data:`KEEP_LOADED_BYTES`: the
    oldest files let go first; then, where the previews' kept results (:func:`_memo`) take it
    over the bytes, those of the oldest file first, its least recently used first."""
    while _loaded and (
        len(_loaded) > KEEP_LOADED or sum(k[2] for k in _loaded.values()) > KEEP_LOADED_BYTES
    ):
        _loaded.pop(next(iter(_loaded)))
    over = sum(k[2] + k[3].nbytes for k in _loaded.values()) - KEEP_LOADED_BYTES
    for _, _, _, memo in _loaded.values():
        if over <= 0:
            break
        held = memo.nbytes
        memo.trim(max(held - over, 0))
        over -= held - memo.nbytes


def _memo(path: Path) -> Memo:
    """What the previews of the copy in ``path`` computed of its arrays with parameters a
    slider may not have changed since (the curvature, the lights' smoothing: :mod:`service.memo`),
    kept with the copy and let go with it; a copy not kept starts afresh."""
    kept = _loaded.get(path)
    return Memo() if kept is None else kept[3]


def forget_deleted() -> None:
    """Let go of what :func:`_load` kept of files deleted since (a frame forgotten or expired)."""
    for path in [p for p in _loaded if not p.exists()]:
        del _loaded[path]


def _stamp(path: Path) -> tuple[int, int, int]:
    stat = path.stat()
    return stat.st_ino, stat.st_mtime_ns, stat.st_size


def _arrays(value: Any) -> list[np.ndarray]:
    """The arrays of ``value``, each once: a small frame's buffers and its score's shape side
    (which shares the frame's depth), or a passthrough's channels."""
    if isinstance(value, tuple):
        small, score = value
        flow = [] if score is None or score.get("flow") is None else vars(score["flow"]).values()
        fields = [x for v in flow for x in (v if isinstance(v, tuple) else (v,))]
        found = [*small.buffers.values(), *fields]
    else:
        found = [c for _, channels in value.parts for c in channels.values()]
    return list({id(a): a for a in found if isinstance(a, np.ndarray)}.values())


def shrink_passthrough(frame: Frame, factor: int) -> Passthrough:
    """The channels of the frame's file on its pixel grid, shrunk by ``factor`` as the geometry
    is (one source pixel a block: Cryptomatte ids and index passes stay exact), with the headers
    as read (manifests, names) but for what the binding cannot pickle (a tiled file's
    ``TileDescription``, its compression and line order: nothing a layer is found by); other
    channels are left out."""
    parts = []
    for header, channels in frame.passthrough.parts:
        small = {}
        for name, value in channels.items():
            pixels = np.asarray(getattr(value, "pixels", value))
            if pixels.shape[:2] == frame.shape:
                small[name] = np.ascontiguousarray(_centres(pixels, factor))
        parts.append(({k: v for k, v in header.items() if _pickles(v)}, small))
    return Passthrough(parts, frame.passthrough.primary)


def _pickles(value: object) -> bool:
    """Whether ``value`` (a header attribute) can be kept in a worker's file."""
    try:
        pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL)
    except (pickle.PicklingError, TypeError, AttributeError):
        return False
    return True


def _score(frame: Frame) -> dict[str, Any] | None:
    """:func:`analysis.score.score_frame` of a copy, with its shape's side of the score under
    ``"flow"`` (its results are scored on it: :func:`_same_shape`), or None when it has no depth
    to score against or is too small to score (under 3 x 3 pixels: its layers are still
    shown)."""
    if min(frame.shape) < 3:
        return None
    try:
        flow = frame_shape(frame)
        return {**score_frame(frame, flow=flow), "flow": flow}
    except FrameError:
        return None


#: The buffers the score reads besides the beauty (:attr:`gbuffer.frame.Frame.mask` included).
_SCORED_SHAPE = ("normal", *MASK_SOURCES)


def _same_shape(result: Frame, frame: Frame) -> bool:
    """Whether a pipeline's ``result`` holds ``frame``'s very arrays for what the score's shape
    side reads (no operator replaces them; one that did would be scored on its own)."""
    return all(result.buffers.get(k) is frame.buffers.get(k) for k in _SCORED_SHAPE)


def _png(rgb: np.ndarray) -> str:
    """The picture as a base64 PNG (:func:`gbuffer.preview.quick_png`: for the browser)."""
    return base64.b64encode(quick_png(rgb)).decode("ascii")


def _score_picture(frame: Frame, score: dict[str, Any]) -> np.ndarray:
    shown = frame.copy()
    shown.outputs = dict(score["layers"])
    return picture(shown, "congruence")


#: Why a copy of a frame has no score map (:func:`_score` made none).
_NO_SCORE_MAP = (
    "no score map: the frame has no depth, or this copy of it is under 3 pixels on a side"
)


def layer_job(folder: str, factor: int, layer: str, read: ReadRequest, out: str) -> dict[str, Any]:
    """A picture of ``layer`` of the frame shrunk by ``factor``, written to ``out`` (PNG)."""
    small, before = _small(Path(folder), factor, read)
    if layer == SCORE_MAP:
        if before is None:
            raise FrameError(_NO_SCORE_MAP)
        score = score_frame(small, maps=True, flow=before.get("flow"))
        write_png(_score_picture(small, score), out, quick=True)
    else:
        write_png(picture(small, layer), out, quick=True)
    return {"size": list(small.shape[::-1])}


def preview_job(
    folder: str,
    factor: int,
    steps: pipeline.Pipeline,
    read: ReadRequest,
    exposure: float,
    score_map: bool,
) -> dict[str, Any]:
    """``steps`` on the frame shrunk by ``factor``: the result as a base64 PNG, the steps'
    warnings (a mask that selects no pixel), the congruence score of the input and of the
    result (on the input's scale) and, with ``score_map``, the result's per-pixel score as a
    base64 PNG."""
    small, before = _small(Path(folder), factor, read)
    if reads_file_layers(steps):
        small = _file_layers(Path(folder), factor, small)
    memo = _memo(_copy_path(Path(folder), factor))
    context = Context(files=False, memo=memo)
    out, op_s = pipeline.run_timed(small, steps, context)
    _within_bounds()  # (with what the run kept)
    answer: dict[str, Any] = {
        "image": _png(picture(out, "beauty", exposure)),
        "size": list(out.shape[::-1]),
        "op_s": op_s,
        "warnings": context.warnings,
        "score": None,
        "score_map": None,
        "pipeline": json.loads(steps.spec.model_dump_json()),
    }
    if before is not None:
        norm = before["shading_norm"] or None  # (0: the input has no shading to measure)
        flow = before.get("flow") if _same_shape(out, small) else None
        after = score_frame(out, maps=score_map, shading_norm=norm, flow=flow)
        answer["score"] = {"before": float(before["score"]), "after": float(after["score"])}
        if score_map:
            answer["score_map"] = _png(_score_picture(out, after))
    return answer
