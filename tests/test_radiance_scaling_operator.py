"""The ``radiance_scaling`` operator in every scenario, through ``service.pipeline.run``.

On two real G-buffers: the committed Blender Cycles render (tests/fixtures/blender, read with
gbuffer.read and its camera.json) and an OSMesa render of a shared mesh (../shared/models), and
on small analytic frames for the parameter plumbing and the errors.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

import gbuffer
from gbuffer.errors import FrameError
from gbuffer.frame import LOBES, Frame
from ops import radiance_scaling as rs
from ops.color import luminance
from ops.curvature import DEFAULT_SCALE, Curvature, isotropic, principal_curvatures
from ops.lighting import apply_lighting_gain, luminance_gain, weighed_gain
from ops.pyramid.masked import masked_gaussian, masked_gaussians
from ops.pyramid.upsample import Upsampled
from ops.radiance_scaling import reflectance_delta, sigma
from ops.shading import parse_light
from ops.unsharp import surface_blurs
from service import pipeline
from service.registry import Context, PipelineError
from tests import analytic

BLENDER = Path(__file__).parent / "fixtures" / "blender"
MODELS = Path(__file__).resolve().parents[2] / "shared" / "models"
WIDTH, HEIGHT = 160, 120
REC709 = np.array([0.2126, 0.7152, 0.0722], np.float32)

#: scenario -> the lobes it writes a σ layer for (None: the renderer lobes the frame has)
SIGMA_LOBES: dict[str, tuple[str, ...] | None] = {
    "lobes": None,
    "beauty": ("beauty",),
    "ao": ("diffuse",),
    "phong": ("ambient", "diffuse", "specular"),
    "sub_lambert": ("ambient", "diffuse", "specular"),
    "toon": ("ambient", "diffuse", "specular"),
    "ashikhmin_shirley": ("diffuse", "specular"),
    "lit_sphere": ("specular",),
    "mirror": ("specular",),
    "refraction": ("specular",),
}
#: scenarios that keep the renderer's shading
POST_PROCESS = ("lobes", "beauty")


@pytest.fixture(scope="module")
def blender_frame() -> Frame:
    exr = BLENDER / "cycles_multilayer.exr"
    if not exr.is_file():
        pytest.skip(f"{exr} is absent (tests/fixtures/blender/README.md)")
    return gbuffer.read(exr, camera=BLENDER / "camera.json")


@pytest.fixture(scope="module")
def mesh_frame() -> Frame:
    path = MODELS / "spot.obj"
    if not path.is_file():
        pytest.skip(f"{path} is absent (the shared test meshes are not checked out)")
    from gbuffer.render import auto_camera, load_mesh, render

    mesh = load_mesh(path)
    mesh.merge_vertices(merge_tex=True, merge_norm=True)  # as analysis.compare.frame_from_mesh
    cam = auto_camera(mesh, width=WIDTH, height=HEIGHT)
    return render(mesh, WIDTH, HEIGHT, camera=cam)  # with SSAO, for the "ao" scenario


FRAMES = ["blender", pytest.param("mesh", marks=pytest.mark.models)]


def get_frame(request: pytest.FixtureRequest, name: str) -> Frame:
    frame: Frame = request.getfixturevalue(f"{name}_frame")
    return frame


def rs_run(
    frame: Frame, *, debug: bool = False, context: Context | None = None, **params: Any
) -> Frame:
    step = [{"op": "radiance_scaling", "params": params}]
    return pipeline.run(frame, step, debug_layers=debug, context=context)


def curvature_of(frame: Frame) -> Curvature:
    """The curvature at the operators' default scale, floored at a pixel as they floor it."""
    scale = max(DEFAULT_SCALE, 1.0 / frame.image_height)
    return principal_curvatures(
        frame.buffers["normal"],
        frame.buffers["depth"],
        frame.mask,
        scale=scale,
        image_height=frame.image_height,
    )


def lum(rgb: np.ndarray) -> np.ndarray:
    return np.asarray(rgb, np.float32) @ REC709


def background(frame: Frame) -> np.ndarray:
    return ~np.isfinite(frame.buffers["depth"])


# -- every scenario on real renders -------------------------------------------------------------


