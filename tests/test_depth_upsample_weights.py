"""The depth-aware pyramid's joint bilateral upsampling weights: the rule (``jb_weights``) and its
compiled passes (``jb_weights_fast``), which must give the same numbers bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

import ops.pyramid._jb
from ops.filtering import normal_pyramid
from ops.pyramid._jb import jb_weights, jb_weights_fast
from ops.pyramid.depth import DepthPyramid, normalize_field
from tests import analytic


def _sphere_before_wall() -> DepthPyramid:
    s = analytic.sphere(160, radius=0.7)
    depth = np.where(s.mask, s.depth, np.float32(s.depth[s.mask].max() + 2.0)).astype(np.float32)
    normal = np.where(s.mask[..., None], s.normal, np.array([0.0, 0.0, 1.0], np.float32)).astype(
        np.float32
    )
    return normal_pyramid(normal, depth, None, scales=5).geometry


Weights = tuple[np.ndarray, np.ndarray]


def _re_weighted_pixels(geo: DepthPyramid, k: int, k_to: int) -> tuple[np.ndarray, np.ndarray]:
    """The rule of the pixels ``up_sparse`` re-weights: every covered level-k_to pixel of the
    blocks under a dirty level-k sample (one within a sample of a depth jump), by row, then
    column."""
    f = 1 << (k - k_to)
    h_to, w_to = geo.shape(k_to)
    py, px = np.nonzero(geo._dirty(k))
    ys = (py * f)[:, None, None] + np.arange(f)[None, :, None]
    xs = (px * f)[:, None, None] + np.arange(f)[None, None, :]
    ys, xs = (a.reshape(-1) for a in np.broadcast_arrays(ys, xs))
    keep = (ys < h_to) & (xs < w_to)
    ys, xs = ys[keep], xs[keep]
    keep = geo.mask[k_to][ys, xs] > 0
    ys, xs = ys[keep], xs[keep]
    order = np.lexsort((xs, ys))
    return ys[order], xs[order]


@pytest.mark.parametrize(("k", "k_to"), [(1, 0), (2, 0), (2, 1)])
def test_the_re_weighted_pixels_are_the_rule(k: int, k_to: int) -> None:
    """The pixels of a sphere before a wall, in a frame whose sides are no multiple of a
    block and with holes in its coverage, that the upsampling from level k re-weights: the
    rule's, in its order."""
    s = analytic.sphere(160, radius=0.7)
    depth = np.where(s.mask, s.depth, np.float32(s.depth[s.mask].max() + 2.0)).astype(np.float32)
    normal = np.where(s.mask[..., None], s.normal, np.array([0.0, 0.0, 1.0], np.float32))
    holes = np.random.default_rng(5).random((150, 157)) > 0.1
    geo = normal_pyramid(
        np.ascontiguousarray(normal[5:155, :157], np.float32),
        np.ascontiguousarray(depth[5:155, :157]),
        holes.astype(np.float32),
        scales=5,
    ).geometry
    ys, xs, _, _ = geo._sparse_taps(k, k_to)
    want_y, want_x = _re_weighted_pixels(geo, k, k_to)
    assert ys.size > 100
    np.testing.assert_array_equal(ys, want_y)
    np.testing.assert_array_equal(xs, want_x)


def _rule_and_fast(
    logd_k: np.ndarray,
    mask_k: np.ndarray,
    sigma: float,
    f: int,
    ys: np.ndarray,
    xs: np.ndarray,
    logd: np.ndarray,
) -> tuple[Weights, Weights]:
    args = (logd_k, mask_k, sigma, f, ys, xs, logd)
    return jb_weights(*args), jb_weights_fast(*args)


