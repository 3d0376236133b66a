"""Every operator at both ends of every number parameter's range, and every pair of operators one
after the other, on a real path-traced frame (the glass corpus frame: lobes, a rest below 0 at
most pixels, transmission): a finite beauty with no value an operator made negative and finite
layers on the surface, or a refusal in one line. Radiance Scaling with γ = 10 or more left
negative pixels where the lobes it scaled towards 0 met that rest."""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
import pytest

from bench import corpus
from gbuffer.frame import Frame
from service import pipeline
from service.registry import REGISTRY, PipelineError

#: JSON-schema keys of a number's range, and how far inside it an exclusive end is taken.
_ENDS = {"minimum": 0.0, "maximum": 0.0, "exclusiveMinimum": 1e-6, "exclusiveMaximum": -1e-6}


def _ends(spec: dict[str, Any]) -> list[float]:
    """The ends of a property's range (in ``anyOf`` too, for optional numbers)."""
    found = []
    for part in [spec, *spec.get("anyOf", [])]:
        for key, inside in _ENDS.items():
            if key in part and isinstance(part[key], int | float):
                value = part[key] + inside
                found.append(int(value) if isinstance(part[key], int) and not inside else value)
    return found


def _cases() -> list[Any]:
    cases = []
    for name, op in REGISTRY.items():
        for field, spec in op.params.model_json_schema().get("properties", {}).items():
            for value in _ends(spec):
                cases.append(pytest.param(name, field, value, id=f"{name}-{field}={value:g}"))
    return cases


@functools.cache
def _frame() -> Frame:
    (found,) = corpus.find_frames(corpus.CI_DIR, ["glass"])
    return found.read()


def assert_clean(frame: Frame, out: Frame) -> None:
    """A finite beauty with no value the pipeline made negative, and finite layers on the
    surface."""
    before, after = frame.buffers["beauty"], out.buffers["beauty"]
    assert np.isfinite(after).all()
    assert not ((after < 0) & (after != before)).any()
    covered = frame.mask > 0
    for name, layer in out.outputs.items():
        assert np.isfinite(layer[covered]).all(), name


@pytest.mark.parametrize(("op", "field", "value"), _cases())
def test_an_operator_at_the_end_of_a_range(op: str, field: str, value: float) -> None:
    frame = _frame()
    try:
        out = pipeline.run(frame, [{"op": op, "params": {field: value}}])
    except PipelineError as exc:  # (a value that needs another to go with it)
        assert "\n" not in str(exc)
        return
    assert_clean(frame, out)


def test_every_operator_is_tried() -> None:
    """The schema's ranges reach every operator (a range written some other way would leave its
    parameters out of the sweep unnoticed)."""
    assert {case.values[0] for case in _cases()} == set(REGISTRY)
    assert len(_cases()) > 150


@pytest.mark.parametrize("second", sorted(REGISTRY))
@pytest.mark.parametrize("first", sorted(REGISTRY))
def test_two_operators_one_after_the_other(first: str, second: str) -> None:
    """Each operator on the result of each other (the second reads the lobes, lights and layers
    the first wrote) with their defaults: the same guarantees as one operator."""
    frame = _frame()
    out = pipeline.run(frame, [{"op": first}, {"op": second}])
    assert_clean(frame, out)
