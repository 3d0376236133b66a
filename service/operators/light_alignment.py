"""``light_alignment``: Local Light Alignment (Mestres et al., EG 2021, §4-6) on a frame.

The lights are aligned per pixel with the depth-guided multi-scale normals
(:func:`ops.filtering.normal_pyramid`, LLA §5) by :func:`ops.light_alignment.align_lights`
(Eq. 1), one direction per shading component (diffuse: normal guide; specular: reflected view
vector; transmission: refracted view vector, §6), then the frame is shaded with them:

``relight``
    Deferred shading of the G-buffer with the aligned lights
    (:func:`ops.shading.shade_directions`): ambient + Lambert / half-Lambert + Blinn-Phong /
    GGX (+ transmission), albedo from the frame (or a constant). The beauty and its lobes are
    replaced. Right for Depict's own renders and for G-buffers without lobes.
``ratio``
    Each renderer lobe is multiplied by shade(aligned) / shade(original) of the same model and
    lights, so the renderer's textures, shadows and indirect light are kept and only the
    alignment is added; the beauty is rebuilt with the change of the lobes, emission and
    everything unmapped untouched. Right for production renders with lobes — with lights given
    as the ones of the shot. A specular or transmission lobe with no light in it (0 everywhere,
    with its light: :func:`service.operators.common.holds_light`) is left as it is, not shaded
    (a diffuse one is relit, to 0).
``auto``
    ``ratio`` when the frame has a diffuse, specular or transmission lobe, else ``relight``.

Only the components the result depends on are aligned (ratio: those with a lobe in the frame that
holds light; relight: diffuse, specular unless ``specular: "none"``, transmission with a
``transmission_weight``). Their aligned directions are written as
``lla_light.<component>.X/Y/Z`` (the first light; ``lla_light<k>.<component>`` for the k-th,
k ≥ 2), camera space, for any shader downstream. A lobe of the ratio form with no light in it
(Blender's transmission passes of a scene without glass) is not aligned: its layers hold the
lights' own directions, so that every frame of a sequence has the same layers.
``--debug-layers`` adds the multi-scale normals ``lla_n<i>.X/Y/Z`` (i = 1 finest … S).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Annotated, Any, ClassVar, Literal, cast

import cv2
import numpy as np
from pydantic import Field, model_validator

from gbuffer.frame import LOBES, Frame
from ops import checks, filtering
from ops.light_alignment import DEFAULT_GAMMA, align_lights
from ops.shading import (
    Light,
    Relit,
    Shading,
    apply_gain,
    light_direction,
    lobe_radiance,
    ratio_relight,
    shading,
)
from service.operators.base import Context, register
from service.operators.common import (
    LightsParams,
    channels,
    frame_albedo,
    holds_light,
    kept_lighting_gain,
    surface_normals,
)

Component = Literal["diffuse", "specular", "transmission"]
COMPONENTS: tuple[Component, ...] = ("diffuse", "specular", "transmission")
Sigmas = list[Annotated[float, Field(**checks.LLA_SIGMA.bounds)]]
#: σ_1 … σ_5 of the paper's "fine-tuned" 6-scale result (LLA Fig. 7), finest first.
PAPER_SIGMAS = [0.5, 0.3, 0.1, 0.2, 0.2]
#: The default: less of the finest scale, whose filtering is a few pixels wide and shows the
#: triangles of a mesh's interpolated normals on production frames, more of the middle ones.
DEFAULT_SIGMAS = [0.1, 0.3, 0.3, 0.2, 0.2]
_SIGMA_ITEMS: dict[str, Any] = {"min_length": 1, "max_length": 7}
#: Fig. 7's scales, the ratio as is and no lighting kept (``preset: "paper"``).
PAPER = {
    "sigmas": PAPER_SIGMAS,
    "ratio_max": 8.0,
    "keep_lighting": False,
    "components": ["diffuse", "specular"],
}


class LightAlignmentParams(LightsParams):
    """Local Light Alignment (LLA §4-6) and the shading with the aligned lights."""

    PRESETS: ClassVar[dict[str, dict[str, Any]]] = {"default": {}, "paper": PAPER}

    preset: Literal["default", "paper"] = Field(
        "default",
        description="default: σ_i that spare the finest scale, ratio ≤ 2 and the lighting kept; "
        "paper: LLA Fig. 7's σ_i, ratio ≤ 8, no lighting kept; parameters given with it "
        "override it",
    )
    sigmas: Sigmas = Field(
        default_factory=lambda: list(DEFAULT_SIGMAS),
        **_SIGMA_ITEMS,
        description="σ_1 … σ_{S−1} in [0, 1], finest first, of the diffuse component (S = "
        "len + 1 scales, up to 8; paper: [0.5, 0.3, 0.1, 0.2, 0.2], LLA Fig. 7)",
    )
    specular_sigmas: Sigmas | None = Field(
        None, **_SIGMA_ITEMS, description="σ_i of the specular component (default: `sigmas`)"
    )
    transmission_sigmas: Sigmas | None = Field(
        None, **_SIGMA_ITEMS, description="σ_i of the transmission component (default: `sigmas`)"
    )
    components: list[Component] = Field(
        default_factory=lambda: list(COMPONENTS),
        min_length=1,
        description="components whose light may be aligned (others keep the original light); "
        "of these only those the result depends on are aligned and written: ratio, those with "
        "a lobe in the frame (a lobe with no light in it is not aligned: its layers hold the "
        "light as it is); relight, diffuse, specular unless 'none', transmission with a "
        "transmission_weight",
    )
    gamma: float = Field(DEFAULT_GAMMA, **checks.LLA_GAMMA.bounds, description="γ of W_γ (Eq. 1)")
    base: float = Field(
        filtering.DEFAULT_BASE,
        **checks.LLA_BASE.bounds,
        description="spatial σ of the first filtering, relative to the image height (§5)",
    )
    factor: float = Field(
        filtering.DEFAULT_FACTOR,
        **checks.FACTOR.bounds,
        description="spatial σ growth per scale (§5)",
    )
    depth_sigma: float = Field(
        filtering.DEFAULT_DEPTH_SIGMA,
        **checks.LLA_DEPTH_SIGMA.bounds,
        description="range σ of the bilateral filter on log depth (relative depth)",
    )
    ior: float = Field(1.5, **checks.IOR.bounds, description="index of refraction (transmission)")
    form: Literal["auto", "relight", "ratio"] = Field(
        "auto",
        description="relight: deferred shading with the aligned lights; ratio: scale the "
        "renderer's lobes by shade(aligned)/shade(original); auto: ratio when the frame has lobes",
    )
    diffuse: Literal["lambert", "half_lambert"] = Field("lambert", description="diffuse model")
    specular: Literal["none", "blinn_phong", "ggx"] = Field(
        "blinn_phong", description="specular model"
    )
    shininess: float = Field(32.0, **checks.SHININESS.bounds, description="Blinn-Phong exponent")
    specular_color: float = Field(
        0.3, **checks.WEIGHT.bounds, description="k_s of Blinn-Phong (GGX: white, Fresnel gives f0)"
    )
    roughness: Annotated[float, Field(**checks.ROUGHNESS.bounds)] | Literal["frame"] = Field(
        0.4, description="GGX roughness in (0, 1], or 'frame' for the frame's roughness pass"
    )
    f0: float = Field(
        0.04, **checks.FRACTION.bounds, description="GGX reflectance at normal incidence"
    )
    ambient: float = Field(
        0.1, **checks.AMBIENT.bounds, description="ambient light (× AO when present)"
    )
    albedo: float | None = Field(
        None, **checks.WEIGHT.bounds, description="constant albedo (default: the frame's, else 0.8)"
    )
    transmission_weight: float = Field(
        0.0, **checks.WEIGHT.bounds, description="relight: weight of a transmission lobe (0: none)"
    )
    ratio_floor: float = Field(
        0.05,
        **checks.RATIO_FLOOR.bounds,
        description="ratio form: ε in (shade_aligned + ε)/(shade_original + ε), relative to "
        "the lights' irradiance",
    )
    ratio_max: float = Field(
        2.0,
        **checks.RATIO_MAX.bounds,
        description="ratio form: largest factor (more brightens grazing rims at silhouettes)",
    )
    keep_lighting: bool = Field(
        True,
        description="ratio form: divide the relit lobes by their low-frequency gain along the "
        "surfaces (at `lighting_scale`), so the mean luminance of every region stays the "
        "input's and only the alignment's shape detail is added (false: the ratio as is)",
    )
    lighting_scale: float = Field(
        0.04,
        **checks.LIGHTING_SCALE.bounds,
        description="σ of the lighting kept by `keep_lighting`, relative to the image height",
    )

    @model_validator(mode="after")
    def _check(self) -> LightAlignmentParams:
        for name in ("sigmas", "specular_sigmas", "transmission_sigmas"):
            values = getattr(self, name)
            if values is None:
                continue
            if len(values) != len(self.sigmas):
                raise ValueError(f"{name} must have {len(self.sigmas)} values, like sigmas")
        return self

    def sigmas_of(self, component: str) -> list[float]:
        own = getattr(self, f"{component}_sigmas", None)
        return list(self.sigmas if own is None else own)


def _form(frame: Frame, p: LightAlignmentParams) -> str:
    if p.form != "auto":
        return p.form
    has_lobes = any(lobe in frame.buffers for lobe in ("diffuse", "specular", "transmission"))
    return "ratio" if has_lobes else "relight"


def _shaded(p: LightAlignmentParams, lit: dict[str, bool] | None, component: str) -> bool:
    """Whether the result depends on ``component``'s light: ratio (``lit``: which lobes of the
    frame hold light, :func:`holds_light`), a lobe of the frame with light in it; relight
    (``lit`` None), a lobe of its shading (diffuse; specular unless 'none'; transmission with
    a weight). Only those are aligned."""
    if lit is not None:
        return lit[component]
    if component == "specular":
        return p.specular != "none"
    return component == "diffuse" or p.transmission_weight > 0.0


def _light_layer(k: int, component: str) -> str:
    return f"lla_light{'' if k == 0 else k + 1}.{component}"


@register(
    "light_alignment",
    summary="Local Light Alignment (Mestres et al. 2021): lights rotated per pixel and per "
    "scale towards the shape (Eq. 1), diffuse / specular / transmission guides, relit",
    params=LightAlignmentParams,
    needs=("normal", "depth"),
    writes=(
        "beauty",
        "lla_light.<component>.X/Y/Z",
        "lla_n<i>.X/Y/Z (debug)",
    ),
)
def apply_light_alignment(frame: Frame, p: LightAlignmentParams, ctx: Context) -> None:
    form = _form(frame, p)
    lights = p.parsed_lights()
    aligned, relit, debug_normals = _align_and_shade(frame, p, form, lights, ctx.debug_layers)
    # (the normals' pyramid and the view vectors are let go by now: the ratio form's kept
    # lighting builds a pyramid of its own, and Light Alignment's peak memory is there)
    if relit is not None:
        _keep_lighting(frame, p, *relit)
    for k in range(len(lights)):
        for c, fields in aligned.items():
            frame.set_layer(_light_layer(k, c), channels(fields[k], copy=False))
    for i, n_i in enumerate(debug_normals, start=1):
        frame.set_layer(f"lla_n{i}", channels(n_i))


def _align_and_shade(
    frame: Frame, p: LightAlignmentParams, form: str, lights: list[Light], debug: bool
) -> tuple[dict[str, list[np.ndarray]], tuple[Relit, list[str]] | None, list[np.ndarray]]:
    """The lights aligned per component (LLA §4-6), and the frame relit with them: the relight
    form is done; the ratio form's relit lobes and beauty are returned with the relit lobes'
    names, for the kept lighting. Also the multi-scale normals when ``debug``."""
    normal = surface_normals(frame, "light_alignment")
    mask = frame.mask
    pyramid = filtering.normal_pyramid(
        normal,
        frame.need("depth", "light_alignment"),
        mask,
        scales=len(p.sigmas) + 1,
        base=p.base,
        factor=p.factor,
        depth_sigma=p.depth_sigma,
    )
    view = frame.view_vectors()
    # (camera-space positions: only point lights read them)
    position = frame.positions() if any(li.kind != "directional" for li in lights) else None
    # the ratio form shades the lobes that hold light: a lobe that is 0 everywhere, with its
    # light (Blender's transmission passes of a scene without glass), stays as it is, as ρ · 0,
    # and its light is not aligned (its layers hold the light as it is)
    lit: dict[str, bool] | None = None
    if form == "ratio":  # (a lobe's light alone, without the lobe, relights nothing)
        lit = {c: c in frame.buffers and holds_light(frame, c) for c in COMPONENTS}
    components: dict[str, list[float]] = {
        c: p.sigmas_of(c) for c in p.components if _shaded(p, lit, c)
    }
    aligned = (
        align_lights(
            lights, pyramid, position, view, components, gamma=p.gamma, ior=p.ior, mask=mask
        )
        if components
        else {}
    )
    with_transmission = p.transmission_weight > 0.0 if lit is None else lit["transmission"]
    specular = p.specular if lit is None or lit["specular"] else "none"
    roughness: float | np.ndarray = (
        p.roughness if p.roughness != "frame" else frame.need("roughness", "roughness='frame'")
    )

    def shade(directions: dict[str, Sequence[np.ndarray]] | None) -> Shading:
        return shading(
            normal,
            view,
            position,
            lights,
            directions,
            diffuse=p.diffuse,
            specular=specular,
            shininess=p.shininess,
            roughness=roughness,
            f0=p.f0,
            transmission=with_transmission,
            ior=p.ior,
        )

    directions: dict[str, Sequence[np.ndarray]] = {c: list(v) for c, v in aligned.items()}
    debug_normals = pyramid.full_list() if debug else []
    if form == "relight":
        _relight(frame, p, shade(directions).arrays())
        return aligned, None, debug_normals
    relit = _ratio(frame, p, shade(None), shade(directions), lights_power(lights))
    assert lit is not None
    dark = [c for c in p.components if c in frame.buffers and not lit[c]]
    if dark:  # their layers hold the lights as they are: a sequence keeps one set of layers
        own = _own_directions(frame.shape, lights, position)
        aligned.update({c: own for c in dark})
    return aligned, relit, debug_normals


def _own_directions(
    shape: tuple[int, int], lights: list[Light], position: np.ndarray | None
) -> list[np.ndarray]:
    """Each light's own direction at every pixel, (H, W, 3), read-only (a directional light's
    vector broadcast, a point light's field from ``position``)."""
    return [np.broadcast_to(light_direction(light, position), (*shape, 3)) for light in lights]


