"""Render float32 G-buffers from a mesh: OSMesa visibility, exact float64 geometry on the CPU.

pyrender's OSMesa context renders into an 8-bit colour buffer, and 8-bit normals add 11-31 %
noise to curvature (DESIGN.md), so Depict reads no colour from it: the GPU only tells which
triangle covers each pixel centre (:class:`gbuffer.osmesa.TriangleIds`, a float32 framebuffer of
its own in pyrender's OSMesa context).

The triangles drawn are those of the smooth surface the mesh stands for: faces welded across UV
seams, with a normal at each corner for the shading mode (:mod:`gbuffer.surface`), refined by Loop
subdivision where they are coarse for the image (:mod:`gbuffer.subdivision`). Everything else is
computed on the CPU in float64 from that index: the exact intersection of the pixel's ray with the
triangle (Möller-Trumbore), its barycentric coordinates, the interpolated vertex normals (or the
facet normal with ``shading="flat"``), colours and texture coordinates (through the position of
the hit on the input face); then stored as float32. This avoids both 8-bit quantisation and the
interpolation error of a software rasteriser on thin triangles (llvmpipe's perspective-correct
interpolation is off by up to 2e-4 there). Pixels are sampled at their centres without
anti-aliasing: coverage is 1 or 0, and every value belongs to exactly one surface.

Vertices are transformed to camera space on the CPU in float64, so the GPU only projects them.
Lobes come from :func:`ops.shading.shade_lobes`, ambient occlusion from
:func:`ops.ambient_occlusion.ssao` (multiplied into the ambient lobe), and the beauty is the sum
of the lobes.
"""

from __future__ import annotations

import atexit
import math
import os
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Literal

import numpy as np
import trimesh

from gbuffer.camera import Camera
from gbuffer.errors import FrameError
from gbuffer.frame import BUFFERS, Frame
from gbuffer.mesh import (
    bounding_sphere,
    corner_colors,
    load_mesh,
    sample_texture,
    texture_image,
)
from gbuffer.osmesa import TriangleIds
from gbuffer.subdivision import View, levels_for, refine
from gbuffer.surface import Shading, smooth_surface
from ops.ambient_occlusion import ssao
from ops.shading import MODELS, Light, shade_lobes

MAX_SIZE = 16384  # llvmpipe's GL_MAX_RENDERBUFFER_SIZE

_CHUNK = 1 << 18  # pixels per float64 batch in the exact-geometry pass


def look_at(eye: np.ndarray, target: np.ndarray, up: Sequence[float] = (0, 1, 0)) -> np.ndarray:
    """World-to-camera matrix (OpenGL: the camera looks down −z, +y up) of a camera at ``eye``."""
    eye = np.asarray(eye, np.float64)
    forward = np.asarray(target, np.float64) - eye
    forward /= np.linalg.norm(forward)
    up_v = np.asarray(up, np.float64)
    if abs(float(np.dot(forward, up_v))) > 0.999 * np.linalg.norm(up_v):
        up_v = np.array([0.0, 0.0, -1.0]) if forward[1] > 0 else np.array([0.0, 0.0, 1.0])
    right = np.cross(forward, up_v)
    right /= np.linalg.norm(right)
    true_up = np.cross(right, forward)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = right, true_up, -forward
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def auto_camera(
    mesh: trimesh.Trimesh,
    *,
    width: int = 1920,
    height: int = 1080,
    azimuth_deg: float = 30.0,
    elevation_deg: float = 20.0,
    distance: float | None = None,
    fov_y_deg: float = 35.0,
    projection: Literal["perspective", "orthographic"] = "perspective",
    margin: float = 1.05,
) -> Camera:
    """A camera that frames the mesh's bounding sphere.

    The camera orbits the sphere's centre: azimuth about world +y (0 = looking from +z, 90 =
    from +x), elevation above the xz plane, up = +y. ``distance`` (from the centre, in scene
    units) defaults to the one that fits the sphere, times ``margin``, in both the vertical and the
    horizontal field of view; orthographic cameras get ``ortho_height`` fitting the sphere and
    stand at 3 radii unless ``distance`` is given.
    """
    _check_size(width, height)
    if not 0.0 < fov_y_deg < 180.0:
        raise ValueError(f"fov_y_deg must be in (0, 180), got {fov_y_deg}")
    if not margin > 0.0:
        raise ValueError(f"margin must be > 0, got {margin}")
    if distance is not None and not distance > 0.0:
        raise ValueError(f"distance must be > 0, got {distance}")
    for name, degrees, bound in (("azimuth", azimuth_deg, 360), ("elevation", elevation_deg, 90)):
        # (not finite: "math domain error", or a NaN camera matrix; past the bounds, the HTTP
        # service's, an elevation of 120 framed the mesh from behind, upside down)
        if not (math.isfinite(degrees) and -bound <= degrees <= bound):
            raise ValueError(
                f"{name} must be a finite number of degrees in [-{bound}, {bound}], got {degrees}"
            )
    centre, radius = bounding_sphere(mesh)
    aspect = width / height
    az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
    direction = np.array([math.cos(el) * math.sin(az), math.sin(el), math.cos(el) * math.cos(az)])
    if projection == "orthographic":
        ortho_height = 2.0 * radius * margin * max(1.0, 1.0 / aspect)
        dist = 3.0 * radius if distance is None else distance
        w2c = look_at(centre + dist * direction, centre)
        return Camera(world_to_camera=w2c, projection="orthographic", ortho_height=ortho_height)
    if projection != "perspective":
        raise ValueError(f"projection must be 'perspective' or 'orthographic', got {projection!r}")
    half_y = math.radians(fov_y_deg) / 2.0
    half = min(half_y, math.atan(math.tan(half_y) * aspect))
    dist = radius * margin / math.sin(half) if distance is None else distance
    w2c = look_at(centre + dist * direction, centre)
    return Camera(world_to_camera=w2c, projection="perspective", fov_y_deg=fov_y_deg)


