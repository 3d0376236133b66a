"""The camera of a frame: extrinsics, intrinsics, per-pixel view geometry, and its file forms.

Depict works in OpenGL camera space (+x right, +y up, the camera looks down -z). Three sources
give a camera:

* a camera JSON file from the user::

      {"world_to_camera": [[...4 rows...]],      # OpenGL/Blender convention, column vectors
       "fov_y_deg": 40.0,                        # or "focal_px": 1200.0
       "projection": "perspective",              # or "orthographic" with "ortho_height": 2.0
      }

* the standard OpenEXR attributes ``worldToCamera`` / ``worldToNDC``. The OpenEXR spec's camera
  space is left-handed with +z forward and its matrices multiply row vectors (Imath), so
  ``M_gl = diag(1, 1, -1, 1) @ M_file.T``. Depict adds its intrinsics as ``depict/projection``,
  ``depict/fovYDeg`` and ``depict/orthoHeight`` so it reads its own files without flags; without
  them the field of view is recovered from ``worldToNDC``.
* V-Ray's ``cameraTransform`` (camera-to-world, row vectors), ``cameraFov`` (horizontal, deg).
"""

from __future__ import annotations

import json
import math
import numbers
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np

from gbuffer.atomic import read_text
from gbuffer.errors import FrameError
from ops.checks import FLOAT32_MAX, holds_truth_value
from ops.opencv import written
from ops.parallel import run_strips, strip_rows

Projection = Literal["perspective", "orthographic"]

#: OpenEXR camera space (+z forward) <-> OpenGL camera space (-z forward).
FLIP_Z = np.diag([1.0, 1.0, -1.0, 1.0])

#: The narrowest vertical field of view, degrees (a focal length of ~1e8 image heights).
MIN_FOV_DEG = 1e-6
#: The orthographic heights a camera may have, scene units.
ORTHO_HEIGHTS = (1e-12, 1e12)


def towards_eye(shape: tuple[int, int]) -> np.ndarray:
    """(H, W, 3) float32 (0, 0, 1): the view vector of an orthographic camera (and of a frame
    without one), written by strips of rows on every core."""
    from ops.numerics import fill_triples  # (compiled: loaded by what computes)

    out = np.empty((*shape, 3), np.float32)
    fill_triples(out, (0.0, 0.0, 1.0))
    return out


