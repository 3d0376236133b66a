"""One place for parameter ranges: ops/checks.py. The ops refuse what the service's parameter
models refuse and accept what they accept, because both read the same :class:`Range`."""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from pydantic import BaseModel, ValidationError

from ops import checks
from ops.checks import Range
from ops.congruence import congruence
from ops.curvature import isotropic, principal_curvatures
from ops.light_alignment import w_gamma
from ops.radiance_scaling import sigma
from ops.shading import blinn_phong, refract
from service.operators.baselines import ExaggeratedParams
from service.operators.congruence import CongruenceParams
from service.operators.curvature import CurvatureParams
from service.operators.light_alignment import LightAlignmentParams
from service.operators.radiance_scaling import RadianceScalingParams
from service.operators.unsharp import UnsharpParams
from tests import analytic


@pytest.mark.parametrize(
    ("rng", "inside", "outside", "text"),
    [
        (Range(0.0, 1.0), [0.0, 0.5, 1.0], [-1e-9, 1.0 + 1e-9], "[0, 1]"),
        (Range(0.0, 1.0, lo_open=True, hi_open=True), [1e-9, 0.5], [0.0, 1.0], "(0, 1)"),
        (Range(0.0, math.inf, lo_open=True), [1e-30, 1e30], [0.0, -1.0], "(0, inf)"),
        (Range(-4.0, 4.0), [-4, 4, np.float32(2.5)], [-4.5, 5], "[-4, 4]"),
    ],
)
def test_range_ends(rng: Range, inside: list[float], outside: list[float], text: str) -> None:
    assert str(rng) == text
    for v in inside:
        assert rng.check(v, "x") == float(v)
    for v in [*outside, math.nan, math.inf, -math.inf]:
        with pytest.raises(ValueError, match=rf"^x={v!r} is outside the allowed range"):
            rng.check(v, "x")


@pytest.mark.parametrize("value", ["3", None, [1.0], np.ones(2)])
def test_range_refuses_what_is_not_one_number(value: object) -> None:
    with pytest.raises(ValueError, match="x must be a number"):
        Range(0.0, 10.0).check(value, "x")


def test_float32_limits_are_numpys() -> None:
    assert checks.FLOAT32_MAX == float(np.finfo(np.float32).max)
    assert checks.FLOAT32_TINY == float(np.finfo(np.float32).tiny)


def test_bounds_are_pydantic_keywords() -> None:
    assert Range(0.0, 1.0).bounds == {"ge": 0.0, "le": 1.0}
    assert Range(0.0, 1.0, lo_open=True, hi_open=True).bounds == {"gt": 0.0, "lt": 1.0}
    assert Range(0.0, math.inf, lo_open=True).bounds == {"gt": 0.0}
    assert Range().bounds == {}


#: (model, field, the range it must take its bounds from)
FIELDS: list[tuple[type[BaseModel], str, Range]] = [
    (RadianceScalingParams, "alpha", checks.ALPHA),
    (RadianceScalingParams, "gamma", checks.GAMMA),
    (RadianceScalingParams, "anisotropy", checks.ANISOTROPY),
    (RadianceScalingParams, "ior", checks.IOR),
    (RadianceScalingParams, "shininess", checks.SHININESS),
    (RadianceScalingParams, "white_percentile", checks.PERCENTILE),
    (LightAlignmentParams, "gamma", checks.LLA_GAMMA),
    (LightAlignmentParams, "base", checks.LLA_BASE),
    (LightAlignmentParams, "factor", checks.FACTOR),
    (LightAlignmentParams, "depth_sigma", checks.LLA_DEPTH_SIGMA),
    (LightAlignmentParams, "ior", checks.IOR),
    (LightAlignmentParams, "shininess", checks.SHININESS),
    (LightAlignmentParams, "ratio_max", checks.RATIO_MAX),
    (CurvatureParams, "scale", checks.CURVATURE_SCALE),
    (CurvatureParams, "gain", checks.CURVATURE_GAIN),
    (CurvatureParams, "depth_jump", checks.CURVATURE_DEPTH_JUMP),
    (CongruenceParams, "gradient_scale", checks.GRADIENT_SCALE),
    (CongruenceParams, "integration_scale", checks.INTEGRATION_SCALE),
    (CongruenceParams, "depth_jump", checks.DEPTH_JUMP),
    (UnsharpParams, "amount", checks.UNSHARP_AMOUNT),
    (UnsharpParams, "depth_sigma", checks.UNSHARP_SIGMA),
    (ExaggeratedParams, "contrast", checks.CONTRAST),
    (ExaggeratedParams, "weight_exponent", checks.WEIGHT_EXPONENT),
]