def default_lights() -> list[Light]:
    """A key light from the upper left (towards (−1, 1, 1)) and a weak fill from the right."""
    return [
        Light("directional", (-1.0, 1.0, 1.0), intensity=1.0),
        Light("directional", (1.0, -0.25, 0.6), intensity=0.25),
    ]


# -- rasteriser -------------------------------------------------------------------------------


def _check_size(width: int, height: int) -> None:
    for name, value in (("width", width), ("height", height)):
        if not isinstance(value, int | np.integer) or not 1 <= value <= MAX_SIZE:
            raise ValueError(f"{name} must be an integer in 1..{MAX_SIZE}, got {value!r}")


def _near_far(z: np.ndarray, orthographic: bool) -> tuple[float, float]:
    """Clip planes (near, far) around points at camera-space ``z`` (the camera looks down −z)."""
    depth_min, depth_max = float(-z.max()), float(-z.min())
    # a margin that survives float32 for flat meshes (zero depth range) far from the camera
    pad = 0.01 * (depth_max - depth_min) + 1e-4 * max(abs(depth_min), abs(depth_max), 1e-6)
    far = depth_max + pad
    if orthographic:
        return depth_min - pad, far
    if far <= 0.0:
        return 1e-3, 1.0  # everything behind the camera: nothing is drawn
    return max(depth_min - pad, far * 1e-4), far


