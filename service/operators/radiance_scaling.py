"""``radiance_scaling``: Radiance Scaling (Vergne et al., TVCG 2011) in every rendering scenario
of §5, on the renderer's lobes or by deferred shading of the G-buffer."""

from __future__ import annotations

from typing import Any, ClassVar, Literal

import numpy as np
from pydantic import Field, field_validator

from gbuffer.frame import LOBES, Frame
from ops import checks
from ops import curvature as curv_ops
from ops import radiance_scaling as rs
from ops.color import luminance, luminance_of_sum
from ops.colorspace import LINEAR_REC709, ColorSpace, convert
from ops.lighting import apply_lighting_gain
from ops.pyramid.masked import masked_gaussians
from ops.pyramid.upsample import Upsampled
from ops.radiance_scaling import scale_lobes, white_level
from service.operators.base import Context, register
from service.operators.common import (
    Alpha,
    Gamma,
    LightsParams,
    WhiteLevel,
    frame_albedo,
    holds_light,
    kept_lighting_gain,
    statistic,
    user_image,
)
from service.operators.curvature import CurvatureParams, frame_curvature, mask_sources, scale_px

#: Albedo (luminance) below which a pixel's light is not beauty / albedo (scenario 'beauty').
MIN_ALBEDO = np.float32(0.02)

Scenario = Literal[
    "auto",
    "lobes",
    "beauty",
    "ao",
    "phong",
    "sub_lambert",
    "toon",
    "ashikhmin_shirley",
    "lit_sphere",
    "mirror",
    "refraction",
]


#: The parameter values of the paper's Eq. 2 and Eq. 4 as printed: δ̄ from each pixel's own
#: light and no lighting kept (``preset: "paper"``; the figures of earlier releases).
PAPER = {"gamma": 3.0, "light_scale": 0.0, "keep_lighting": False}


class RadianceScalingParams(LightsParams, CurvatureParams):
    """Radiance Scaling (Vergne et al. 2011) in every rendering scenario of §5."""

    PRESETS: ClassVar[dict[str, dict[str, Any]]] = {"default": {}, "paper": PAPER}

    scenario: Scenario = Field(
        "auto",
        description="lobes: scale the renderer's lobes (Eq. 4); beauty: the beauty as one lobe; "
        "ao: ambient occlusion × prefiltered environment (§5.3.1); phong / sub_lambert / toon / "
        "ashikhmin_shirley: deferred shading with `lights` (§5.1-5.2); lit_sphere: a matcap "
        "(§5.3.1); mirror / refraction: an environment map (§5.3.2); auto: lobes when the "
        "frame has them, else beauty",
    )
    alpha: Alpha = Field(0.5, description="scaling-invariant point α in (0, 1) (Eq. 2)")
    preset: Literal["default", "paper"] = Field(
        "default",
        description="default: enhance shape and keep the lighting (δ̄ from the light smoothed "
        "at `light_scale`, `keep_lighting`, γ = 1); paper: Eq. 2 and 4 as printed (γ = 3, δ̄ "
        "per pixel, no lighting kept); parameters given with it override it",
    )
    gamma: Gamma = Field(1.0, description="scaling magnitude γ ≥ 0 for every lobe (Eq. 2)")
    gamma_ambient: Gamma | None = Field(None, description="γ of the ambient lobe")
    gamma_diffuse: Gamma | None = Field(None, description="γ of the diffuse lobe")
    gamma_specular: Gamma | None = Field(None, description="γ of the specular lobe")
    gamma_transmission: Gamma | None = Field(None, description="γ of the transmission lobe")
    anisotropy: float = Field(
        0.0,
        **checks.ANISOTROPY.bounds,
        description="λ ∈ [−1, 1] of the anisotropic mapping κ(ℓ) (§4)",
    )
    white: WhiteLevel = Field(
        "auto",
        description="white level of δ̄ (lobes, beauty): a number pins it for sequences; auto = "
        "the `white_percentile` of the covered pixels",
    )
    white_percentile: float = Field(
        99.0, **checks.PERCENTILE.bounds, description="percentile of auto"
    )
    light_scale: float | None = Field(
        None,
        **checks.CURVATURE_SCALE.bounds,
        description="lobes, beauty: δ̄ from the light averaged over this σ, relative to the image "
        "height (at least a pixel), so Monte-Carlo noise does not drive σ (default: the "
        "curvature `scale`; 0: each pixel's own light, as the paper)",
    )
    keep_lighting: bool = Field(
        True,
        description="lobes, beauty: divide the scaled radiance by its low-frequency gain along "
        "the surfaces (at `lighting_scale`), so the mean luminance of every region stays the "
        "input's and only shape detail is added (false: Eq. 4 as printed)",
    )
    lighting_scale: float = Field(
        0.04,
        **checks.LIGHTING_SCALE.bounds,
        description="σ of the lighting kept by `keep_lighting`, relative to the image height",
    )
    lobes: list[str] | None = Field(
        None,
        min_length=1,  # ([] scaled every lobe, as leaving it out does)
        description="renderer lobes to scale (default: every lobe the frame has with light in "
        "it; all of them when none has)",
    )
    ambient: float = Field(0.1, **checks.AMBIENT.bounds, description="k_a of Phong")
    specular: float = Field(0.3, **checks.WEIGHT.bounds, description="k_s of Phong")
    shininess: float = Field(32.0, **checks.SHININESS.bounds, description="Phong exponent η")
    zeta: float = Field(
        0.5, **checks.FRACTION.bounds, description="sub-Lambertian exponent ζ (§5.1)"
    )
    toon_levels: int = Field(4, **checks.TOON_LEVELS.bounds, description="bands of toon shading")
    as_exponent: float = Field(100.0, **checks.EXPONENT.bounds, description="Ashikhmin-Shirley n")
    ior: float = Field(1.5, **checks.IOR.bounds, description="refraction index (refraction)")
    matcap: str | None = Field(None, description="lit sphere image (default: a clay sphere)")
    environment: str | None = Field(
        None, description="equirectangular environment (EXR/HDR/PNG; default: a simple sky)"
    )

    @field_validator("lobes")
    @classmethod
    def _lobes(cls, value: list[str] | None) -> list[str] | None:
        for lobe in value or []:
            if lobe not in LOBES:
                raise ValueError(f"unknown lobe {lobe!r}; lobes: {', '.join(LOBES)}")
        return value

    def gamma_of(self, lobe: str) -> float:
        specific = getattr(self, f"gamma_{lobe}", None)
        return self.gamma if specific is None else float(specific)