@pytest.mark.parametrize("scenario", list(SIGMA_LOBES))
@pytest.mark.parametrize("which", FRAMES)
def test_every_scenario_on_a_real_render(
    request: pytest.FixtureRequest, which: str, scenario: str
) -> None:
    frame = get_frame(request, which)
    beauty_in = frame.buffers["beauty"].copy()
    # Eq. 2 as printed (σ = 1 where κ = 0): the default also keeps the lighting (tested below)
    out = rs_run(frame, debug=True, scenario=scenario, preset="paper", gamma=3.0)
    ref = rs_run(frame, scenario=scenario, preset="paper", gamma=0.0)  # unscaled
    # the input frame is left as it was
    np.testing.assert_array_equal(frame.buffers["beauty"], beauty_in)
    assert not any(k.startswith(("rs_sigma.", "curvature.")) for k in frame.outputs)

    b, b0 = out.buffers["beauty"], ref.buffers["beauty"]
    assert b.dtype == np.float32 and b.shape == (HEIGHT, WIDTH, 3)
    assert np.isfinite(b).all()
    kappa = out.outputs["curvature.H"]
    assert kappa.shape == (HEIGHT, WIDTH) and np.abs(kappa).max() <= 1.0
    # where the surface is curved (and lit) the scaling changes the picture...
    curved = (np.abs(kappa) > 0.2) & (lum(b0) > 1e-3)
    assert curved.sum() > 300
    change = np.abs(b - b0)[curved].max(axis=1) / lum(b0)[curved]
    assert np.mean(change > 1e-3) > 0.9
    # ...and where κ = 0 (background, depth jumps, the Blender ground plane) it does not
    flat = kappa == 0
    assert flat.sum() > 1000
    np.testing.assert_allclose(b[flat], b0[flat], rtol=1e-6, atol=1e-6)
    bg = background(frame)
    assert bg.sum() > 1000
    # the renderer's background passes through, whatever the scenario
    np.testing.assert_allclose(b[bg], beauty_in[bg], rtol=1e-6, atol=1e-6)

    # debug layers: κ and the σ of each lobe, σ = 1 where κ = 0; none without debug_layers
    lobes = SIGMA_LOBES[scenario] or tuple(lobe for lobe in LOBES if lobe in frame.buffers)
    written = {k for k in out.outputs if k.startswith("rs_sigma.")}
    assert written == {f"rs_sigma.{lobe}.X" for lobe in lobes}
    for name in written:
        s = out.outputs[name]
        assert s.dtype == np.float32 and s.shape == (HEIGHT, WIDTH), name
        assert np.isfinite(s).all() and (s > 0).all(), name
        assert (s[flat] == 1.0).all(), name
        assert np.abs(s - 1.0).max() > 0.1, name
    assert not any(k.startswith("rs_sigma.") or k == "curvature.H" for k in ref.outputs)


def test_lobes_with_gamma_zero_reproduce_the_blender_beauty(blender_frame: Frame) -> None:
    """beauty' = Σ σ̄_j lobe_j + remainder with σ̄ ≡ 1 is the input beauty."""
    out = rs_run(blender_frame, scenario="lobes", preset="paper", gamma=0.0)
    np.testing.assert_allclose(
        out.buffers["beauty"], blender_frame.buffers["beauty"], rtol=1e-6, atol=1e-6
    )


def test_lobes_rebuild_the_beauty_from_each_lobe_and_its_light(blender_frame: Frame) -> None:
    """Eq. 4 on Cycles' passes: σ̄_j from δ̄_j = lum(light_j) / white_j (the lobe's light without
    its colour, DiffDir + DiffInd), each lobe with its own γ; the remainder passes unchanged."""
    f = blender_frame
    ctx = Context(debug_layers=True)
    out = rs_run(
        f, context=ctx, scenario="lobes", preset="paper", alpha=0.4, gamma=3.0, gamma_specular=1.5
    )
    kappa = out.outputs["curvature.H"]
    expect = f.buffers["remainder"].copy()
    for lobe, g in (("diffuse", 3.0), ("specular", 1.5), ("transmission", 3.0)):
        white = ctx.measured[f"radiance_scaling.white.{lobe}"]
        s = sigma(kappa, reflectance_delta(f.buffers[f"{lobe}.light"], white), 0.4, g)
        np.testing.assert_allclose(out.outputs[f"rs_sigma.{lobe}.X"], s, rtol=1e-5, err_msg=lobe)
        expect += s[..., None] * f.buffers[lobe]
    np.testing.assert_allclose(out.buffers["beauty"], expect, rtol=1e-5, atol=1e-5)
    # a pinned white level (a sequence) is used instead of measuring it
    pinned = Context(debug_layers=True, pinned={"radiance_scaling.white.diffuse": 0.5})
    out2 = rs_run(f, context=pinned, scenario="lobes", preset="paper", alpha=0.4, gamma=3.0)
    s = sigma(kappa, reflectance_delta(f.buffers["diffuse.light"], 0.5), 0.4, 3.0)
    np.testing.assert_allclose(out2.outputs["rs_sigma.diffuse.X"], s, rtol=1e-5)
    assert "radiance_scaling.white.diffuse" not in pinned.measured