class Rasterizer(TriangleIds):
    """Rasterises meshes into G-buffers in an OSMesa context (:class:`TriangleIds`).

    One instance is reusable across meshes and sizes (the framebuffer is reallocated when the size
    changes; creating the context is the expensive part). Thread-safe (one render at a time).
    Call :meth:`delete` (or use it as a context manager) to free the context.
    """

    def rasterize(
        self,
        mesh: trimesh.Trimesh,
        camera: Camera,
        width: int,
        height: int,
        *,
        shading: Shading = "auto",
        albedo: Sequence[float] | None = None,
    ) -> dict[str, np.ndarray]:
        """Geometry buffers of ``mesh`` seen by ``camera`` over a ``width`` × ``height`` window.

        The mesh stands for the smooth surface of :func:`gbuffer.surface.smooth_surface` (faces
        welded across UV seams, corner normals for ``shading``), Loop-subdivided as the image
        needs (:func:`gbuffer.subdivision.levels_for`). The GPU only resolves visibility: which
        triangle covers each pixel centre. Position, depth, normal and albedo are then computed on
        the CPU in float64 from that triangle: the exact intersection of the pixel's ray with it,
        its barycentric coordinates, and the barycentric interpolation of the vertex normals
        (renormalised) or the facet normal (``flat``); normals of back faces are flipped towards
        the camera.

        Returns canonical buffers (row 0 at the top): ``coverage`` (H, W) 1/0, ``normal``
        (H, W, 3) camera-space unit (0 on background), ``depth`` (H, W) planar, +inf on
        background, ``position`` (H, W, 3) camera space (0 on background), ``albedo`` (H, W, 3)
        linear (mesh texture / vertex / face colours unless ``albedo`` is given; 0.8 grey
        otherwise; 0 on background).
        """
        _check_size(width, height)
        if camera.world_to_camera is None:
            raise FrameError("rendering needs a camera with a world_to_camera matrix")
        if camera.projection == "orthographic" and camera.ortho_height is None:
            raise FrameError("rendering with an orthographic camera needs its ortho_height")
        if camera.projection == "perspective" and camera.fov_y_deg is None:
            raise FrameError("rendering with a perspective camera needs its fov_y_deg")
        faces = np.asarray(mesh.faces, np.int64)
        if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
            raise FrameError("mesh has no triangles")
        constant = np.asarray((0.8, 0.8, 0.8) if albedo is None else albedo, np.float64)
        if constant.shape != (3,) or not np.all(np.isfinite(constant)) or np.any(constant < 0):
            raise ValueError(f"albedo must be 3 finite values >= 0, got {albedo!r}")
        rays = _PixelRays(camera, width, height)
        geometry = _MeshGeometry(mesh, shading, camera, rays, albedo is not None)
        near, far = _near_far(geometry.verts[:, 2], rays.ortho)
        proj = camera.projection_matrix(width / height, near, far).astype(np.float32)
        corners = geometry.verts.astype(np.float32)[geometry.drawn.faces].reshape(-1, 3)
        with self._lock:
            ids = self.draw(corners, proj, width, height)
        buffers = geometry.buffers(ids, rays)
        if geometry.texture is None and geometry.corner_colors is None:
            buffers["albedo"][buffers["coverage"] > 0] = constant
        return buffers


