"""Congruence score (LLA Eq. 2) and the 21-direction sweep, on analytic G-buffers."""

from __future__ import annotations

import numpy as np
import pytest

from ops.congruence import CongruenceResult, congruence, shape_flow
from ops.directions import comparison_directions
from tests import analytic


def sphere(size: int = 128, radius: float = 0.8) -> tuple[np.ndarray, np.ndarray]:
    """Orthographic analytic sphere (tests.analytic): (normal, depth), depth +inf outside."""
    s = analytic.sphere(size, radius)
    return s.normal, s.depth


def lambert(normal: np.ndarray, light) -> np.ndarray:
    light = np.asarray(light, np.float32)
    light = light / np.linalg.norm(light)
    return np.clip(normal @ light, 0.0, None).astype(np.float32)


def bumpy_depth(h: int = 96, w: int = 128) -> np.ndarray:
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    return (5.0 + 0.3 * np.sin(2 * np.pi * 2 * x / w) * np.sin(2 * np.pi * 1.5 * y / h)).astype(
        np.float32
    )


# -- the score ---------------------------------------------------------------------------------


def test_shading_that_follows_depth_scores_near_one() -> None:
    depth = bumpy_depth()
    # the depth itself, and a monotone function of it (a point-light-like falloff)
    assert congruence(depth, depth).score > 0.95
    assert congruence(1.0 / depth**2, depth).score > 0.9
    # a frontally lit sphere: shading varies radially like the depth
    normal, depth_s = sphere()
    assert congruence(lambert(normal, (0, 0, 1)), depth_s).score > 0.9


def test_shading_across_the_shape_flow_scores_low() -> None:
    depth = bumpy_depth()
    y, x = np.mgrid[0 : depth.shape[0], 0 : depth.shape[1]].astype(np.float32)
    # stripes whose gradient is perpendicular to the depth gradient of a plane tilted along x
    plane = (5.0 + 0.01 * x).astype(np.float32)
    stripes = (0.5 + 0.5 * np.sin(2 * np.pi * y / 12.0)).astype(np.float32)
    # integrate over more than a stripe period so that the shading strength is steady
    assert congruence(stripes, plane, integration_scale=0.06).score < 0.1
    along = (0.5 + 0.5 * np.sin(2 * np.pi * x / 12.0)).astype(np.float32)
    assert congruence(along, plane, integration_scale=0.06).score > 0.9


def test_with_normals_planes_carry_no_weight() -> None:
    """The normals' shape flow is 0 on a plane (LLA §7: flat surfaces should not count), so what
    a slanted floor shows (cast shadows, noise) does not move the score; the log depth's flow
    gives the same floor most of the weight."""
    floor = analytic.plane(128, tilt_y_deg=60.0, distance=30.0)
    ball = analytic.sphere(128, 0.25)
    on_ball = ball.mask
    normal = np.where(on_ball[..., None], ball.normal, floor.normal).astype(np.float32)
    depth = np.where(on_ball, ball.depth, floor.depth).astype(np.float32)
    lit = lambert(normal, (0.1, 0.3, 1.0))
    y, x = np.mgrid[0:128, 0:128].astype(np.float32)
    shadows = (0.55 + 0.45 * np.sin(2 * np.pi * (x + 0.4 * y) / 23.0)).astype(np.float32)
    striped = np.where(on_ball, lit, lit * shadows).astype(np.float32)
    by_normals = [congruence(img, depth, normal=normal).score for img in (lit, striped)]
    by_depth = [congruence(img, depth).score for img in (lit, striped)]
    assert by_normals[0] > 0.5
    assert by_normals[1] == pytest.approx(by_normals[0], abs=0.02)
    assert abs(by_depth[1] - by_depth[0]) > 0.1
    res = congruence(lit, depth, normal=normal)
    weight = res.shape_strength * res.weight
    assert weight[~on_ball].sum() < 0.01 * weight.sum()


