"""The camera of a frame solved from its world-space position pass and the pixel grid.

A renderer's world-space position pass (Blender's ``Position``, Arnold's and Karma's ``P``) holds,
for each pixel, the world point its centre ray hit. The pixel grid and those points determine the
projection exactly, so a file that carries no camera still tells it:

1. the covered pixels whose neighbours are covered too (away from anti-aliased edges) give pairs
   (pixel centre (u, v) in the display window, world point X), u = column + 0.5 + data-window
   offset;
2. a **direct linear transform** (Hartley's normalised DLT) fits the 3×4 projection matrix P with
   (u, v, 1) ∝ P (X, 1); an affine fit (P's last row (0, 0, 0, 1)) that is as good means an
   orthographic camera;
3. P is decomposed (RQ) into the intrinsics K and the pose [R | t], and the pose and the focal
   length (perspective) or the scale (orthographic) are **refined** by Levenberg-Marquardt with a
   robust loss, in Depict's camera model: square pixels, principal point at the centre of the
   display window, OpenGL camera space (the camera looks down −z);
4. the reprojection error of every usable pixel, in pixels, says how well the model fits (a lens
   shift or a non-square pixel shows up there).

Points on one plane do not determine a 3×4 DLT; the perspective solve then starts the refinement
from :func:`cv2.solvePnP` poses over a sweep of fields of view instead.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from gbuffer.camera import Camera
from gbuffer.errors import FrameError

#: At most this many pixels feed the DLT and the refinement (a regular subsample beyond).
MAX_FIT_POINTS = 6000
#: At most this many pixels are checked for the reprojection error.
MAX_CHECK_POINTS = 250000
#: Fewer usable pixels than this: no solve.
MIN_POINTS = 12
#: An affine (orthographic) fit within this many pixels (RMS) of the DLT is taken as orthographic.
AFFINE_SLACK_PX = 0.01
#: Pixels whose reprojection error is above this many pixels (and 5 x the median) are outliers.
OUTLIER_PX = 1.0

_CV_TO_GL = np.diag([1.0, -1.0, -1.0])


@dataclass(frozen=True)
class CameraFit:
    """How well a camera explains a position pass: reprojection error over the usable pixels.

    ``rms_px`` / ``max_px``: over the inliers; ``pixels``: usable pixels; ``outliers``: pixels
    further than max(1 px, 5 × the median error) (mixed edge samples, a model that does not fit).
    """

    rms_px: float
    max_px: float
    pixels: int
    outliers: int

    def as_dict(self) -> dict[str, float | int]:
        return {
            "rms_px": self.rms_px,
            "max_px": self.max_px,
            "pixels": self.pixels,
            "outliers": self.outliers,
        }


# -- pairs of pixels and points ------------------------------------------------------------------


def usable_pixels(points: np.ndarray, covered: np.ndarray) -> np.ndarray:
    """(H, W) bool: covered pixels with finite, non-zero points whose 4 neighbours are usable
    too (a renderer may average positions at anti-aliased edges); all covered ones if that
    leaves too few."""
    ok = covered & _all3(np.isfinite(points)) & ~_all3(points == 0.0)
    inner = cv2.erode(ok.astype(np.uint8), np.ones((3, 3), np.uint8), borderValue=0) > 0
    return inner if int(inner.sum()) >= MIN_POINTS else ok


def _all3(flags: np.ndarray) -> np.ndarray:
    """(H, W) bool: all three of (H, W, 3) bool ``flags`` (a new, contiguous array) set, from
    its bytes (10x NumPy's ``all(axis=-1)`` over so short an axis)."""
    b = flags.view(np.uint8)
    return (b[..., 0] & b[..., 1] & b[..., 2]).view(bool)


def sample_pixels(mask: np.ndarray, limit: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(rows, columns) of the ``mask`` pixels, a regular subsample of at most ``limit``."""
    flat = np.flatnonzero(mask)  # (6x np.nonzero's two coordinates for every pixel)
    if limit is not None and flat.size > limit:
        flat = flat[np.linspace(0, flat.size - 1, limit).astype(np.int64)]
    rows, cols = np.divmod(flat, mask.shape[1])
    return rows, cols


def pixel_pairs(
    points: np.ndarray, mask: np.ndarray, origin: tuple[int, int], limit: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """((N, 2) pixel centres in the display window, (N, 3) world points) of ``mask``, float64,
    a regular subsample of at most ``limit`` pairs."""
    rows, cols = sample_pixels(mask, limit)
    uv = np.stack([cols + origin[0] + 0.5, rows + origin[1] + 0.5], axis=1).astype(np.float64)
    return uv, points[rows, cols].astype(np.float64)


# -- the camera model --------------------------------------------------------------------------


def project(camera: Camera, xyz: np.ndarray, display_size: tuple[int, int]) -> np.ndarray:
    """(N, 2) pixel positions (u right, v down, display window) of world points ``xyz``."""
    if camera.world_to_camera is None:
        raise FrameError("cannot project world points with a camera without world_to_camera")
    m = camera.world_to_camera
    pc = xyz @ m[:3, :3].T + m[:3, 3]
    dw, dh = display_size
    if camera.projection == "orthographic":
        if camera.ortho_height is None:
            raise FrameError("orthographic camera without ortho_height")
        scale = dh / camera.ortho_height
        return np.stack([dw / 2.0 + scale * pc[:, 0], dh / 2.0 - scale * pc[:, 1]], axis=1)
    focal = camera.focal_px(dh)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = -1.0 / pc[:, 2]
    return np.stack([dw / 2.0 + focal * pc[:, 0] * inv, dh / 2.0 - focal * pc[:, 1] * inv], 1)


def reprojection_fit(
    camera: Camera,
    points: np.ndarray,
    mask: np.ndarray,
    display_size: tuple[int, int],
    origin: tuple[int, int],
    limit: int = MAX_CHECK_POINTS,
) -> CameraFit:
    """The reprojection error of ``camera`` on the world ``points`` of the ``mask`` pixels (a
    regular subsample of at most ``limit`` of them)."""
    uv, xyz = pixel_pairs(points, mask, origin, limit)
    err = np.linalg.norm(project(camera, xyz, display_size) - uv, axis=1)
    err = np.where(np.isfinite(err), err, np.inf)
    if err.size == 0:
        return CameraFit(math.nan, math.nan, 0, 0)
    cut = max(OUTLIER_PX, 5.0 * float(np.median(err)))
    inliers = err[err <= cut]
    rms = float(np.sqrt(np.mean(inliers**2))) if inliers.size else math.inf
    top = float(inliers.max()) if inliers.size else math.inf
    return CameraFit(rms, top, int(err.size), int(err.size - inliers.size))


def _rotation(rvec: np.ndarray) -> np.ndarray:
    return np.asarray(cv2.Rodrigues(np.asarray(rvec, np.float64))[0], np.float64)


def _rvec(rot: np.ndarray) -> np.ndarray:
    return np.asarray(cv2.Rodrigues(np.asarray(rot, np.float64))[0], np.float64).ravel()


def _world_to_camera(rot_gl: np.ndarray, t_gl: np.ndarray) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = rot_gl, t_gl
    return m


# -- linear fits ---------------------------------------------------------------------------------


def _normaliser(x: np.ndarray) -> np.ndarray:
    """Hartley's similarity: centroid to the origin, mean distance sqrt(dim)."""
    dim = x.shape[1]
    centre = x.mean(axis=0)
    spread = float(np.mean(np.linalg.norm(x - centre, axis=1))) or 1.0
    s = math.sqrt(dim) / spread
    t = np.eye(dim + 1)
    t[:dim, :dim] *= s
    t[:dim, dim] = -s * centre
    return t


def dlt(uv: np.ndarray, xyz: np.ndarray) -> tuple[np.ndarray, float]:
    """The normalised direct linear transform: (3×4 P with (u, v, 1) ∝ P (X, 1), the ratio of
    the two smallest singular values: near 1 when the points do not determine P)."""
    t2, t3 = _normaliser(uv), _normaliser(xyz)
    x = np.c_[xyz, np.ones(len(xyz))] @ t3.T
    u = np.c_[uv, np.ones(len(uv))] @ t2.T
    zero = np.zeros_like(x)
    a = np.empty((2 * len(x), 12))
    a[0::2] = np.c_[x, zero, -u[:, :1] * x]
    a[1::2] = np.c_[zero, x, -u[:, 1:2] * x]
    # the right singular vectors of A are the eigenvectors of the 12×12 AᵀA (ascending)
    ev, vecs = np.linalg.eigh(a.T @ a)
    sv = np.sqrt(np.clip(ev, 0.0, None))
    p = np.linalg.inv(t2) @ vecs[:, 0].reshape(3, 4) @ t3
    scale = np.linalg.norm(p[2, :3]) or np.linalg.norm(p)
    return p / scale, float(sv[0] / sv[1]) if sv[1] > 0 else 1.0


def affine_fit(uv: np.ndarray, xyz: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares affine camera (u, v) = A (X, 1): (2×4 A, RMS residual in pixels)."""
    x = np.c_[xyz, np.ones(len(xyz))]
    a, *_ = np.linalg.lstsq(x, uv, rcond=None)
    res = x @ a - uv
    return a.T, float(np.sqrt(np.mean(np.sum(res**2, axis=1))))


def _dlt_rms(p: np.ndarray, uv: np.ndarray, xyz: np.ndarray) -> float:
    h = np.c_[xyz, np.ones(len(xyz))] @ p.T
    with np.errstate(divide="ignore", invalid="ignore"):
        res = h[:, :2] / h[:, 2:3] - uv
    return float(np.sqrt(np.mean(np.sum(res**2, axis=1))))


@dataclass(frozen=True)
class _Fit:
    """A refinement's parameters and its robust cost."""

    x: np.ndarray
    cost: float


#: The soft-L1 loss's scale: pixels off by more than this weigh less and less.
_LOSS_SCALE_PX = 0.5


def _robust_cost(r: np.ndarray) -> float:
    """Σ C² (√(1 + (r/C)²) − 1): the soft-L1 loss, quadratic below C and linear beyond."""
    c2 = _LOSS_SCALE_PX**2
    return float(c2 * np.sum(np.sqrt(1.0 + r * r / c2) - 1.0))


def _jacobian(f: Callable[[np.ndarray], np.ndarray], x: np.ndarray) -> np.ndarray:
    """Central differences of ``f`` at ``x`` (a few parameters, a few thousand residuals)."""
    cols = []
    for i in range(len(x)):
        h = 1e-6 * max(1.0, abs(float(x[i])))
        step = np.zeros_like(x)
        step[i] = h
        cols.append((f(x + step) - f(x - step)) / (2.0 * h))
    return np.stack(cols, axis=1)


def _refine(
    residuals: Callable[..., np.ndarray],
    x0: np.ndarray,
    uv: np.ndarray,
    xyz: np.ndarray,
    centre: np.ndarray,
    iterations: int = 200,
) -> _Fit:
    """Levenberg-Marquardt with a robust (soft L1) loss: pixels off by more than half a pixel
    (mixed edge samples) weigh less and less. Each step solves the Gauss-Newton system weighted
    by the loss's slope (iteratively reweighted least squares), damped until the cost falls."""

    def f(x: np.ndarray) -> np.ndarray:
        return residuals(x, uv, xyz, centre)

    x = np.asarray(x0, np.float64)
    r = f(x)
    cost, damping = _robust_cost(r), 1e-3
    for _ in range(iterations):
        jac = _jacobian(f, x)
        weight = 1.0 / np.sqrt(1.0 + r * r / _LOSS_SCALE_PX**2)
        normal = jac.T @ (weight[:, None] * jac)
        gradient = jac.T @ (weight * r)
        while damping < 1e12:
            damped = normal + damping * np.diag(np.diag(normal) + 1e-12)
            step = np.linalg.solve(damped, -gradient)
            r_new = f(x + step)
            new_cost = _robust_cost(r_new)
            if new_cost < cost:
                break
            damping *= 10.0
        else:
            break  # no step lowers the cost: a minimum
        x, r, damping = x + step, r_new, max(damping / 10.0, 1e-12)
        done = cost - new_cost <= 1e-12 * cost or np.linalg.norm(step) <= 1e-12 * (
            np.linalg.norm(x) + 1e-12
        )
        cost = new_cost
        if done:
            break
    return _Fit(x=x, cost=cost)


def _rq(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """a = R Q, R upper triangular and Q orthogonal (a QR decomposition of a flipped)."""
    flip = np.eye(3)[::-1]
    q, r = np.linalg.qr((flip @ a).T)
    return flip @ r.T @ flip, flip @ q.T


# -- perspective ---------------------------------------------------------------------------------


def _decompose(p: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """P = K [R | t] -> (focal in pixels, OpenGL rotation, OpenGL translation)."""
    if np.linalg.det(p[:, :3]) < 0:
        p = -p
    k, r = _rq(p[:, :3])
    d = np.diag(np.sign(np.diag(k)))
    k, r = k @ d, d @ r
    t = np.linalg.solve(k, p[:, 3])
    k = k / k[2, 2]
    focal = 0.5 * (k[0, 0] + k[1, 1])
    return float(focal), _CV_TO_GL @ r, _CV_TO_GL @ t


def _perspective_residuals(
    x: np.ndarray, uv: np.ndarray, xyz: np.ndarray, centre: np.ndarray
) -> np.ndarray:
    rot, t, focal = _rotation(x[:3]), x[3:6], math.exp(x[6])
    pc = xyz @ rot.T + t
    z = np.where(pc[:, 2] < -1e-12, pc[:, 2], -1e-12)  # points behind the eye: huge residuals
    u = centre[0] - focal * pc[:, 0] / z
    v = centre[1] + focal * pc[:, 1] / z
    return np.concatenate([u - uv[:, 0], v - uv[:, 1]])


def _pnp_starts(
    uv: np.ndarray, xyz: np.ndarray, centre: np.ndarray, height: int
) -> list[np.ndarray]:
    """Initial (rvec, t, log f) from solvePnP over a sweep of fields of view (planar points)."""
    starts = []
    for fov in (10.0, 20.0, 35.0, 50.0, 70.0, 90.0, 120.0):
        focal = 0.5 * height / math.tan(math.radians(fov) / 2.0)
        k = np.array([[focal, 0, centre[0]], [0, focal, centre[1]], [0, 0, 1.0]])
        ok, rvec, tvec = cv2.solvePnP(xyz, uv, k, None, flags=cv2.SOLVEPNP_ITERATIVE)
        if ok:
            rot = _CV_TO_GL @ _rotation(rvec.ravel())
            starts.append(np.r_[_rvec(rot), _CV_TO_GL @ tvec.ravel(), math.log(focal)])
    return starts


def _solve_perspective(
    uv: np.ndarray, xyz: np.ndarray, display_size: tuple[int, int], p: np.ndarray | None
) -> Camera:
    dw, dh = display_size
    centre = np.array([dw / 2.0, dh / 2.0])
    if p is not None:
        focal, rot, t = _decompose(p)
        starts = [np.r_[_rvec(rot), t, math.log(max(focal, 1e-6))]]
    else:
        starts = _pnp_starts(uv, xyz, centre, dh)
    if not starts:
        raise FrameError("the position pass does not determine a perspective camera")
    best = None
    for x0 in starts:
        fit = _refine(_perspective_residuals, x0, uv, xyz, centre)
        if best is None or fit.cost < best.cost:
            best = fit
    assert best is not None
    x = best.x
    fov = math.degrees(2.0 * math.atan(0.5 * dh / math.exp(x[6])))
    return Camera(world_to_camera=_world_to_camera(_rotation(x[:3]), x[3:6]), fov_y_deg=fov)


# -- orthographic --------------------------------------------------------------------------------


def _orthographic_residuals(
    x: np.ndarray, uv: np.ndarray, xyz: np.ndarray, centre: np.ndarray
) -> np.ndarray:
    rot, scale = _rotation(x[:3]), math.exp(x[5])
    pc = xyz @ rot[:2].T + x[3:5]
    u = centre[0] + scale * pc[:, 0]
    v = centre[1] - scale * pc[:, 1]
    return np.concatenate([u - uv[:, 0], v - uv[:, 1]])


def _solve_orthographic(
    uv: np.ndarray,
    xyz: np.ndarray,
    display_size: tuple[int, int],
    affine: np.ndarray,
    depth: np.ndarray | None,
) -> Camera:
    """u = w/2 + s (x·X + tx), v = h/2 − s (y·X + ty); the depth pass places the camera along
    its axis (without one, one scene depth in front of the nearest point)."""
    dw, dh = display_size
    centre = np.array([dw / 2.0, dh / 2.0])
    a, c = affine[0, :3], affine[1, :3]
    scale = 0.5 * float(np.linalg.norm(a) + np.linalg.norm(c))
    u_, _, vt = np.linalg.svd(np.stack([a, -c, np.cross(a, -c)]))
    rot = u_ @ vt  # the rotation nearest to (x, y, x × y) axes
    tx = (affine[0, 3] - centre[0]) / scale
    ty = (centre[1] - affine[1, 3]) / scale
    x0 = np.r_[_rvec(rot), tx, ty, math.log(scale)]
    fit = _refine(_orthographic_residuals, x0, uv, xyz, centre)
    rot, scale = _rotation(fit.x[:3]), math.exp(float(fit.x[5]))
    along = xyz @ rot[2]
    known = np.isfinite(depth) if depth is not None else np.zeros(0, bool)
    if depth is not None and known.any():
        tz = float(np.median(-depth[known] - along[known]))
    else:
        span = float(np.ptp(along)) or 1.0
        tz = -float(along.max()) - span
    t = np.array([fit.x[3], fit.x[4], tz])
    return Camera(
        world_to_camera=_world_to_camera(rot, t), projection="orthographic", ortho_height=dh / scale
    )


# -- the solve -----------------------------------------------------------------------------------


def solve_camera(
    points: np.ndarray,
    covered: np.ndarray,
    display_size: tuple[int, int],
    origin: tuple[int, int] = (0, 0),
    depth: np.ndarray | None = None,
) -> tuple[Camera, CameraFit]:
    """The camera that projects each pixel's world point onto its pixel centre.

    Parameters
    ----------
    points : (H, W, 3) world-space positions of the pixel-centre hits.
    covered : (H, W) bool, pixels that hit a surface.
    display_size : (width, height) of the display window; origin: the data window's offset in it.
    depth : (H, W) planar depth, optional: places an orthographic camera along its axis.

    Returns
    -------
    (camera, its :class:`CameraFit` over every usable pixel).

    Raises
    ------
    FrameError
        Too few usable pixels, or points that determine no camera.
    """
    mask = usable_pixels(points, covered)
    count = int(mask.sum())
    if count < MIN_POINTS:
        raise FrameError(f"only {count} usable pixels in the position pass (need {MIN_POINTS})")
    uv, xyz = pixel_pairs(points, mask, origin, MAX_FIT_POINTS)
    p, degeneracy = dlt(uv, xyz)
    affine, affine_rms = affine_fit(uv, xyz)
    planar = degeneracy > 0.1
    # points on one plane determine no DLT: only an exact affine fit says orthographic then
    dlt_rms = 0.0 if planar else _dlt_rms(p, uv, xyz)
    if affine_rms <= dlt_rms + AFFINE_SLACK_PX or affine_rms < AFFINE_SLACK_PX:
        if planar:
            raise FrameError(
                "the position pass holds one plane seen by an orthographic camera: ambiguous"
            )
        d = None
        if depth is not None:
            rows, cols = sample_pixels(mask, MAX_FIT_POINTS)
            d = depth[rows, cols].astype(np.float64)
        camera = _solve_orthographic(uv, xyz, display_size, affine, d)
    else:
        camera = _solve_perspective(uv, xyz, display_size, None if planar else p)
    return camera, reprojection_fit(camera, points, mask, display_size, origin)