def lights_power(lights: list[Light]) -> float:
    """Σ of the lights' intensity × mean colour: the unit of the ratio form's ε."""
    return float(sum(light.intensity * float(np.mean(light.color)) for light in lights)) or 1.0


def _relight(frame: Frame, p: LightAlignmentParams, light: dict[str, np.ndarray]) -> None:
    """Deferred shading: ambient (× AO) + the lobes lit by the aligned lights."""
    mask = frame.mask
    shape = (*frame.shape, 3)
    albedo = frame_albedo(frame, p.albedo)
    amb = np.multiply(mask, np.float32(p.ambient), dtype=np.float32)
    if "ao" in frame.buffers:
        amb *= frame.buffers["ao"]
    specular = np.float32(1.0 if p.specular == "ggx" else p.specular_color)
    colors = {
        "ambient": albedo,
        "diffuse": albedo,
        "specular": np.full(3, specular, np.float32),
        "transmission": albedo * np.float32(p.transmission_weight),
    }
    lights = {"ambient": np.asarray(cv2.merge([amb, amb, amb])), **light}
    for lobe in LOBES:  # a lobe not relit (specular 'none', no transmission) is not in the beauty
        if lobe not in lights:
            for name in (lobe, f"{lobe}.light", f"{lobe}.color"):
                frame.buffers.pop(name, None)
    radiance, beauty = lobe_radiance(lights, {lobe: colors[lobe] for lobe in lights})
    for lobe, lit in lights.items():
        color = colors[lobe]
        if color.ndim != 3:  # a constant colour: stored as a read-only broadcast view
            color = np.broadcast_to(color, shape)
        frame.buffers[lobe] = radiance[lobe]
        frame.buffers[f"{lobe}.light"] = lit
        frame.buffers[f"{lobe}.color"] = color
    frame.buffers.pop("remainder", None)
    old = frame.buffers.get("beauty")
    if old is not None:  # the renderer's background stays
        cv2.copyTo(old, (mask <= 0).view(np.uint8), dst=beauty)
    frame.buffers["beauty"] = beauty


