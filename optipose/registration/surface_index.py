"""The CAD surface's search structure, built once per part: what a
:class:`~optipose.registration.reference.SurfaceReference` is made of (:func:`surface_arrays`, about 440 bytes a
face, the names :data:`ARRAY_NAMES`) — each face's plane and inward edge planes, the face across each edge
(:func:`adjacent_faces`), a number per plane, the grid of the faces that cross each cell (:func:`face_grid`,
compiled: numba, cached next to this file), each face's float32 bounding box (:func:`face_boxes`) and the smooth
surface's corner normals. The search itself, point by point, is :mod:`optipose.registration.closest_surface`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from optipose.model.planes import edge_planes, plane_numbers
from optipose.registration.smooth import CREASE_DEG, corner_normals

__all__ = [
    "surface_arrays",
    "search_reach",
    "face_grid",
    "adjacent_faces",
    "face_boxes",
    "ARRAY_NAMES",
    "MAX_CELLS",
]

_CELL = 0.5e-3  # m: grid cells of nearest(), larger if the part would need more than MAX_CELLS
MAX_CELLS = 4_000_000  # grid cells at most, of the surface's grid and of a sampled reference's
_SURFACE_REACH = 2  # rings of cells around a point that the surface's search looks at: exact within 2 cells
# A dense mesh gets smaller cells, about this many of its mean edges across (at least _FINE_CELL, and at most
# two cells a face in all): a cell of _CELL would list the faces of a 5 M-face sphere by the hundred, and every
# point the search answers would test them all. The reach in cells grows to keep the same reach in metres.
_EDGES_A_CELL = 4.0
_FINE_CELL = 0.1e-3

ARRAY_NAMES = (  # what a surface reference is built from, in the order SurfaceReference.arrays gives them
    "vertices",
    "faces",
    "tri",
    "planes",
    "plane_c",
    "adjacent",
    "paired",
    "plane_id",
    "grid_start",
    "grid_faces",
    "box32",
    "corners",
    "meta",
)


def surface_arrays(vertices: np.ndarray, faces: np.ndarray) -> dict:
    """The arrays of :class:`~optipose.registration.reference.SurfaceReference` (see its ``arrays``), about 440
    bytes a face: the mesh, its triangles (f, 3, 3), each face's plane and inward edge planes packed (f, 4, 3) and
    (f, 4) for one gather per point, the face across each edge (int32) and whether it is the only one (a bit per
    edge), a number per plane (int32), the grid, and each face's bounding box in float32 (the search's first test,
    :func:`face_boxes`), and the smooth surface's normals at its corners in float32
    (:func:`optipose.registration.smooth.corner_normals`)."""
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    tri = vertices[faces]  # (f, 3, 3)
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area2 = np.linalg.norm(normal, axis=1)
    normal /= np.maximum(area2, 1e-300)[:, None]
    planes = np.empty((len(faces), 4, 3))
    plane_c = np.empty((len(faces), 4))
    planes[:, 0], plane_c[:, 0] = normal, np.einsum("ij,ij->i", normal, tri[:, 0])
    planes[:, 1:], plane_c[:, 1:] = edge_planes(tri, normal)
    del normal
    plane_id = plane_numbers(planes[:, 0], plane_c[:, 0]).astype(np.int32)
    adjacent, paired = adjacent_faces(faces)
    lo, hi = tri.min(axis=1).min(axis=0), tri.max(axis=1).max(axis=0)
    area = 0.5 * float(area2.sum())
    edge = np.sqrt(4.0 * area / np.sqrt(3.0) / max(len(faces), 1))  # an equilateral face's, of the mean area
    fine = min(_CELL, max(_FINE_CELL, _EDGES_A_CELL * edge))
    cell = max(fine, float(np.prod(hi - lo + 4 * _CELL) / max(MAX_CELLS, 2 * len(faces))) ** (1 / 3))
    margin = search_reach(cell) * cell  # exact for points within a millimetre of the surface
    origin = lo - margin
    shape = np.floor((hi + margin - origin) / cell).astype(np.int64) + 1
    start, listed = face_grid(tri, planes[:, 0], plane_c[:, 0], origin, cell, shape)
    meta = np.concatenate([[area], origin, [cell], shape.astype(np.float64)])
    return {
        "vertices": vertices,
        "faces": faces,
        "tri": tri,
        "planes": planes,
        "plane_c": plane_c,
        "adjacent": adjacent,
        "paired": paired,
        "plane_id": plane_id,
        "grid_start": start,
        "grid_faces": listed,
        "box32": face_boxes(tri),
        "meta": meta,
        "corners": corner_normals(vertices, faces, planes[:, 0].copy(), np.cos(np.deg2rad(CREASE_DEG))),
    }


def search_reach(cell: float) -> int:
    """The rings of cells of side ``cell`` (m) the surface's search looks at: ``_SURFACE_REACH`` of the default cell's
    width in metres, or of this cell's if it is larger."""
    return max(_SURFACE_REACH, int(np.ceil(_SURFACE_REACH * _CELL / cell - 1e-9)))