def blurred_luminance(rgb: np.ndarray, mask: np.ndarray, sigma_px: float) -> np.ndarray:
    return masked_gaussian(lum(rgb), mask, sigma_px)


def test_default_adds_detail_and_keeps_the_lighting(blender_frame: Frame) -> None:
    """The default keeps what the eye reads as lighting (the luminance smoothed over 4 % of the
    image height) and changes the picture where the surface is curved; Eq. 4 as printed
    (preset paper) relights the objects."""
    f = blender_frame
    covered = f.mask > 0.5
    ctx = Context(debug_layers=True)
    out = rs_run(f, context=ctx)
    paper = rs_run(f, preset="paper")
    b0, b1, bp = f.buffers["beauty"], out.buffers["beauty"], paper.buffers["beauty"]
    assert np.isfinite(b1).all() and (b1 >= 0).all()
    sigma_px = 0.04 * f.image_height
    lf0, lf1, lfp = (blurred_luminance(b, covered, sigma_px)[covered] for b in (b0, b1, bp))
    drift = np.abs(lf1 / lf0 - 1.0)
    assert np.percentile(drift, 95) < 0.03
    assert np.percentile(np.abs(lfp / lf0 - 1.0), 95) > 3 * np.percentile(drift, 95)
    kappa = out.outputs["curvature.H"]
    curved = (np.abs(kappa) > 0.2) & (lum(b0) > 1e-3)
    change = np.abs(lum(b1) - lum(b0))[curved] / lum(b0)[curved]
    assert np.median(change) > 0.01


def test_delta_is_mapped_from_the_smoothed_light(blender_frame: Frame) -> None:
    """δ̄ = lum(light averaged at light_scale) / white: noise does not drive σ."""
    f = blender_frame
    ctx = Context(debug_layers=True)
    out = rs_run(f, context=ctx, keep_lighting=False, light_scale=0.02, lobes=["diffuse"])
    light = masked_gaussian(f.buffers["diffuse.light"], f.mask, 0.02 * f.image_height)
    white = ctx.measured["radiance_scaling.white.diffuse"]
    assert white == pytest.approx(float(np.percentile(lum(light)[f.mask > 0], 99)), rel=1e-4)
    s = sigma(out.outputs["curvature.H"], reflectance_delta(light, white), 0.5, 1.0)
    np.testing.assert_allclose(out.outputs["rs_sigma.diffuse.X"], s, rtol=1e-5, atol=1e-6)


def test_presets_fill_in_what_a_step_does_not_give() -> None:
    from service.registry import get

    op = get("radiance_scaling")
    paper = op.parse({"preset": "paper"})
    assert (paper.gamma, paper.light_scale, paper.keep_lighting) == (3.0, 0.0, False)
    mine = op.parse({"preset": "paper", "gamma": 1.5})
    assert (mine.gamma, mine.keep_lighting) == (1.5, False)
    default = op.parse({})
    assert (default.gamma, default.light_scale, default.keep_lighting) == (1.0, None, True)
    with pytest.raises(PipelineError, match="preset"):
        op.parse({"preset": "nope"})


@pytest.mark.parametrize("scenario", ["lobes", "phong"])
@pytest.mark.parametrize("which", FRAMES)
def test_gamma_per_lobe(request: pytest.FixtureRequest, which: str, scenario: str) -> None:
    f = get_frame(request, which)
    out = rs_run(f, debug=True, scenario=scenario, gamma=3.0, gamma_specular=0.0)
    assert (out.outputs["rs_sigma.specular.X"] == 1.0).all()
    assert np.abs(out.outputs["rs_sigma.diffuse.X"] - 1.0).max() > 0.1