def _ratio(
    frame: Frame,
    p: LightAlignmentParams,
    original: Shading,
    aligned: Shading,
    power: float,
) -> tuple[Relit, list[str]]:
    """Each renderer lobe × (shade(aligned) + ε)/(shade(original) + ε), clamped to ratio_max:
    the relit lobes (with their lights) and beauty, and the lobes' names."""
    eps = cast(float, np.float32(p.ratio_floor * power))  # float32 on purpose, as the lobes
    lobes = [lobe for lobe in aligned.lobes if lobe in frame.buffers]
    if not lobes:
        frame.need("diffuse", "form 'ratio' needs a diffuse, specular or transmission lobe")
    beauty = frame.need("beauty", "form 'ratio' rebuilds the beauty")
    given = {lobe: (frame.buffers[lobe], frame.buffers.get(f"{lobe}.light")) for lobe in lobes}
    weights = frame.colorspace.weights if p.keep_lighting else None
    return ratio_relight(beauty, given, original, aligned, eps, p.ratio_max, weights), lobes


def _keep_lighting(frame: Frame, p: LightAlignmentParams, relit: Relit, lobes: list[str]) -> None:
    """The ratio form's result into the frame, with the lighting kept (``keep_lighting``: the
    relit lobes, their lights and the beauty by the gain that gives the lobes' sum the input's
    low-frequency luminance)."""
    out, new, new_light, before, after = relit
    if before is not None and after is not None:  # (keep_lighting)
        gain = kept_lighting_gain(frame, before, after, p.lighting_scale, "light_alignment")
        apply_gain(out, gain, [new[lobe] for lobe in lobes], list(new_light.values()))
    frame.buffers.update(new)
    frame.buffers.update({f"{lobe}.light": light for lobe, light in new_light.items()})
    frame.buffers["beauty"] = out