class _PixelRays:
    """Camera rays through pixel centres: origin and direction, camera space, float64."""

    def __init__(self, camera: Camera, width: int, height: int) -> None:
        self.width, self.height = width, height
        self.ortho = camera.projection == "orthographic"
        if self.ortho:
            assert camera.ortho_height is not None
            self.scale = camera.ortho_height / height
        else:
            self.scale = 1.0 / camera.focal_px(height)
        self.cx, self.cy = width / 2.0, height / 2.0

    def at(self, pix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(origins, directions), each (N, 3), for flat pixel indices; direction z = −1."""
        rows, cols = np.divmod(pix, self.width)
        x = (cols + (0.5 - self.cx)) * self.scale
        y = -(rows + (0.5 - self.cy)) * self.scale
        n = pix.size
        origin = np.zeros((n, 3))
        direction = np.empty((n, 3))
        direction[:, 2] = -1.0
        if self.ortho:
            origin[:, 0], origin[:, 1] = x, y
            direction[:, 0] = direction[:, 1] = 0.0
        else:
            direction[:, 0], direction[:, 1] = x, y
        return origin, direction

    def view(self, near: float) -> View:
        """What :func:`gbuffer.subdivision.levels_for` needs to size triangles in pixels."""
        return View(self.scale, self.ortho, self.width, self.height, near)


class _MeshGeometry:
    """A mesh's surface in camera space, the triangles drawn for it, and the exact per-pixel
    evaluation."""

    def __init__(
        self,
        mesh: trimesh.Trimesh,
        shading: Shading,
        camera: Camera,
        rays: _PixelRays,
        constant_albedo: bool,
    ) -> None:
        assert camera.world_to_camera is not None
        w2c = np.asarray(camera.world_to_camera, np.float64)
        rot = w2c[:3, :3]
        surface = smooth_surface(mesh, shading)
        self.faces = np.asarray(mesh.faces, np.int64)  # for texture coordinates and colours
        verts = surface.vertices @ rot.T + w2c[:3, 3]
        near = _near_far(verts[:, 2], rays.ortho)[0]
        self.drawn = refine(surface, levels_for(surface, verts, rays.view(near)))
        self.verts = self.drawn.vertices @ rot.T + w2c[:3, 3]
        self.normals: np.ndarray | None = None  # camera space, indexed by drawn.normal_faces
        if self.drawn.normals is not None:
            normals = self.drawn.normals @ np.linalg.inv(rot)  # (R⁻¹)ᵀ n, as row vectors
            length = np.linalg.norm(normals, axis=1, keepdims=True)
            self.normals = normals / np.maximum(length, 1e-300)
        self.texture = None if constant_albedo else texture_image(mesh)
        self.uv = (
            np.asarray(getattr(mesh.visual, "uv", None), np.float64)
            if self.texture is not None
            else None
        )
        self.corner_colors = (
            None if constant_albedo or self.texture is not None else corner_colors(mesh)
        )

    def buffers(self, ids: np.ndarray, rays: _PixelRays) -> dict[str, np.ndarray]:
        """Canonical geometry buffers from the drawn triangle at each pixel (``ids``, −1: none);
        albedo holds the colours (0 where the mesh has none)."""
        height, width = ids.shape
        covered = ids >= 0
        pix = np.flatnonzero(covered)
        position = np.zeros((height * width, 3), np.float32)
        normal = np.zeros((height * width, 3), np.float32)
        depth = np.full(height * width, np.inf, np.float32)
        color = np.zeros((height * width, 3), np.float32)
        tri = ids.reshape(-1)[pix]
        for i in range(0, pix.size, _CHUNK):
            sel = slice(i, i + _CHUNK)
            p, n, c = self.shade(tri[sel], *rays.at(pix[sel]))
            position[pix[sel]] = p
            normal[pix[sel]] = n
            depth[pix[sel]] = -p[:, 2]
            if c is not None:
                color[pix[sel]] = c
        if self.texture is not None and pix.size:
            color = sample_texture(self.texture, color, covered.reshape(-1))
        shape3 = (height, width, 3)
        return {
            "coverage": covered.astype(np.float32),
            "normal": normal.reshape(shape3),
            "depth": depth.reshape(height, width),
            "position": position.reshape(shape3),
            "albedo": color.reshape(shape3),
        }

    def shade(
        self, tri: np.ndarray, origin: np.ndarray, direction: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """Position, normal and colour (or uv for textures) at the rays' hits on drawn
        triangles ``tri``.

        Möller-Trumbore: with e1 = B − A, e2 = C − A, s = o − A, the hit o + t d has barycentric
        coordinates (1 − u − v, u, v), u = (s·(d × e2))/det, v = (d·(s × e1))/det,
        t = (e2·(s × e1))/det, det = e1·(d × e2), all in float64.
        """
        corners = self.verts[self.drawn.faces[tri]]
        a = corners[:, 0]
        e1 = corners[:, 1] - a
        e2 = corners[:, 2] - a
        pvec = np.cross(direction, e2)
        det = np.einsum("ij,ij->i", e1, pvec)
        ok = np.abs(det) > 1e-300
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        svec = origin - a
        qvec = np.cross(svec, e1)
        u = np.einsum("ij,ij->i", svec, pvec) * inv
        v = np.einsum("ij,ij->i", direction, qvec) * inv
        t = np.einsum("ij,ij->i", e2, qvec) * inv
        # a triangle seen exactly edge-on (det = 0): its centroid
        u = np.where(ok, u, 1.0 / 3.0)
        v = np.where(ok, v, 1.0 / 3.0)
        centroid_t = -(a[:, 2] + (e1[:, 2] + e2[:, 2]) / 3.0) - origin[:, 2]
        t = np.where(ok, t, centroid_t)
        position = origin + t[:, None] * direction
        w = np.stack([1.0 - u - v, u, v], axis=1)
        face_n = np.cross(e1, e2)
        if self.normals is None or self.drawn.normal_faces is None:
            n = face_n
        else:
            n = np.einsum("ij,ijk->ik", w, self.normals[self.drawn.normal_faces[tri]])
            weak = np.einsum("ij,ij->i", n, n) < 1e-24
            n[weak] = face_n[weak]
        # seen from behind (the ray runs along the facet normal): flip towards the camera
        back = np.einsum("ij,ij->i", face_n, direction) > 0.0
        n[back] = -n[back]
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
        color: np.ndarray | None = None
        if self.uv is not None or self.corner_colors is not None:
            color = self._color(tri, w)
        return (
            position.astype(np.float32),
            n.astype(np.float32),
            None if color is None else color.astype(np.float32),
        )

    def _color(self, tri: np.ndarray, w: np.ndarray) -> np.ndarray:
        """Colours (or texture coordinates, in the first two channels) at barycentric
        coordinates ``w`` on drawn triangles ``tri``: those of the input face under them."""
        face = self.drawn.parent[tri]
        if self.drawn.bary is not None:
            w = np.einsum("ij,ijk->ik", w, self.drawn.bary[tri])
        # a hit a rounding error outside its triangle: no colour outside the corners' range
        w = np.clip(w, 0.0, None)
        w /= w.sum(axis=1, keepdims=True)
        if self.uv is not None:
            color = np.zeros((len(tri), 3))
            color[:, :2] = np.einsum("ij,ijk->ik", w, self.uv[self.faces[face]])
            return color
        assert self.corner_colors is not None
        return np.einsum("ij,ijk->ik", w, self.corner_colors[face])


_SHARED: Rasterizer | None = None
_SHARED_PID = 0
_SHARED_LOCK = threading.Lock()


def shared_rasterizer() -> Rasterizer:
    """The process-wide :class:`Rasterizer` (created on first use, freed at exit).

    A forked child (worker processes) gets a fresh one rather than its parent's context.
    """
    global _SHARED, _SHARED_PID
    with _SHARED_LOCK:
        if _SHARED is None or _SHARED_PID != os.getpid():
            _SHARED = Rasterizer()
            _SHARED_PID = os.getpid()
        return _SHARED


@atexit.register
def release_context() -> None:
    """Free the shared rasterizer's OSMesa context (it is recreated if needed again)."""
    global _SHARED
    with _SHARED_LOCK:
        if _SHARED is not None and _SHARED_PID == os.getpid():
            _SHARED.delete()
        _SHARED = None


# -- render -----------------------------------------------------------------------------------


def render(
    mesh: trimesh.Trimesh | str | Path,
    width: int = 1920,
    height: int = 1080,
    camera: Camera | None = None,
    lights: Sequence[Light] | None = None,
    albedo: Sequence[float] | None = None,
    ao: Literal["ssao", "none"] = "ssao",
    *,
    shading: Shading = "auto",
    model: str = "blinn_phong",
    ambient: float = 0.1,
    specular: float | Sequence[float] = 0.3,
    shininess: float = 32.0,
    ao_radius: float | None = None,
    ao_directions: int = 8,
    ao_steps: int = 4,
    rasterizer: Rasterizer | None = None,
    outputs: bool = True,
) -> Frame:
    """Render a mesh into a canonical frame: float32 geometry, lobes, AO and beauty.

    Parameters
    ----------
    mesh : a mesh, or a path for :func:`load_mesh`.
    width, height : image size in pixels, 1..16384.
    camera : default :func:`auto_camera` (30° azimuth, 20° elevation, 35° vertical FOV).
    lights : camera-space lights; default :func:`default_lights` (key upper left + weak fill).
    albedo : linear RGB; default the mesh's texture / vertex / face colours, else 0.8 grey.
    ao : ``"ssao"`` (:func:`ops.ambient_occlusion.ssao`, multiplied into the ambient lobe) or
        ``"none"`` (AO = 1).
    shading : ``"auto"`` (the file's normals, else smooth with the creases of a creased mesh),
        ``"smooth"`` or ``"flat"`` (facet normals); see :mod:`gbuffer.surface`.
    model, ambient, specular, shininess : shading, see :func:`ops.shading.shade_lobes`.
    ao_radius : SSAO radius in scene units; default 0.2 × the bounding-sphere radius.
    ao_directions, ao_steps : SSAO sampling.
    rasterizer : a :class:`Rasterizer` to use; default the shared one.
    outputs : fill ``frame.outputs`` with :func:`canonical_outputs` (contiguous per-channel
        copies: as much memory again as the buffers); ``False`` leaves it empty.

    Returns
    -------
    Frame with ``preset="canonical"``, buffers :data:`gbuffer.frame.RENDER_BUFFERS` (beauty =
    ambient + diffuse + specular; alpha = coverage, 1 covered / 0 background), ``outputs``
    filled by :func:`canonical_outputs` and ``attributes`` by ``camera.to_header``.
    """
    if not isinstance(mesh, trimesh.Trimesh):
        mesh = load_mesh(mesh)
    _check_size(width, height)
    if ao not in ("ssao", "none"):
        raise ValueError(f"ao must be 'ssao' or 'none', got {ao!r}")
    if model not in MODELS:
        raise ValueError(f"model must be one of {', '.join(MODELS)}; got {model!r}")
    if ao_radius is not None and not (math.isfinite(ao_radius) and ao_radius > 0.0):
        raise ValueError(f"ao_radius must be > 0 (scene units), got {ao_radius}")
    if camera is None:
        camera = auto_camera(mesh, width=width, height=height)
    light_list = default_lights() if lights is None else list(lights)
    for light in light_list:
        if not isinstance(light, Light):
            raise ValueError(
                f"lights must be ops.shading.Light objects, got {type(light).__name__}"
            )
    raster = rasterizer if rasterizer is not None else shared_rasterizer()
    geo = raster.rasterize(mesh, camera, width, height, shading=shading, albedo=albedo)
    display = (width, height)
    view = camera.view_vectors((height, width), display)
    if ao == "ssao":
        radius = 0.2 * bounding_sphere(mesh)[1] if ao_radius is None else ao_radius
        ao_buf = _ssao(geo, camera, radius, ao_directions, ao_steps)
    else:
        ao_buf = np.ones((height, width), np.float32)
    lobes = shade_lobes(
        geo["normal"],
        geo["position"],
        view,
        geo["albedo"],
        light_list,
        ambient=ambient,
        specular=specular,
        shininess=shininess,
        ao=ao_buf,
        model=model,
    )
    beauty = lobes["ambient"] + lobes["diffuse"] + lobes["specular"]
    buffers: dict[str, np.ndarray] = {
        "beauty": np.asarray(beauty, np.float32),
        "alpha": geo["coverage"],
        **geo,
        "ao": np.where(geo["coverage"] > 0, ao_buf, np.float32(1.0)).astype(np.float32),
        **lobes,
    }
    source = "depict render (OSMesa float32 rasteriser)"
    return Frame(
        buffers=buffers,
        camera=camera,
        display_size=display,
        preset="canonical",
        sources={name: source for name in buffers},
        outputs=canonical_outputs(buffers) if outputs else {},
        attributes=camera.to_header(display),
    )


def _ssao(
    geo: dict[str, np.ndarray], camera: Camera, radius: float, directions: int, steps: int
) -> np.ndarray:
    """:func:`ops.ambient_occlusion.ssao` of rasterised geometry seen by ``camera``."""
    height = geo["depth"].shape[0]
    ortho = camera.projection == "orthographic"
    return ssao(
        geo["depth"],
        geo["normal"],
        radius=radius,
        focal_px=None if ortho else camera.focal_px(height),
        pixel_size=camera.ortho_height / height if ortho and camera.ortho_height else None,
        directions=directions,
        steps=steps,
    )


# -- canonical channels -----------------------------------------------------------------------

_CHANNELS: dict[str, tuple[str, ...]] = {
    "beauty": ("R", "G", "B"),
    "alpha": ("A",),
    "normal": ("N.X", "N.Y", "N.Z"),
    "depth": ("depth.Z",),
    "position": ("P.X", "P.Y", "P.Z"),
    "ao": ("AO.X",),
    "coverage": ("coverage.X",),
    "roughness": ("roughness.X",),
}


def channel_names(name: str) -> tuple[str, ...]:
    """EXR channel names of canonical buffer ``name`` (DESIGN.md, "Canonical channels").

    ``beauty`` -> R G B, ``alpha`` -> A, ``normal`` -> N.X N.Y N.Z, ``depth`` -> depth.Z,
    ``position`` -> P.X P.Y P.Z, ``ao`` -> AO.X, colour buffers such as ``albedo``, ``diffuse``,
    ``diffuse.light`` -> ``<name>.R .G .B``; other one-channel buffers -> ``<name>.X``.
    """
    if name in _CHANNELS:
        return _CHANNELS[name]
    comps = BUFFERS.get(name, (3, ""))[0]
    return (f"{name}.X",) if comps == 1 else (f"{name}.R", f"{name}.G", f"{name}.B")


def canonical_outputs(buffers: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """EXR channel name -> (H, W) float32 for each buffer, named per :func:`channel_names`.

    ``coverage`` is left out when ``alpha`` is present (a render's alpha is its coverage).
    Raises ValueError for a buffer whose shape does not fit its channel count.
    """
    out: dict[str, np.ndarray] = {}
    for name, arr in buffers.items():
        if name == "coverage" and "alpha" in buffers:
            continue
        names = channel_names(name)
        a = np.asarray(arr, np.float32)
        if len(names) == 1:
            if a.ndim == 3 and a.shape[2] == 1:
                a = a[..., 0]
            if a.ndim != 2:
                raise ValueError(f"buffer {name!r} must be (H, W), got shape {a.shape}")
            out[names[0]] = np.ascontiguousarray(a)
        else:
            if a.ndim != 3 or a.shape[2] != len(names):
                raise ValueError(f"buffer {name!r} must be (H, W, {len(names)}), got {a.shape}")
            for i, channel in enumerate(names):
                out[channel] = np.ascontiguousarray(a[..., i])
    return out