@dataclass
class Camera:
    """A pinhole or orthographic camera.

    Attributes
    ----------
    world_to_camera : (4, 4) float64 or None
        World to OpenGL camera space, for column vectors. ``None`` when only camera-space
        buffers are used (no world-space normals to convert).
    projection : "perspective" or "orthographic"
    fov_y_deg : float or None
        Vertical field of view of the display window (perspective).
    ortho_height : float or None
        Height of the display window in scene units (orthographic).
    source : where it came from ("given", "file header (worldToCamera)", "solved from ...").
    fit : its reprojection error against the frame's world-space position pass, when there is
        one (:class:`gbuffer.camera_solve.CameraFit` as a dict: rms_px, max_px, pixels,
        outliers).
    """

    world_to_camera: np.ndarray | None = None
    projection: Projection = "perspective"
    fov_y_deg: float | None = None
    ortho_height: float | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    source: str = ""
    fit: dict[str, float | int] | None = None

    def __post_init__(self) -> None:
        if self.projection not in ("perspective", "orthographic"):
            raise FrameError(
                f"camera projection {self.projection!r} is not 'perspective' or 'orthographic'"
            )
        if self.world_to_camera is not None:
            m = np.asarray(self.world_to_camera, dtype=np.float64)
            if m.shape != (4, 4) or not np.all(np.abs(m) <= FLOAT32_MAX):
                raise FrameError(  # (over float32, the header's type: written as inf)
                    "camera world_to_camera must be a 4x4 matrix (4 rows) of numbers finite in "
                    "float32"
                )
            if not abs(np.linalg.det(m[:3, :3])) > 1e-12:
                raise FrameError(
                    "camera world_to_camera has no inverse (its rotation part is singular, e.g. "
                    "all zeros): world-space normals could not be turned into camera space"
                )
            if not np.allclose(m[3], (0.0, 0.0, 0.0, 1.0), rtol=0.0, atol=1e-6):
                raise FrameError(  # (it was ignored: [0, 0, 0, 0] read as a camera)
                    f"camera world_to_camera's last row must be [0, 0, 0, 1] (a rigid "
                    f"transform), got {m[3].tolist()}"
                )
            self.world_to_camera = m
        if self.fov_y_deg is not None and not MIN_FOV_DEG <= self.fov_y_deg < 180.0:
            raise FrameError(f"camera fov_y_deg={self.fov_y_deg} is outside [{MIN_FOV_DEG}, 180)")
        low, high = ORTHO_HEIGHTS
        if self.ortho_height is not None and not low <= self.ortho_height <= high:
            raise FrameError(  # (1e-300 gave pixel sizes of 0, 1e300 inf in the header)
                f"camera ortho_height={self.ortho_height} is outside [{low:g}, {high:g}] scene "
                "units"
            )

    # -- intrinsics ---------------------------------------------------------------------------

    @property
    def has_intrinsics(self) -> bool:
        """Whether it tells a pixel's size: a perspective camera's field of view, an orthographic
        one's height (a file's ``worldToCamera`` alone gives only the pose)."""
        if self.projection == "orthographic":
            return self.ortho_height is not None
        return self.fov_y_deg is not None

    def missing_intrinsics(self) -> str:
        """What it lacks to tell a pixel's size, in words ("" when nothing): "no field of view",
        or "no height" for an orthographic camera, with where a file header gives it."""
        if self.has_intrinsics:
            return ""
        if self.projection == "orthographic":
            return "no height (orthographic: ortho_height)"
        if "worldToCamera" in self.source:
            return (
                "no field of view (a file's worldToCamera needs worldToNDC or depict/fovYDeg "
                "beside it)"
            )
        if "V-Ray" in self.source:
            return "no field of view (V-Ray's cameraFov and displayWindow give it)"
        return "no field of view"

    def focal_px(self, display_height: int) -> float:
        """Focal length in pixels for a display window ``display_height`` pixels high."""
        if self.projection != "perspective" or self.fov_y_deg is None:
            raise FrameError(
                f"the camera ({self.source or 'given'}) has no perspective field of view"
            )
        return 0.5 * display_height / math.tan(math.radians(self.fov_y_deg) / 2.0)

    def pixel_size_at(self, depth: np.ndarray, display_height: int) -> np.ndarray:
        """Scene-unit size of one pixel at planar ``depth`` (for sizes given in scene units)."""
        if self.projection == "orthographic":
            if self.ortho_height is None:
                raise FrameError("orthographic camera without ortho_height")
            return np.full_like(depth, self.ortho_height / display_height, dtype=np.float32)
        return (depth / np.float32(self.focal_px(display_height))).astype(np.float32)

    def view_vectors(
        self,
        shape: tuple[int, int],
        display_size: tuple[int, int],
        origin: tuple[int, int] = (0, 0),
    ) -> np.ndarray:
        """Unit vectors from each pixel's surface point towards the eye, camera space.

        Parameters
        ----------
        shape : (H, W) of the frame's pixel grid (its data window).
        display_size : (width, height) of the display window; intrinsics refer to it.
        origin : (x, y) of the data window's top-left pixel inside the display window.

        Returns
        -------
        (H, W, 3) float32. Orthographic cameras give (0, 0, 1) everywhere.
        """
        if self.projection == "orthographic":
            return towards_eye(shape)
        h, w = shape
        out = np.empty((h, w, 3), np.float32)
        xs, ys = self.image_coordinates(shape, display_size, origin)
        sq_x, sq_y, neg_x = np.square(xs)[None, :], np.square(ys)[:, None], -xs[None, :]

        def rows(a: int, b: int) -> None:
            # the eye is at the origin; the point is at (x, -y, -1) * depth: eye - point ∝
            # (-x, y, 1)
            inv = np.add(sq_x, sq_y[a:b])
            inv += np.float32(1.0)
            cv2.sqrt(inv, dst=inv)
            cv2.divide(1.0, inv, dst=inv)
            written(
                cv2.merge([inv * neg_x, inv * ys[a:b, None], inv], dst=out[a:b]), out, slice(a, b)
            )

        run_strips(h, rows, strip_rows(w))
        return out

    def image_coordinates(
        self,
        shape: tuple[int, int],
        display_size: tuple[int, int],
        origin: tuple[int, int] = (0, 0),
    ) -> tuple[np.ndarray, np.ndarray]:
        """(x per column, y per row) of pixel centres on the image plane at unit depth
        (perspective): x right, y **down** (rows), 0 at the display window's centre."""
        h, w = shape
        dw, dh = display_size
        f = self.focal_px(dh)
        xs = (np.arange(w, dtype=np.float32) + origin[0] + 0.5 - dw / 2.0) / np.float32(f)
        ys = (np.arange(h, dtype=np.float32) + origin[1] + 0.5 - dh / 2.0) / np.float32(f)
        return xs.astype(np.float32), ys.astype(np.float32)

    # -- JSON -------------------------------------------------------------------------------

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Camera:
        """Build a camera from the camera JSON form (see the module docstring)."""
        unknown = sorted(set(data) - _JSON_KEYS)
        if unknown:
            raise FrameError(
                f"camera JSON has unknown keys {unknown}; valid keys: {sorted(_JSON_KEYS)}"
            )
        for key in ("world_to_camera", "fov_y_deg", "focal_px", "height", "ortho_height"):
            if holds_truth_value(data.get(key)):  # (JSON's true is a Python 1)
                raise FrameError(f"camera JSON {key}: expected numbers, not true or false")
        projection = data.get("projection", "perspective")
        fov = _json_number(data, "fov_y_deg")
        if "focal_px" in data:
            if "height" not in data:
                raise FrameError(
                    "camera JSON with focal_px also needs 'height' (the display height in "
                    "pixels it refers to), or give fov_y_deg instead"
                )
            focal, height = (_positive_number(data, k) for k in ("focal_px", "height"))
            fov = math.degrees(2.0 * math.atan(0.5 * height / focal))
        if projection == "perspective" and fov is None:
            raise FrameError("perspective camera JSON needs fov_y_deg or focal_px (+ height)")
        if projection == "orthographic" and data.get("ortho_height") is None:
            raise FrameError("orthographic camera JSON needs ortho_height (scene units)")
        w2c = data.get("world_to_camera")
        cells: Any = [] if w2c is None else np.asarray(w2c, dtype=object).ravel()
        if not all(isinstance(v, numbers.Real) for v in cells):  # ("1" was converted)
            raise FrameError("camera JSON world_to_camera: expected rows of numbers")
        try:
            return cls(
                world_to_camera=None if w2c is None else np.array(w2c, dtype=np.float64),
                projection=projection,
                fov_y_deg=None if fov is None else float(fov),
                ortho_height=_json_number(data, "ortho_height"),
            )
        except (TypeError, ValueError) as exc:
            if isinstance(exc, FrameError):
                raise
            raise FrameError(f"camera JSON is not valid: {exc}") from exc

    @classmethod
    def from_json_file(cls, path: str | Path) -> Camera:
        try:
            data = json.loads(read_text(path))
        except UnicodeDecodeError:
            raise FrameError(f"cannot read camera file {path}: it is not UTF-8 text") from None
        except (OSError, ValueError) as exc:  # (not JSON, a number of too many digits)
            why = (exc.strerror if isinstance(exc, OSError) else None) or exc
            raise FrameError(f"cannot read camera file {path}: {why}") from exc
        except RecursionError:
            raise FrameError(f"cannot read camera file {path}: nested too deeply") from None
        if not isinstance(data, dict):
            raise FrameError(f"camera file {path} must hold a JSON object")
        return cls.from_dict(data)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"projection": self.projection}
        if self.world_to_camera is not None:
            out["world_to_camera"] = self.world_to_camera.tolist()
        if self.fov_y_deg is not None:
            out["fov_y_deg"] = self.fov_y_deg
        if self.ortho_height is not None:
            out["ortho_height"] = self.ortho_height
        return out

    # -- EXR header ---------------------------------------------------------------------------

    def projection_matrix(
        self, aspect: float, near: float = 0.1, far: float = 1000.0
    ) -> np.ndarray:
        """OpenGL-style projection (column vectors) of OpenGL camera space to clip space."""
        p = np.zeros((4, 4))
        if self.projection == "orthographic":
            assert self.ortho_height is not None
            top = self.ortho_height / 2.0
            p[0, 0] = 1.0 / (top * aspect)
            p[1, 1] = 1.0 / top
            p[2, 2] = -2.0 / (far - near)
            p[2, 3] = -(far + near) / (far - near)
            p[3, 3] = 1.0
        else:
            assert self.fov_y_deg is not None
            t = 1.0 / math.tan(math.radians(self.fov_y_deg) / 2.0)
            p[0, 0] = t / aspect
            p[1, 1] = t
            p[2, 2] = (far + near) / (near - far)
            p[2, 3] = 2.0 * far * near / (near - far)
            p[3, 2] = -1.0
        return p

    def to_header(self, display_size: tuple[int, int]) -> dict[str, Any]:
        """Header attributes: ``worldToCamera``, ``worldToNDC`` (OpenEXR convention), intrinsics."""
        w2c = np.eye(4) if self.world_to_camera is None else self.world_to_camera
        aspect = display_size[0] / display_size[1]
        ndc = self.projection_matrix(aspect) @ w2c
        attrs: dict[str, Any] = {
            # C order: the OpenEXR binding reads the buffer without looking at strides.
            "worldToCamera": np.ascontiguousarray((FLIP_Z @ w2c).T, dtype=np.float32),
            "worldToNDC": np.ascontiguousarray(ndc.T, dtype=np.float32),
            "depict/projection": self.projection,
        }
        if self.fov_y_deg is not None:
            attrs["depict/fovYDeg"] = float(self.fov_y_deg)
        if self.ortho_height is not None:
            attrs["depict/orthoHeight"] = float(self.ortho_height)
        if self.source and not self.source.startswith("file header"):
            attrs["depict/cameraSource"] = self.describe_source()
        return attrs

    def describe_source(self) -> str:
        """Where the camera came from, with its reprojection error when known (one line)."""
        text = self.source or "unknown"
        if self.fit and self.fit.get("pixels"):
            text += (
                f"; reprojection error against the position pass: RMS "
                f"{self.fit['rms_px']:.4g} px, max {self.fit['max_px']:.4g} px over "
                f"{self.fit['pixels']} pixels"
            )
            if self.fit.get("outliers"):
                text += f" ({self.fit['outliers']} outliers left out)"
        return text

    @classmethod
    def from_header(cls, header: dict[str, Any]) -> Camera | None:
        """The camera stored in an EXR header, or ``None`` when the header holds none."""
        if "worldToCamera" in header:
            w2c = FLIP_Z @ np.asarray(header["worldToCamera"], dtype=np.float64).T
            projection = header.get("depict/projection", "perspective")
            fov = header.get("depict/fovYDeg")
            ortho = header.get("depict/orthoHeight")
            if fov is None and ortho is None and "worldToNDC" in header:
                ndc = np.asarray(header["worldToNDC"], dtype=np.float64).T
                p = ndc @ np.linalg.inv(w2c)
                if abs(p[3, 2]) > 1e-9:  # perspective: w = -z
                    fov = math.degrees(2.0 * math.atan(1.0 / p[1, 1]))
                else:
                    projection = "orthographic"
                    ortho = 2.0 / p[1, 1]
            how = header.get("depict/cameraSource")
            return cls(
                world_to_camera=w2c,
                projection=projection,
                fov_y_deg=None if fov is None else float(fov),
                ortho_height=None if ortho is None else float(ortho),
                source="file header (worldToCamera" + (f"; {how})" if how else ")"),
            )
        if "cameraTransform" in header:  # V-Ray: camera-to-world, row vectors, -z forward
            c2w = np.asarray(header["cameraTransform"], dtype=np.float64).T
            fov = None
            if "cameraFov" in header and "displayWindow" in header:
                (x0, y0), (x1, y1) = header["displayWindow"]
                aspect = (x1 - x0 + 1) / (y1 - y0 + 1)
                half_h = math.tan(math.radians(float(header["cameraFov"])) / 2.0) / aspect
                fov = math.degrees(2.0 * math.atan(half_h))
            return cls(
                world_to_camera=np.linalg.inv(c2w),
                fov_y_deg=fov,
                source="file header (V-Ray cameraTransform)",
            )
        return None


#: The keys of a camera JSON (:meth:`Camera.from_dict`).
_JSON_KEYS = frozenset(
    {"world_to_camera", "fov_y_deg", "focal_px", "height", "projection", "ortho_height"}
)


def _json_number(data: dict[str, Any], key: str) -> float | None:
    """``data[key]`` of a camera JSON as a number (None when absent): a string ("40") or any
    other kind is refused."""
    value = data.get(key)
    if value is None:
        return None
    if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Real):
        raise FrameError(f"camera JSON {key}: expected a number, got {value!r}")
    return float(value)


def _positive_number(data: dict[str, Any], key: str) -> float:
    """:func:`_json_number`, which must be there, finite and above 0 (a focal length of 0 was
    a division by zero)."""
    value = _json_number(data, key)
    if value is None or not (math.isfinite(value) and value > 0):
        raise FrameError(f"camera JSON {key} must be a finite number above 0, got {value!r}")
    return value
