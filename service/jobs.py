"""The analysis commands' work, shared by the CLI and the HTTP service.

``depict score``, ``compare`` and ``relief-pick`` call :func:`score_job`, :func:`compare_job` and
:func:`pick_job` in their own process; the routes ``/v1/score``, ``/v1/compare`` and
``/v1/relief/pick`` submit the same functions to a worker (:mod:`service.http.worker`), so both
print the same answer. Each reads its frame with a :class:`service.enhance.ReadRequest` and
returns a small JSON-able dict. Enhancing and rendering are :func:`service.enhance.enhance` and
:func:`service.scene.render_to_file`.
"""

from __future__ import annotations

import base64
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from analysis.compare import compare, frame_from_mesh
from analysis.methods import METHODS
from analysis.pictures import SHEET_DIRECTIONS, contact_sheet
from analysis.score import score_frame
from gbuffer.limits import Limits
from ops import relief as rl
from service import pipeline
from service.enhance import ReadRequest
from service.errors import PipelineError
from service.registry import Context


def score_job(
    in_path: str,
    steps: pipeline.Pipeline | None,
    read: ReadRequest,
    options: dict[str, Any],
    files: bool = False,
) -> dict[str, Any]:
    """``depict score``: the congruence score (LLA Eq. 2) of the frame's beauty
    (:func:`analysis.score.score_frame`), after the pipeline ``steps`` when given."""
    frame = read.read(in_path)
    op_s: list[tuple[str, float]] = []
    context = Context(files=files)
    if steps is not None:
        frame, op_s = pipeline.run_timed(frame, steps, context)
    out = score_frame(frame, maps=False, **options)
    scored = bool(frame.covered().any())  # (0.0 and nothing said, for an all-NaN beauty)
    return {
        "score": float(out["score"]),
        "shading_norm": float(out["shading_norm"]),
        "analysis_shape": [int(v) for v in out["analysis_shape"]],
        "image_shape": [int(v) for v in out["image_shape"]],
        "params": {k: v if isinstance(v, str) else float(v) for k, v in out["params"].items()},
        "op_s": op_s,
        "warnings": context.warnings + ([] if scored else [NOTHING_SCORED]),
    }


#: Why a comparison's scores are all 0 when no pixel could be scored (a mesh out of view).
NOTHING_COMPARED = (
    "no pixel was scored: none is covered (a finite, positive depth on a surface); the scores "
    "0 say nothing of the methods"
)

#: Why a score is 0 when no pixel could be scored.
NOTHING_SCORED = (
    "no pixel was scored: none is covered (a finite, positive depth on a surface) with a finite "
    "radiance (NaN or Inf pixels are holes); the score 0 says nothing of the picture"
)


def compare_job(
    in_path: str,
    read: ReadRequest | None,
    options: dict[str, Any],
    sheet: bool = False,
    limits: Limits | None = None,
    files: bool = False,
) -> dict[str, Any]:
    """``depict compare``: the comparison bench (LLA §7) on an EXR frame (``read`` given) or a
    mesh (``read`` None: rendered at ``options["width"]`` × ``options["height"]``, within
    ``limits.max_pixels``).

    ``options``: ``methods``, ``directions``, ``params``, ``albedo``, ``shading_norm``
    (:func:`analysis.compare.compare`), and for meshes ``width``, ``height``, ``azimuth``,
    ``elevation``. Returns :meth:`ComparisonResult.to_dict`, with ``sheet``, plus
    ``sheet_png``: the contact sheet as a base64 PNG. ``files``: whether the methods' parameters
    may name image files on this machine (the command line; never for a client of the service).
    """
    opts = dict(options)
    if read is None:
        width, height = int(opts.pop("width", 512)), int(opts.pop("height", 512))
        (limits or Limits.from_env()).check_render(width, height, "compare")
        frame = frame_from_mesh(
            in_path,
            width,
            height,
            azimuth_deg=float(opts.pop("azimuth", 30.0)),
            elevation_deg=float(opts.pop("elevation", 20.0)),
        )
    else:
        frame = read.read(in_path)
    result = compare(
        frame,
        methods=opts.get("methods") or METHODS,
        directions=opts.get("directions", 21),
        params=opts.get("params"),
        albedo=opts.get("albedo", "white"),
        keep_images=SHEET_DIRECTIONS if sheet else False,
        label=opts.get("label", ""),
        shading_norm=opts.get("shading_norm", "reference"),
        files=files,
    )
    out = result.to_dict()
    out["warnings"] = [] if frame.covered().any() else [NOTHING_COMPARED]
    if sheet:
        with tempfile.TemporaryDirectory() as tmp:
            png = contact_sheet(result, Path(tmp) / "sheet.png").read_bytes()
        out["sheet_png"] = base64.b64encode(png).decode("ascii")
    return out


def pick_job(
    in_path: str, read: ReadRequest, x: int, y: int, params: dict[str, Any]
) -> dict[str, Any]:
    """``depict relief-pick``: the Apparent Relief descriptor S under pixel (x, y) with the
    ``apparent_relief`` parameters ``params``, its ARM texture coordinates and its region."""
    frame = read.read(in_path)
    h, w = frame.shape
    if 0 <= x < w and 0 <= y < h and not frame.covered()[y, x]:  # (else rl.pick says which)
        if frame.holes is not None and frame.holes[y, x]:  # (its depth may be fine)
            raise PipelineError(
                f"pixel ({x}, {y}) is a NaN or Inf pixel of the beauty (a hole the operators "
                "leave out): pick a pixel beside it"
            )
        raise PipelineError(
            f"pixel ({x}, {y}) shows no surface (no finite, positive depth there): pick a pixel "
            "on an object"
        )
    steps = pipeline.compile([{"op": "apparent_relief", "params": {**params, "style": "cel"}}])
    context = Context(files=False)
    out, _ = pipeline.run_timed(frame, steps, context)
    s = np.dstack([out.outputs["relief.S.X"], out.outputs["relief.S.Y"]])
    picked = rl.pick(s, x, y)
    region = rl.REGIONS[int(rl.classify(s[y : y + 1, x : x + 1])[0, 0])]
    norm = context.measured.get("apparent_relief.curvedness_norm", params.get("curvedness_norm"))
    return {
        "x": x,
        "y": y,
        "s": [picked.s1, picked.s2],
        "uv": [picked.u, picked.v],
        "region": region,
        "r": float(out.outputs["relief.X"][y, x]),
        "curvedness_norm": float(norm) if norm is not None else None,
    }
