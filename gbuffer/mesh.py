"""Meshes: reading them (trimesh, PLY triangle strips included) and their colours.

Colours are linear RGB: a base-colour texture (sampled per pixel by :func:`sample_texture`), or
vertex / face colours per face corner; sRGB 8-bit values are linearised through a lookup table.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import trimesh

from gbuffer.atomic import regular_file
from gbuffer.errors import FrameError

MESH_SUFFIXES = (".obj", ".ply", ".stl", ".glb", ".gltf", ".off")
FILE_NORMALS = "depict_file_normals"  #: mesh.metadata key: its normals are the file's own


# -- meshes -----------------------------------------------------------------------------------


def _tristrips_to_faces(strips: np.ndarray) -> np.ndarray:
    """Triangles of PLY ``tristrips`` (−1 restarts, alternating winding), degenerates dropped."""
    s = np.asarray(strips, np.int64).reshape(-1)
    if s.size < 3:
        return np.zeros((0, 3), np.int64)
    restart = s < 0
    start = np.maximum.accumulate(np.where(restart, np.arange(s.size), -1))  # last restart idx
    pos = np.arange(s.size) - start - 1  # index within its strip
    i = np.arange(s.size - 2)
    ok = ~(restart[i] | restart[i + 1] | restart[i + 2])
    i = i[ok]
    odd = (pos[i] % 2) == 1
    a, b, c = s[i], s[i + 1], s[i + 2]
    faces = np.stack([a, np.where(odd, c, b), np.where(odd, b, c)], axis=1)
    keep = (
        (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    )
    return faces[keep]


def _from_point_cloud(loaded: Any, path: Path) -> trimesh.Trimesh | None:
    """A mesh from a PLY whose faces are triangle strips (trimesh reads those as points)."""
    raw = getattr(loaded, "metadata", {}).get("_ply_raw")
    if not raw or "tristrips" not in raw:
        return None
    data = raw["tristrips"]["data"]
    # ASCII files give {name: (rows, n) array}; binary ones a structured array (count, values)
    rows = next(iter(data.values())) if isinstance(data, dict) else data[data.dtype.names[0]]
    strips = [np.asarray(row[row.dtype.names[-1]] if row.dtype.names else row) for row in rows]
    faces = _tristrips_to_faces(np.concatenate([np.append(st, -1) for st in strips]))
    vertices = np.asarray(loaded.vertices, np.float64)
    if faces.size and (faces.max() >= len(vertices) or faces.min() < 0):
        raise FrameError(f"mesh {path}: triangle strips index missing vertices")
    return trimesh.Trimesh(vertices=vertices, faces=faces, process=False)


#: The largest vertex coordinate a mesh may have: the renderer works in float32, where the
#: squares of larger ones overflow (1e30 gave NaN pixels).
MAX_COORDINATE = 1e15


#: mesh.metadata key: (triangles left out for vertices with NaN or infinite coordinates, of all)
LEFT_OUT = "depict_left_out"


def _read(path: Path) -> tuple[Any, tuple[int, int]]:
    """trimesh's reading of ``path`` (a scene flattened into one mesh) and how many of its
    triangles had a vertex with NaN or infinite coordinates, of all: trimesh's processing
    (merged vertices, as ``trimesh.load`` does by default) leaves those out."""
    loaded: Any = trimesh.load(str(path), process=False)
    parts = list(loaded.geometry.values()) if isinstance(loaded, trimesh.Scene) else [loaded]
    bad = total = 0
    for part in parts:
        if isinstance(part, trimesh.Trimesh):
            finite = np.isfinite(np.asarray(part.vertices)).all(axis=1)
            faces = np.asarray(part.faces)
            bad += int(np.count_nonzero(~finite[faces].all(axis=1))) if len(faces) else 0
            total += len(faces)
            part.process()
    if isinstance(loaded, trimesh.Scene):
        loaded = loaded.to_mesh() if loaded.geometry else None
    return loaded, (bad, total)


def load_mesh(path: str | Path) -> trimesh.Trimesh:
    """Read a triangle mesh (OBJ, PLY incl. triangle strips, STL, GLB/glTF, OFF).

    Scenes (glTF, multi-object OBJ) are flattened into one mesh with their node transforms
    applied. Raises :class:`FrameError` when the file is missing, unreadable, or holds no
    triangles.
    """
    path = Path(path)
    try:
        regular_file(path)
    except FileNotFoundError:
        raise FrameError(f"mesh file {path} does not exist") from None
    except OSError as exc:  # (a FIFO, a folder: "does not exist" was wrong, and a FIFO blocks)
        raise FrameError(f"mesh file {path}: {exc.strerror or exc}") from None
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise FrameError(
            f"mesh file {path} has suffix {path.suffix!r}; supported: {', '.join(MESH_SUFFIXES)}"
        )
    loaded: Any
    try:
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore", RuntimeWarning)  # (NaN or huge coordinates: said below)
            loaded, (bad, total) = _read(path)
    except Exception as exc:  # trimesh raises many types on bad files
        raise FrameError(f"cannot read mesh {path}: {type(exc).__name__}: {exc}") from exc
    mesh: trimesh.Trimesh | None = None
    if isinstance(loaded, trimesh.Trimesh):
        mesh = loaded
    elif isinstance(loaded, trimesh.PointCloud):
        mesh = _from_point_cloud(loaded, path)
    if mesh is None or len(mesh.faces) == 0 or len(mesh.vertices) == 0:
        finite = f" with finite vertices ({bad} of {total} have NaN or infinite coordinates)"
        raise FrameError(f"mesh file {path} holds no triangles{finite if bad else ''}")
    if not np.all(np.abs(mesh.vertices) <= MAX_COORDINATE):  # (NaN too)
        raise FrameError(
            f"mesh file {path} has vertex coordinates that are not finite or over "
            f"{MAX_COORDINATE:g} (rendering is float32: they gave NaN); scale the mesh down"
        )
    from_file = "vertex_normals" in mesh._cache
    if from_file and not np.all(np.isfinite(mesh._cache["vertex_normals"])):
        raise FrameError(f"mesh file {path} has vertex normals that are not finite (vn nan)")
    mesh.metadata[FILE_NORMALS] = from_file  # read from the file
    mesh.metadata[LEFT_OUT] = (bad, total)
    return mesh


def has_file_normals(mesh: trimesh.Trimesh) -> bool:
    """Whether ``mesh`` carries the normals its file gave (OBJ ``vn``, PLY ``nx ny nz``)."""
    return bool(mesh.metadata.get(FILE_NORMALS)) and "vertex_normals" in mesh._cache


def bounding_sphere(mesh: trimesh.Trimesh) -> tuple[np.ndarray, float]:
    """(centre, radius): the bounding-box centre and the farthest vertex from it."""
    v = np.asarray(mesh.vertices, np.float64)
    centre = 0.5 * (v.min(axis=0) + v.max(axis=0))
    radius = float(np.sqrt(((v - centre) ** 2).sum(axis=1).max()))
    return centre, max(radius, 1e-12)


# -- colours ----------------------------------------------------------------------------------

_SRGB_LUT = np.array(
    [c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4 for c in np.arange(256) / 255.0],
    np.float32,
)


def _srgb8_to_linear(rgb8: np.ndarray) -> np.ndarray:
    return _SRGB_LUT[np.asarray(rgb8)[..., :3].astype(np.uint8)]


def _is_placeholder(image: np.ndarray) -> bool:
    """trimesh's stand-in texture (2×2, RGBA 100,100,100,255) for an OBJ without materials."""
    return image.shape[:2] == (2, 2) and bool(
        np.all(image.reshape(-1, image.shape[-1])[:, :3] == 100)
    )