@pytest.mark.parametrize(
    "which",
    ["blender", pytest.param("mesh", marks=pytest.mark.models)],
)
def test_lobes_left_out_stay_in_the_beauty(request: pytest.FixtureRequest, which: str) -> None:
    f = get_frame(request, which)
    only = rs_run(f, debug=True, scenario="lobes", preset="paper", gamma=3.0, lobes=["diffuse"])
    s = only.outputs["rs_sigma.diffuse.X"]
    rest = f.buffers["beauty"] - f.buffers["diffuse"]
    np.testing.assert_allclose(
        only.buffers["beauty"], rest + s[..., None] * f.buffers["diffuse"], rtol=1e-5, atol=1e-5
    )


def test_lobe_selection_scales_only_the_named_lobes(blender_frame: Frame) -> None:
    only = rs_run(blender_frame, debug=True, scenario="lobes", gamma=3.0, lobes=["diffuse"])
    assert {k for k in only.outputs if k.startswith("rs_sigma.")} == {"rs_sigma.diffuse.X"}
    both = rs_run(blender_frame, debug=True, scenario="lobes", gamma=3.0)
    np.testing.assert_array_equal(
        only.outputs["rs_sigma.diffuse.X"], both.outputs["rs_sigma.diffuse.X"]
    )


def test_a_lobe_without_light_is_left_as_it_is(blender_frame: Frame) -> None:
    # Blender writes transmission passes of a scene without glass: zeros. By default such a lobe
    # is not scaled (σ̄ · 0 is 0): the same beauty as a frame without it, the very arrays given
    # back; its σ̄ is 1 (with debug layers, every frame of a sequence has the same layers)
    dark, without = blender_frame.copy(), blender_frame.copy()
    beauty = blender_frame.buffers["beauty"] - blender_frame.buffers["transmission"]
    zero = np.zeros_like(beauty)
    dark.buffers.update({"beauty": beauty, "transmission": zero, "transmission.light": zero + 0})
    without.buffers["beauty"] = beauty
    for name in ("transmission", "transmission.light", "transmission.color"):
        del without.buffers[name]
    out, ref = rs_run(dark, debug=True), rs_run(without, debug=True)
    np.testing.assert_array_equal(out.buffers["beauty"], ref.buffers["beauty"])
    for name in ("transmission", "transmission.light"):
        assert out.buffers[name] is dark.buffers[name]
    lit = rs_run(blender_frame, debug=True)
    sigma_layers = {k for k in out.outputs if k.startswith("rs_sigma.")}
    assert sigma_layers == {k for k in lit.outputs if k.startswith("rs_sigma.")}
    assert sigma_layers == {f"rs_sigma.{lobe}.X" for lobe in LOBES if lobe != "ambient"}
    assert np.all(np.asarray(out.outputs["rs_sigma.transmission.X"]) == 1.0)
    for lobe in ("diffuse", "specular"):
        name = f"rs_sigma.{lobe}.X"
        np.testing.assert_array_equal(out.outputs[name], ref.outputs[name])
    named = rs_run(dark, debug=True, lobes=["diffuse", "transmission"])  # (asked for: scaled)
    assert "rs_sigma.transmission.X" in named.outputs
    # its white level is measured all the same: a sequence whose glass comes into view after
    # the first frame scales it with the level pinned on the first
    first = Context()
    rs_run(dark, context=first)
    assert "radiance_scaling.white.transmission" in first.measured
    later = Context(pinned=dict(first.measured))
    rs_run(blender_frame, context=later)
    assert later.measured == {}


def test_auto_scenario(blender_frame: Frame) -> None:
    f = blender_frame
    auto = rs_run(f, gamma=2.0)
    lobes = rs_run(f, scenario="lobes", gamma=2.0)
    np.testing.assert_array_equal(auto.buffers["beauty"], lobes.buffers["beauty"])
    bare = Frame(
        buffers={k: v for k, v in f.buffers.items() if k.split(".")[0] not in LOBES},
        camera=f.camera,
    )
    auto = rs_run(bare, gamma=2.0)
    beauty = rs_run(bare, scenario="beauty", gamma=2.0)
    np.testing.assert_array_equal(auto.buffers["beauty"], beauty.buffers["beauty"])
    assert not np.array_equal(auto.buffers["beauty"], lobes.buffers["beauty"])


