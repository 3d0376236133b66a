"""Lights, vector helpers, BRDF terms and the lobe shader of ops.shading."""

from __future__ import annotations

import math

import numpy as np
import pytest

from ops.color import luminance_of_sum
from ops.shading import (
    Light,
    MadeShading,
    ashikhmin_shirley,
    blinn_phong,
    dot,
    ggx,
    half_lambert,
    lambert,
    light_irradiance,
    light_vectors,
    lobe_radiance,
    normalize,
    parse_light,
    phong,
    ratio_relight,
    reflect,
    refract,
    shade_directions,
    shade_lobes,
    shading,
    transmission,
)

UP = np.array([0.0, 0.0, 1.0], np.float32)


def field(vectors: np.ndarray) -> np.ndarray:
    """(N, 3) vectors as an (1, N, 3) float32 field."""
    return np.asarray(vectors, np.float32).reshape(1, -1, 3)


def in_plane(angles_deg: np.ndarray) -> np.ndarray:
    """Unit vectors in the xz plane at the given angles from +z (positive towards +x)."""
    a = np.radians(angles_deg)
    return field(np.stack([np.sin(a), np.zeros_like(a), np.cos(a)], axis=1))


def hemisphere(n_samples: int = 20000) -> np.ndarray:
    """Uniform (Fibonacci) directions on the +z hemisphere, (N, 3)."""
    i = np.arange(n_samples) + 0.5
    z = 1.0 - i / n_samples
    phi = i * math.pi * (3.0 - math.sqrt(5.0))
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def sphere_normals(size: int = 64) -> np.ndarray:
    """Normals of a sphere seen orthographically from +z, 0 outside the disc."""
    c = (np.arange(size) + 0.5) / size * 2.0 - 1.0
    x, y = np.meshgrid(c, -c)
    z2 = 1.0 - x * x - y * y
    n = np.stack([x, y, np.sqrt(np.maximum(z2, 0.0))], axis=2)
    n[z2 <= 0] = 0.0
    return n.astype(np.float32)


# -- lights ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "kind", "vector", "color", "intensity"),
    [
        ("-1,1,1", "directional", (-1 / 3**0.5, 1 / 3**0.5, 1 / 3**0.5), (1, 1, 1), 1.0),
        ("dir:0,0,2", "directional", (0, 0, 1), (1, 1, 1), 1.0),
        ("directional:0,3,0*0.5", "directional", (0, 1, 0), (1, 1, 1), 0.5),
        ("point:0,2,1@1,0.9,0.8*4", "point", (0, 2, 1), (1, 0.9, 0.8), 4.0),
        ("  POINT : 1e-1, -2 , .5 @ 0,0,1 ", "point", (0.1, -2, 0.5), (0, 0, 1), 1.0),
        ("1,0,0@0.5,0.5,0.5", "directional", (1, 0, 0), (0.5, 0.5, 0.5), 1.0),
    ],
)
def test_parse_light(
    text: str,
    kind: str,
    vector: tuple[float, float, float],
    color: tuple[float, float, float],
    intensity: float,
) -> None:
    light = parse_light(text)
    assert light.kind == kind
    np.testing.assert_allclose(light.vector, vector, atol=1e-9)
    np.testing.assert_allclose(light.color, color, atol=1e-9)
    assert light.intensity == pytest.approx(intensity)


@pytest.mark.parametrize(
    "text",
    ["", "1,2", "1,2,3,4", "foo:1,2,3", "1,2,3@1,2", "0,0,0", "1,2,3*-1", "1,2,3@-1,0,0",
     "nan,0,1", "1;2;3", "point:1,2,3*", "dir:"],
)  # fmt: skip
def test_parse_light_rejects_bad_text(text: str) -> None:
    with pytest.raises(ValueError, match="light"):
        parse_light(text)


def test_light_validation() -> None:
    with pytest.raises(ValueError, match="kind"):
        Light("spot", (0.0, 0.0, 1.0))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="intensity"):
        Light("directional", (0.0, 0.0, 1.0), intensity=float("inf"))
    # a point light's position is kept as given (not normalised)
    assert Light("point", (0.0, 0.0, 5.0)).vector == (0.0, 0.0, 5.0)


