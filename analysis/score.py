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
from ops.congruence import CongruenceResult, congruence

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
    **cong: Any,
) -> CongruenceResult:
    """:func:`ops.congruence.congruence` of ``image`` with the congruence parameters ``cong``,
    whose ``shape`` ("normals", the default, or "depth") picks the shape signal; without
    normals the shape is the depth. A parameter it does not take is a ValueError."""
    shape = cong.pop("shape", "normals")
    if shape not in SHAPES:
        raise ValueError(f"params['congruence']: shape must be one of {SHAPES}, got {shape!r}")
    use = normal if shape == "normals" else None
    try:
        return congruence(image, depth, mask, image_height=image_height, normal=use, **cong)
    except TypeError as exc:  # an unknown keyword
        raise ValueError(f"params['congruence']: {exc}") from None


def score_frame(frame: Frame, *, maps: bool = False, **params: Any) -> dict[str, Any]:
    """The congruence score (LLA Eq. 2) of ``frame``'s beauty against its depth (``depict score``).

    Parameters
    ----------
    frame : a frame with ``beauty`` and ``depth`` (coverage from :attr:`Frame.mask`).
    maps : also return the per-pixel layers under ``"layers"``: ``congruence.X`` (score map),
        ``congruence.shading.X/Y`` and ``congruence.shape.X/Y`` (the two flows, camera x right /
        y up), ``congruence.weight.X`` — ready for ``frame.outputs``.
    **params : keywords of :func:`ops.congruence.congruence` (``gradient_scale``,
        ``integration_scale``, ``percentile``, ``depth_jump``).

    Returns
    -------
    dict with ``score``, ``shading_norm`` (the shading strength mapped to 1: pass it as
    ``shading_norm`` to score another rendering of the frame on this one's scale),
    ``analysis_shape``, ``image_shape``, ``params`` (the congruence parameters used) and, with
    ``maps``, ``layers``.
    """
    cong = {**CONGRUENCE, **params}
    beauty = np.asarray(frame.need("beauty", "the image to score"), np.float32)
    depth = np.asarray(frame.need("depth", "for the shape flow of the score"), np.float32)
    normal = frame.buffers.get("normal")
    if normal is None:
        cong["shape"] = "depth"
    res = score_image(
        beauty,
        depth,
        frame.mask,
        normal,
        int(frame.image_height),
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
