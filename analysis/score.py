"""The congruence score of a picture against a frame's shape (Mestres et al., EG 2021, §7, Eq. 2):
:func:`score_image` for any rendering of a frame, :func:`score_frame` for the frame's own beauty
(``depict score``, the ``congruence`` operator), :func:`congruence_layers` for its maps.

This module needs only :mod:`ops` and :mod:`gbuffer`, so the ``congruence`` operator of the
registry can use it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from gbuffer.frame import Frame
from ops.congruence import CongruenceResult, ShapeFlow, congruence, shape_flow

F32 = NDArray[np.float32]

#: Parameters of the score as used when none are given (keywords of
#: :func:`ops.congruence.congruence`, plus ``shape``).
CONGRUENCE: dict[str, Any] = {
    "gradient_scale": 0.002,
    "integration_scale": 0.01,
    "percentile": 95.0,
    "shape": "normals",
}
#: Shape signals of the score: the normals' gradients (planes carry no weight) or the log depth's.
SHAPES = ("normals", "depth")


def score_image(
    image: F32,
    depth: F32,
    mask: NDArray[np.generic],
    normal: F32 | None,
    image_height: int,
    flow: ShapeFlow | None = None,
    **cong: Any,
) -> CongruenceResult:
    """:func:`ops.congruence.congruence` of ``image`` with the congruence parameters ``cong``,
    whose ``shape`` ("normals", the default, or "depth") picks the shape signal; without
    normals the shape is the depth. ``flow``: :func:`shape_of` the same frame and parameters
    (computed once for several images). A parameter it does not take is a ValueError."""
    use = _shape_signal(normal, cong)
    try:
        return congruence(
            image, depth, mask, image_height=image_height, normal=use, flow=flow, **cong
        )
    except TypeError as exc:  # an unknown keyword
        raise ValueError(f"params['congruence']: {exc}") from None


def shape_of(
    depth: F32,
    mask: NDArray[np.generic],
    normal: F32 | None,
    image_height: int,
    **cong: Any,
) -> ShapeFlow:
    """The shape's side of :func:`score_image` with the same arguments (``shading_norm`` and
    ``weights`` among ``cong`` concern the image: left out), to score several images of the
    frame: :func:`ops.congruence.shape_flow`."""
    use = _shape_signal(normal, cong)
    params = {k: v for k, v in cong.items() if k not in ("shading_norm", "weights")}
    try:
        return shape_flow(depth, mask, image_height=image_height, normal=use, **params)
    except TypeError as exc:  # an unknown keyword, named as the score's (the name users know)
        detail = str(exc).replace("shape_flow()", "congruence()")
        raise ValueError(f"params['congruence']: {detail}") from None


def _shape_signal(normal: F32 | None, cong: dict[str, Any]) -> F32 | None:
    """The normals when ``cong``'s ``shape`` (taken out of it) is "normals", else None."""
    shape = cong.pop("shape", "normals")
    if shape not in SHAPES:
        raise ValueError(f"params['congruence']: shape must be one of {SHAPES}, got {shape!r}")
    return normal if shape == "normals" else None


def score_frame(
    frame: Frame, *, maps: bool = False, flow: ShapeFlow | None = None, **params: Any
) -> dict[str, Any]:
    """The congruence score (LLA Eq. 2) of ``frame``'s beauty against its depth (``depict score``).

    Parameters
    ----------
    frame : a frame with ``beauty`` and ``depth`` (coverage from :attr:`Frame.mask`).
    maps : also return the per-pixel layers under ``"layers"``: ``congruence.X`` (score map),
        ``congruence.shading.X/Y`` and ``congruence.shape.X/Y`` (the two flows, camera x right /
        y up), ``congruence.weight.X`` — ready for ``frame.outputs``.
    flow : :func:`frame_shape` of a frame with the same depth, mask and normals, and the same
        ``params`` (a rendering or enhancement of it): its shape's side, not computed again.
    **params : keywords of :func:`ops.congruence.congruence` (``gradient_scale``,
        ``integration_scale``, ``percentile``, ``depth_jump``).

    Returns
    -------
    dict with ``score``, ``shading_norm`` (the shading strength mapped to 1: pass it as
    ``shading_norm`` to score another rendering of the frame on this one's scale),
    ``analysis_shape``, ``image_shape``, ``params`` (the congruence parameters used) and, with
    ``maps``, ``layers``.
    """
    beauty = np.asarray(frame.need("beauty", "the image to score"), np.float32)
    cong, depth, normal = _frame_shape_args(frame, params)
    res = score_image(
        beauty,
        depth,
        frame.mask,
        normal,
        int(frame.image_height),
        flow,
        weights=frame.colorspace.weights,  # the shading: luminance in the frame's space
        **dict(cong),
    )
    out: dict[str, Any] = {
        "score": res.score,
        "shading_norm": float(res.shading_norm),
        "analysis_shape": list(res.analysis_shape),
        "image_shape": list(depth.shape),
        "params": cong,
    }
    if maps:
        out["layers"] = congruence_layers(res)
    return out


def frame_shape(frame: Frame, **params: Any) -> ShapeFlow:
    """The shape's side of :func:`score_frame` with these ``params``, for every image of the
    frame (``flow``)."""
    cong, depth, normal = _frame_shape_args(frame, params)
    return shape_of(depth, frame.mask, normal, int(frame.image_height), **cong)


def _frame_shape_args(
    frame: Frame, params: dict[str, Any]
) -> tuple[dict[str, Any], F32, F32 | None]:
    """The congruence parameters of a frame's score (the depth's shape without normals), its
    depth and its normals."""
    cong = {**CONGRUENCE, **params}
    depth = np.asarray(frame.need("depth", "for the shape flow of the score"), np.float32)
    normal = frame.buffers.get("normal")
    if normal is None:
        cong["shape"] = "depth"
    return cong, depth, normal


def congruence_layers(res: CongruenceResult) -> dict[str, F32]:
    """Output channels of a score: ``congruence.X`` and the flows (see :func:`score_frame`)."""
    return {
        "congruence.X": res.score_map,
        "congruence.weight.X": res.weight,
        "congruence.shading.X": np.ascontiguousarray(res.shading_flow[..., 0]),
        "congruence.shading.Y": np.ascontiguousarray(res.shading_flow[..., 1]),
        "congruence.shape.X": np.ascontiguousarray(res.shape_flow[..., 0]),
        "congruence.shape.Y": np.ascontiguousarray(res.shape_flow[..., 1]),
    }