@pytest.mark.parametrize("mode", ["mirror", "refraction"])
def test_environment_scenarios_look_up_in_world_space(blender_frame: Frame, mode: str) -> None:
    """The map is looked up along camera_to_world of the reflected / refracted view."""
    f = blender_frame
    out = rs_run(f, scenario=mode, gamma=0.0, ior=1.3)
    w2c = f.camera.world_to_camera if f.camera is not None else None
    assert w2c is not None
    args = (f.buffers["normal"], f.view_vectors(), curvature_of(f), rs.sky_environment())
    c2w = np.linalg.inv(w2c)[:3, :3]
    world = rs.environment(*args, mode=mode, ior=1.3, camera_to_world=c2w, gamma=0.0)
    covered = f.mask > 0  # the background keeps the renderer's
    np.testing.assert_allclose(
        out.buffers["beauty"][covered], world.beauty[covered], rtol=1e-5, atol=1e-6
    )
    camera = rs.environment(*args, mode=mode, ior=1.3, gamma=0.0)
    assert np.abs(camera.beauty - world.beauty).max() > 0.1


# -- parameters reach ops/ -----------------------------------------------------------------------


def analytic_frame(with_lobes: bool = False) -> Frame:
    s = analytic.cylinder(48, length=1.4)  # anisotropic: κ(ℓ) depends on the light (λ ≠ 0)
    shade = np.clip(s.normal @ np.array([-0.4, 0.5, 0.77], np.float32), 0, 1)
    buffers = {
        "normal": s.normal,
        "depth": s.depth,
        "beauty": np.repeat(shade[..., None], 3, axis=2).astype(np.float32),
        "ao": (0.5 + 0.5 * s.normal[..., 2]).astype(np.float32),
    }
    if with_lobes:
        buffers["diffuse"] = buffers["beauty"].copy()
    return Frame(buffers=buffers)


PARAMS = {
    "alpha": 0.35,
    "gamma": 2.0,
    "gamma_ambient": 0.5,
    "gamma_specular": 4.0,
    "gain": 0.2,
    "anisotropy": 0.5,
    "lights": ["-0.3,0.5,0.8", "point:1,1,-8*30"],
    "ambient": 0.2,
    "specular": 0.6,
    "shininess": 12.0,
    "zeta": 0.3,
    "toon_levels": 3,
    "as_exponent": 40.0,
    "ior": 1.3,
}


def direct(frame: Frame, scenario: str) -> rs.Scaled:
    """What the scenario must compute, called on ops/ directly with PARAMS."""
    p = PARAMS
    curv = curvature_of(frame)
    n, view, pos = frame.buffers["normal"], frame.view_vectors(), frame.positions()
    lights = [parse_light(t) for t in p["lights"]]
    albedo = np.array([0.8, 0.8, 0.8], np.float32)  # the frame has none
    common = {"alpha": p["alpha"], "gain": p["gain"]}
    if scenario in ("phong", "sub_lambert", "toon"):
        return rs.phong(
            n, pos, view, lights, curv, albedo=albedo, ambient=p["ambient"],
            specular=p["specular"], shininess=p["shininess"], gamma_ambient=p["gamma_ambient"],
            gamma_diffuse=p["gamma"], gamma_specular=p["gamma_specular"], lam=p["anisotropy"],
            zeta=p["zeta"] if scenario == "sub_lambert" else 1.0,
            toon_levels=p["toon_levels"] if scenario == "toon" else 0, **common,
        )  # fmt: skip
    if scenario == "ashikhmin_shirley":
        return rs.ashikhmin_shirley(
            n, pos, view, lights, curv, albedo=albedo, exponent=p["as_exponent"],
            gamma_diffuse=p["gamma"], gamma_specular=p["gamma_specular"], lam=p["anisotropy"],
            **common,
        )  # fmt: skip
    if scenario == "ao":
        ao = frame.buffers["ao"]
        return rs.precomputed_diffuse(n, curv, ao=ao, albedo=albedo, gamma=p["gamma"], **common)
    if scenario == "lit_sphere":
        return rs.lit_sphere(n, curv, rs.studio_matcap(), gamma=p["gamma_specular"], **common)
    return rs.environment(
        n, view, curv, rs.sky_environment(), mode=scenario, ior=p["ior"],
        gamma=p["gamma_specular"], **common,
    )  # fmt: skip


