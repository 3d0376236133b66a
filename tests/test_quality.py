"""The pictures a compositor would ship: the defaults of Radiance Scaling, Light Alignment and
unsharp masking on every committed corpus frame (real Cycles renders, tests/fixtures/corpus),
held to the targets of bench/quality.py:

- the objects' mean luminance within ±13 % of the input's;
- hot pixels (a channel above twice its input and the input's maximum) ≤ 0.1 %;
- no negative or non-finite value;
- high-frequency noise of the flat lit floor at most 1.2 × the input's;
- low-frequency luminance (the lighting) correlated ≥ 0.97 with the input's;
- more band-pass detail on the objects than the input;
- congruence (LLA Eq. 2, as ``depict score``) of the whole frame and of the objects alone:
  higher after Radiance Scaling and Light Alignment, not lower after unsharp masking.

Operators run with the frame's key lights (``*.lights.json``) where they take lights; the
result's congruence is measured with its shading strength on the input's scale.
Apparent Relief and the depth-buffer unsharp mask are held to the finite, non-negative target.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

import pytest

from bench import corpus, quality
from service import pipeline

OPS = ("radiance_scaling", "light_alignment", "unsharp_masking")
FRAMES = {f.name: f for f in corpus.find_frames(corpus.CI_DIR)}


def _target(name: str) -> Callable[[quality.Figures, str], bool]:
    passes = quality.TARGETS[name][0]
    return lambda fig, op: passes(fig.as_dict()[name])


def _rises(before: str, after: str) -> Callable[[quality.Figures, str], bool]:
    """After above before for RS and LLA, not below it for unsharp masking (both beyond the
    float rounding of the score)."""
    tol = quality.CONGRUENCE_TOLERANCE

    def check(fig: quality.Figures, op: str) -> bool:
        b, a = getattr(fig, before), getattr(fig, after)
        return bool(a >= b - tol if op == "unsharp_masking" else a > b + tol)

    return check


CHECKS: dict[str, Callable[[quality.Figures, str], bool]] = {
    "lum_objects": _target("lum_objects"),
    "hot": _target("hot"),
    "finite": lambda fig, op: fig.negatives == 0 and fig.nonfinite == 0,
    "floor_noise": _target("floor_noise"),
    "lf_corr": _target("lf_corr"),
    "detail": _target("detail"),
    "cong": _rises("cong_before", "cong_after"),
    "cong_objects": _rises("cong_objects_before", "cong_objects_after"),
}


def _cases() -> list[Any]:
    return [
        pytest.param(name, op, check, id=f"{op}-{check}-{name}")
        for op in OPS
        for check in CHECKS
        for name in sorted(FRAMES)
    ]


@functools.cache
def _reference(name: str) -> quality.Reference:
    return quality.reference(FRAMES[name].read())


@functools.cache
def _figures(name: str, op: str) -> quality.Figures:
    ref = _reference(name)
    return quality.figures(ref, quality.run_operator(ref.frame, op, FRAMES[name].light_strings()))


def test_every_scene_is_held() -> None:
    assert {n.split("_240p")[0] for n in FRAMES} == set(corpus.scene_names())


@pytest.mark.parametrize(("name", "op", "check"), _cases())
def test_default_meets_target(name: str, op: str, check: str) -> None:
    fig = _figures(name, op)
    assert CHECKS[check](fig, op), f"{op} on {name}: {check} misses its target; {fig}"


@pytest.mark.parametrize("op", [op for op in quality.DEFAULT_OPS if op not in OPS])
@pytest.mark.parametrize("name", sorted(FRAMES))
def test_the_other_operators_make_no_negative_or_non_finite_pixel(name: str, op: str) -> None:
    """Apparent Relief and the depth-buffer unsharp mask on the real frames: the latter's CIELAB
    round trip wrote −1e-9 in black channels of the glass and rock frames."""
    ref = _reference(name)
    after = quality.run_operator(ref.frame, op, FRAMES[name].light_strings())
    assert quality.bad_pixels(after.buffers["beauty"]) == (0, 0)


@pytest.mark.parametrize("keep_lighting", [True, False])
def test_a_beauty_rebuilt_from_scaled_lobes_is_never_negative(keep_lighting: bool) -> None:
    """The glass frame's beauty minus its lobes (what Radiance Scaling adds back) is below 0 at
    58 000 pixels (half floats, noise): with γ = 30 the scaled lobes went towards 0 there and
    left 4 919 negative pixels (6 without the kept lighting); an operator's new negatives are 0."""
    ref = _reference("glass_240p_16spp")
    assert (ref.frame.buffers["remainder"] < 0).any()
    params = {"gamma": 30.0, "keep_lighting": keep_lighting}
    out = pipeline.run(ref.frame, [{"op": "radiance_scaling", "params": params}])
    assert quality.bad_pixels(out.buffers["beauty"]) == (0, 0)
