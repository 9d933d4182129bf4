"""The convex hull of a mesh, computed once per mesh and, for a dense mesh, once per machine.

The collision model (its bounding polytope) and the scanner (:mod:`optipose.scan.hull`, the faces in a
supporting plane) both need the hull of the part's vertices, and every process that builds either — the
search's, the hand layout's processes beside it, each evaluator worker — used to run qhull again on every
vertex (a round part's hull holds most of them). Here the hull is trimesh's (qhull, options ``QbB Pp Qt``,
its vertices merged as trimesh does) without trimesh's winding repair, which neither user needs: the same
vertices in the same order, each hull face unoriented (``tests/test_dense.py`` checks both against
``mesh.convex_hull``). It is kept per mesh object in the process, and a dense mesh's is shared between the
processes of the machine (:func:`optipose.model.machine.per_machine`).
"""

from __future__ import annotations

import threading
import weakref

import numpy as np

from optipose.model import machine

__all__ = ["hull_arrays"]

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

    hull = convex_hull(np.asarray(mesh.vertices, dtype=np.float64), repair=False)
    return np.ascontiguousarray(hull.vertices, dtype=np.float64), np.ascontiguousarray(hull.faces, dtype=np.int64)
