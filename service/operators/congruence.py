"""``congruence``: the congruence score of the current beauty against the shape (Mestres et al.,
EG 2021, §7, Eq. 2) as a pipeline step.

It leaves the beauty as it is and writes the per-pixel score ``congruence.X``, its weight
``congruence.weight.X``, the two flows ``congruence.shading.X/Y`` and ``congruence.shape.X/Y``
(camera x right, y up) and the mean score as the header attribute ``depict/congruence``. Put it
last in a pipeline to measure what the steps before it did (``depict score`` prints it).
With ``mask_stats``, the score, its strength normalisation and its mean are those of the
pixels inside the step's mask only (e.g. one object's congruence).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import Field

from analysis.score import CONGRUENCE, score_frame
from gbuffer.frame import Frame
from ops import checks
from service.masks import MASK_FIELDS
from service.operators.base import Context, Params, register

_DEFAULTS = CONGRUENCE


class CongruenceParams(Params):
    """Scales of the structure tensors and the strength normalisation of LLA Eq. 2."""

    gradient_scale: float = Field(
        _DEFAULTS["gradient_scale"],
        **checks.GRADIENT_SCALE.bounds,
        description="σ of the gradients, relative to the image height",
    )
    integration_scale: float = Field(
        _DEFAULTS["integration_scale"],
        **checks.INTEGRATION_SCALE.bounds,
        description="σ integrating the structure tensors, relative to the image height",
    )
    percentile: float = Field(
        _DEFAULTS["percentile"],
        **checks.PERCENTILE.bounds,
        description="percentile each strength is divided by (both e in [0, 1])",
    )
    shape: Literal["normals", "depth"] = Field(
        _DEFAULTS["shape"],
        description="shape flow from the normals' gradients (planes carry no weight; the depth "
        "when the frame has no normals) or from the log depth's gradients (the paper's wording, "
        "which gives receding floors most of the weight)",
    )
    depth_jump: float = Field(
        0.05, **checks.DEPTH_JUMP.bounds, description="largest log-depth step still one surface"
    )
    shading_norm: float | None = Field(
        None,
        **checks.SHADING_NORM.bounds,
        description="shading strength mapped to 1 (default: the image's own percentile); pin "
        "it to compare frames or renderings on one scale",
    )


@register(
    "congruence",
    summary="congruence score (Mestres et al. 2021, Eq. 2): how well the shading flow follows "
    "the shape flow; per-pixel map, flows, and the mean in the header",
    params=CongruenceParams,
    needs=("beauty", "depth"),
    writes=(
        "congruence.X",
        "congruence.weight.X",
        "congruence.shading.X/Y",
        "congruence.shape.X/Y",
    ),
)
def apply_congruence(frame: Frame, p: CongruenceParams, ctx: Context) -> None:
    scored = frame
    if ctx.region is not None:  # mask_stats: the score and its normalisation inside the mask
        scored = frame.copy()
        scored.buffers["coverage"] = np.where(ctx.region, frame.mask, np.float32(0))
    result = score_frame(
        scored, maps=True, **p.model_dump(exclude_none=True, exclude=set(MASK_FIELDS))
    )
    frame.outputs.update(result["layers"])
    frame.attributes["depict/congruence"] = float(result["score"])
