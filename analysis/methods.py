"""The depiction methods of the comparison (LLA §7, Fig. 14), as steps of the operator registry.

Every method but Lambert is a registry operator (:mod:`service.operators`) run by
:func:`service.pipeline.run` on the frame's geometry with one white directional light, with the
parameters that make it the paper's method; Lambert, the baseline, is the plain shading
ρ max(n·ℓ, 0) of :func:`ops.baselines.lambert_image` (the registry has no operator that only
shades).

``radiance_scaling``
    Radiance Scaling (Vergne et al., TVCG 2011, Eq. 2 and §5.1) of the Lambert term with the
    settings of LLA Fig. 14 e: scenario ``phong`` with no ambient and no specular term,
    isotropic curvature (λ = 0), α = 0.5, γ = 4; I = σ_{α,γ}(κ, δ) δ with δ = max(n·ℓ, 0).
``exaggerated_shading``
    Exaggerated Shading (Rusinkiewicz, Burns, DeCarlo 2006) with its own clamped
    half-Lambertian (Fig. 14 c).
``light_warping``
    Our directional-light approximation of Light Warping (Vergne et al. 2009), Lambert shading
    with the warped light (Fig. 14 d).
``light_alignment``
    Local Light Alignment (``preset: paper``: σ_i = (0.5, 0.3, 0.1, 0.2, 0.2), the fine-tuned
    6-scale setting of Fig. 7; γ = 3, "γ = 3 in all the results presented in the paper", §4)
    with the diffuse guide, ``form: relight`` with Lambert alone: max(n·ℓ', 0) (Fig. 14 b).

The curvature-based methods use a gain of :data:`COMPARE_CURVATURE_GAIN`. A method's section of
the comparison's ``params`` overrides its operator parameters (``depict ops`` lists them); the
light is the comparison's own.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from analysis.score import CONGRUENCE
from gbuffer.frame import Frame
from ops.baselines import lambert_image
from service import pipeline
from service.registry import Context, get

F32 = NDArray[np.float32]

#: Curvature gain of the curvature-based methods here: above the operators' default (0.03,
#: chosen for looks), as both score higher with it on the shared meshes (Radiance Scaling 0.515
#: against 0.501, Light Warping 0.621 against 0.557, mean congruence), so neither baseline is
#: weakened by the choice.
COMPARE_CURVATURE_GAIN = 0.1


@dataclass(frozen=True)
class Method:
    """One method: its display name and the registry operator that renders it.

    ``op`` is the operator (``None``: plain Lambert), ``params`` the operator parameters that
    make it the method of the paper, ``light`` the parameter its light goes to (``"lights"``
    takes a list).
    """

    label: str
    op: str | None = None
    params: Mapping[str, Any] = field(default_factory=dict)
    light: str = "lights"


#: The methods, in the order of the tables and plots.
METHOD_TABLE: dict[str, Method] = {
    "lambert": Method("Lambert"),
    "radiance_scaling": Method(
        "Radiance Scaling",
        "radiance_scaling",
        {
            "scenario": "phong",
            "ambient": 0.0,
            "specular": 0.0,
            "alpha": 0.5,
            "gamma": 4.0,
            "gain": COMPARE_CURVATURE_GAIN,
        },
    ),
    "exaggerated_shading": Method(
        "Exaggerated Shading", "exaggerated_shading", {"albedo": 1.0}, light="light"
    ),
    "light_warping": Method(
        "Light Warping",
        "light_warping",
        {"albedo": 1.0, "strength": 1.0, "gain": COMPARE_CURVATURE_GAIN},
        light="light",
    ),
    "light_alignment": Method(
        "Light Alignment",
        "light_alignment",
        {
            "preset": "paper",
            "gamma": 3.0,
            "form": "relight",
            "components": ["diffuse"],
            "specular": "none",
            "ambient": 0.0,
            "albedo": 1.0,
        },
    ),
}
#: Method names, in table order.
METHODS: tuple[str, ...] = tuple(METHOD_TABLE)
#: Display names (tables, legends, sheets).
LABELS: dict[str, str] = {name: m.label for name, m in METHOD_TABLE.items()}


def resolve_params(params: Mapping[str, Mapping[str, Any]] | None = None) -> dict[str, dict]:
    """Every method's operator parameters and the congruence parameters (``"congruence"``),
    updated with ``params`` (one dict per section); raises ValueError naming an unknown section,
    a parameter the operator does not take or a value out of its range."""
    out: dict[str, dict[str, Any]] = {"congruence": dict(CONGRUENCE)}
    out.update({name: dict(m.params) for name, m in METHOD_TABLE.items()})
    for key, value in (params or {}).items():
        if key not in out:
            allowed = ", ".join(out)
            raise ValueError(f"params: unknown section {key!r}; allowed: {allowed}")
        if not isinstance(value, Mapping):
            raise ValueError(f"params[{key!r}] must be a mapping of parameter names to values")
        out[key].update(value)
    others = sorted(set(out["congruence"]) - set(CONGRUENCE_PARAMETERS))
    if others:  # (the image height, normals, weights and shading scale are the comparison's)
        raise ValueError(
            f"params['congruence']: unknown parameter {others[0]!r}; allowed: "
            f"{', '.join(CONGRUENCE_PARAMETERS)}"
        )
    for name, method in METHOD_TABLE.items():
        _check(name, method, out[name])
    return out


#: The congruence parameters a comparison may be given (``--set congruence.KEY=VALUE``).
CONGRUENCE_PARAMETERS = ("gradient_scale", "integration_scale", "percentile", "depth_jump", "shape")


def _check(name: str, method: Method, params: Mapping[str, Any]) -> None:
    if method.op is None:
        if params:
            raise ValueError(f"params[{name!r}]: {method.label} takes no parameters")
        return
    if method.light in params:
        raise ValueError(
            f"params[{name!r}]: {method.light!r} is set by the comparison (one light per direction)"
        )
    get(method.op).parse({**params, method.light: _light_value(method, "0,0,1")})


def _light_value(method: Method, light: str) -> str | list[str]:
    return [light] if method.light == "lights" else light


def light_text(direction: NDArray[np.floating]) -> str:
    """A direction as an operator's light (``"X,Y,Z"``, each float written exactly)."""
    return ",".join(repr(float(c)) for c in direction)


def shade(
    name: str, geometry: Frame, direction: F32, params: Mapping[str, Any], files: bool = True
) -> F32:
    """Method ``name`` under the white directional light ``direction`` on ``geometry`` (a frame
    with normal, depth, coverage and a white albedo): the (H, W) shading, not clipped.
    ``files``: whether ``params`` may name image files on this machine (a matcap, an
    environment, a mask; not over HTTP: :attr:`service.registry.Context.files`)."""
    method = METHOD_TABLE[name]
    if method.op is None:
        return lambert_image(geometry.buffers["normal"], geometry.mask, direction)
    step = {method.light: _light_value(method, light_text(direction)), **params}
    out = pipeline.run(geometry, [{"op": method.op, "params": step}], context=Context(files=files))
    return np.ascontiguousarray(out.buffers["beauty"][..., 0])
