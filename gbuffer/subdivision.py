"""Loop subdivision of a mesh's smooth surface as fine as pixels need, vertices and creases kept.

Normals interpolated linearly over a coarse mesh bend at every edge, so curvature (their
derivative) jumps there and Radiance Scaling draws the triangles. Loop subdivision (Loop 1987)
converges to a surface whose curvature is continuous away from the few vertices of valence ≠ 6;
:func:`refine` applies it ``levels`` times (each level cuts every triangle into four), with
Hoppe et al.'s rules (SIGGRAPH 1994) where the surface is not smooth: crease and boundary edges
are refined as curves of their own and vertices where three or more of them meet stay put.
The corner normals are refined with the same masks (a vertex is split where its corners' normals
differ, so each side of a crease keeps its own), and both are moved to their limit at the end.

Loop's surface does not pass through the mesh's vertices: it shrinks a coarse mesh (an 80-face
icosphere to 0.91 of its radius). Before refining, the positions are pushed out so that their limit
lands on the input vertices: a few Jacobi iterations of P ← P + (X − lim P), where lim is Loop's
limit-position mask (Halstead et al. 1993 solve the same system exactly). The normals are not
pushed: they stay the smooth field of the input's normals.

:func:`levels_for` picks the level from the camera: enough for most curved edges (the 90th
percentile of those on screen) to be at most :data:`EDGE_HEIGHTS` of the image height long (about
three times the derivative scale of the curvature operators, 0.003 of the height; at least
:data:`MIN_EDGE_PX` pixels), within :data:`MAX_TRIANGLES`; a mesh that is already that fine is
left as it is. Scans are (the Stanford bunny's edges are 0.008 of the image height when it fills
the frame, Igea's 0.006); spot.obj is not (0.03: two levels).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import trimesh

from gbuffer.surface import SmoothSurface

EDGE_HEIGHTS = 0.01  #: on-screen length the curved edges are refined down to, × image height
MIN_EDGE_PX = 4.0  #: ... but not below this many pixels (small images)
MAX_LEVELS = 8  #: most subdivision levels
MAX_TRIANGLES = 2_000_000  #: most triangles a refinement may produce
PUSHES = 3  #: Jacobi iterations that make the limit surface pass through the input vertices
_SMOOTH, _CREASE, _CORNER = 0, 1, 2


@dataclass(frozen=True)
class View:
    """What the level choice needs of the camera: pixels per scene unit at a depth."""

    pixel: float  #: pixel size in scene units (orthographic), or per unit depth (perspective)
    orthographic: bool
    width: int
    height: int
    near: float

    def outside(self, verts: np.ndarray) -> np.ndarray:
        """(V,) bit mask of the image sides (with a 10 % margin) each camera-space vertex lies
        beyond, 16 behind the near plane."""
        depth = -verts[:, 2]
        scale = self.pixel * (1.0 if self.orthographic else np.maximum(depth, self.near))
        x, y = verts[:, 0] / scale, verts[:, 1] / scale
        half_w, half_h = 0.55 * self.width, 0.55 * self.height
        bits = (x < -half_w) * 1 + (x > half_w) * 2 + (y < -half_h) * 4 + (y > half_h) * 8
        if not self.orthographic:
            bits = np.where(depth < self.near, 16, bits)
        return bits.astype(np.int64)

    def pixels(self, length: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """On-screen size in pixels of ``length`` scene units at ``depth``."""
        if self.orthographic:
            return length / self.pixel
        return length / (self.pixel * np.maximum(depth, self.near))


@dataclass(frozen=True)
class Refined:
    """A mesh's surface as triangles to draw: each lies on one face of the input mesh."""

    vertices: np.ndarray  #: (S, 3) float64 positions
    faces: np.ndarray  #: (T, 3) int64 into ``vertices``
    normals: np.ndarray | None  #: (N, 3) unit normals; None: flat shading (facet normals)
    normal_faces: np.ndarray | None  #: (T, 3) int64 into ``normals``, per triangle corner
    parent: np.ndarray  #: (T,) the input face each lies on
    bary: np.ndarray | None  #: (T, 3, 3) barycentric coordinates of its corners on the parent
    #: face; None when the triangles are the faces themselves