def test_normals_shape_flow_follows_the_surface() -> None:
    normal, depth = sphere()
    assert congruence(lambert(normal, (0, 0, 1)), depth, normal=normal).score > 0.85
    cyl = analytic.cylinder(128)
    across = lambert(cyl.normal, (0.3, 0.0, 1.0))
    assert congruence(across, cyl.depth, normal=cyl.normal).score > 0.8
    with pytest.raises(ValueError, match="normal must be"):
        congruence(depth, depth, normal=normal[:-1])


def test_one_firefly_does_not_change_the_score() -> None:
    """A sun glint thousands of times brighter than the rest sets no noise floor."""
    normal, depth = sphere()
    img = lambert(normal, (0.3, 0.4, 1.0))
    ref = congruence(img, depth, normal=normal).score
    glint = img.copy()
    glint[64, 64] = 5000.0
    assert congruence(glint, depth, normal=normal).score == pytest.approx(ref, abs=0.05)


def test_constant_image_scores_zero() -> None:
    _, depth = sphere()
    res = congruence(np.full((*depth.shape, 3), 0.7, np.float32), depth)
    assert res.score == 0.0
    assert np.all(res.score_map == 0.0)


def test_score_invariant_to_brightness_and_depth_units() -> None:
    normal, depth = sphere()
    img = np.repeat(lambert(normal, (0.6, 0.3, 0.74))[..., None], 3, axis=2)
    ref = congruence(img, depth).score
    assert 0.2 < ref < 0.99
    for k in (10.0, 0.1, 1e-3):
        assert congruence(img * np.float32(k), depth).score == pytest.approx(ref, abs=1e-3)
    # depth in other units (log depth: invariant)
    assert congruence(img, depth * np.float32(100.0)).score == pytest.approx(ref, abs=1e-3)


def test_a_shared_shading_scale_keeps_extra_contrast() -> None:
    """With the reference's scale, more contrast never lowers the score (the clamp of Eq. 2)
    and less contrast lowers it; each image on its own scale sees no difference at all."""
    normal, depth = sphere()
    shading = lambert(normal, (0.3, 0.4, 1.0))
    ref = congruence(shading, depth)
    assert ref.shading_norm > 0
    same = congruence(shading, depth, shading_norm=ref.shading_norm)
    assert same.score == pytest.approx(ref.score, abs=1e-9)
    stronger = congruence(3.0 * shading, depth, shading_norm=ref.shading_norm)
    weaker = congruence(0.3 * shading, depth, shading_norm=ref.shading_norm)
    assert stronger.score >= ref.score - 1e-9
    assert weaker.score < ref.score - 0.05
    assert congruence(0.3 * shading, depth).score == pytest.approx(ref.score, abs=1e-6)
    with pytest.raises(ValueError, match="shading_norm"):
        congruence(shading, depth, shading_norm=0.0)


@pytest.mark.parametrize(("size", "integration"), [(513, 0.01), (512, 0.02), (97, 0.05)])
def test_sizes_that_do_not_divide_the_analysis_levels(size: int, integration: float) -> None:
    normal, depth = sphere(size)
    res = congruence(lambert(normal, (0.2, 0.3, 1.0)), depth, integration_scale=integration)
    assert 0.5 < res.score <= 1.0
    assert res.score_map.shape == (size, size)