@pytest.mark.parametrize("scenario", [s for s in SIGMA_LOBES if s not in POST_PROCESS])
def test_deferred_scenarios_pass_their_parameters_to_ops(scenario: str) -> None:
    frame = analytic_frame()
    out = rs_run(frame, debug=True, scenario=scenario, **PARAMS)
    expect = direct(frame, scenario)
    np.testing.assert_allclose(out.buffers["beauty"], expect.beauty, rtol=1e-5, atol=1e-6)
    for lobe, s in expect.sigmas.items():
        np.testing.assert_allclose(out.outputs[f"rs_sigma.{lobe}.X"], s, rtol=1e-5, atol=1e-6)
    # the curvature layer is κ at the operator's gain
    np.testing.assert_allclose(
        out.outputs["curvature.H"], isotropic(curvature_of(frame), 0.2), atol=1e-6
    )


def test_beauty_scenario_uses_beauty_over_albedo_luminance_as_its_light() -> None:
    """δ̄ = Y(beauty) / Y(albedo) / white: a ratio of luminances (the same in any primaries)."""
    frame = analytic_frame()
    frame.buffers["albedo"] = np.broadcast_to(
        np.array([0.5, 0.25, 0.5], np.float32), frame.buffers["beauty"].shape
    ).copy()
    light = frame.buffers["beauty"] / luminance(frame.buffers["albedo"])[..., None]
    params = {"alpha": 0.4, "gamma": 2.0, "white": 1.5, "gain": 0.2}
    out = rs_run(frame, debug=True, scenario="beauty", preset="paper", **params)
    kappa = out.outputs["curvature.H"]
    s = sigma(kappa, reflectance_delta(light, 1.5), 0.4, 2.0)
    np.testing.assert_allclose(out.outputs["rs_sigma.beauty.X"], s, rtol=1e-5)
    np.testing.assert_allclose(
        out.buffers["beauty"], frame.buffers["beauty"] * s[..., None], rtol=1e-5, atol=1e-6
    )


# -- errors --------------------------------------------------------------------------------------


def test_beauty_white_level_ignores_pixels_without_albedo(blender_frame: Frame) -> None:
    """Glass and emitters (albedo ~0) must not set the white level: beauty / albedo explodes
    there (thousands on the fixture) and would leave δ ‹ α everywhere else."""
    beauty_ctx, lobes_ctx = Context(), Context()
    rs_run(blender_frame, scenario="beauty", context=beauty_ctx)
    rs_run(blender_frame, scenario="lobes", context=lobes_ctx)
    white = beauty_ctx.measured["radiance_scaling.white.beauty"]
    diffuse = lobes_ctx.measured["radiance_scaling.white.diffuse"]
    assert diffuse / 2 < white < diffuse * 4


@pytest.mark.parametrize(
    ("params", "word"),
    [
        ({"alpha": 0.0}, "alpha"),
        ({"alpha": 1.5}, "alpha"),
        ({"gamma": -1.0}, "gamma"),
        ({"gamma_specular": -1.0}, "gamma_specular"),
        ({"lobes": ["nope"]}, "lobes"),
        ({"scenario": "nope"}, "scenario"),
        ({"toon_levels": 1}, "toon_levels"),
        ({"zeta": 1.5}, "zeta"),
        ({"lights": ["up"]}, "lights"),
        ({"gamma_diffuse": 1.0, "gama": 2.0}, "gama"),
    ],
)
def test_bad_parameters_are_refused_by_name(params: dict[str, Any], word: str) -> None:
    with pytest.raises(PipelineError, match=word):
        rs_run(analytic_frame(with_lobes=True), **params)


def test_missing_buffers_are_named() -> None:
    with pytest.raises(FrameError, match="lobes"):  # no renderer lobe at all
        rs_run(analytic_frame(), scenario="lobes")
    with pytest.raises(FrameError, match=r"'specular'.*parameter 'lobes'"):
        rs_run(analytic_frame(with_lobes=True), scenario="lobes", lobes=["specular"])
    bare = analytic_frame()
    del bare.buffers["ao"]
    with pytest.raises(FrameError, match=r"'ao'.*scenario 'ao'"):
        rs_run(bare, scenario="ao")


