"""The frame: named float32 buffers on one pixel grid, the camera, and what the file held.

A :class:`Frame` is what every operator reads. Its ``buffers`` use canonical names (the table
:data:`BUFFERS`) whatever the renderer called them; the preset that mapped them is recorded in
``preset`` and where each came from in ``sources``. Everything read but not interpreted (other
channels, parts, header attributes, windows, pixel types, compression) rides along in
``passthrough`` so :func:`gbuffer.write` can give it back bit for bit. What an operator produces
goes to ``outputs`` (EXR channel name -> (H, W) float32 array); writing puts ``outputs`` over
the passthrough channels of the primary part.

Pixel grid: the data window of the primary part (the part holding the interpreted buffers), row 0
at the top. ``display_size`` and ``origin`` place it in the display window, to which the camera's
intrinsics and all sizes "relative to the image height" refer.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from gbuffer.camera import Camera, towards_eye
from gbuffer.errors import MissingBufferError, MissingCameraError
from ops.colorspace import LINEAR_REC709, ColorSpace

#: Canonical buffers: name -> (components, description).
BUFFERS: dict[str, tuple[int, str]] = {
    "beauty": (3, "linear scene-referred RGB radiance"),
    "alpha": (1, "alpha of the beauty"),
    "coverage": (1, "fraction of the pixel covered by a trusted surface, 0..1"),
    "normal": (3, "camera-space unit normal (OpenGL: +z towards the camera)"),
    "depth": (1, "planar view depth (-z camera), positive, +inf on background"),
    "position": (3, "camera-space position"),
    "albedo": (3, "surface albedo (diffuse colour)"),
    "roughness": (1, "specular roughness 0..1"),
    "ao": (1, "ambient occlusion, 1 = unoccluded"),
    "ambient": (3, "ambient lobe radiance"),
    "diffuse": (3, "diffuse lobe radiance"),
    "specular": (3, "specular lobe radiance"),
    "transmission": (3, "transmission lobe radiance"),
    "ambient.light": (3, "ambient lobe light without its colour"),
    "diffuse.light": (3, "diffuse lobe light without its colour (e.g. DiffDir + DiffInd)"),
    "specular.light": (3, "specular lobe light without its colour"),
    "transmission.light": (3, "transmission lobe light without its colour"),
    "ambient.color": (3, "ambient lobe colour"),
    "diffuse.color": (3, "diffuse lobe colour (e.g. DiffCol)"),
    "specular.color": (3, "specular lobe colour"),
    "transmission.color": (3, "transmission lobe colour"),
    "remainder": (3, "beauty minus the sum of lobes (emission, environment, ...)"),
}

#: The buffers of a frame Depict renders (:func:`gbuffer.render.render`).
RENDER_BUFFERS: tuple[str, ...] = (
    "beauty",
    "alpha",
    "coverage",
    "normal",
    "depth",
    "position",
    "albedo",
    "ao",
    "ambient",
    "diffuse",
    "specular",
    "ambient.light",
    "diffuse.light",
    "specular.light",
    "ambient.color",
    "diffuse.color",
    "specular.color",
)

#: Radiance lobes, in the order the beauty is rebuilt from them.
LOBES: tuple[str, ...] = ("ambient", "diffuse", "specular", "transmission")

#: The buffers :attr:`Frame.mask` is made of (the first present): what a result that depends on
#: the mask depends on.
MASK_SOURCES: tuple[str, ...] = ("coverage", "depth", "alpha")


#: Largest component of a normal taken as one (a unit vector's are at most 1): the readers
#: renormalise a file's normals, a frame built in Python holds what its script put there.
NORMAL_COMPONENT_MAX = 2.0


def normals_in_range(normal: np.ndarray) -> bool:
    """Whether no component of ``normal`` (H, W, 3) is past ±:data:`NORMAL_COMPONENT_MAX` (NaN
    does not count): :func:`normal_faults`."""
    return not normal_faults(normal)[0]


def normal_faults(normal: np.ndarray) -> tuple[bool, bool]:
    """Whether some component of ``normal`` (H, W, 3) is past ±:data:`NORMAL_COMPONENT_MAX`
    (±inf is, NaN is not), and whether some component is NaN or ±inf: one compiled pass over
    row strips on every core."""
    from ops.numerics import past_and_not_finite  # (compiled: loaded by what computes)

    n = np.ascontiguousarray(normal, np.float32)
    if n.size == 0:
        return False, False
    return past_and_not_finite(n.reshape(n.shape[0], -1), NORMAL_COMPONENT_MAX)


def _on_surface(depth: np.ndarray) -> np.ndarray:
    """Where a depth is a surface's: finite and positive (0 or below is no surface, as files are
    read)."""
    return np.isfinite(depth) & (depth > 0)


def _check_buffer(name: str, buffer: Any) -> None:
    """ValueError naming ``name`` unless ``buffer`` is an array of real numbers shaped as
    :data:`BUFFERS` says ((H, W) for one component, (H, W, C) for C; any of them for others)."""
    if not isinstance(buffer, np.ndarray) or buffer.dtype.kind not in "biuf":
        kind = buffer.dtype if isinstance(buffer, np.ndarray) else type(buffer).__name__
        raise ValueError(f"frame buffer {name!r} must be an array of real numbers, got {kind}")
    components = BUFFERS.get(name, (0, ""))[0]
    if components == 1:
        right = buffer.ndim == 2
    elif components:
        right = buffer.ndim == 3 and buffer.shape[2] == components
    else:
        right = buffer.ndim in (2, 3)
    if not right:
        want = {1: "(H, W)", 0: "(H, W) or (H, W, C)"}.get(components, f"(H, W, {components})")
        raise ValueError(f"frame buffer {name!r} must be {want}, got {buffer.shape}")


@dataclass
class Passthrough:
    """The file as read, for a lossless write-back.

    ``parts`` is a list of ``(header, channels)`` where ``header`` is the part's attribute dict
    and ``channels`` maps channel names to ``OpenEXR.Channel`` objects holding the pixels in
    their original type. ``primary`` indexes the part whose data window is the frame's grid.
    """

    parts: list[tuple[dict[str, Any], dict[str, Any]]] = field(default_factory=list)
    primary: int = 0


@dataclass
class Frame:
    """Named float32 buffers on one grid, plus the camera and the file's passthrough.

    Attributes
    ----------
    buffers : canonical name -> (H, W) or (H, W, C) float32 array (see :data:`BUFFERS`).
    camera : the camera, or ``None`` when unknown.
    display_size : (width, height) of the display window.
    origin : (x, y) of pixel (0, 0) of the grid inside the display window.
    preset : name of the renderer preset that mapped the file (``"canonical"`` for renders).
    sources : canonical name -> the file channels (or description) it came from.
    outputs : EXR channel name -> (H, W) float32 array, written over the passthrough.
    attributes : header attributes to add or replace in the primary part on write.
    passthrough : the file as read (empty for frames built in memory).
    holes : (H, W) bool, pixels whose radiance was NaN/Inf (:mod:`gbuffer.holes`), or None.
    hole_beauty : the beauty read in the holes, (N, 3), given back after the operators.
    result_layer : the layer a result written into this file goes to by default, following
        the renderer's convention (``"ViewLayer.Depict"`` for a Blender multilayer file, the
        layer of the file's earlier Depict result); ``None``: ``R,G,B,A``.
    history : the pipeline steps applied to the frame so far, each with every parameter.
    colorspace : the linear RGB working space of the radiance, with where it came from
        (:mod:`gbuffer.colorspace`; linear Rec.709 unless the file or the user says otherwise).
    """

    buffers: dict[str, np.ndarray]
    camera: Camera | None = None
    display_size: tuple[int, int] | None = None
    origin: tuple[int, int] = (0, 0)
    preset: str = "canonical"
    sources: dict[str, str] = field(default_factory=dict)
    outputs: dict[str, np.ndarray] = field(default_factory=dict)
    attributes: dict[str, Any] = field(default_factory=dict)
    passthrough: Passthrough = field(default_factory=Passthrough)
    holes: np.ndarray | None = None
    hole_beauty: np.ndarray | None = None
    result_layer: str | None = None
    history: list[dict[str, Any]] = field(default_factory=list)
    colorspace: ColorSpace = LINEAR_REC709

    def __post_init__(self) -> None:
        for name, buffer in self.buffers.items():
            _check_buffer(name, buffer)
        shapes = {b.shape[:2] for b in self.buffers.values()}
        if len(shapes) > 1:
            raise ValueError(f"frame buffers have different sizes: {sorted(shapes)}")
        if self.display_size is None:
            h, w = self.shape
            self.display_size = (w, h)
        elif not (
            len(self.display_size) == 2
            and all(isinstance(v, int | np.integer) and v > 0 for v in self.display_size)
        ):
            raise ValueError(
                f"display_size must be (width, height), two whole numbers > 0; "
                f"got {self.display_size!r}"
            )

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of the pixel grid."""
        for b in self.buffers.values():
            return (int(b.shape[0]), int(b.shape[1]))
        for o in self.outputs.values():
            return (int(o.shape[0]), int(o.shape[1]))
        if self.passthrough.parts:  # a file with no buffer Depict knows (only mattes, ...)
            for c in self.passthrough.parts[self.passthrough.primary][1].values():
                pixels = np.asarray(getattr(c, "pixels", c))
                return (int(pixels.shape[0]), int(pixels.shape[1]))
        raise ValueError("frame has no buffers")

    @property
    def image_height(self) -> int:
        """Height of the display window: the unit of every size given relative to the image."""
        assert self.display_size is not None
        return self.display_size[1]

    def has(self, name: str) -> bool:
        return name in self.buffers

    def need(self, name: str, why: str = "") -> np.ndarray:
        """The buffer ``name``, or a :class:`MissingBufferError` that says who needs it."""
        try:
            return self.buffers[name]
        except KeyError:
            have = ", ".join(sorted(self.buffers)) or "none"
            reason = f" ({why})" if why else ""
            raise MissingBufferError(
                f"the frame has no '{name}' buffer{reason}; buffers found: {have}. "
                f"Pass --preset or map the channel explicitly (--map {name}=LAYER)"
            ) from None

    def need_camera(self, why: str) -> Camera:
        """The frame's camera, one that tells a pixel's size (:attr:`Camera.has_intrinsics`)."""
        if self.camera is None:
            lacks = (
                "no camera in the file, none given and no world-space position pass to solve it "
                "from"
            )
        elif not self.camera.has_intrinsics:
            source = self.camera.source or "given"
            lacks = f"the camera ({source}) has {self.camera.missing_intrinsics()}"
        else:
            return self.camera
        raise MissingCameraError(
            f"{lacks} ({why}); give a camera JSON (--camera CAM.json on the command line, "
            'the camera form field over HTTP): {"world_to_camera": [[...4 rows...]], '
            '"fov_y_deg": 40}'
        )

    @property
    def mask(self) -> np.ndarray:
        """(H, W) float32 in [0, 1]: surface presence (coverage, else finite positive depth, else
        alpha)."""
        if "coverage" in self.buffers:
            return self.buffers["coverage"]
        if "depth" in self.buffers:
            return _on_surface(self.buffers["depth"]).astype(np.float32)
        if "alpha" in self.buffers:
            return np.clip(self.buffers["alpha"], 0.0, 1.0)
        return np.ones(self.shape, np.float32)

    def covered(self) -> np.ndarray:
        """(H, W) bool: the pixels with a surface, ``mask > 0`` (straight from the depth when the
        mask comes from it: no float mask to build and compare)."""
        if "coverage" not in self.buffers and "depth" in self.buffers:
            return _on_surface(self.buffers["depth"])
        return np.asarray(self.mask > 0)

    def view_vectors(self) -> np.ndarray:
        """(H, W, 3) unit vectors towards the eye (orthographic default without a camera)."""
        assert self.display_size is not None
        if self.camera is None or not self.camera.has_intrinsics:
            return towards_eye(self.shape)
        return self.camera.view_vectors(self.shape, self.display_size, self.origin)

    def positions(self) -> np.ndarray:
        """(H, W, 3) camera-space positions: the ``position`` buffer, else rebuilt from depth.

        Perspective: the point on the eye ray at planar depth d, (x d, −y d, −d) with (x, y) the
        pixel on the image plane at unit depth. Orthographic: (x, y, −d) with x, y from the
        pixel's place in the display window. Without a camera (or one without a field of view):
        (0, 0, −d).
        """
        if "position" in self.buffers:
            return self.buffers["position"]
        depth = self.need("depth", "to rebuild camera-space positions")
        d = np.where(np.isfinite(depth), depth, 0.0).astype(np.float32)
        camera = self.camera if self.camera is not None and self.camera.has_intrinsics else None
        if camera is not None and camera.projection == "orthographic":
            assert self.display_size is not None and camera.ortho_height is not None
            dw, dh = self.display_size
            px = camera.ortho_height / dh
            h, w = self.shape
            xs = (np.arange(w, dtype=np.float32) + self.origin[0] + 0.5 - dw / 2.0) * px
            ys = (dh / 2.0 - np.arange(h, dtype=np.float32) - self.origin[1] - 0.5) * px
            return np.dstack(
                [np.broadcast_to(xs[None, :], (h, w)), np.broadcast_to(ys[:, None], (h, w)), -d]
            ).astype(np.float32)
        if camera is None:  # view_vectors' default (0, 0, 1): the point straight ahead
            zero = np.zeros_like(d)
            return np.asarray(cv2.merge([zero, zero, -d]), np.float32)
        # the point on the eye ray at planar depth d is (x d, −y d, −d) (image rows grow down)
        assert self.display_size is not None
        xs, ys = camera.image_coordinates(self.shape, self.display_size, self.origin)
        return np.asarray(cv2.merge([d * xs[None, :], d * -ys[:, None], -d]), np.float32)

    def set_layer(self, layer: str, channels: dict[str, np.ndarray]) -> None:
        """Add output channels ``layer.<name>`` (e.g. ``set_layer("curvature", {"H": h})``)."""
        for name, arr in channels.items():
            self.outputs[f"{layer}.{name}" if layer else name] = np.asarray(arr, np.float32)

    def copy(self) -> Frame:
        """A shallow copy whose dicts can be changed without touching this frame."""
        return Frame(
            buffers=dict(self.buffers),
            camera=self.camera,
            display_size=self.display_size,
            origin=self.origin,
            preset=self.preset,
            sources=dict(self.sources),
            outputs=dict(self.outputs),
            attributes=dict(self.attributes),
            passthrough=self.passthrough,
            holes=self.holes,
            hole_beauty=self.hole_beauty,
            result_layer=self.result_layer,
            history=list(self.history),
            colorspace=self.colorspace,
        )

    def layer(self, name: str) -> dict[str, np.ndarray]:
        """Channels of layer ``name`` (outputs first, then the primary part of the file, then its
        other parts on the same grid, e.g. the result part of the ``part`` layout).

        ``layer("curvature")`` gives ``{"H": ..., "k1": ..., ...}``; a bare channel name such as
        ``"Z"`` gives ``{"Z": ...}``. Arrays are float32 on the frame grid.
        """
        found: dict[str, np.ndarray] = {}
        pt = self.passthrough
        # (channels, whether they may lie off the frame's grid): other parts, the primary part,
        # the outputs last, so that they win
        pools = [(c, True) for i, (_, c) in enumerate(pt.parts) if i != pt.primary]
        if pt.parts:
            pools.append((pt.parts[pt.primary][1], False))
        pools.append((self.outputs, False))
        prefix = f"{name}."
        for pool, off_grid in pools:
            for channel, value in pool.items():
                if not (channel == name or channel.startswith(prefix)):
                    continue
                pixels = getattr(value, "pixels", value)
                if off_grid and np.shape(pixels) != self.shape:
                    continue
                if channel == name:
                    found[channel] = np.asarray(pixels, np.float32)
                elif channel.startswith(prefix):
                    found[channel[len(prefix) :]] = np.asarray(pixels, np.float32)
        return found