def _white(
    ctx: Context,
    p: RadianceScalingParams,
    key: str,
    light: np.ndarray,
    mask: np.ndarray,
    weights: tuple[float, float, float],
) -> float:
    return statistic(
        ctx,
        f"radiance_scaling.white.{key}",
        p.white,
        lambda: white_level(light, ctx.counted(mask), p.white_percentile, weights),
    )


def _scenario(frame: Frame, p: RadianceScalingParams) -> str:
    if p.scenario != "auto":
        return p.scenario
    return "lobes" if any(lobe in frame.buffers for lobe in LOBES) else "beauty"


def _light_sigma(frame: Frame, p: RadianceScalingParams) -> float:
    """σ in pixels of the lights' smoothing: ``light_scale`` (default: the curvature's), 0 for
    none."""
    scale = p.scale if p.light_scale is None else p.light_scale
    return scale_px(frame, scale) if scale > 0 else 0.0


def _smoothed_lights(frame: Frame, lights: list[np.ndarray], sigma: float) -> list[np.ndarray]:
    """The lights δ̄ is mapped from, as luminances (all δ̄ reads of them): averaged over the
    covered pixels at ``sigma`` (:func:`_light_sigma`; one coverage average for them all)."""
    ys = [x if x.ndim == 2 else luminance(x, frame.colorspace.weights) for x in lights]
    return masked_gaussians(ys, frame.mask, sigma)


def _lights(
    frame: Frame, p: RadianceScalingParams, lights: list[np.ndarray], ctx: Context
) -> list[np.ndarray]:
    """:func:`_smoothed_lights` of the frame's own arrays, which the run's memo keeps for the
    next run on the same lights and mask (:attr:`Context.memo`)."""
    sigma = _light_sigma(frame, p)
    params = (sigma, frame.colorspace.weights)
    arrays = (*lights, *mask_sources(frame))
    return ctx.memo.get("lights", arrays, params, lambda: _smoothed_lights(frame, lights, sigma))


def _lighting_gain(
    frame: Frame, p: RadianceScalingParams, scaled: np.ndarray, before: np.ndarray
) -> np.ndarray:
    """The factor per pixel (H, W) that gives ``scaled`` = Σ σ̄_j lobe_j the low-frequency
    luminance of ``before`` = Σ lobe_j along the surfaces, at ``lighting_scale``
    (:func:`service.operators.common.kept_lighting_gain`): exactly 1 where they are equal."""
    return kept_lighting_gain(frame, before, scaled, p.lighting_scale, "radiance_scaling")


