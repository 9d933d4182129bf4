"""Which faces of a mesh lie in a supporting plane of the part (the whole part behind the face's plane), in
time and memory linear in the mesh.

A face's plane supports the part when no vertex of the convex hull lies more than ``tol`` in front of it:
the largest height of the hull's vertices over the plane. A linear function's largest value over a convex
polytope is found by climbing the hull's vertex graph (a vertex none of whose neighbours is higher is the
highest of all, as in the simplex method), and a climb stops as soon as it is above the plane. Each face's
climb starts at the highest vertex for the centre of a cell of a cube map of directions holding its
normal, so it takes a few steps (the map has more cells for a larger hull, about :data:`_PER_CELL` hull
vertices to a cell, so the steps stay few as the mesh is refined): the whole test is linear in the faces, where the heights of every hull
vertex over every face's plane would be the hull's vertices times the faces (a round part's hull holds most
of its vertices).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from optipose.model import machine
from optipose.model.convex import hull_arrays
from optipose.model.grouping import vertex_faces

__all__ = ["supporting_faces", "face_arrays"]

_FACE_ARRAYS = ("plane", "normals", "offsets", "edge_n", "edge_c", "on_hull")

_CELLS = 8  # cells per side of each of the cube map's six faces, at least ...
_MAX_CELLS = 128  # ... and at most
_PER_CELL = 24  # hull vertices to a cell


def supporting_faces(mesh, normals: np.ndarray, offsets: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """(f,) bool: face f's plane (unit ``normals`` (f, 3), ``offsets`` (f,): ``n·x = offset``) has every vertex
    of ``mesh``'s convex hull at most ``tol`` in front of it. Degenerate faces (zero normals) are not."""
    try:
        points, tris = hull_arrays(mesh)  # computed once per mesh (and per machine for a dense one)
    except Exception:  # qhull fails on flat or degenerate meshes: then no face is known to support the part
        return np.zeros(len(normals), dtype=bool)
    if len(points) == 0 or len(tris) == 0:
        return np.zeros(len(normals), dtype=bool)
    n = len(points)
    tris = np.ascontiguousarray(tris, dtype=np.int64)
    indptr, neighbours = _neighbours(tris, *vertex_faces(tris, n))
    cells = int(np.clip(np.sqrt(n / (6 * _PER_CELL)), _CELLS, _MAX_CELLS))
    starts = _cell_starts(points, indptr, neighbours, _cell_centres(cells))
    normals = np.ascontiguousarray(normals, dtype=np.float64)
    return _supporting(points, indptr, neighbours, starts, normals, np.asarray(offsets, dtype=np.float64), tol, cells)


def face_arrays(mesh, vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, ...]:
    """The scanner's per-face arrays of ``mesh`` (its ``vertices`` float64, ``faces`` int64): those of
    :func:`optipose.model.planes.shared_planes` and :func:`supporting_faces`; a dense mesh's once per machine
    (:func:`optipose.model.machine.per_machine`), the same arrays."""
    from optipose.model.planes import shared_planes

    def compute():
        planes = shared_planes(vertices, faces)
        return (*planes, supporting_faces(mesh, planes[1], planes[2]))

    if len(faces) <= machine.SHARED_FACES:
        return compute()
    return machine.per_machine("faces", machine.digest(vertices, faces), compute, _FACE_ARRAYS)


def _cell_centres(cells: int) -> np.ndarray:
    """Unit directions (6 · cells², 3) at the centres of the cube map's cells, in :func:`_cell` order."""
    centres = (np.arange(cells) + 0.5) / cells * 2.0 - 1.0
    out = np.empty((3, 2, cells, cells, 3))
    for axis in range(3):
        for side, sign in enumerate((1.0, -1.0)):
            out[axis, side, :, :, axis] = sign
            out[axis, side, :, :, (axis + 1) % 3] = centres[:, None]
            out[axis, side, :, :, (axis + 2) % 3] = centres[None, :]
    out = out.reshape(-1, 3)
    return out / np.linalg.norm(out, axis=1, keepdims=True)


@njit(cache=True, nogil=True)
def _neighbours(tris, indptr, around):
    """The hull's vertex graph as CSR (``indptr`` (n + 1,), ``neighbours``) from the triangles around each vertex
    (:func:`optipose.model.grouping.vertex_faces`): each vertex's neighbours once, in ascending order."""
    n = indptr.shape[0] - 1
    out = np.zeros(n + 1, np.int64)
    neighbours = np.empty(2 * around.shape[0], np.int64)
    m = 0
    for v in range(n):
        row = np.empty(2 * (indptr[v + 1] - indptr[v]), np.int64)
        r = 0
        for a in range(indptr[v], indptr[v + 1]):
            for k in range(3):
                w = tris[around[a], k]
                if w != v:
                    row[r] = w
                    r += 1
        row = np.sort(row[:r])
        for i in range(r):
            if i == 0 or row[i] != row[i - 1]:
                neighbours[m] = row[i]
                m += 1
        out[v + 1] = m
    return out, neighbours[:m].copy()


@njit(cache=True, nogil=True, inline="always")
def _cell(n0, n1, n2, cells):
    """The cube-map cell of direction (n0, n1, n2): its largest component picks the face."""
    a0, a1, a2 = abs(n0), abs(n1), abs(n2)
    if a0 >= a1 and a0 >= a2:
        axis, m, u, v = 0, n0, n1, n2
    elif a1 >= a2:
        axis, m, u, v = 1, n1, n2, n0
    else:
        axis, m, u, v = 2, n2, n0, n1
    side = 0 if m >= 0 else 1
    i = min(int((u / abs(m) + 1.0) * 0.5 * cells), cells - 1)
    j = min(int((v / abs(m) + 1.0) * 0.5 * cells), cells - 1)
    return ((axis * 2 + side) * cells + i) * cells + j


@njit(cache=True, nogil=True)
def _climb(points, indptr, neighbours, n0, n1, n2, u, stop):
    """From vertex u, the steepest climb of ``n·x`` over the hull's vertex graph until no neighbour is higher
    or the height exceeds ``stop``: returns the vertex and its height."""
    h = n0 * points[u, 0] + n1 * points[u, 1] + n2 * points[u, 2]
    while h <= stop:
        best, best_h = -1, h
        for k in range(indptr[u], indptr[u + 1]):
            w = neighbours[k]
            hw = n0 * points[w, 0] + n1 * points[w, 1] + n2 * points[w, 2]
            if hw > best_h:
                best, best_h = w, hw
        if best < 0:
            break
        u, h = best, best_h
    return u, h


@njit(cache=True, nogil=True)
def _cell_starts(points, indptr, neighbours, centres):
    """Per cube-map cell, the hull vertex highest along the cell's centre direction."""
    out = np.empty(centres.shape[0], np.int64)
    u = 0
    for c in range(centres.shape[0]):
        u, _ = _climb(points, indptr, neighbours, centres[c, 0], centres[c, 1], centres[c, 2], u, np.inf)
        out[c] = u
    return out


@njit(cache=True, nogil=True)
def _supporting(points, indptr, neighbours, starts, normals, offsets, tol, cells):
    out = np.zeros(normals.shape[0], np.bool_)
    for f in range(normals.shape[0]):
        n0, n1, n2 = normals[f, 0], normals[f, 1], normals[f, 2]
        if n0 * n0 + n1 * n1 + n2 * n2 <= 0.25:  # a degenerate face has no plane
            continue
        _, h = _climb(points, indptr, neighbours, n0, n1, n2, starts[_cell(n0, n1, n2, cells)], offsets[f] + tol)
        out[f] = h - offsets[f] <= tol
    return out