def levels_for(surface: SmoothSurface, verts: np.ndarray, view: View) -> int:
    """Subdivision levels for ``surface`` whose vertices are at camera-space ``verts``: enough
    for the 90th percentile of the on-screen lengths of its curved edges (their two corners'
    normals differ by more than 1°) to fall to :data:`EDGE_HEIGHTS` of the image height (or
    :data:`MIN_EDGE_PX`), within :data:`MAX_TRIANGLES`."""
    if surface.normals is None:
        return 0
    start, end = surface.faces, np.roll(surface.faces, -1, axis=1)  # edge k: corner k -> k + 1
    n_start, n_end = surface.normals, np.roll(surface.normals, -1, axis=1)
    curved = np.einsum("fkd,fkd->fk", n_start, n_end) < math.cos(math.radians(1.0))
    outside = view.outside(verts)
    shown = (outside[start] & outside[end]) == 0
    a, b = start[curved & shown], end[curved & shown]
    if a.size == 0:
        return 0
    depth = np.minimum(-verts[a, 2], -verts[b, 2])
    px = view.pixels(np.linalg.norm(verts[a] - verts[b], axis=1), depth)
    wanted = float(np.percentile(px, 90)) / max(EDGE_HEIGHTS * view.height, MIN_EDGE_PX)
    levels = min(MAX_LEVELS, max(0, math.ceil(math.log2(wanted)))) if wanted > 1.0 else 0
    while levels and len(surface.faces) * 4**levels > MAX_TRIANGLES:
        levels -= 1
    return levels


def refine(surface: SmoothSurface, levels: int) -> Refined:
    """``surface`` after ``levels`` of Loop subdivision, its limit through the input vertices.

    With no normals (flat shading) or no levels, the faces themselves."""
    n_faces = len(surface.faces)
    parent = np.arange(n_faces)
    if surface.normals is None:
        return Refined(surface.vertices, surface.faces, None, None, parent, None)
    if levels == 0:  # a normal per face corner
        corners = np.arange(3 * n_faces).reshape(-1, 3)
        normals = surface.normals.reshape(-1, 3)
        return Refined(surface.vertices, surface.faces, normals, corners, parent, None)
    positions, normals, faces, welded = _split(surface)
    values = np.concatenate([_push(positions, faces, welded), normals], axis=1)
    bary = np.broadcast_to(np.eye(3), (n_faces, 3, 3))
    for _ in range(levels):
        values, faces, welded, parent, bary = _step(values, faces, welded, parent, bary)
    values = _Topology(faces, welded, len(values)).limit(values)
    normals = values[:, 3:] / np.maximum(
        np.linalg.norm(values[:, 3:], axis=1, keepdims=True), 1e-300
    )
    bary = bary.astype(np.float32)  # exact: dyadic fractions
    return Refined(values[:, :3], faces, normals, faces, parent, bary)


def _split(surface: SmoothSurface) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The faces on vertices split where their corners' normals differ: (positions, normals,
    faces, welded vertex of each)."""
    assert surface.normals is not None
    corner_vertex = surface.faces.reshape(-1)
    corner_normal = surface.normals.reshape(-1, 3)
    key = np.column_stack([corner_vertex, corner_normal])
    first, inverse = trimesh.grouping.unique_rows(key, digits=6)
    welded = corner_vertex[first]
    faces = np.asarray(inverse, np.int64).reshape(-1, 3)
    return surface.vertices[welded], corner_normal[first], faces, welded


def _loop_beta(valence: np.ndarray) -> np.ndarray:
    """Loop's weight of each neighbour of a smooth vertex of ``valence`` neighbours."""
    k = np.maximum(valence, 1).astype(np.float64)
    return (0.625 - (0.375 + 0.25 * np.cos(2.0 * np.pi / k)) ** 2) / k