def _schema_bounds(model: type[BaseModel], name: str) -> dict[str, float]:
    prop = model.model_json_schema()["properties"][name]
    keys = {"minimum": "ge", "exclusiveMinimum": "gt", "maximum": "le", "exclusiveMaximum": "lt"}
    return {keys[k]: v for k, v in prop.items() if k in keys}


@pytest.mark.parametrize(("model", "name", "rng"), FIELDS)
def test_models_publish_the_ranges_of_ops_checks(
    model: type[BaseModel], name: str, rng: Range
) -> None:
    assert _schema_bounds(model, name) == rng.bounds
    for value, ok in _edges(rng):
        if ok:
            model(**{name: value})
        else:
            with pytest.raises(ValidationError):
                model(**{name: value})


def _edges(rng: Range) -> list[tuple[float, bool]]:
    """Values at and just beyond each finite end, and whether ``rng`` holds them."""
    out = []
    for end in (rng.lo, rng.hi):
        if math.isfinite(end):
            step = max(abs(end), 1.0) * 1e-6
            out += [(v, v in rng) for v in (end - step, end, end + step)]
    return out


_UP = np.tile(np.float32([0, 0, 1]), (2, 2, 1))


@functools.cache
def _scene() -> Any:
    return analytic.sphere(32)


@functools.cache
def _curv() -> Any:
    s = _scene()
    return principal_curvatures(s.normal, s.depth, s.mask)


#: (model, field, the op call with that value, the range): the op and the model agree at both
#: ends of the range.
CALLS: list[tuple[type[BaseModel], str, Callable[[float], object], Range]] = [
    (RadianceScalingParams, "alpha", lambda v: sigma(0.5, 0.5, v, 1.0), checks.ALPHA),
    (RadianceScalingParams, "gamma", lambda v: sigma(0.5, 0.5, 0.5, v), checks.GAMMA),
    (LightAlignmentParams, "gamma", lambda v: w_gamma(0.5, v), checks.LLA_GAMMA),
    (
        LightAlignmentParams,
        "ior",
        lambda v: refract(_UP, _UP, v),
        checks.IOR,
    ),
    (
        LightAlignmentParams,
        "shininess",
        lambda v: blinn_phong(_UP, _UP, _UP, v),
        checks.SHININESS,
    ),
    (CurvatureParams, "gain", lambda v: isotropic(_curv(), v), checks.CURVATURE_GAIN),
    (
        CongruenceParams,
        "integration_scale",
        lambda v: congruence(_scene().normal[..., 0], _scene().depth, integration_scale=v),
        checks.INTEGRATION_SCALE,
    ),
]


@pytest.mark.parametrize(("model", "name", "call", "rng"), CALLS)
def test_ops_and_models_accept_the_same_values(
    model: type[BaseModel], name: str, call: Callable[[float], object], rng: Range
) -> None:
    for value, ok in _edges(rng):
        if ok:
            model(**{name: value})
            call(value)
        else:
            with pytest.raises(ValidationError):
                model(**{name: value})
            with pytest.raises(ValueError, match=name):
                call(value)
