"""Holes: pixels whose radiance is NaN or Inf, the fireflies of a path-traced frame.

A renderer that diverges on a few samples writes NaN or Inf (or a value past 1e18, which the
operators' float32 cannot square) into the beauty or a lobe. Such a
pixel says nothing about the shading there, so Depict does not refuse the frame: reading makes
it a **hole**. The frame's ``coverage`` is 0 there (operators treat it as an uncovered pixel),
its radiance buffers hold 0 (no NaN spreads through a filter), and after the operators have run
the beauty there is given back exactly as it was read (:func:`restore`), so the output keeps the
original values, non-finite ones included. One warning line counts them.

NaN or Inf in a *data* channel (normals, depth, position, AO) is still an error for operators
(:class:`gbuffer.errors.FrameError` naming the channel); ``depict inspect`` reads with
``strict=False`` and reports those pixels as holes too, so it always describes the file.
"""

from __future__ import annotations

import numpy as np

from gbuffer.frame import LOBES, Frame

#: The radiance buffers that get 0 in a hole.
RADIANCE = (
    "beauty",
    "albedo",
    "remainder",
    *LOBES,
    *(f"{lobe}.light" for lobe in LOBES),
    *(f"{lobe}.color" for lobe in LOBES),
)


def mark_holes(frame: Frame, holes: np.ndarray, original_beauty: np.ndarray | None) -> int:
    """Make ``holes`` (H, W bool) holes of ``frame``: coverage 0, radiance 0, and the beauty
    read there (``original_beauty``, non-finite values included) kept for :func:`restore`.
    Returns the number of hole pixels."""
    frame.holes = holes
    frame.hole_beauty = None if original_beauty is None else original_beauty[holes]
    coverage = frame.buffers.get("coverage")
    coverage = np.ones(frame.shape, np.float32) if coverage is None else coverage.copy()
    coverage[holes] = 0.0
    frame.buffers["coverage"] = coverage
    frame.sources["coverage"] = frame.sources.get("coverage", "all") + " (0 in holes)"
    for name in RADIANCE:
        if name in frame.buffers:
            arr = frame.buffers[name].copy()
            arr[holes] = 0.0
            frame.buffers[name] = arr
    return int(holes.sum())


def hole_warnings(radiance: dict[str, int], data: dict[str, int], pixels: int) -> list[str]:
    """The warning lines of :func:`mark_holes`: one for radiance, one for data channels."""
    out = []
    if radiance:
        out.append(
            f"{pixels} pixel(s) with NaN/Inf radiance (or beyond 1e18) ({_counts(radiance)}) "
            "treated as holes: "
            "left out of the operators and written back unchanged"
        )
    if data:
        out.append(
            f"NaN/Inf in data channels on covered pixels ({_counts(data)}): masked here; "
            "enhance refuses such a file"
        )
    return out


def _counts(counts: dict[str, int]) -> str:
    return ", ".join(f"{name}: {n}" for name, n in sorted(counts.items()))


def fill(frame: Frame) -> None:
    """Beauty 0 in the holes (undoes :func:`restore` before more operators run)."""
    if frame.holes is not None and "beauty" in frame.buffers:
        beauty = frame.buffers["beauty"].copy()
        beauty[frame.holes] = 0.0
        frame.buffers["beauty"] = beauty


def restore(frame: Frame) -> None:
    """The beauty read in the holes put back, exactly (after the operators)."""
    if frame.holes is None or frame.hole_beauty is None or "beauty" not in frame.buffers:
        return
    beauty = np.array(frame.buffers["beauty"], np.float32)
    if beauty.shape[:2] != frame.holes.shape:
        return
    beauty[frame.holes] = frame.hole_beauty
    frame.buffers["beauty"] = beauty