@njit(cache=True, nogil=True)
def face_grid(tri, normals, offsets, origin, cell, shape):
    """Faces listed per cell of a grid (origin (3,), cube side ``cell``, ``shape`` (3,) cells): every face
    whose bounding box overlaps the cell and whose plane passes within the cell's half-diagonal of its
    centre (a superset of the faces that meet the cell). Returns the CSR start (cells + 1,) int64 and the
    face list (int32). A face is listed in the few cells it crosses, whatever the mesh's density: the search
    (:func:`optipose.registration.closest_surface.nearest_into`) looks at the cells around a point, ring by ring."""
    n_cells = shape[0] * shape[1] * shape[2]
    start = np.zeros(n_cells + 1, np.int64)
    _grid_pass(tri, normals, offsets, origin, cell, shape, start[1:], np.empty(0, np.int32))
    for c in range(n_cells):
        start[c + 1] += start[c]
    faces = np.empty(start[n_cells], np.int32)
    _grid_pass(tri, normals, offsets, origin, cell, shape, start[:-1].copy(), faces)
    return start, faces


@njit(cache=True, nogil=True)
def _grid_pass(tri, normals, offsets, origin, cell, shape, slot, faces):
    """Count faces per cell into ``slot`` (faces empty), or write them at ``slot`` (advanced)."""
    write = faces.shape[0] > 0
    half_diag = 0.5 * np.sqrt(3.0) * cell * (1.0 + 1e-9)
    pad = 1e-9 * cell
    lo_c = np.empty(3, np.int64)
    hi_c = np.empty(3, np.int64)
    for f in range(tri.shape[0]):
        for j in range(3):
            lo_v = min(tri[f, 0, j], tri[f, 1, j], tri[f, 2, j]) - pad  # a hair over: no cell lost to rounding
            hi_v = max(tri[f, 0, j], tri[f, 1, j], tri[f, 2, j]) + pad
            lo_c[j] = max(0, np.int64(np.floor((lo_v - origin[j]) / cell)))
            hi_c[j] = min(shape[j] - 1, np.int64(np.floor((hi_v - origin[j]) / cell)))
        for i in range(lo_c[0], hi_c[0] + 1):
            for j in range(lo_c[1], hi_c[1] + 1):
                for k in range(lo_c[2], hi_c[2] + 1):
                    cx = origin[0] + (i + 0.5) * cell
                    cy = origin[1] + (j + 0.5) * cell
                    cz = origin[2] + (k + 0.5) * cell
                    if abs(normals[f, 0] * cx + normals[f, 1] * cy + normals[f, 2] * cz - offsets[f]) > half_diag:
                        continue
                    c = (i * shape[1] + j) * shape[2] + k
                    if write:
                        faces[slot[c]] = f
                    slot[c] += 1


def adjacent_faces(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(f, 3) int32: the face across each face's edge k (corner k to corner k + 1), -1 on a boundary;
    where more than two faces share an edge, one of the others. And (f,) uint8: bit k set where edge k
    has exactly one face across (the mesh is a 2-manifold there)."""
    f = len(faces)
    following = np.roll(faces, -1, axis=1)
    # each half-edge as one int64 key (its lower vertex, then its higher), row 3·face + k: sorted in linear memory
    key = (np.minimum(faces, following) * (int(faces.max(initial=0)) + 1) + np.maximum(faces, following)).ravel()
    order = np.argsort(key, kind="stable")
    adjacent = np.full(3 * f, -1, dtype=np.int32)
    same = key[order[1:]] == key[order[:-1]]  # consecutive half-edges of one edge: each the other's neighbour
    a, b = order[:-1][same], order[1:][same]
    adjacent[a], adjacent[b] = b // 3, a // 3
    # an edge of exactly two faces: a pair of equal keys with no third before or after it
    alone = same & ~np.r_[False, same[:-1]] & ~np.r_[same[1:], False]
    two = np.zeros(3 * f, dtype=np.uint8)
    two[order[:-1][alone]] = two[order[1:][alone]] = 1
    paired = (two.reshape(f, 3) << np.arange(3, dtype=np.uint8)).sum(axis=1).astype(np.uint8)
    return adjacent.reshape(f, 3), paired


def face_boxes(tri: np.ndarray) -> np.ndarray:
    """(f, 6) float32: each face's bounding box, lowest corner then highest, rounded outward so that it
    contains the float64 box of ``tri`` (f, 3, 3): the first test of :func:`optipose.registration.closest_surface.nearest_into`'s search."""
    lo, hi = tri.min(axis=1), tri.max(axis=1)
    lo32, hi32 = lo.astype(np.float32), hi.astype(np.float32)
    lo32 = np.where(lo32 > lo, np.nextafter(lo32, np.float32(-np.inf)), lo32)
    hi32 = np.where(hi32 < hi, np.nextafter(hi32, np.float32(np.inf)), hi32)
    return np.ascontiguousarray(np.hstack([lo32, hi32]))