def test_weighed_gain_is_its_formula() -> None:
    # 1 + w (gain − 1), w = min(1, |ΔY| / (0.05 |Y|)): exactly 1 where Y is unchanged, the full
    # gain from a 5 % change, NaN stays NaN, Y = 0 weighs by |ΔY|
    rng = np.random.default_rng(5)
    y0 = rng.uniform(0.1, 1.0, (70, 90)).astype(np.float32)
    y1 = y0 * rng.uniform(0.9, 1.1, y0.shape).astype(np.float32)
    y1[::4] = y0[::4]
    y0[1, :3], y1[1, :3] = 0.0, [0.0, 0.5, 2.0]
    y1[2, 0] = np.nan
    gain = rng.uniform(0.5, 2.0, y0.shape).astype(np.float32)
    w = np.abs(y1 - y0)
    np.divide(w, np.float32(0.05) * np.abs(y0), out=w, where=y0 != 0)
    w = np.minimum(w, np.float32(1.0))
    w[y1 == y0] = 0.0
    out = weighed_gain(gain, y0, y1, 0.05)
    np.testing.assert_allclose(out, 1.0 + w * (gain - 1.0), rtol=1e-6)
    assert (out[::4] == 1.0).all() and np.isnan(out[2, 0])
    assert out[1, 0] == 1.0 and out[1, 1] == 1.0 + 0.5 * (gain[1, 1] - 1.0)
    assert out[1, 2] == gain[1, 2]


@pytest.mark.parametrize("bool_mask", [False, True])
def test_luminance_gain_is_its_formula(bool_mask: bool) -> None:
    # LF(y0) / LF(y1) on one surface pyramid, 1 where either is darker than 1e-6 at that scale
    # (two boxes in front of a wall, each dark in one luminance: the smoothing keeps them
    # apart) or off the surface (a background strip)
    rng = np.random.default_rng(8)
    h, w = 120, 160
    depth = np.full((h, w), 5.0, np.float32)
    depth[20:60, 30:80] = 3.0
    depth[70:110, 90:150] = 2.0
    normal = np.zeros((h, w, 3), np.float32)
    normal[..., 2] = 1.0
    mask = np.ones((h, w), np.float32)
    mask[:, :12] = 0.0
    y0 = rng.uniform(0.2, 1.0, (h, w)).astype(np.float32)
    y1 = y0 * rng.uniform(0.5, 1.5, (h, w)).astype(np.float32)
    y1[20:60, 30:80] = 0.0
    y0[70:110, 90:150] = 0.0
    m = mask > 0 if bool_mask else mask
    kw: dict[str, Any] = {"sigma_scene": 0.05, "pixel_size": depth / np.float32(200.0)}
    lf0, lf1 = surface_blurs([y0, y1], depth, normal, m, **kw)
    ok = (lf0 > np.float32(1e-6)) & (lf1 > np.float32(1e-6)) & (mask > 0)
    expect = np.divide(lf0, lf1, out=np.ones_like(lf0), where=ok)
    got = luminance_gain(y0, y1, depth, normal, m, **kw)
    np.testing.assert_array_equal(got, expect)
    assert (got[:, :12] == 1.0).all() and not np.allclose(got[:, 12:25], 1.0)
    assert (got[25:55, 35:75] == 1.0).all() and (got[75:105, 95:145] == 1.0).all()
    # weighed in the same pass: weighed_gain's numbers (some pixels left unchanged)
    y1[5:15, 40:60] = y0[5:15, 40:60]
    weighed = luminance_gain(y0, y1, depth, normal, m, **kw, full_change=0.05)
    plain = luminance_gain(y0, y1, depth, normal, m, **kw)
    assert np.array_equal(weighed, weighed_gain(plain, y0, y1, 0.05))
    assert (weighed[5:15, 40:60] == 1.0).all() and not np.array_equal(weighed, plain)