def test_background_does_not_bleed_into_the_score() -> None:
    normal, depth = sphere()
    img = lambert(normal, (0.5, 0.5, 0.7))
    inside = np.isfinite(depth)
    bright_bg = np.where(inside, img, np.float32(50.0)).astype(np.float32)
    a = congruence(img, depth)
    b = congruence(bright_bg, depth)
    assert b.score == pytest.approx(a.score, abs=1e-4)
    assert np.all(a.score_map[~inside] == 0.0)
    assert np.all(a.weight[~inside] == 0.0)
    # non-positive depth is background too
    neg = np.where(inside, depth, np.float32(-1.0)).astype(np.float32)
    assert congruence(bright_bg, neg).score == pytest.approx(a.score, abs=1e-4)
    # an explicit mask restricts the scored pixels further
    half = inside & (np.arange(depth.shape[1])[None, :] < depth.shape[1] // 2)
    c = congruence(img, depth, half)
    assert np.all(c.weight[~half] == 0.0)
    assert c.score != pytest.approx(a.score, abs=1e-3)


def test_depth_discontinuities_are_not_scored() -> None:
    # two overlapping spheres: where the front one hides the back one, the depth jumps
    scene = analytic.two_spheres(128)
    seg = scene.segment
    res = congruence(lambert(scene.normal, (0, 0, 1)), scene.depth)
    jump = np.zeros_like(scene.mask)
    jump[:, 1:] |= (seg[:, 1:] != seg[:, :-1]) & (seg[:, 1:] >= 0) & (seg[:, :-1] >= 0)
    jump[:, :-1] |= jump[:, 1:].copy()
    assert jump.sum() > 20
    assert np.all(res.weight[jump] == 0.0)
    assert res.weight[scene.interior(0.08)].min() == 1.0
    assert 0.0 < res.score <= 1.0
    # with an absurd jump threshold the contour would be scored
    loose = congruence(lambert(scene.normal, (0, 0, 1)), scene.depth, depth_jump=100.0)
    assert loose.weight[jump].max() > 0.0


def test_score_decreases_when_the_light_goes_behind() -> None:
    normal, depth = sphere()
    dirs = comparison_directions()
    scores = [congruence(lambert(normal, d), depth).score for d in dirs]
    assert all(0.0 <= s <= 1.0 for s in scores)
    assert scores[0] > 0.9  # frontal
    assert scores[0] > scores[5] and scores[0] > scores[20]  # 150° behind the object


def test_score_is_resolution_independent() -> None:
    small = sphere(96)
    big = sphere(480)  # takes the downsampled path (gradient and integration levels)
    light = (0.6, 0.3, 0.74)
    r_small = congruence(lambert(small[0], light), small[1])
    r_big = congruence(lambert(big[0], light), big[1])
    assert r_big.analysis_shape[0] < 480
    assert r_big.score_map.shape == (480, 480)
    assert r_big.score == pytest.approx(r_small.score, abs=0.05)


# -- flows and maps -----------------------------------------------------------------------------


def _flow_at_center(flow: np.ndarray) -> np.ndarray:
    h, w = flow.shape[:2]
    return np.abs(flow[h // 4 : 3 * h // 4, w // 4 : 3 * w // 4].reshape(-1, 2)).mean(axis=0)


def test_flows_are_gradient_directions_in_camera_convention() -> None:
    """Convention: the flow is the dominant eigenvector = the gradient direction (across the
    stripes), x right, y up."""
    h, w = 96, 96
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    plane_x = (5.0 + 0.02 * x).astype(np.float32)
    vertical_stripes = np.sin(2 * np.pi * x / 16.0).astype(np.float32)  # vary along x
    res = congruence(vertical_stripes, plane_x)
    np.testing.assert_allclose(_flow_at_center(res.shading_flow), [1.0, 0.0], atol=0.02)
    np.testing.assert_allclose(_flow_at_center(res.shape_flow), [1.0, 0.0], atol=0.02)

    plane_y = (5.0 + 0.02 * y).astype(np.float32)
    horizontal_stripes = np.sin(2 * np.pi * y / 16.0).astype(np.float32)
    res = congruence(horizontal_stripes, plane_y)
    np.testing.assert_allclose(_flow_at_center(res.shading_flow), [0.0, 1.0], atol=0.02)
    np.testing.assert_allclose(_flow_at_center(res.shape_flow), [0.0, 1.0], atol=0.02)

    # f = sin(x - row): gradient (1, -1) in (x, row) = (1, 1) in camera (x, y up)
    diagonal = np.sin(2 * np.pi * (x - y) / 16.0).astype(np.float32)
    res = congruence(diagonal, plane_x)
    v = res.shading_flow[h // 2, w // 2]
    assert abs(v[0] * v[1]) == pytest.approx(0.5, abs=0.02)
    assert v[0] * v[1] > 0  # same signs: along (1, 1), not (1, -1)
    # and that orientation is 45° from the shape flow (along x): |v_c·v_s| = cos 45°
    assert res.score_map[h // 2, w // 2] == pytest.approx(np.cos(np.pi / 4), abs=0.05)


def test_maps_are_consistent_with_eq2() -> None:
    normal, depth = sphere()
    res = congruence(lambert(normal, (0.3, -0.6, 0.74)), depth)
    assert isinstance(res, CongruenceResult)
    assert res.analysis_shape == depth.shape  # small image: no resampling
    for m in (res.score_map, res.shading_strength, res.shape_strength, res.weight):
        assert m.shape == depth.shape and m.dtype == np.float32
        assert m.min() >= 0.0 and m.max() <= 1.0
    for f in (res.shading_flow, res.shape_flow):
        assert f.shape == (*depth.shape, 2) and f.dtype == np.float32
        norm = np.linalg.norm(f, axis=2)
        assert np.all((np.abs(norm - 1.0) < 1e-3) | (norm == 0.0))
    vdot = np.abs((res.shading_flow * res.shape_flow).sum(axis=2))
    expected = (1.0 - np.clip(res.shape_strength - res.shading_strength, 0, 1)) * vdot
    np.testing.assert_allclose(res.score_map, expected, atol=2e-3)
    w = res.shape_strength * res.weight
    assert res.score == pytest.approx(float((w * res.score_map).sum() / w.sum()), abs=1e-3)


# -- validation ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"gradient_scale": 0.0}, "gradient_scale"),
        ({"gradient_scale": 0.5}, "gradient_scale"),
        ({"integration_scale": -1.0}, "integration_scale"),
        ({"percentile": 0.0}, "percentile"),
        ({"percentile": 101.0}, "percentile"),
        ({"depth_jump": 0.0}, "depth_jump"),
        ({"image_height": 0}, "image_height"),
    ],
)
def test_bad_parameters_raise(kwargs: dict, match: str) -> None:
    depth = bumpy_depth()
    with pytest.raises(ValueError, match=match):
        congruence(depth, depth, **kwargs)


def test_bad_inputs_raise() -> None:
    depth = bumpy_depth()
    with pytest.raises(ValueError, match="image"):
        congruence(depth[:-1], depth)
    with pytest.raises(ValueError, match="image"):
        congruence(np.zeros((*depth.shape, 4), np.float32), depth)
    with pytest.raises(ValueError, match="depth"):
        congruence(depth, depth[None])
    with pytest.raises(ValueError, match="mask"):
        congruence(depth, depth, np.ones((3, 3), bool))
    bad = depth.copy()
    bad[5, 5] = np.nan
    with pytest.raises(ValueError, match="image contains NaN"):
        congruence(bad, depth)
    with pytest.raises(ValueError, match="depth contains NaN"):
        congruence(depth, bad)


def _results_equal(a: CongruenceResult, b: CongruenceResult) -> bool:
    maps = ("score_map", "shading_flow", "shape_flow", "shading_strength", "shape_strength")
    return (a.score, a.shading_norm, a.analysis_shape) == (
        b.score,
        b.shading_norm,
        b.analysis_shape,
    ) and all(np.array_equal(getattr(a, m), getattr(b, m)) for m in (*maps, "weight"))


@pytest.mark.parametrize("size", [128, 513])  # (513: levels that do not divide the image)
@pytest.mark.parametrize("with_normals", [True, False])
def test_a_shape_flow_made_once_scores_every_image_as_congruence_alone(
    size: int, with_normals: bool
) -> None:
    """The shape's side of Eq. 2 made once (:func:`shape_flow`, the viewer's previews and
    ``depict compare``) scores each image of the frame bit for bit as :func:`congruence` does
    without it, and scoring leaves it as it was."""
    normal, depth = sphere(size)
    mask = np.isfinite(depth).astype(np.float32)
    kw = {"normal": normal if with_normals else None, "gradient_scale": 0.005}
    flow = shape_flow(depth, mask, **kw)
    images = [lambert(normal, light) for light in ((0, 0, 1), (1, 1, 0.3), (-1, 0.2, 0.5))]
    images.append(np.dstack([images[1], images[2], images[0]]))  # RGB
    for image in images * 2:  # (twice: the flow read, not changed)
        for norm in (None, 0.01):
            alone = congruence(image, depth, mask, shading_norm=norm, **kw)
            shared = congruence(image, depth, mask, shading_norm=norm, flow=flow, **kw)
            assert _results_equal(shared, alone)


def test_a_shape_flow_of_another_frame_or_other_parameters_is_refused() -> None:
    """A flow is checked against the depth, mask and normals it is given with, and the
    parameters: another frame of the same size would otherwise be scored on this one's shape."""
    normal, depth = sphere(96)
    flow = shape_flow(depth, normal=normal)
    image = lambert(normal, (0, 0, 1))
    with pytest.raises(ValueError, match="another frame or other parameters"):
        congruence(image, depth, normal=normal, flow=flow, percentile=90.0)
    with pytest.raises(ValueError, match="another frame or other parameters"):
        congruence(image, depth, flow=flow)  # (no normals: the depth's shape)
    small_normal, small_depth = sphere(64)
    with pytest.raises(ValueError, match="another frame or other parameters"):
        congruence(lambert(small_normal, (0, 0, 1)), small_depth, flow=flow)
    # the same size and parameters, other arrays: another depth, mask or normals
    tilted = depth + np.linspace(0, 1, 96, dtype=np.float32)[None, :]
    for other in ({"depth": tilted}, {"mask": np.isfinite(depth)}, {"normal": -normal}):
        args = {"depth": depth, "normal": normal, **other}
        with pytest.raises(ValueError, match="another frame or other parameters"):
            congruence(image, args.pop("depth"), args.pop("mask", None), flow=flow, **args)
    copies = {"depth": depth.copy(), "normal": normal.copy()}  # the same values: taken
    assert congruence(image, copies["depth"], normal=copies["normal"], flow=flow).score == (
        congruence(image, depth, normal=normal).score
    )


def test_empty_coverage_scores_zero() -> None:
    depth = np.full((32, 32), np.inf, np.float32)
    res = congruence(np.ones((32, 32), np.float32), depth)
    assert res.score == 0.0
    assert np.all(res.weight == 0.0)


# -- the sweep of light directions ---------------------------------------------------------------


def test_comparison_directions_are_the_fixed_sweep() -> None:
    dirs = comparison_directions()
    assert dirs.shape == (21, 3) and dirs.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0, atol=1e-6)
    np.testing.assert_array_equal(dirs[0], [0.0, 0.0, 1.0])
    assert len({tuple(np.round(d, 4)) for d in dirs}) == 21
    # frontal -> grazing -> behind on each arc
    z = dirs[1:].reshape(4, 5, 3)[..., 2]
    assert np.all(np.diff(z, axis=1) < 0)
    np.testing.assert_allclose(z[:, 2], 0.0, atol=1e-6)
    assert np.all(z[:, -1] < -0.8)
    np.testing.assert_allclose(dirs[1], [0.5, 0.0, np.sqrt(3) / 2], atol=1e-6)  # from the right
    np.testing.assert_array_equal(comparison_directions(5), dirs[:5])
    np.testing.assert_array_equal(comparison_directions(), dirs)  # fixed


@pytest.mark.parametrize("n", [0, 22, 2.5, True])
def test_comparison_directions_rejects_bad_n(n: object) -> None:
    with pytest.raises(ValueError, match="n must be"):
        comparison_directions(n)  # type: ignore[arg-type]
