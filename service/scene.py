"""Render a mesh to a canonical G-buffer EXR: ``depict render`` and ``POST /v1/render`` (on a
worker) both call :func:`render_to_file` with a :class:`RenderRequest`.

The renderer (trimesh, pyrender, OpenGL) is imported when a mesh is rendered, so the HTTP
server's own process, which builds render requests, never loads it; its workers do.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

from gbuffer.camera import Camera
from gbuffer.io import write
from ops.shading import parse_light


@dataclass(frozen=True)
class RenderRequest:
    """What to render: size, the camera (``None``: framed automatically from ``azimuth`` and
    ``elevation``, degrees), lights as ``depict render --light`` takes them (none: the
    default), and the normals' ``shading`` (auto, smooth or flat)."""

    width: int = 960
    height: int = 720
    camera: Camera | None = None
    azimuth: float = 30.0
    elevation: float = 20.0
    lights: tuple[str, ...] = ()
    shading: Literal["auto", "smooth", "flat"] = "auto"


def render_to_file(
    mesh_path: str | Path, out_path: str | Path, scene: RenderRequest
) -> dict[str, Any]:
    """Render ``mesh_path`` as ``scene`` says and write the EXR; ``{"size": [w, h],
    "warnings": [...]}`` (:data:`NOTHING_SEEN` when no pixel shows the mesh; the triangles left
    out for vertices that are not finite).

    A light that does not parse is a ValueError naming ``--light`` (the service names its field).
    """
    from gbuffer.mesh import LEFT_OUT
    from gbuffer.render import auto_camera, load_mesh, render

    mesh = load_mesh(mesh_path)
    try:
        lights = [parse_light(text) for text in scene.lights] or None
    except ValueError as exc:
        raise ValueError(f"--light: {exc}") from None
    camera = scene.camera
    if camera is None:
        camera = auto_camera(
            mesh,
            width=scene.width,
            height=scene.height,
            azimuth_deg=scene.azimuth,
            elevation_deg=scene.elevation,
        )
    frame = render(
        mesh, scene.width, scene.height, camera=camera, lights=lights, shading=scene.shading
    )
    write(frame, out_path)
    said = [] if frame.covered().any() else [NOTHING_SEEN]
    bad, total = mesh.metadata.get(LEFT_OUT, (0, 0))
    if bad:
        said.append(
            f"{bad} of the mesh's {total} triangles have a vertex with NaN or infinite "
            "coordinates: they are left out"
        )
    return {"size": [scene.width, scene.height], "warnings": said}


#: The warning of a render in which no pixel shows the mesh.
NOTHING_SEEN = (
    "no pixel shows the mesh: it is out of the camera's view, or has no area (degenerate "
    "triangles); check the camera or the mesh"
)
