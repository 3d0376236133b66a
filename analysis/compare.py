"""The comparison bench of Local Light Alignment (Mestres et al., EG 2021, §7, Figs. 12-14).

:func:`compare` shades one frame's geometry with each depiction method of
:mod:`analysis.methods` (registry operators) under the fixed sweep of light directions of
:func:`ops.directions.comparison_directions` and scores every rendering with the congruence
score of :func:`analysis.score.score_image` (LLA Eq. 2) against the frame's shape;
:mod:`analysis.pictures` draws the scores like the paper's Fig. 13 and the renderings with their
per-pixel score maps like Fig. 12.

Directions. The fixed sweep of :mod:`ops.directions`: #1 frontal, then four arcs (light from
the right, above, left, below) at 30°, 60°, 90° (grazing), 120° and 150° (behind) from the view
axis. The paper's inset is not in its text; this sweep follows its description.

Albedo. By default every method shades a **white** surface (ρ = 1). The score compares the
luminance flow of the picture with the shape flow; a texture would add the same shape-unrelated
gradients to every method and blur the differences, and the paper's comparison renderings
(Figs. 12, 14) are untextured. ``albedo="frame"`` multiplies each rendering by the frame's albedo
buffer instead (RGB images).

Display range. Every shading is clipped to [0, 1] before it is scored, as the renderings the
paper compares are displayed pictures (Figs. 12, 14). Only Radiance Scaling is affected: with
γ = 4 its factor σ reaches e^{±γκ} = 55 (δ → 1, κ → 1) and its unclipped output spans two
decades, which would make the score's per-image strength normalisation (a percentile) see
only the blown-out highlights.

Score. Every image is scored on the frame's depth and coverage, with the same congruence
parameters for all methods (``params["congruence"]``) and sizes relative to the frame's display
height.

Normalisation (``shading_norm``). Eq. 2 compares a shading strength with a shape strength, which
need a common scale; the paper does not say which. By default (``"reference"``) every rendering
of the frame is put on **one** scale: its shading strength is divided by that of the frame's
plain Lambert rendering under direction #1 (its 95th percentile), the same number for every
method and direction. A method that raises shading contrast then keeps it, and the clamp of
Eq. 2 ("prevents the score from dropping in case of exaggeration, i.e. if e_s > e_c", §7) acts
as the paper describes. ``"per_image"`` divides each rendering by its own percentile instead
(as :func:`analysis.score.score_frame` does for a single image, which makes a score invariant
to brightness): then extra contrast is normalised away, and a method that concentrates contrast
at features (Light Alignment) loses to Lambert under near-frontal lights, where their
directions agree. A number pins the scale.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from analysis.methods import METHODS, resolve_params, shade
from analysis.result import ComparisonResult
from analysis.score import score_image, shape_of
from gbuffer.frame import Frame
from ops.congruence import CongruenceResult
from ops.directions import N_DIRECTIONS, comparison_directions
from ops.shading import dot

F32 = NDArray[np.float32]

#: Albedo choices.
ALBEDOS: tuple[str, ...] = ("white", "frame")


def compare(
    frame: Frame,
    methods: Sequence[str] = METHODS,
    directions: int | Sequence[int] = N_DIRECTIONS,
    params: Mapping[str, Mapping[str, Any]] | None = None,
    *,
    albedo: str = "white",
    keep_images: bool | Iterable[int] = True,
    label: str = "",
    shading_norm: str | float = "reference",
    files: bool = True,
) -> ComparisonResult:
    """Shade ``frame`` with each method under each light direction and score it (LLA §7).

    Parameters
    ----------
    frame : a frame with ``normal`` (camera space), ``depth`` and coverage (``albedo`` too when
        ``albedo="frame"``).
    methods : names from :data:`analysis.methods.METHODS`.
    directions : how many directions of the fixed sweep (1…21, the first N), or a list of
        direction numbers (1-based) of :func:`ops.directions.comparison_directions`.
    params : per-section overrides of :func:`analysis.methods.resolve_params`:
        ``"congruence"`` (keywords of :func:`ops.congruence.congruence`, and ``shape``) and,
        per method, parameters of its registry operator (``depict ops``), e.g.
        ``{"light_alignment": {"gamma": 2}}``.
    albedo : ``"white"`` (ρ = 1, default) or ``"frame"`` (the frame's albedo buffer).
    keep_images : keep every rendering (True), none (False), or those of these direction numbers
        (for :func:`analysis.pictures.contact_sheet`; 21 × 5 renderings of a 1080p frame take
        ~0.9 GB).
    label : a name for the input, carried into tables and plots.
    shading_norm : ``"reference"`` (default: every rendering on the scale of the frame's
        Lambert rendering under #1), ``"per_image"``, or a number (see the module docstring).
    files : whether ``params`` may name image files on this machine (a matcap, an environment,
        a mask): not for a client of the HTTP service.
    """
    ms = _check_methods(methods)
    numbers = _direction_numbers(directions)
    keep = _kept(keep_images, numbers)
    resolved = resolve_params(params)
    geometry = _geometry(frame, albedo)
    albedo_rgb = _albedo(frame) if albedo == "frame" else None
    mask = geometry.mask > 0.5
    depth, normal = geometry.buffers["depth"], geometry.buffers["normal"]
    height = int(frame.image_height)
    weights = frame.colorspace.weights

    def render(method: str, light: F32) -> F32:
        img = shade(method, geometry, light, resolved[method], files)
        img = np.where(mask, np.clip(img, 0.0, 1.0), np.float32(0.0)).astype(np.float32)
        return img if albedo_rgb is None else np.asarray(albedo_rgb * img[..., None], np.float32)

    # the shape's side of the score, once for every rendering (they differ by shading_norm)
    flow = shape_of(depth, mask, normal, height, **dict(resolved["congruence"]))

    def score(img: F32, cong: Mapping[str, Any]) -> CongruenceResult:
        return score_image(img, depth, mask, normal, height, flow, weights=weights, **dict(cong))

    sweep = comparison_directions(N_DIRECTIONS)
    cong, norm = _normalisation(shading_norm, resolved["congruence"], render, score, sweep[0])
    scores = np.zeros((len(ms), len(numbers)), np.float64)
    results: dict[str, list[CongruenceResult]] = {m: [] for m in ms}
    images: dict[str, dict[int, F32]] = {m: {} for m in ms}
    seconds = {m: 0.0 for m in ms} | {"score": 0.0}
    for j, number in enumerate(numbers):
        for i, m in enumerate(ms):
            t0 = time.perf_counter()
            img = render(m, sweep[number - 1])
            t1 = time.perf_counter()
            res = score(img, cong)
            seconds[m] += t1 - t0
            seconds["score"] += time.perf_counter() - t1
            scores[i, j] = res.score
            results[m].append(res)
            if number in keep:
                images[m][number] = img
    return ComparisonResult(
        methods=ms,
        numbers=tuple(numbers),
        directions=np.ascontiguousarray(sweep[np.asarray(numbers) - 1], np.float32),
        scores=scores,
        results=results,
        images=images,
        params=resolved,
        albedo=albedo,
        image_shape=(int(depth.shape[0]), int(depth.shape[1])),
        seconds=seconds,
        label=label,
        shading_norm=norm,
    )


def _check_methods(methods: Iterable[str]) -> tuple[str, ...]:
    ms = tuple(methods)
    if not ms:
        raise ValueError(f"methods must name at least one of: {', '.join(METHODS)}")
    for m in ms:
        if m not in METHODS:
            raise ValueError(f"methods: unknown method {m!r}; allowed: {', '.join(METHODS)}")
    if len(set(ms)) != len(ms):
        raise ValueError(f"methods must not repeat a method, got {list(ms)}")
    return ms


def _direction_numbers(directions: int | Sequence[int]) -> list[int]:
    """The direction numbers (1-based) of ``directions``: a count or a list of numbers."""
    if isinstance(directions, int | np.integer) and not isinstance(directions, bool):
        if not 1 <= int(directions) <= N_DIRECTIONS:
            raise ValueError(f"directions must be in [1, {N_DIRECTIONS}], got {directions!r}")
        return list(range(1, int(directions) + 1))
    numbers = [int(k) for k in directions]  # type: ignore[union-attr]
    if not numbers or any(not 1 <= k <= N_DIRECTIONS for k in numbers):
        raise ValueError(
            f"directions must be direction numbers in [1, {N_DIRECTIONS}], got {directions!r}"
        )
    return numbers


def _kept(keep_images: bool | Iterable[int], numbers: list[int]) -> set[int]:
    if keep_images is True:
        return set(numbers)
    if keep_images is False:
        return set()
    return {int(k) for k in keep_images}


def _normalisation(
    shading_norm: str | float,
    congruence: Mapping[str, Any],
    render: Callable[[str, F32], F32],
    score: Callable[[F32, Mapping[str, Any]], CongruenceResult],
    frontal: F32,
) -> tuple[dict[str, Any], dict[str, Any]]:
    """The congruence parameters with the shading scale of ``shading_norm``, and how it was
    chosen (``{"mode": ..., "value": ...}``)."""
    cong = dict(congruence)
    if shading_norm == "reference":
        reference = score(render("lambert", frontal), cong)
        # (0: the reference has no shading to measure, e.g. no usable normals: none pinned)
        cong["shading_norm"] = reference.shading_norm or None
        return cong, {"mode": "reference", "value": reference.shading_norm}
    if shading_norm == "per_image":
        return cong, {"mode": "per_image", "value": None}
    if isinstance(shading_norm, int | float) and not isinstance(shading_norm, bool):
        cong["shading_norm"] = float(shading_norm)
        return cong, {"mode": "pinned", "value": float(shading_norm)}
    raise ValueError(
        f"shading_norm must be 'reference', 'per_image' or a number, got {shading_norm!r}"
    )


def _geometry(frame: Frame, albedo: str) -> Frame:
    """What the methods shade: the frame's normals and depth on its trusted pixels (coverage
    above 0.5, a finite positive depth, a normal of some length), a white albedo, no camera
    (the orthographic view of the paper's comparison), the frame's display window."""
    if albedo not in ALBEDOS:
        raise ValueError(f"albedo must be one of {', '.join(ALBEDOS)}, got {albedo!r}")
    normal = np.ascontiguousarray(frame.need("normal", "to shade the comparison"), np.float32)
    depth = np.ascontiguousarray(frame.need("depth", "for the shape flow of the score"), np.float32)
    if normal.ndim != 3 or normal.shape[2] != 3:
        raise ValueError(f"frame normal must be (H, W, 3), got shape {normal.shape}")
    mask = (np.asarray(frame.mask) > 0.5) & np.isfinite(depth) & (depth > 0)
    mask &= dot(normal, normal) > 0.25
    white = np.broadcast_to(np.float32(1.0), normal.shape)
    buffers = {
        "normal": np.where(mask[..., None], normal, np.float32(0.0)).astype(np.float32),
        "depth": np.where(mask, depth, np.float32(np.inf)).astype(np.float32),
        "coverage": mask.astype(np.float32),
        "albedo": white,
    }
    return Frame(
        buffers=buffers,
        display_size=frame.display_size,
        origin=frame.origin,
        colorspace=frame.colorspace,
    )


def _albedo(frame: Frame) -> F32:
    a = np.asarray(frame.need("albedo", "albedo='frame'"), np.float32)
    return np.ascontiguousarray(a if a.ndim == 3 else np.dstack([a, a, a]), np.float32)


def frame_from_mesh(
    path: str | Path,
    width: int = 512,
    height: int = 512,
    *,
    azimuth_deg: float = 30.0,
    elevation_deg: float = 20.0,
    weld: bool = True,
) -> Frame:
    """Render a mesh into a frame for :func:`compare` (no AO: only the geometry is used).

    ``weld`` merges vertices that share a position whatever their texture coordinates or
    normals: meshes with UV seams (spot.obj) store split vertices whose normals are averaged on
    each side of the seam only, a crease in the shading normals that is not in the shape and
    that every enhancement amplifies. The comparison is about shape, so it welds by default.
    """
    from gbuffer.render import auto_camera, load_mesh, render

    mesh = load_mesh(path)
    if weld:
        mesh.merge_vertices(merge_tex=True, merge_norm=True)
    cam = auto_camera(
        mesh, width=width, height=height, azimuth_deg=azimuth_deg, elevation_deg=elevation_deg
    )
    return render(mesh, width, height, camera=cam, ao="none")
