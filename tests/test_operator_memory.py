"""What an operator holds where its memory peaks: Light Alignment's ratio form peaks in the kept
lighting (a surface pyramid of its own over the relit luminance), so what only the alignment and
the shading read is let go before it."""

from __future__ import annotations

import gc
import weakref
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import gbuffer
import service.operators.light_alignment as light_alignment
from gbuffer.frame import Frame
from ops import filtering
from service import pipeline

FIXTURE = Path(__file__).parent / "fixtures" / "blender" / "cycles_multilayer.exr"


def test_light_alignment_lets_its_normals_pyramid_and_view_go_before_the_kept_lighting(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    made: list[weakref.ref[Any]] = []
    alive_then: list[int] = []
    normal_pyramid, view_vectors = filtering.normal_pyramid, Frame.view_vectors
    kept_lighting_gain = light_alignment.kept_lighting_gain

    def pyramid_made(*args: Any, **kwargs: Any) -> Any:
        pyramid = normal_pyramid(*args, **kwargs)
        made.append(weakref.ref(pyramid))
        return pyramid

    def view_made(self: Frame) -> np.ndarray:
        view = view_vectors(self)
        made.append(weakref.ref(view))
        return view

    def kept(*args: Any, **kwargs: Any) -> np.ndarray:
        gc.collect()
        alive_then.append(sum(ref() is not None for ref in made))
        return kept_lighting_gain(*args, **kwargs)

    monkeypatch.setattr(filtering, "normal_pyramid", pyramid_made)
    monkeypatch.setattr(Frame, "view_vectors", view_made)
    monkeypatch.setattr(light_alignment, "kept_lighting_gain", kept)
    frame = gbuffer.read(FIXTURE)
    out = pipeline.run(frame, [{"op": "light_alignment"}])
    assert len(made) == 2  # the pyramid and the view, each made once
    assert alive_then == [0]  # one kept lighting, with neither of them alive
    assert np.isfinite(out.buffers["beauty"]).all()
