"""The convex hull of a mesh, computed once per mesh and, for a dense mesh, once per machine.

The collision model (its bounding polytope) and the scanner (:mod:`optipose.scan.hull`, the faces in a
supporting plane) both need the hull of the part's vertices, and every process that builds either — the
search's, the hand layout's processes beside it, each evaluator worker — used to run qhull again on every
vertex (a round part's hull holds most of them). Here the hull is trimesh's (qhull, options ``QbB Pp Qt``,
its vertices merged as trimesh does) without trimesh's winding repair, which neither user needs: the same
vertices in the same order, each hull face unoriented (``tests/test_dense.py`` checks both against
``mesh.convex_hull``). It is kept per mesh object in the process, and a dense mesh's is shared between the
processes of the machine (:func:`optipose.model.machine.per_machine`).

A dense closed mesh (over :data:`optipose.model.machine.SHARED_FACES` faces, watertight, consistently wound)
is first read for what its own surface says, in time linear in it (qhull's is n log n and took a third of a
5 M-face part's set-up):

- a mesh **convex** at every edge (each face's plane has every vertex of the faces around its corners at
  most :data:`_TOL` in front) is its own hull: its vertices and faces are returned as they are. A closed,
  connected, locally convex surface bounds a convex solid, so no vertex is outside its faces' planes; the
  collision model and the scanner read only the largest height of the hull's vertices along a direction,
  which a vertex inside a hull face does not change;
- otherwise a vertex in the **middle of a flat patch** (every vertex of its faces within :data:`_TOL` of
  the plane through it) cannot be a corner of the hull, and qhull is given the others: the same hull to
  :data:`_TOL`, from a small share of a finely meshed flat part's vertices.
"""

from __future__ import annotations

import threading
import weakref

import numpy as np
from numba import njit

from optipose.model import machine
from optipose.model.grouping import closed_and_wound, vertex_faces

__all__ = ["hull_arrays"]

_TOL = 1e-8  # m: ten float32 roundings of a 0.05 m coordinate, far below any clearance or scan noise
_LOCK = threading.Lock()
_HULLS: dict[int, tuple] = {}  # id(mesh) -> (weak reference to the mesh, vertices, faces)


def hull_arrays(mesh) -> tuple[np.ndarray, np.ndarray]:
    """The convex hull of ``mesh``'s vertices: vertices (h, 3) float64 and triangles (t, 3) int64, read-only.
    Raises what qhull raises for a flat or degenerate mesh (the callers have their fallbacks)."""
    key = id(mesh)
    with _LOCK:
        entry = _HULLS.get(key)
        if entry is not None and entry[0]() is mesh:
            return entry[1], entry[2]
    if len(mesh.faces) > machine.SHARED_FACES:
        content = machine.digest(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64))
        vertices, faces = machine.per_machine("hull", content, lambda: _compute(mesh), ("vertices", "faces"))
    else:
        vertices, faces = _compute(mesh)
    vertices.flags.writeable = False
    faces.flags.writeable = False
    with _LOCK:
        _HULLS[key] = (weakref.ref(mesh, lambda _ref, key=key: _HULLS.pop(key, None)), vertices, faces)
    return vertices, faces


def _compute(mesh) -> tuple[np.ndarray, np.ndarray]:
    from trimesh.convex import convex_hull

    points = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.ascontiguousarray(mesh.faces, dtype=np.int64)
    csr = vertex_faces(faces, len(points)) if len(faces) > machine.SHARED_FACES else None
    if csr is not None and closed_and_wound(faces, len(points), csr) == (True, True):
        normals = np.ascontiguousarray(mesh.face_normals, dtype=np.float64)
        indptr, around = csr
        if _locally_convex(points, faces, normals, indptr, around, _TOL):
            return np.ascontiguousarray(points), faces
        points = points[~_flat_interior(points, faces, normals, indptr, around, _TOL)]
    hull = convex_hull(points, repair=False)
    return np.ascontiguousarray(hull.vertices, dtype=np.float64), np.ascontiguousarray(hull.faces, dtype=np.int64)


@njit(cache=True, nogil=True)
def _locally_convex(points, faces, normals, indptr, around, tol):
    """Every vertex of the faces around each face's corners at most ``tol`` in front of the face's plane
    (which holds the vertex across each of its edges); a degenerate face (zero normal) fails it."""
    for f in range(faces.shape[0]):
        n0, n1, n2 = normals[f, 0], normals[f, 1], normals[f, 2]
        if n0 * n0 + n1 * n1 + n2 * n2 < 0.25:
            return False
        c = faces[f, 0]
        d = n0 * points[c, 0] + n1 * points[c, 1] + n2 * points[c, 2] + tol
        for k in range(3):
            v = faces[f, k]
            for a in range(indptr[v], indptr[v + 1]):
                g = around[a]
                for j in range(3):
                    w = faces[g, j]
                    if n0 * points[w, 0] + n1 * points[w, 1] + n2 * points[w, 2] > d:
                        return False
    return True


@njit(cache=True, nogil=True)
def _flat_interior(points, faces, normals, indptr, around, tol):
    """(n,) bool: the vertex and every vertex of its faces lie within ``tol`` of one plane through it (the
    mean of its faces' normals, each within 60° of it); a vertex of a closed surface surrounded so lies in
    the hull of its neighbours."""
    out = np.zeros(points.shape[0], np.bool_)
    for v in range(points.shape[0]):
        m0 = m1 = m2 = 0.0
        for a in range(indptr[v], indptr[v + 1]):
            g = around[a]
            m0 += normals[g, 0]
            m1 += normals[g, 1]
            m2 += normals[g, 2]
        length = (m0 * m0 + m1 * m1 + m2 * m2) ** 0.5
        if indptr[v + 1] - indptr[v] < 3 or length <= 0.0:
            continue
        m0, m1, m2 = m0 / length, m1 / length, m2 / length
        d = m0 * points[v, 0] + m1 * points[v, 1] + m2 * points[v, 2]
        flat = True
        for a in range(indptr[v], indptr[v + 1]):
            g = around[a]
            if normals[g, 0] * m0 + normals[g, 1] * m1 + normals[g, 2] * m2 < 0.5:
                flat = False
                break
            for j in range(3):
                w = faces[g, j]
                if abs(m0 * points[w, 0] + m1 * points[w, 1] + m2 * points[w, 2] - d) > tol:
                    flat = False
            if not flat:
                break
        out[v] = flat
    return out