def test_apply_lighting_gain_is_numpys_in_order() -> None:
    # out · gain + plus − Σ minus, each operation rounded as NumPy rounds it (bit for bit),
    # with and without what is added back; a strided array is refused
    rng = np.random.default_rng(9)
    shape = (70, 90, 3)
    scaled, plus, *minus = (rng.uniform(0.0, 2.0, shape).astype(np.float32) for _ in range(5))
    gain = rng.uniform(0.5, 1.5, shape[:2]).astype(np.float32)
    for add, less in ((plus, minus), (plus, []), (None, [])):
        want = scaled * gain[..., None]
        if add is not None:
            want += add
        for x in less:
            want -= x
        got = scaled.copy()
        apply_lighting_gain(got, gain, add, less)
        assert np.array_equal(got, want)
    # where the gain is exactly 1 and κ is 0, the original instead (κ on a grid 2x smaller,
    # or at full resolution)
    gain[10:40, 20:60] = 1.0
    original = rng.uniform(0.0, 2.0, shape).astype(np.float32)
    for grid in (np.zeros((35, 45), np.float32), np.zeros(shape[:2], np.float32)):
        grid[grid.shape[0] // 4 :, : grid.shape[1] // 3] = 0.5  # κ ≠ 0 there
        kappa = Upsampled(grid, shape[:2])
        alone = (gain == 1.0) & (np.asarray(kappa) == 0.0)
        assert 0 < alone.sum() < (gain == 1.0).sum()
        want = scaled * gain[..., None] + plus
        want[alone] = original[alone]
        got = scaled.copy()
        apply_lighting_gain(got, gain, plus, [], (original, kappa))
        assert np.array_equal(got, want)
    with pytest.raises(ValueError, match="C-contiguous"):
        apply_lighting_gain(np.zeros((90, 70, 3), np.float32).transpose(1, 0, 2), gain, None, [])


@pytest.mark.parametrize("channels", [(), (3,)])
def test_masked_gaussian_matches_the_normalised_convolution(channels: tuple[int, ...]) -> None:
    # G * (v c) / G * c on the covered pixels (non-finite values count as 0), the rest kept;
    # fully covered: a plain Gaussian (to rounding)
    rng = np.random.default_rng(6)
    values = rng.uniform(0.0, 1.0, (60, 80, *channels)).astype(np.float32)
    values[5, 5] = np.nan
    values[9, 9] = np.inf
    mask = np.ones((60, 80), np.float32)
    mask[:, 50:] = 0.0
    for m in (mask, np.ones_like(mask)):
        c = (m > 0).astype(np.float32)
        c_v = c[..., None] if channels else c
        num = cv2.GaussianBlur(np.nan_to_num(values, posinf=0.0) * c_v, (0, 0), 3.0)
        den = cv2.GaussianBlur(c, (0, 0), 3.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            want = np.where(c_v > 0, num / (den[..., None] if channels else den), values)
        out = masked_gaussian(values, m, 3.0)
        np.testing.assert_allclose(out, want, rtol=1e-6, atol=1e-7)


def test_masked_gaussians_share_the_coverage_and_match_one_by_one() -> None:
    """Several planes (a lobe's light each) over one mask: each bit for bit what
    :func:`masked_gaussian` gives it alone, and what the release before the compiled passes
    gave, planes and RGB, with holes and non-finite values, float and bool masks."""
    rng = np.random.default_rng(7)
    planes = [rng.uniform(0.0, 2.0, (61, 83)).astype(np.float32) for _ in range(2)]
    planes.append(rng.uniform(0.0, 1.0, (61, 83, 3)).astype(np.float32))
    planes[1][7, 7] = np.nan
    mask = (rng.random((61, 83)) > 0.2).astype(np.float32)
    mask[:, :9] = 0.0  # a band far from any covered pixel: values kept, too little weight
    for m in (mask, mask > 0, np.ones_like(mask), np.ones(mask.shape, bool)):
        for sigma_px in (2.5, 0.0):
            together = masked_gaussians(planes, m, sigma_px)
            assert len(together) == len(planes)
            for plane, got in zip(planes, together, strict=True):
                assert np.array_equal(got, masked_gaussian(plane, m, sigma_px), equal_nan=True)
                want = _masked_gaussian_alone(plane, m, sigma_px)
                assert np.array_equal(got, want, equal_nan=True)


def _masked_gaussian_alone(values: np.ndarray, mask: np.ndarray, sigma_px: float) -> np.ndarray:
    """The masked Gaussian of one plane as the release before the shared coverage average
    computed it (its own G_σ * c), for the bit-for-bit comparison."""
    src = np.ascontiguousarray(values, dtype=np.float32)
    if sigma_px <= 0.0:
        return src
    covered = mask > 0
    weighted = np.where(np.isfinite(src), src, np.float32(0.0))
    if covered.all():
        return np.asarray(cv2.GaussianBlur(weighted, (0, 0), sigma_px), np.float32)
    weighted = cv2.copyTo(weighted, covered.view(np.uint8))
    out = np.asarray(cv2.GaussianBlur(weighted, (0, 0), sigma_px), np.float32)
    den = np.asarray(cv2.GaussianBlur(covered.astype(np.float32), (0, 0), sigma_px), np.float32)
    keep = ~covered | (den <= 1e-4)
    np.divide(1.0, den, out=den, where=~keep)
    out *= den[..., None] if src.ndim == 3 else den
    return np.asarray(cv2.copyTo(src, keep.view(np.uint8), out), np.float32)
