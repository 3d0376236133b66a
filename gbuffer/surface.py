"""The smooth surface a mesh stands for: its shading normals, welded across seams, creases kept.

Mesh files split a vertex wherever its texture coordinates differ (along UV seams), and smooth
normals averaged per split vertex differ on the two sides of a seam (by 15° on average, up to 68°,
at the seams of ``spot.obj``). :func:`smooth_surface` welds the faces by position first
(``trimesh.Trimesh.merge_vertices`` with ``merge_tex`` and ``merge_norm``), then gives every face
corner the angle-weighted mean of the face normals around its vertex, across every edge that is
not a crease:

- ``smooth``: no creases;
- ``flat``: facet normals (every edge a crease);
- ``auto``: the file's own normals where it has them (OBJ ``vn``, PLY ``nx ny nz``: they say where
  the author wants creases); otherwise edges bent by more than :data:`CREASE_DEG` are creases on
  a mesh made of creases, where such edges outnumber the ones bent by half as much (a box, a CAD
  part such as fandisk), and nowhere on the others (scans and sculpts, whose sharpest edges are
  folds of a smooth surface).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
import trimesh

from gbuffer.mesh import has_file_normals

Shading = Literal["auto", "smooth", "flat"]
SHADINGS: tuple[str, ...] = ("auto", "smooth", "flat")

CREASE_DEG = 30.0  #: dihedral angle above which ``auto`` makes an edge a crease (creased meshes)


@dataclass(frozen=True)
class SmoothSurface:
    """A mesh's faces on vertices welded by position, with a normal at every face corner."""

    vertices: np.ndarray  #: (V, 3) float64, one per distinct position
    faces: np.ndarray  #: (F, 3) int64 into ``vertices``, in the mesh's face order
    normals: np.ndarray | None  #: (F, 3, 3) unit normal at each face corner; None: flat shading


def smooth_surface(mesh: trimesh.Trimesh, shading: Shading = "auto") -> SmoothSurface:
    """The faces of ``mesh`` welded across seams and their corner normals for ``shading``.

    Kept in the mesh's cache (dropped when its vertices or faces change): a mesh rendered again,
    from another camera, does not pay for it twice."""
    if shading not in SHADINGS:
        raise ValueError(f"shading must be one of {', '.join(SHADINGS)}; got {shading!r}")
    key = f"depict_smooth_surface_{shading}"
    cached = mesh._cache[key]
    if isinstance(cached, SmoothSurface):
        return cached
    surface = _smooth_surface(mesh, shading)
    mesh._cache[key] = surface
    return surface


def _smooth_surface(mesh: trimesh.Trimesh, shading: Shading) -> SmoothSurface:
    welded = trimesh.Trimesh(vertices=mesh.vertices, faces=mesh.faces, process=False)
    welded.merge_vertices(merge_tex=True, merge_norm=True)  # keeps the faces' order
    vertices = np.asarray(welded.vertices, np.float64)
    faces = np.asarray(welded.faces, np.int64)
    if shading == "flat":
        return SmoothSurface(vertices, faces, None)
    if shading == "auto" and has_file_normals(mesh):
        given = np.asarray(mesh.vertex_normals, np.float64)[np.asarray(mesh.faces)]
        return SmoothSurface(vertices, faces, _unit(given, welded.face_normals))
    crease = math.radians(CREASE_DEG) if shading == "auto" and is_creased(welded) else None
    return SmoothSurface(vertices, faces, corner_normals(welded, crease))


def is_creased(mesh: trimesh.Trimesh, crease_deg: float = CREASE_DEG) -> bool:
    """Whether the mesh is made of creases: its edges bent by more than ``crease_deg`` outnumber
    those bent by between half that and ``crease_deg`` (boxes, CAD parts; not scans or sculpts,
    whose bends spread over many edges)."""
    angles = np.degrees(mesh.face_adjacency_angles)
    sharp = int(np.count_nonzero(angles > crease_deg))
    bent = int(np.count_nonzero((angles > crease_deg / 2) & (angles <= crease_deg)))
    return sharp > bent


def corner_normals(mesh: trimesh.Trimesh, crease: float | None) -> np.ndarray:
    """(F, 3, 3) unit normal at each face corner: the face normals around the corner's vertex,
    weighted by their angle there, summed over the faces reached without crossing an edge bent
    by more than ``crease`` radians (None: no creases)."""
    faces = np.asarray(mesh.faces, np.int64)
    face_n = np.asarray(mesh.face_normals, np.float64)
    weighted = (np.asarray(mesh.face_angles, np.float64)[..., None] * face_n[:, None, :]).reshape(
        -1, 3
    )
    if crease is None:
        group = faces.reshape(-1)
    else:
        smooth = np.asarray(mesh.face_adjacency_angles) <= crease
        pairs = np.asarray(mesh.face_adjacency, np.int64)[smooth]
        shared = np.asarray(mesh.face_adjacency_edges, np.int64)[smooth]
        links = [
            np.stack([_corner_of(faces, pairs[:, 0], v), _corner_of(faces, pairs[:, 1], v)], 1)
            for v in shared.T
        ]
        group = trimesh.graph.connected_component_labels(
            np.concatenate(links), node_count=faces.size
        )
    total = np.stack(
        [np.bincount(group, weights=weighted[:, i]) for i in range(3)], axis=1
    )  # (groups, 3)
    return _unit(total[group].reshape(-1, 3, 3), face_n)


def _corner_of(faces: np.ndarray, face: np.ndarray, vertex: np.ndarray) -> np.ndarray:
    """Flat corner index (3 f + k) of ``vertex`` in each ``face``."""
    return face * 3 + np.argmax(faces[face] == vertex[:, None], axis=1)


def _unit(normals: np.ndarray, face_normals: np.ndarray) -> np.ndarray:
    """(F, 3, 3) corner normals normalised; the face's normal where one is (nearly) zero."""
    length = np.linalg.norm(normals, axis=-1, keepdims=True)
    weak = length[..., 0] < 1e-12
    out = normals / np.maximum(length, 1e-300)
    out[weak] = np.broadcast_to(face_normals[:, None, :], out.shape)[weak]
    return out