class _Topology:
    """Edges of a mesh on split vertices, and the kind of each vertex: smooth, on a crease
    (or boundary) with exactly two crease edges, or a corner."""

    def __init__(self, faces: np.ndarray, welded: np.ndarray, count: int) -> None:
        self.faces = faces
        half = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
        self.opposite = np.concatenate([faces[:, 2], faces[:, 0], faces[:, 1]])
        first, self.edge_of = trimesh.grouping.unique_rows(np.sort(half, axis=1))
        self.edges = np.sort(half[first], axis=1)  # (E, 2)
        uses = np.bincount(self.edge_of, minlength=len(first))
        self.crease = uses != 2  # boundaries, creases (split), non-manifold edges
        self.count = count
        self.valence = self._gather(np.ones((count, 1)), self.edges)[:, 0]
        # welded edges with any crease copy, counted at their welded vertices
        welded_edges = np.sort(welded[self.edges], axis=1)
        w_first, w_of = trimesh.grouping.unique_rows(welded_edges)
        w_crease = np.bincount(w_of, weights=self.crease, minlength=len(w_first)) > 0
        crease_ends = welded_edges[w_first][w_crease].reshape(-1)
        w_count = np.bincount(crease_ends, minlength=welded.max() + 1)[welded]
        self.crease_valence = np.bincount(self.edges[self.crease].reshape(-1), minlength=count)
        odd_copy = (w_count == 2) & (self.crease_valence != 2)
        bad = np.bincount(welded[odd_copy], minlength=welded.max() + 1)[welded] > 0
        self.kind = np.where(
            w_count <= 1, _SMOOTH, np.where((w_count == 2) & ~bad, _CREASE, _CORNER)
        )
        self.welded_edge = w_of  # welded edge of each edge
        self.welded_edges = len(w_first)

    def _gather(self, values: np.ndarray, edges: np.ndarray) -> np.ndarray:
        """Per vertex, the sum of ``values`` at its neighbours along ``edges``."""
        ends = np.concatenate([edges[:, 0], edges[:, 1]])
        other = np.concatenate([edges[:, 1], edges[:, 0]])
        return np.stack(
            [
                np.bincount(ends, weights=values[other, c], minlength=self.count)
                for c in range(values.shape[1])
            ],
            axis=1,
        )

    def _masks(
        self, values: np.ndarray, smooth_weight: np.ndarray, crease_weight: float
    ) -> np.ndarray:
        """Vertex masks: v + w (mean of neighbours − v) with w = k·``smooth_weight`` on smooth
        vertices (k neighbours), ``crease_weight`` along creases; corners stay."""
        ring = self._gather(values, self.edges)
        crease_ring = self._gather(values, self.edges[self.crease])
        k = self.valence[:, None]
        smooth = (1.0 - k * smooth_weight[:, None]) * values + smooth_weight[:, None] * ring
        crease = (1.0 - crease_weight) * values + 0.5 * crease_weight * crease_ring
        kind = self.kind[:, None]
        return np.where(kind == _SMOOTH, smooth, np.where(kind == _CREASE, crease, values))

    def even(self, values: np.ndarray) -> np.ndarray:
        """Loop's new position of each old vertex (β; ¾ v + ⅛ (b₀ + b₁) along creases)."""
        return self._masks(values, _loop_beta(self.valence), 0.25)

    def limit(self, values: np.ndarray) -> np.ndarray:
        """Loop's limit position of each vertex: χ = 1 / (3 / (8 β) + k) per neighbour;
        ⅔ v + ⅙ (b₀ + b₁) along creases."""
        beta = _loop_beta(self.valence)
        chi = 1.0 / (3.0 / (8.0 * beta) + self.valence)
        return self._masks(values, chi, 1.0 / 3.0)

    def odd(self, values: np.ndarray) -> np.ndarray:
        """A new vertex per edge: ⅜ (a + b) + ⅛ (c + d) inside, the midpoint on creases."""
        a, b = values[self.edges[:, 0]], values[self.edges[:, 1]]
        opposite = np.stack(
            [
                np.bincount(self.edge_of, weights=values[self.opposite, c], minlength=len(a))
                for c in range(values.shape[1])
            ],
            axis=1,
        )
        inside = 0.375 * (a + b) + 0.125 * opposite
        return np.where(self.crease[:, None], 0.5 * (a + b), inside)


def _push(positions: np.ndarray, faces: np.ndarray, welded: np.ndarray) -> np.ndarray:
    """Control points whose Loop limit is (nearly) ``positions``: P ← P + (X − lim P)."""
    topology = _Topology(faces, welded, len(positions))
    pushed = positions
    for _ in range(PUSHES):
        pushed = pushed + (positions - topology.limit(pushed))
    return pushed


def _step(
    values: np.ndarray,
    faces: np.ndarray,
    welded: np.ndarray,
    parent: np.ndarray,
    bary: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One level of Loop subdivision: every face into four (corner, corner, corner, middle)."""
    topology = _Topology(faces, welded, len(values))
    n_faces, count = len(faces), len(values)
    mid = count + topology.edge_of.reshape(3, n_faces).T  # new vertex on face edge k (k -> k + 1)
    a, b, c = faces.T
    m0, m1, m2 = mid.T
    new_faces = np.concatenate(
        [
            np.stack([a, m0, m2], axis=1),
            np.stack([m0, b, m1], axis=1),
            np.stack([m2, m1, c], axis=1),
            np.stack([m0, m1, m2], axis=1),
        ]
    )
    ba, bb, bc = bary[:, 0], bary[:, 1], bary[:, 2]
    mab, mbc, mca = 0.5 * (ba + bb), 0.5 * (bb + bc), 0.5 * (bc + ba)
    new_bary = np.concatenate(
        [
            np.stack([ba, mab, mca], axis=1),
            np.stack([mab, bb, mbc], axis=1),
            np.stack([mca, mbc, bc], axis=1),
            np.stack([mab, mbc, mca], axis=1),
        ]
    )
    new_values = np.concatenate([topology.even(values), topology.odd(values)])
    new_welded = np.concatenate([welded, welded.max() + 1 + topology.welded_edge])
    return new_values, new_faces, new_welded, np.tile(parent, 4), new_bary
