"""The geometry of a frame being read: normals and positions to camera space, the trust in a
filtered normal, and the camera (the file's, or solved from world-space positions)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any

import cv2
import numpy as np

from gbuffer.camera import Camera
from gbuffer.camera_solve import reprojection_fit, solve_camera, usable_pixels
from gbuffer.errors import FrameError, MissingCameraError
from gbuffer.presets.channels import describe

#: A camera whose points land further than this from their pixels (RMS) gets a warning.
CAMERA_DISAGREES_PX = 0.5


def length_trust(length: np.ndarray, tol: float) -> np.ndarray:
    """f(|n|) of the coverage formula (module docstring)."""
    low = np.float32(1.0 - tol)
    high = np.float32(1.0 + tol)
    f = np.ones_like(length)
    short = length < low
    f[short] = length[short] / low
    long_ = length > high
    f[long_] = high / length[long_]
    return f


def camera_error(where: str, what: str, src: str, camera: Camera | None) -> MissingCameraError:
    have = "the camera given has no world_to_camera matrix" if camera else "the file has none"
    return MissingCameraError(
        f"{where}: the {what} ({src}) are in world space and no camera is known ({have}, and "
        "no world-space position pass to solve it from); give a camera JSON (--camera "
        'CAM.json on the command line, the camera form field over HTTP) with {"world_to_camera": '
        '[[4 numbers], [4], [4], [4]], "fov_y_deg": 40} (OpenGL camera looking down -z), or '
        "declare them camera-space (--normal-space camera, normal_space=camera)"
    )


def to_camera_normals(n: np.ndarray, space: str, camera: Camera | None) -> np.ndarray:
    """Normals in camera space: world ones by the inverse transpose of the camera rotation,
    left-handed ones (+z forward) with z flipped (in place)."""
    return _to_camera(n, space, camera, lambda w2c: np.linalg.inv(w2c[:3, :3]).T)


def to_camera_points(p: np.ndarray, space: str, camera: Camera | None) -> np.ndarray:
    """Points in camera space: world ones by the camera matrix, left-handed ones with z
    flipped (in place)."""
    return _to_camera(p, space, camera, lambda w2c: w2c[:3, :])


def _to_camera(
    v: np.ndarray,
    space: str,
    camera: Camera | None,
    matrix: Callable[[np.ndarray], np.ndarray],
) -> np.ndarray:
    if space == "camera":
        return v
    if space == "camera-lh":
        v[..., 2] *= -1.0
        return v
    assert camera is not None and camera.world_to_camera is not None
    m = matrix(camera.world_to_camera).astype(np.float32)
    return np.asarray(cv2.transform(v, m), dtype=np.float32)


def camera_from_positions(
    camera: Camera | None,
    points: np.ndarray,
    covered: np.ndarray,
    display_size: tuple[int, int],
    origin: tuple[int, int],
    depth: np.ndarray | None,
    found: Mapping[str, list[str]],
    warnings: list[str],
) -> Camera | None:
    """The camera solved from world-space positions when none is known; a known pose without
    a field of view given the one solved from them (:func:`_complete`); else the known camera
    with its reprojection error against them (a wrong field of view shows up in pixels)."""
    src = describe(found["position"])
    finite_depth = None if depth is None else np.where(covered, depth, np.inf)
    if camera is not None and camera.world_to_camera is not None:
        if not camera.has_intrinsics:
            return _complete(
                camera, points, covered, display_size, origin, finite_depth, src, warnings
            )
        fit = reprojection_fit(camera, points, usable_pixels(points, covered), display_size, origin)
        if fit.rms_px > CAMERA_DISAGREES_PX:
            warnings.append(
                f"the camera ({camera.source or 'given'}) puts the points of {src} "
                f"{fit.rms_px:.3g} px (RMS) away from their pixels: check its field of view and "
                "pose (a Blender camera's angle_y is the sensor's, not the image's), or give no "
                "camera and let Depict solve it from the position pass"
            )
        return dataclasses.replace(camera, fit=fit.as_dict())
    if camera is not None:  # intrinsics only: camera-space buffers, nothing to solve
        return camera
    try:
        solved, fit = solve_camera(points, covered, display_size, origin, finite_depth)
    except FrameError as exc:
        warnings.append(f"no camera solved from {src}: {exc}")
        return None
    return dataclasses.replace(
        solved, source=f"solved from {src} (world positions)", fit=fit.as_dict()
    )


def _complete(
    camera: Camera,
    points: np.ndarray,
    covered: np.ndarray,
    display_size: tuple[int, int],
    origin: tuple[int, int],
    depth: np.ndarray | None,
    src: str,
    warnings: list[str],
) -> Camera:
    """``camera`` (a pose without a field of view: a file's ``worldToCamera`` alone) with the
    projection and field of view (or orthographic height) of the camera the positions solve,
    where its own pose with them puts the points on their pixels (within
    :data:`CAMERA_DISAGREES_PX`); else ``camera`` as it is (:func:`pose_only_warning` says
    what it lacks)."""
    why = f"the field of view of the camera in the file ({camera.source}) is not solved from {src}"
    try:
        solved, _ = solve_camera(points, covered, display_size, origin, depth)
    except FrameError as exc:
        warnings.append(f"{why}: {exc}")
        return camera
    completed = dataclasses.replace(
        camera,
        projection=solved.projection,
        fov_y_deg=solved.fov_y_deg,
        ortho_height=solved.ortho_height,
        source=f"{camera.source}, its field of view solved from {src}",
    )
    fit = reprojection_fit(completed, points, usable_pixels(points, covered), display_size, origin)
    if not fit.rms_px <= CAMERA_DISAGREES_PX:
        warnings.append(
            f"{why}: with the file's pose, the solved one puts the points {fit.rms_px:.3g} px "
            "(RMS) away from their pixels (the pose does not match the position pass)"
        )
        return camera
    return dataclasses.replace(completed, fit=fit.as_dict())


def check_facing(
    n: np.ndarray,
    camera: Camera | None,
    shape: tuple[int, int],
    display_size: tuple[int, int],
    origin: tuple[int, int],
    src: str,
    warnings: list[str],
) -> None:
    """Warn when most converted normals face away from the camera (a convention mix-up)."""
    if camera is None:
        return
    try:
        view = camera.view_vectors(shape, display_size, origin)
    except FrameError:
        view = np.zeros((*shape, 3), np.float32)
        view[..., 2] = 1.0
    facing = np.einsum("ijk,ijk->ij", n, view)
    covered = np.abs(facing) > 1e-3
    if covered.sum() > 16 and (facing[covered] < 0).mean() > 0.5:
        warnings.append(
            f"most normals from {src} face away from the camera after the world -> camera "
            "conversion: check the camera matrix (world_to_camera, OpenGL convention)"
        )


def file_camera(header: dict[str, Any], warnings: list[str]) -> Camera | None:
    """The camera of a part's header (:meth:`Camera.from_header`); one that cannot be read is
    ignored with a warning; one without a field of view is kept for its pose (a world-space
    position pass may complete it: :func:`camera_from_positions`)."""
    try:
        return Camera.from_header(header)
    except Exception as exc:
        warnings.append(f"camera in the file ignored ({exc})")
        return None


def pose_only_warning(camera: Camera | None) -> str | None:
    """What a file's camera that still lacks its field of view means for the user (None: it
    has one, or there is no camera)."""
    if camera is None or camera.has_intrinsics:
        return None
    return (
        f"the camera in the file ({camera.source}) has {camera.missing_intrinsics()}: its pose "
        "is used, and sizes in scene units need a camera JSON (--camera CAM.json)"
    )