def _scale_renderer_lobes(
    frame: Frame, p: RadianceScalingParams, kappa: Upsampled, ctx: Context
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Eq. 4 on the renderer's lobes; the beauty is rebuilt as Σ σ̄_j lobe_j + remainder (with
    the kept lighting, Σ σ̄_j lobe_j is corrected before the remainder is added)."""
    present = [lobe for lobe in LOBES if lobe in frame.buffers]
    # a lobe with no light in it (Blender's transmission passes of a scene without glass) stays
    # 0 when scaled: by default it is left as it is, neither scaled nor written
    lit = present if p.lobes else [lobe for lobe in present if holds_light(frame, lobe)]
    names = p.lobes or lit or present
    if not names:
        frame.need("diffuse", "scenario 'lobes' needs at least one radiance lobe")
    lobes = {n: frame.need(n, "a lobe to scale (parameter 'lobes')") for n in names}
    given = [frame.buffers.get(f"{n}.light", lobes[n]) for n in names]
    lights = dict(zip(names, _lights(frame, p, given, ctx), strict=True))
    mask = frame.mask > 0
    weights = frame.colorspace.weights
    white = {n: _white(ctx, p, n, lights[n], mask, weights) for n in names}
    # a dark lobe left out: its white level is measured all the same (the level a sequence pins
    # on its first frame serves the frames where the lobe has light)
    left_out = [] if p.lobes or not lit else [n for n in present if n not in lit]
    for n in left_out:
        _white(ctx, p, n, frame.buffers.get(f"{n}.light", frame.buffers[n]), mask, weights)
    remainder = frame.buffers.get("remainder")
    if remainder is not None:  # beauty minus every lobe: add back the lobes left unscaled
        for lobe in lit:
            if lobe not in lobes:
                remainder = remainder + frame.buffers[lobe]
    beauty = frame.buffers.get("beauty") if remainder is None else None
    scaled, sigmas = scale_lobes(
        lobes,
        lights,
        kappa,
        p.alpha,
        {n: p.gamma_of(n) for n in names},
        white,
        None if p.keep_lighting else remainder,
        mask=mask,
        beauty=None if p.keep_lighting else beauty,
        with_sigmas=ctx.debug_layers,
        weights=weights,
    )
    del lights  # frame-sized, and no longer needed by the kept lighting
    if ctx.debug_layers:  # a lobe left out is not scaled: σ̄ = 1, so a sequence keeps its layers
        unscaled = np.broadcast_to(np.float32(1.0), frame.shape)
        sigmas.update({n: unscaled for n in left_out})
    if not p.keep_lighting:
        return scaled, sigmas
    # (Σ lobe_j summed as the kernel does)
    before = luminance_of_sum(list(lobes.values()), weights)
    gain = _lighting_gain(frame, p, scaled, before)
    del before
    # where the operator changed nothing (κ = 0, so σ̄ = 1 for every lobe, and a lighting gain of
    # exactly 1), the beauty as it was, bit for bit: Σ lobe_j + rest only rounds back to it
    original = frame.buffers.get("beauty")
    unchanged = None if original is None else (original, kappa)
    if remainder is not None:
        apply_lighting_gain(scaled, gain, remainder, [], unchanged)
    else:  # + beauty − Σ lobe_j
        minus = [] if beauty is None else list(lobes.values())
        apply_lighting_gain(scaled, gain, beauty, minus, unchanged)
    return scaled, sigmas


def _scale_beauty(
    frame: Frame, p: RadianceScalingParams, kappa: Upsampled, ctx: Context
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The beauty as a single lobe; its light's luminance is Y(beauty) / Y(albedo) where the
    frame has an albedo (a ratio of luminances, the same in every working space, where a
    channel-by-channel beauty / albedo would depend on the primaries; glass, emitters and other
    pixels of albedo ~0 keep the beauty's as their light's, and do not count in the white
    level)."""
    beauty = frame.need("beauty", "scenario 'beauty'")
    counted = frame.mask > 0
    weights = frame.colorspace.weights
    light = luminance(beauty, weights=weights)
    if "albedo" in frame.buffers:
        y_albedo = luminance(frame.buffers["albedo"], weights=weights)
        has_albedo = y_albedo > MIN_ALBEDO
        np.divide(light, y_albedo, out=light, where=has_albedo)
        counted &= has_albedo
    (light,) = _smoothed_lights(frame, [light], _light_sigma(frame, p))
    white = _white(ctx, p, "beauty", light, counted, weights)
    scaled, sigmas = scale_lobes(
        {"beauty": beauty},
        {"beauty": light},
        kappa,
        p.alpha,
        p.gamma,
        white,
        with_sigmas=ctx.debug_layers,
        weights=weights,
    )
    if p.keep_lighting:
        scaled *= _lighting_gain(frame, p, scaled, beauty)[..., None]
    return scaled, sigmas


def _camera_to_world(frame: Frame) -> np.ndarray | None:
    if frame.camera is None or frame.camera.world_to_camera is None:
        return None
    return np.linalg.inv(frame.camera.world_to_camera)[:3, :3]