def texture_image(mesh: trimesh.Trimesh) -> np.ndarray | None:
    """The mesh's base-colour texture as linear float32 (h, w, 3), or None."""
    visual = mesh.visual
    if getattr(visual, "kind", None) != "texture" or getattr(visual, "uv", None) is None:
        return None
    material = getattr(visual, "material", None)
    image = getattr(material, "image", None)
    if image is None:
        image = getattr(material, "baseColorTexture", None)
    if image is None:
        return None
    arr = np.asarray(image.convert("RGBA"))
    if _is_placeholder(arr):
        return None
    return _srgb8_to_linear(arr)


def corner_colors(mesh: trimesh.Trimesh) -> np.ndarray | None:
    """Linear RGB per face corner (F, 3, 3) from vertex / face colours, or None."""
    visual: Any = mesh.visual
    kind = getattr(visual, "kind", None)
    faces = np.asarray(mesh.faces)
    if kind == "vertex":
        return np.asarray(_srgb8_to_linear(visual.vertex_colors)[faces], np.float32)
    if kind == "face":
        fc = _srgb8_to_linear(visual.face_colors)
        return np.repeat(fc[:, None, :], 3, axis=1).astype(np.float32)
    if kind == "texture" and texture_image(mesh) is None:
        factor = getattr(getattr(visual, "material", None), "baseColorFactor", None)
        if factor is not None:
            rgb = _srgb8_to_linear(np.asarray(factor, np.uint8))
            return np.broadcast_to(rgb, (len(faces), 3, 3)).astype(np.float32)
    return None


def sample_texture(texture: np.ndarray, uv: np.ndarray, covered: np.ndarray) -> np.ndarray:
    """Bilinear, repeating lookup of ``texture`` at per-pixel (u, v) (v up, OpenGL style)."""
    th, tw = texture.shape[:2]
    map_x = (uv[:, 0] * tw - 0.5).astype(np.float32).reshape(1, -1)
    map_y = ((1.0 - uv[:, 1]) * th - 0.5).astype(np.float32).reshape(1, -1)
    out = np.zeros_like(uv)
    idx = np.flatnonzero(covered)
    for i in range(0, idx.size, 16384):  # cv2.remap maps must be narrower than 32767
        sel = idx[i : i + 16384]
        sampled = cv2.remap(
            texture,
            map_x[:, sel],
            map_y[:, sel],
            cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_WRAP,
        )
        out[sel] = np.asarray(sampled, np.float32).reshape(-1, 3)
    return out