def test_light_vectors_and_inverse_square_irradiance() -> None:
    pos = field([[0, 0, -2], [1, 0, -2]])
    point = Light("point", (0.0, 0.0, 0.0), color=(1.0, 0.5, 0.25), intensity=8.0)
    lv = light_vectors(point, pos)
    np.testing.assert_allclose(lv[0, 0], [0, 0, 1], atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(lv, axis=2), 1.0, atol=1e-6)
    e = light_irradiance(point, pos)
    np.testing.assert_allclose(e[0, 0], np.array([1.0, 0.5, 0.25]) * 8.0 / 4.0, rtol=1e-6)
    np.testing.assert_allclose(e[0, 1], np.array([1.0, 0.5, 0.25]) * 8.0 / 5.0, rtol=1e-6)
    sun = Light("directional", (0.0, 3.0, 4.0), intensity=2.0)
    np.testing.assert_allclose(light_vectors(sun, pos)[0, 1], [0, 0.6, 0.8], atol=1e-6)
    np.testing.assert_allclose(light_irradiance(sun, pos), [2.0, 2.0, 2.0])


# -- vector helpers ---------------------------------------------------------------------------


def test_dot_normalize_reflect_refract() -> None:
    rng = np.random.default_rng(1)
    a = rng.normal(size=(7, 5, 3)).astype(np.float32)
    b = rng.normal(size=(7, 5, 3)).astype(np.float32)
    np.testing.assert_allclose(dot(a, b), (a * b).sum(axis=2), rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(dot(a, UP), a[..., 2], atol=1e-6)
    u = normalize(a)
    np.testing.assert_allclose(np.linalg.norm(u, axis=2), 1.0, atol=1e-6)
    assert np.all(normalize(np.zeros((2, 2, 3), np.float32)) == 0.0)

    v = field([[1.0, 0.0, 1.0]]) / np.float32(math.sqrt(2.0))
    np.testing.assert_allclose(reflect(v, UP)[0, 0], [-(0.5**0.5), 0, 0.5**0.5], atol=1e-6)
    # ior 1: the eye ray goes straight on
    np.testing.assert_allclose(refract(v, UP, 1.0)[0, 0], -v[0, 0], atol=1e-6)
    # Snell: sin(theta_t) = sin(theta_i) / ior
    t = refract(v, UP, 1.5)[0, 0]
    assert np.linalg.norm(t) == pytest.approx(1.0, abs=1e-6)
    assert t[2] < 0.0  # into the surface
    assert math.hypot(t[0], t[1]) == pytest.approx(math.sin(math.pi / 4) / 1.5, abs=1e-6)
    # total internal reflection (leaving a dense medium at a grazing angle) gives 0
    grazing = field([[0.95, 0.0, math.sqrt(1 - 0.95**2)]])
    assert np.all(refract(grazing, UP, 1.0 / 1.5) == 0.0)
    with pytest.raises(ValueError, match="ior"):
        refract(v, UP, 0.0)


# -- BRDF terms -------------------------------------------------------------------------------


def test_lambert_is_clamped_cosine() -> None:
    angles = np.array([0.0, 30.0, 60.0, 89.0, 90.0, 120.0, 180.0])
    got = lambert(UP, in_plane(angles))[0]
    np.testing.assert_allclose(got, np.maximum(np.cos(np.radians(angles)), 0.0), atol=1e-6)


def test_half_lambert_forms() -> None:
    ls = in_plane(np.array([0.0, 90.0, 180.0]))
    np.testing.assert_allclose(half_lambert(UP, ls, "valve")[0], [1.0, 0.25, 0.0], atol=1e-6)
    np.testing.assert_allclose(half_lambert(UP, ls, "exaggerated")[0], [1.0, 0.5, 0.0], atol=1e-6)
    with pytest.raises(ValueError, match="form"):
        half_lambert(UP, ls, "quarter")  # type: ignore[arg-type]


@pytest.mark.parametrize("term", [blinn_phong, phong])
def test_specular_peaks_at_the_mirror_direction(term: object) -> None:
    view = in_plane(np.array([-35.0]))[0, 0]  # eye 35 deg to the left of the normal
    angles = np.linspace(-89.0, 89.0, 357)
    values = term(UP, in_plane(angles), view, 40.0)[0]  # type: ignore[operator]
    assert angles[int(np.argmax(values))] == pytest.approx(35.0, abs=0.5)
    assert values.max() == pytest.approx(1.0, abs=1e-4)
    assert np.all((values >= 0.0) & (values <= 1.0 + 1e-6))


def test_specular_is_zero_for_lights_below_the_horizon() -> None:
    below = in_plane(np.array([100.0, 150.0]))
    for values in (blinn_phong(UP, below, UP, 8.0), phong(UP, below, UP, 8.0)):
        assert np.all(values == 0.0)


def test_blinn_phong_value() -> None:
    light = in_plane(np.array([60.0]))
    # h is 30 deg from n
    assert blinn_phong(UP, light, UP, 4.0)[0, 0] == pytest.approx(math.cos(math.radians(30)) ** 4)
    with pytest.raises(ValueError, match="shininess"):
        blinn_phong(UP, light, UP, 0.0)


@pytest.mark.parametrize("roughness", [0.05, 0.3, 0.7, 1.0])
def test_ggx_is_energy_sane(roughness: float) -> None:
    rng = np.random.default_rng(2)
    n = normalize(rng.normal(size=(40, 40, 3)).astype(np.float32))
    lv = normalize(rng.normal(size=(40, 40, 3)).astype(np.float32))
    vv = normalize(rng.normal(size=(40, 40, 3)).astype(np.float32))
    values = ggx(n, lv, vv, roughness, 0.5)
    assert values.dtype == np.float32
    assert np.all(np.isfinite(values)) and np.all(values >= 0.0)
    assert np.all(values[dot(n, lv) <= 0] == 0.0)
    if roughness < 0.2:
        return  # too sharp a lobe for the quadrature below
    # directional albedo: (1/pi) * integral of pi f (n.l) over the hemisphere <= 1 (f0 = 1)
    ls = field(hemisphere())
    for view_deg in (0.0, 45.0, 80.0):
        v = in_plane(np.array([view_deg]))[0, 0]
        albedo = 2.0 * float(ggx(UP, ls, v, roughness, 1.0).mean())
        assert 0.3 < albedo <= 1.02, (roughness, view_deg, albedo)


def test_ggx_peaks_at_the_mirror_direction() -> None:
    view = in_plane(np.array([-40.0]))[0, 0]
    angles = np.linspace(-89.0, 89.0, 357)
    values = ggx(UP, in_plane(angles), view, 0.2, 0.04)[0]
    assert angles[int(np.argmax(values))] == pytest.approx(40.0, abs=2.0)
    with pytest.raises(ValueError, match="roughness"):
        ggx(UP, UP, UP, 0.0)


def test_ashikhmin_shirley() -> None:
    diff, spec = ashikhmin_shirley(UP, field([UP]), UP, exponent=50.0, rs=0.05)
    # normal incidence: 28/23 (1 - rs) (1 - (1/2)^5)^2 (n.l = n.v = 1)
    assert diff[0, 0] == pytest.approx(28 / 23 * 0.95 * (1 - 0.5**5) ** 2, rel=1e-5)
    # (e + 1)/8 * F(1) / (h.l max(n.l, n.v)) with h = n: F = rs
    assert spec[0, 0] == pytest.approx(51 / 8 * 0.05, rel=1e-5)
    rng = np.random.default_rng(3)
    ls = normalize(rng.normal(size=(30, 30, 3)).astype(np.float32))
    vv = normalize(rng.normal(size=(30, 30, 3)).astype(np.float32))
    d, s = ashikhmin_shirley(UP, ls, vv, exponent=200.0, rs=0.5)
    assert np.all(np.isfinite(d)) and np.all(np.isfinite(s))
    assert np.all(d >= 0) and np.all(s >= 0)
    assert np.all(d[(dot(ls, UP) <= 0) | (dot(vv, UP) <= 0)] == 0.0)
    # the specular lobe peaks at the mirror direction
    view = in_plane(np.array([-30.0]))[0, 0]
    angles = np.linspace(-89.0, 89.0, 357)
    _, spec_scan = ashikhmin_shirley(UP, in_plane(angles), view, exponent=300.0)
    assert angles[int(np.argmax(spec_scan[0]))] == pytest.approx(30.0, abs=1.0)


def test_transmission_lights_from_behind_only() -> None:
    view = in_plane(np.array([0.0]))[0, 0]
    behind = field([[0.0, 0.0, -1.0]])
    front = field([[0.0, 0.0, 1.0]])
    assert transmission(UP, behind, view, ior=1.5)[0, 0] == pytest.approx(1.0, abs=1e-6)
    assert transmission(UP, front, view, ior=1.5)[0, 0] == 0.0
    # oblique view: the lobe follows the refracted (bent towards -n), not the straight, ray
    v = in_plane(np.array([50.0]))[0, 0]
    t = refract(field([v]), UP, 1.5)[0, 0]
    straight = -v
    assert transmission(UP, field([t]), v, ior=1.5)[0, 0] == pytest.approx(1.0, abs=1e-5)
    assert transmission(UP, field([straight]), v, ior=1.5)[0, 0] < 0.9


# -- shade_lobes -----------------------------------------------------------------------------


@pytest.mark.parametrize("model", ["lambert", "blinn_phong", "phong", "ggx", "ashikhmin_shirley"])
def test_shade_lobes_structure(model: str) -> None:
    n = sphere_normals()
    pos = n.copy()
    pos[..., 2] -= 3.0
    lights = [Light("directional", (-1.0, 1.0, 1.0)), Light("point", (2.0, 0.0, 1.0), (1, 0.5, 0))]
    out = shade_lobes(
        n, pos, UP, (0.8, 0.6, 0.4), lights, ao=np.full(n.shape[:2], 0.5), model=model
    )
    mask = np.linalg.norm(n, axis=2) > 0.5
    for lobe in ("ambient", "diffuse", "specular"):
        for key in (lobe, f"{lobe}.light", f"{lobe}.color"):
            arr = out[key]
            assert arr.shape == (*n.shape[:2], 3) and arr.dtype == np.float32, key
            assert np.all(np.isfinite(arr)) and np.all(arr >= 0.0), key
            assert np.all(arr[~mask] == 0.0), key
        np.testing.assert_allclose(out[lobe], out[f"{lobe}.color"] * out[f"{lobe}.light"], 1e-6)
    np.testing.assert_allclose(out["ambient.light"][mask], 0.05, rtol=1e-6)  # 0.1 ambient x AO
    np.testing.assert_allclose(
        out["diffuse.color"][mask], np.broadcast_to([0.8, 0.6, 0.4], (mask.sum(), 3)), rtol=1e-6
    )
    np.testing.assert_allclose(out["specular.color"][mask], 0.3, rtol=1e-6)
    assert out["diffuse.light"][mask].max() > 0.5
    if model == "lambert":
        assert np.all(out["specular"] == 0.0)
    else:
        assert out["specular.light"].max() > 0.1


def test_shade_lobes_sums_lights_and_lights_from_the_left_brighten_the_left() -> None:
    n = sphere_normals()
    pos = np.zeros_like(n)
    left = Light("directional", (-1.0, 0.0, 0.3))
    right = Light("directional", (1.0, 0.2, 0.5), color=(0.2, 0.4, 1.0), intensity=0.7)
    a = shade_lobes(n, pos, UP, 0.5, [left])
    b = shade_lobes(n, pos, UP, 0.5, [right])
    both = shade_lobes(n, pos, UP, 0.5, [left, right])
    for key in ("diffuse.light", "specular.light"):
        np.testing.assert_allclose(both[key], a[key] + b[key], rtol=1e-5, atol=1e-6)
    lum = a["diffuse"].mean(axis=2)
    half = n.shape[1] // 2
    assert lum[:, :half].mean() > 3.0 * lum[:, half:].mean()
    # a coloured light: diffuse.light carries its colour, the albedo stays in diffuse.color
    rgb = b["diffuse.light"][b["diffuse.light"][..., 2] > 0.1]
    np.testing.assert_allclose(rgb[:, 0] / rgb[:, 2], 0.2, rtol=1e-5)


def test_shade_lobes_point_light_matches_the_analytic_value() -> None:
    n = np.zeros((1, 2, 3), np.float32)
    n[..., 2] = 1.0
    pos = np.array([[[0.0, 0.0, -2.0], [1.0, 0.0, -2.0]]], np.float32)
    light = Light("point", (0.0, 0.0, 0.0), intensity=4.0)
    out = shade_lobes(n, pos, UP, 1.0, [light], ambient=0.0, model="lambert")
    assert out["diffuse.light"][0, 0, 0] == pytest.approx(1.0, rel=1e-5)  # 4 / 2^2 * cos 0
    d = math.sqrt(5.0)
    assert out["diffuse.light"][0, 1, 0] == pytest.approx(4.0 / 5.0 * (2.0 / d), rel=1e-5)


def test_shade_lobes_transmission_and_validation() -> None:
    n = sphere_normals(32)
    behind = Light("directional", (0.0, 0.0, -1.0))
    out = shade_lobes(n, np.zeros_like(n), UP, 0.5, [behind], transmission_weight=1.0)
    assert out["transmission.light"].max() > 0.9
    assert np.all(out["diffuse"] == 0.0)
    mask = np.linalg.norm(n, axis=2) > 0.5
    assert np.all(out["transmission"][~mask] == 0.0)
    with pytest.raises(ValueError, match="model"):
        shade_lobes(n, n, UP, 0.5, [behind], model="cel")
    with pytest.raises(ValueError, match="ambient"):
        shade_lobes(n, n, UP, 0.5, [behind], ambient=-1.0)
    with pytest.raises(ValueError, match="albedo"):
        shade_lobes(n, n, UP, (1.0, 2.0), [behind])
    with pytest.raises(ValueError, match="normal"):
        shade_lobes(n[..., :2], n, UP, 0.5, [behind])


def test_lobe_radiance_is_light_times_colour_and_its_sum() -> None:
    rng = np.random.default_rng(7)
    lights = {
        n: rng.random((9, 11, 3), dtype=np.float32) for n in ("ambient", "diffuse", "specular")
    }
    albedo = rng.random((9, 11, 3), dtype=np.float32)
    colors = {
        "ambient": albedo,
        "diffuse": albedo,
        "specular": np.array([0.5, 0.5, 0.5], np.float32),
    }
    radiance, beauty = lobe_radiance(lights, colors)
    for n in lights:
        np.testing.assert_allclose(radiance[n], lights[n] * colors[n], rtol=1e-6)
    np.testing.assert_allclose(beauty, sum(lights[n] * colors[n] for n in lights), rtol=1e-5)
    with pytest.raises(ValueError, match="colors"):
        lobe_radiance(lights, {**colors, "specular": np.ones((2, 2, 3), np.float32)})


def test_ratio_relight_scales_each_lobe_by_the_clamped_ratio() -> None:
    rng = np.random.default_rng(3)
    shape = (7, 13, 3)
    diffuse, specular, light = (rng.random(shape, dtype=np.float32) for _ in range(3))
    remainder = rng.random(shape, dtype=np.float32)
    beauty = diffuse + specular + remainder
    original = {n: rng.random(shape, dtype=np.float32) for n in ("diffuse", "specular")}
    aligned = {n: 3 * rng.random(shape, dtype=np.float32) for n in ("diffuse", "specular")}
    kept = {n: a.copy() for n, a in original.items()}
    lobes = {"diffuse": (diffuse, light), "specular": (specular, None)}
    out, new, new_light, y0, y1 = ratio_relight(beauty, lobes, original, aligned, 0.05, 4.0)
    assert y0 is None and y1 is None  # (no weights: no luminances)
    ratio = {n: np.clip((aligned[n] + 0.05) / (original[n] + 0.05), 0, 4.0) for n in aligned}
    np.testing.assert_allclose(new["diffuse"], diffuse * ratio["diffuse"], rtol=1e-6)
    np.testing.assert_allclose(new["specular"], specular * ratio["specular"], rtol=1e-6)
    np.testing.assert_allclose(new_light["diffuse"], light * ratio["diffuse"], rtol=1e-6)
    assert set(new_light) == {"diffuse"}
    np.testing.assert_allclose(out, remainder + new["diffuse"] + new["specular"], atol=1e-5)
    for n in original:  # the inputs are left as they were
        np.testing.assert_array_equal(original[n], kept[n])


def _unit_field(rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    v = rng.standard_normal((*shape, 3)).astype(np.float32)
    return (v / np.linalg.norm(v, axis=-1, keepdims=True)).astype(np.float32)


LIGHTS_2 = [parse_light("-0.4,0.6,0.7"), parse_light("0.6,0.2,0.5*0.35")]


@pytest.mark.parametrize(
    "models",
    [{}, {"diffuse": "half_lambert", "specular": "none"}, {"transmission": True, "shininess": 7.5}],
)
def test_a_shading_made_strip_by_strip_is_shade_directions(models: dict[str, object]) -> None:
    """Directional lights: ``shading`` makes the lobes on demand; any strip of them is
    ``shade_directions``' rows bit for bit, constant and per-pixel light directions alike."""
    rng = np.random.default_rng(5)
    shape = (37, 29)
    normal = _unit_field(rng, shape)
    normal[:4] = 0.0  # background rows
    view = _unit_field(rng, shape)
    view[..., 2] = np.abs(view[..., 2])
    dirs = {"specular": [_unit_field(rng, shape) for _ in LIGHTS_2]}
    whole = shade_directions(normal, view, None, LIGHTS_2, dirs, **models)  # type: ignore[arg-type]
    lazy = shading(normal, view, None, LIGHTS_2, dirs, **models)  # type: ignore[arg-type]
    assert not isinstance(lazy, MadeShading) and lazy.lobes == list(whole)
    for r0, r1 in ((0, 37), (3, 4), (5, 22), (30, 37)):
        rows = lazy.rows(r0, r1)
        for lobe, arr in whole.items():
            np.testing.assert_array_equal(rows[lobe], arr[r0:r1].reshape(r1 - r0, -1))
    point = [parse_light("point:0,0,2")]
    position = np.zeros((*shape, 3), np.float32)
    assert isinstance(shading(normal, view, position, point), MadeShading)  # made at once


def test_ratio_relight_from_shadings_made_in_its_pass_is_the_same() -> None:
    """The ratio pass making both shadings strip by strip gives the result of the shadings
    made first, bit for bit, and the luminances of the lobes' sums before and after are
    ``luminance_of_sum``'s."""
    rng = np.random.default_rng(11)
    shape = (53, 31)
    normal = _unit_field(rng, shape)
    normal[:, :3] = 0.0
    view = _unit_field(rng, shape)
    dirs = {c: [_unit_field(rng, shape) for _ in LIGHTS_2] for c in ("diffuse", "specular")}
    diffuse, specular, light, rest = (rng.random((*shape, 3), dtype=np.float32) for _ in range(4))
    beauty = diffuse + specular + rest
    lobes = {"diffuse": (diffuse, light), "specular": (specular, None)}
    weights = (0.25, 0.6, 0.15)
    lazy, made = (
        ratio_relight(
            beauty,
            lobes,
            shade(normal, view, None, LIGHTS_2),
            shade(normal, view, None, LIGHTS_2, dirs),
            0.05,
            2.0,
            weights,
        )
        for shade in (shading, shade_directions)  # (the second gives arrays)
    )
    np.testing.assert_array_equal(lazy.beauty, made.beauty)
    for lobe in lobes:
        np.testing.assert_array_equal(lazy.lobes[lobe], made.lobes[lobe])
    np.testing.assert_array_equal(lazy.lights["diffuse"], made.lights["diffuse"])
    after = luminance_of_sum([made.lobes["diffuse"], made.lobes["specular"]], weights)
    for relit in (lazy, made):
        assert relit.y_before is not None and relit.y_after is not None
        before = luminance_of_sum([diffuse, specular], weights)
        np.testing.assert_array_equal(relit.y_before, before)
        np.testing.assert_array_equal(relit.y_after, after)
    with pytest.raises(ValueError, match="original"):
        small = shading(normal[1:], view[1:], None, LIGHTS_2)
        ratio_relight(beauty, lobes, small, made.lobes, 0.05, 2.0)
    with pytest.raises(ValueError, match=r"aligned\['specular'\]"):
        wrong = {"diffuse": diffuse, "specular": specular[:, 1:]}
        ratio_relight(beauty, lobes, made.lobes, wrong, 0.05, 2.0)