def _environment(p: RadianceScalingParams, ctx: Context, space: ColorSpace) -> np.ndarray:
    """The environment map in the frame's space (the built-in sky is linear Rec.709)."""
    if p.environment:
        return user_image(ctx, p.environment, "environment", space=space)
    return convert(rs.sky_environment(), LINEAR_REC709, space)


def _deferred(
    frame: Frame,
    p: RadianceScalingParams,
    curv: curv_ops.Curvature,
    scenario: str,
    ctx: Context,
) -> rs.Scaled:
    normal = frame.need("normal", f"scenario '{scenario}'")
    albedo = frame_albedo(frame, None)
    space = frame.colorspace
    common: dict[str, Any] = {"alpha": p.alpha, "gain": p.gain}
    if scenario in ("phong", "sub_lambert", "toon", "ashikhmin_shirley"):
        lit = (normal, frame.positions(), frame.view_vectors(), p.parsed_lights(), curv)
        common.update(albedo=albedo, lam=p.anisotropy)
    if scenario in ("phong", "sub_lambert", "toon"):
        return rs.phong(
            *lit,
            ambient=p.ambient,
            specular=p.specular,
            shininess=p.shininess,
            gamma_ambient=p.gamma_of("ambient"),
            gamma_diffuse=p.gamma_of("diffuse"),
            gamma_specular=p.gamma_of("specular"),
            zeta=p.zeta if scenario == "sub_lambert" else 1.0,
            toon_levels=p.toon_levels if scenario == "toon" else 0,
            **common,
        )
    if scenario == "ashikhmin_shirley":
        return rs.ashikhmin_shirley(
            *lit,
            exponent=p.as_exponent,
            gamma_diffuse=p.gamma_of("diffuse"),
            gamma_specular=p.gamma_of("specular"),
            **common,
        )
    if scenario == "ao":
        irradiance = None
        if p.environment:
            to_world = _camera_to_world(frame)
            n_world = normal if to_world is None else rs.rotate_directions(normal, to_world)
            irradiance = rs.sh_irradiance(_environment(p, ctx, space), n_world)
        return rs.precomputed_diffuse(
            normal,
            curv,
            ao=frame.need("ao", "scenario 'ao'"),
            irradiance=irradiance,
            albedo=albedo,
            gamma=p.gamma_of("diffuse"),
            weights=space.weights,
            **common,
        )
    if scenario == "lit_sphere":
        if p.matcap:
            sphere = user_image(ctx, p.matcap, "matcap", space=space)
        else:
            sphere = convert(rs.studio_matcap(), LINEAR_REC709, space)
        return rs.lit_sphere(
            normal, curv, sphere, gamma=p.gamma_of("specular"), weights=space.weights, **common
        )
    return rs.environment(
        normal,
        frame.view_vectors(),
        curv,
        _environment(p, ctx, space),
        mode=scenario,
        ior=p.ior,
        camera_to_world=_camera_to_world(frame),
        gamma=p.gamma_of("specular"),
        weights=space.weights,
        **common,
    )


@register(
    "radiance_scaling",
    summary="Radiance Scaling (Vergne et al. 2011): scale reflected light by curvature and "
    "reflectance, per lobe, in every scenario of §5",
    params=RadianceScalingParams,
    needs=("normal", "depth"),
    writes=("beauty", "curvature.H (debug)", "rs_sigma.<lobe>.X (debug)"),
)
def apply_radiance_scaling(frame: Frame, p: RadianceScalingParams, ctx: Context) -> None:
    curv = frame_curvature(frame, p, ctx)
    scenario = _scenario(frame, p)
    kappa = None
    if scenario in ("lobes", "beauty"):
        kappa = curv_ops.isotropic_field(curv, p.gain)
        if scenario == "lobes":
            beauty, sigmas = _scale_renderer_lobes(frame, p, kappa, ctx)
        else:
            beauty, sigmas = _scale_beauty(frame, p, kappa, ctx)
    else:
        scaled = _deferred(frame, p, curv, scenario, ctx)
        beauty, sigmas = scaled.beauty, scaled.sigmas
        frame.buffers.update(scaled.lobes)
        if "beauty" in frame.buffers:  # the renderer's background passes through
            covered = (frame.mask > 0)[..., None]
            beauty = np.where(covered, beauty, frame.buffers["beauty"])
    frame.buffers["beauty"] = beauty.astype(np.float32, copy=False)
    if ctx.debug_layers:
        h_map = curv_ops.isotropic(curv, p.gain) if kappa is None else np.asarray(kappa)
        frame.set_layer("curvature", {"H": h_map})
        for lobe, s in sigmas.items():
            frame.set_layer(f"rs_sigma.{lobe}", {"X": s})
