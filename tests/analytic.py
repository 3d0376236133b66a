"""Analytic camera-space G-buffers for tests: spheres, bowl, saddle, cylinder, planes, ridge.

Every scene is defined by a function of the image-plane coordinates ``(u, v)``, measured in units of
the image height from the image centre (``u`` right, ``v`` up, OpenGL camera space: +z towards the
camera, the camera at the origin looking down -z). Sampling it at the pixel centres gives the
G-buffer (normal, planar depth with +inf background, mask); evaluating it a tiny step away gives a
float64 reference of the view-centred curvature (Radiance Scaling §4) at any foreshortening:
``H = ∇(n_xy / n_z^f)`` per unit of image height, κ > 0 on convexities.

For an orthographic view (``ortho_height`` scene units across the image height) a sphere of radius
``R`` has, at ``f = 0``, κ1 = κ2 = ortho_height / R everywhere; a cylinder κ1 = ortho_height / R,
κ2 = 0; a bowl (inside of a sphere) -ortho_height / R; a plane 0.

Usage::

    s = sphere(256, radius=0.5)          # spans half the image height (ortho_height = 2)
    s.normal, s.depth, s.mask            # (H, W, 3) / (H, W) float32, (H, W) bool
    s.k1, s.k2                           # reference at f = 0, NaN where undefined
    k1, k2, dx, dy = s.reference(0.5)    # reference at another foreshortening
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ops.curvature import DEFAULT_GAIN, Curvature, principal_curvatures

#: (u, v) float64 arrays -> (normal (..., 3), depth, covered, segment id) float64/bool/int arrays.
SceneFn = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]

DEFAULT_ORTHO_HEIGHT = 2.0
#: Distance from the camera to the scene's reference plane (z = -DISTANCE).
DISTANCE = 10.0
_FD_STEP = 1e-5  # finite-difference step for the reference, in image heights


@dataclass
class Scene:
    """An analytic G-buffer.

    Attributes
    ----------
    normal : (H, W, 3) float32
        Camera-space unit normal, zero on background.
    depth : (H, W) float32
        Planar depth (-z), +inf on background.
    mask : (H, W) bool
        Covered pixels.
    ortho_height : float or None
        Scene units spanned by the image height (orthographic); None for perspective.
    fov_y_deg : float or None
        Vertical field of view (perspective); None for orthographic.
    segment : (H, W) int32
        Which surface is visible (0, 1, ...), -1 on background.
    k1, k2 : (H, W) float32
        Reference principal curvatures per unit image height at foreshortening 0, NaN where they
        are undefined (background, creases, where a tiny stencil leaves the surface).
    dir_x, dir_y : (H, W) float32
        Reference direction of k1 (unit, camera x/y), NaN where undefined or umbilic.
    """

    normal: np.ndarray
    depth: np.ndarray
    mask: np.ndarray
    ortho_height: float | None
    fov_y_deg: float | None
    segment: np.ndarray
    k1: np.ndarray
    k2: np.ndarray
    dir_x: np.ndarray
    dir_y: np.ndarray
    fn: SceneFn = field(repr=False)
    u: np.ndarray = field(repr=False)
    v: np.ndarray = field(repr=False)

    @property
    def shape(self) -> tuple[int, int]:
        return (int(self.depth.shape[0]), int(self.depth.shape[1]))

    def reference(
        self, foreshortening: float = 0.0
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Reference (k1, k2, dir_x, dir_y) per unit image height at the given foreshortening."""
        return _reference(self.fn, self.u, self.v, foreshortening)

    def curvature(self, **kw: float) -> Curvature:
        """:func:`ops.curvature.principal_curvatures` of the scene's normals, depth and mask."""
        return principal_curvatures(self.normal, self.depth, self.mask, **kw)  # type: ignore[arg-type]

    def ring(self, h_map: np.ndarray) -> float:
        """Largest excess of a curvature map |H| (``tanh`` of the default gain) over the
        analytic |H| anywhere on the surfaces: what a depth jump counted as curvature adds."""
        ref = np.tanh(DEFAULT_GAIN * (self.k1 + self.k2))
        ok = np.isfinite(ref)
        return float((np.abs(h_map) - np.abs(ref))[ok].max())

    def interior(self, margin: float) -> np.ndarray:
        """Covered pixels at least ``margin`` image heights (centre to centre) from any pixel of
        another segment or the background (a square neighbourhood test)."""
        r = max(1, math.ceil(margin * self.shape[0]))
        seg = self.segment
        ok = seg >= 0
        pad = np.pad(seg, r, mode="constant", constant_values=-2)
        h, w = seg.shape
        for dy in range(-r, r + 1, max(1, r // 4)):
            for dx in range(-r, r + 1, max(1, r // 4)):
                ok &= pad[r + dy : r + dy + h, r + dx : r + dx + w] == seg
        return ok


def pixel_coords(height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """Image-plane coordinates (u right, v up) of the pixel centres, in image heights."""
    cols = (np.arange(width, dtype=np.float64) + 0.5 - width / 2.0) / height
    rows = (height / 2.0 - np.arange(height, dtype=np.float64) - 0.5) / height
    return np.meshgrid(cols, rows)


def _reference(
    fn: SceneFn, u: np.ndarray, v: np.ndarray, f: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    h = _FD_STEP

    def q(uu: np.ndarray, vv: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        n, _, cov, seg = fn(uu, vv)
        nz = np.maximum(n[..., 2], 1e-12) ** f
        return n[..., 0] / nz, n[..., 1] / nz, cov, seg

    _, _, cov0, seg0 = fn(u, v)
    xp, yp, cp, sp = q(u + h, v)
    xm, ym, cm, sm = q(u - h, v)
    xu, yu, cu, su = q(u, v + h)
    xd, yd, cd, sd = q(u, v - h)
    a = (xp - xm) / (2 * h)
    c = (yu - yd) / (2 * h)
    b = 0.5 * ((xu - xd) / (2 * h) + (yp - ym) / (2 * h))
    ok = cov0 & cp & cm & cu & cd & (sp == seg0) & (sm == seg0) & (su == seg0) & (sd == seg0)
    m = 0.5 * (a + c)
    r = np.hypot(0.5 * (a - c), b)
    k1, k2 = m + r, m - r
    theta = 0.5 * np.arctan2(b, 0.5 * (a - c))
    dx, dy = np.cos(theta), np.sin(theta)
    # Creases (the ridge's tangent points) show as huge one-sided differences: not defined there.
    nan = ~ok
    out = []
    for arr in (k1, k2):
        arr = np.where(nan, np.nan, arr)
        out.append(arr.astype(np.float32))
    umbilic = r < 1e-6 * np.maximum(1.0, np.abs(m))
    for arr in (dx, dy):
        arr = np.where(nan | umbilic, np.nan, arr)
        out.append(arr.astype(np.float32))
    return out[0], out[1], out[2], out[3]


def _make(
    height: int,
    width: int | None,
    fn: SceneFn,
    ortho_height: float | None,
    fov_y_deg: float | None = None,
) -> Scene:
    width = height if width is None else width
    u, v = pixel_coords(height, width)
    n, depth, cov, seg = fn(u, v)
    normal = np.where(cov[..., None], n, 0.0).astype(np.float32)
    depth32 = np.where(cov, depth, np.inf).astype(np.float32)
    seg = np.where(cov, seg, -1).astype(np.int32)
    k1, k2, dx, dy = _reference(fn, u, v, 0.0)
    return Scene(
        normal=np.ascontiguousarray(normal),
        depth=depth32,
        mask=cov.astype(bool),
        ortho_height=ortho_height,
        fov_y_deg=fov_y_deg,
        segment=seg,
        k1=k1,
        k2=k2,
        dir_x=dx,
        dir_y=dy,
        fn=fn,
        u=u,
        v=v,
    )


def _unit(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    n = np.stack([x, y, z], axis=-1)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


# -- single surfaces (orthographic) ------------------------------------------------------------


def _sphere_fn(
    radius: float, cx: float, cy: float, dist: float, ortho_height: float, inside: bool = False
) -> SceneFn:
    def fn(u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        x, y = u * ortho_height - cx, v * ortho_height - cy
        r2 = x * x + y * y
        cov = r2 < radius * radius
        h = np.sqrt(np.maximum(radius * radius - r2, 0.0))
        if inside:  # inner surface of the far hemisphere, normal towards the centre (camera)
            n = np.stack([-x, -y, h], axis=-1) / radius
            depth = dist + h
        else:
            n = np.stack([x, y, h], axis=-1) / radius
            depth = dist - h
        return n, depth, cov, np.zeros(u.shape, np.int64)

    return fn


def sphere(
    height: int = 256,
    radius: float = 0.5,
    *,
    width: int | None = None,
    centre: tuple[float, float] = (0.0, 0.0),
    ortho_height: float = DEFAULT_ORTHO_HEIGHT,
    distance: float = DISTANCE,
) -> Scene:
    """Sphere of ``radius`` (scene units) seen from outside; centre (x, y) in scene units.

    At f = 0, κ1 = κ2 = ortho_height / radius everywhere on it (per unit image height).
    """
    fn = _sphere_fn(radius, centre[0], centre[1], distance, ortho_height)
    return _make(height, width, fn, ortho_height)


def bowl(
    height: int = 256,
    radius: float = 0.5,
    *,
    width: int | None = None,
    ortho_height: float = DEFAULT_ORTHO_HEIGHT,
    distance: float = DISTANCE,
) -> Scene:
    """Inside of a hemisphere open towards the camera: κ1 = κ2 = -ortho_height / radius."""
    fn = _sphere_fn(radius, 0.0, 0.0, distance, ortho_height, inside=True)
    return _make(height, width, fn, ortho_height)


def saddle(
    height: int = 256,
    radius: float = 1.0,
    *,
    width: int | None = None,
    extent: float = 0.8,
    ortho_height: float = DEFAULT_ORTHO_HEIGHT,
    distance: float = DISTANCE,
) -> Scene:
    """Height field z = (x² - y²) / (2R) towards the camera over a disc of radius ``extent``.

    Convex along y, concave along x: at the centre κ1 = ortho_height / R (direction y),
    κ2 = -ortho_height / R.
    """

    def fn(u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        x, y = u * ortho_height, v * ortho_height
        z = (x * x - y * y) / (2.0 * radius)
        n = _unit(-x / radius, y / radius, np.ones_like(x))
        cov = x * x + y * y < extent * extent
        return n, distance - z, cov, np.zeros(u.shape, np.int64)

    return _make(height, width, fn, ortho_height)


def cylinder(
    height: int = 256,
    radius: float = 0.5,
    *,
    width: int | None = None,
    length: float | None = None,
    ortho_height: float = DEFAULT_ORTHO_HEIGHT,
    distance: float = DISTANCE,
) -> Scene:
    """Cylinder with its axis along camera y: κ1 = ortho_height / R (direction x), κ2 = 0.

    ``length`` (scene units) limits it vertically; None spans the whole image.
    """

    def fn(u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        x, y = u * ortho_height, v * ortho_height
        cov = np.abs(x) < radius
        if length is not None:
            cov &= np.abs(y) < length / 2.0
        h = np.sqrt(np.maximum(radius * radius - x * x, 0.0))
        n = np.stack([x, np.zeros_like(x), h], axis=-1) / radius
        return n, distance - h, cov, np.zeros(u.shape, np.int64)

    return _make(height, width, fn, ortho_height)


def plane(
    height: int = 256,
    *,
    width: int | None = None,
    tilt_x_deg: float = 0.0,
    tilt_y_deg: float = 0.0,
    extent: float | None = None,
    ortho_height: float = DEFAULT_ORTHO_HEIGHT,
    distance: float = DISTANCE,
) -> Scene:
    """Plane through (0, 0, -distance), its normal turned by ``tilt_x_deg`` towards +x and
    ``tilt_y_deg`` towards +y. ``extent`` (half-size, scene units) limits it to a square."""
    tx, ty = math.radians(tilt_x_deg), math.radians(tilt_y_deg)
    nvec = np.array([math.sin(tx) * math.cos(ty), math.sin(ty), math.cos(tx) * math.cos(ty)])
    nvec /= np.linalg.norm(nvec)

    def fn(u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        x, y = u * ortho_height, v * ortho_height
        z = -(nvec[0] * x + nvec[1] * y) / nvec[2]
        n = np.broadcast_to(nvec, (*u.shape, 3)).copy()
        cov = np.ones(u.shape, bool)
        if extent is not None:
            cov = (np.abs(x) < extent) & (np.abs(y) < extent)
        return n, distance - z, cov, np.zeros(u.shape, np.int64)

    return _make(height, width, fn, ortho_height)


def ridge(
    height: int = 256,
    *,
    width: int | None = None,
    slope_deg: float = 35.0,
    rounding: float = 0.2,
    ortho_height: float = DEFAULT_ORTHO_HEIGHT,
    distance: float = DISTANCE,
) -> Scene:
    """Two planes z = -tan(slope)·|x| meeting along the camera y axis, the crest rounded by a
    cylinder of radius ``rounding``: κ1 = ortho_height / rounding on the crest (|x| <
    rounding·sin(slope), direction x), 0 on the flanks, κ2 = 0."""
    beta = math.radians(slope_deg)
    xt = rounding * math.sin(beta)  # tangent points
    z0 = -rounding / math.cos(beta)  # arc centre (crest at z = 0)

    def fn(u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        x = u * ortho_height
        on_arc = np.abs(x) < xt
        h = np.sqrt(np.maximum(rounding * rounding - x * x, 0.0))
        z = np.where(on_arc, z0 + h, -np.abs(x) * math.tan(beta))
        nx = np.where(on_arc, x / rounding, np.sign(x) * math.sin(beta))
        nz = np.where(on_arc, h / rounding, math.cos(beta))
        n = np.stack([nx, np.zeros_like(x), nz], axis=-1)
        seg = np.where(on_arc, 0, np.where(x < 0, 1, 2))  # creases at the tangent points
        return n, distance - z, np.ones(u.shape, bool), seg

    return _make(height, width, fn, ortho_height)


def two_spheres(
    height: int = 256,
    *,
    width: int | None = None,
    front: tuple[float, float, float] = (-0.25, 0.0, 0.45),
    back: tuple[float, float, float] = (0.35, 0.1, 0.55),
    gap: float = 1.5,
    ortho_height: float = DEFAULT_ORTHO_HEIGHT,
    distance: float = DISTANCE,
) -> Scene:
    """Two overlapping spheres, (x, y, radius) each; the back one ``gap`` scene units further
    than the front one (a depth jump where the front one hides it). Segment 0 = front."""
    fa = _sphere_fn(front[2], front[0], front[1], distance, ortho_height)
    fb = _sphere_fn(back[2], back[0], back[1], distance + gap + front[2] + back[2], ortho_height)

    def fn(u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        na, da, ca, _ = fa(u, v)
        nb, db, cb, _ = fb(u, v)
        use_a = ca & (~cb | (da <= db))
        n = np.where(use_a[..., None], na, nb)
        d = np.where(use_a, da, db)
        seg = np.where(use_a, 0, 1)
        return n, d, ca | cb, seg

    return _make(height, width, fn, ortho_height)


# -- perspective ---------------------------------------------------------------------------------


def perspective_sphere(
    height: int = 256,
    radius: float = 1.0,
    *,
    width: int | None = None,
    distance: float = 5.0,
    fov_y_deg: float = 30.0,
    centre: tuple[float, float] = (0.0, 0.0),
) -> Scene:
    """Sphere of ``radius`` centred at (cx, cy, -distance) seen by a pinhole camera.

    At the image centre (f = 0) κ1 = κ2 ≈ 2·tan(fov/2)·(distance - radius) / radius per unit image
    height; ``k1``/``k2`` hold the exact per-pixel reference.
    """
    t = 2.0 * math.tan(math.radians(fov_y_deg) / 2.0)
    c = np.array([centre[0], centre[1], -distance])

    def fn(u: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        d = np.stack([u * t, v * t, -np.ones_like(u)], axis=-1)
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        b = d @ c
        disc = b * b - (c @ c - radius * radius)
        cov = disc > 0
        s = b - np.sqrt(np.maximum(disc, 0.0))
        p = d * s[..., None]
        n = (p - c) / radius
        return n, -p[..., 2], cov, np.zeros(u.shape, np.int64)

    return _make(height, width, fn, None, fov_y_deg)


def small_cap(height: int = 32, width: int = 40) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A small frame of a bulging cap on background: (normal (H, W, 3), 0 off the cap; depth
    (H, W), +inf off it; the cap's coverage (H, W) bool), float32 (fuzzing found its faults)."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    x, y = (x + 0.5) / width * 2 - 1, (y + 0.5) / height * 2 - 1
    inside = x**2 + y**2 < 0.9
    z = np.sqrt(np.clip(1.2 - x**2 - y**2, 0.05, None))
    normal = np.dstack([x, y, z]) / np.sqrt(x**2 + y**2 + z**2)[..., None]
    normal = np.where(inside[..., None], normal, 0.0).astype(np.float32)
    depth = np.where(inside, 4.0 - z, np.inf).astype(np.float32)
    return normal, depth, inside