def _tent(idx: np.ndarray, ys: np.ndarray, xs: np.ndarray, f: int, w_k: int) -> np.ndarray:
    """The bilinear weight of each tap (9, N): 1 − |Δ| along each axis, 0 beyond one sample."""
    sy, sx = (ys + 0.5) / f - 0.5, (xs + 0.5) / f - 0.5
    ty = np.maximum(1.0 - np.abs(idx // w_k - sy), 0.0)
    tx = np.maximum(1.0 - np.abs(idx % w_k - sx), 0.0)
    return ty * tx


@pytest.mark.parametrize("points", [8192, 97])  # points per task on the cores
@pytest.mark.parametrize(("k", "k_to"), [(2, 0), (1, 0), (2, 1)])
def test_compiled_weights_are_the_rule_on_a_sphere_before_a_wall(
    k: int, k_to: int, points: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """At the pixels the pyramid re-weights (next to the sphere's outline), the compiled
    weights and sample indices are the rule's, bit for bit; among them footprints whose
    weights the range term changed and plain bilinear ones."""
    monkeypatch.setattr(ops.pyramid._jb, "_POINTS", points)
    geo = _sphere_before_wall()
    ys, xs, _, _ = geo._sparse_taps(k, k_to)
    assert ys.size > 200
    f = 1 << (k - k_to)
    (i_rule, w_rule), (i_fast, w_fast) = _rule_and_fast(
        geo.logd[k], geo.mask[k], geo.depth_sigma, f, ys, xs, geo.logd[k_to][ys, xs]
    )
    assert i_fast.dtype == np.int64 and w_fast.dtype == np.float32
    np.testing.assert_array_equal(i_fast, i_rule)
    np.testing.assert_array_equal(w_fast, w_rule)
    np.testing.assert_allclose(w_fast.sum(axis=0), 1.0, atol=1e-6)
    plain = np.isclose(w_fast, _tent(i_fast, ys, xs, f, geo.shape(k)[1]), atol=1e-4).all(axis=0)
    assert plain.any() and (~plain).any()


def test_compiled_weights_leave_points_without_their_surface_to_the_rule() -> None:
    """Points whose 2×2 footprint holds nothing of their surface take the rule's 3×3 softmax
    (weight on samples outside the footprint); with such points among others the compiled
    result is still the rule's, bit for bit."""
    rng = np.random.default_rng(3)
    logd_k = rng.normal(0.0, 0.3, (40, 60)).astype(np.float32)
    mask_k = (rng.random((40, 60)) > 0.2).astype(np.float32)
    ys, xs = rng.integers(0, 160, 5000), rng.integers(0, 240, 5000)
    logd = (logd_k[ys // 4, xs // 4] + rng.normal(0.0, 0.05, 5000)).astype(np.float32)
    (i_rule, w_rule), (i_fast, w_fast) = _rule_and_fast(logd_k, mask_k, 0.02, 4, ys, xs, logd)
    np.testing.assert_array_equal(i_fast, i_rule)
    np.testing.assert_array_equal(w_fast, w_rule)
    np.testing.assert_allclose(w_fast.sum(axis=0), 1.0, atol=1e-6)
    outside = _tent(i_fast, ys, xs, 4, 60) == 0.0
    far = ((w_fast > 0.0) & outside).any(axis=0)
    assert 50 < far.sum() < 4950  # both kinds of points


def test_weights_on_one_surface_are_bilinear() -> None:
    """On one plane (log depth within 2σ everywhere) the weights are the bilinear ones of the
    2×2 footprint: pixel (3, 3) of a ×2 upsampling lies at (1.25, 1.25) on the level and
    takes ¾·¾, ¾·¼, ¼·¾, ¼·¼ of samples (1, 1), (1, 2), (2, 1), (2, 2)."""
    logd_k = np.full((6, 7), 0.5, np.float32)
    mask_k = np.ones((6, 7), np.float32)
    ys, xs = np.array([3]), np.array([3])
    idx, w = jb_weights_fast(logd_k, mask_k, 0.1, 2, ys, xs, np.array([0.51], np.float32))
    got = {int(i): float(v) for i, v in zip(idx[:, 0], w[:, 0], strict=True) if v > 0}
    assert got == pytest.approx({8: 0.5625, 9: 0.1875, 15: 0.1875, 16: 0.0625})


@pytest.mark.parametrize("masked", [False, True])
def test_unit_fields_by_strips_are_the_per_pixel_rule(masked: bool) -> None:
    """``normalize_field`` of a large field (planes, strips of rows on every core) is the
    per-pixel rule of a small one, bit for bit: v / |v|, zero vectors 0, × the coverage."""
    rng = np.random.default_rng(6)
    v = rng.standard_normal((517, 301, 3)).astype(np.float32)
    v[rng.random((517, 301)) < 0.05] = 0.0
    mask = (rng.random((517, 301)) > 0.3).astype(np.float32) if masked else None
    n2 = v[..., 0] * v[..., 0] + v[..., 1] * v[..., 1] + v[..., 2] * v[..., 2]
    inv = np.zeros_like(n2)
    np.divide(1.0, np.sqrt(n2), out=inv, where=n2 > 1e-20)
    want = v * inv[..., None]
    if mask is not None:
        want *= mask[..., None]
    got = normalize_field(v, mask)
    assert got.dtype == np.float32 and got.flags.c_contiguous
    np.testing.assert_array_equal(got, want)


def _jump_rule(logd: np.ndarray, m: np.ndarray, depth_sigma: float) -> np.ndarray:
    """Samples next to a depth jump, in NumPy: a second difference of log depth between two
    covered neighbours past 2 σ, or a step to a covered 4-neighbour past 3 σ; covered only."""
    lp, mp = np.pad(logd, 1, mode="edge"), np.pad(m, 1)
    tau, step = np.float32(2.0 * depth_sigma), np.float32(3.0 * depth_sigma)
    jump = (np.abs(lp[1:-1, :-2] + lp[1:-1, 2:] - 2.0 * logd) > tau) & mp[1:-1, :-2] & mp[1:-1, 2:]
    jump |= (np.abs(lp[:-2, 1:-1] + lp[2:, 1:-1] - 2.0 * logd) > tau) & mp[:-2, 1:-1] & mp[2:, 1:-1]
    sx = (np.abs(logd[:, 1:] - logd[:, :-1]) > step) & m[:, 1:] & m[:, :-1]
    sy = (np.abs(logd[1:] - logd[:-1]) > step) & m[1:] & m[:-1]
    jump[:, 1:] |= sx
    jump[:, :-1] |= sx
    jump[1:] |= sy
    jump[:-1] |= sy
    return jump & m


@pytest.mark.parametrize("depth_sigma", [0.02, 0.05, 0.1])
def test_depth_jumps_are_the_rule(depth_sigma: float) -> None:
    """The samples next to a depth jump at every level (compiled, by strips) are the rule's, on
    a sphere before a wall with a rough depth and holes in the coverage."""
    rng = np.random.default_rng(1)
    s = analytic.sphere(160, radius=0.7)
    depth = np.where(s.mask, s.depth, np.float32(s.depth[s.mask].max() + 2.0)).astype(np.float32)
    depth *= (1.0 + 0.02 * rng.standard_normal(depth.shape)).astype(np.float32)
    normal = np.where(s.mask[..., None], s.normal, np.array([0, 0, 1], np.float32))
    cover = (rng.random(depth.shape) > 0.05).astype(np.float32)
    geo = normal_pyramid(
        normal.astype(np.float32), depth, cover, scales=5, depth_sigma=depth_sigma
    ).geometry
    found = 0
    for k in range(len(geo.logd)):
        want = _jump_rule(geo.logd[k], geo.mask[k] > 0, depth_sigma)
        np.testing.assert_array_equal(geo._jumps(k), want)
        found += int(want.sum())
    assert found > 100
