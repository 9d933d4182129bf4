"""The convex hull of a mesh, computed once per mesh and, for a dense mesh, once per machine.

The collision model (its bounding polytope) and the scanner (:mod:`optipose.scan.hull`, the faces in a
supporting plane) both need the hull of the part's vertices, and every process that builds either — the
search's, the hand layout's run beside it, each evaluator worker — used to run qhull again on every vertex
(a round part's hull holds most of them). Here the hull is trimesh's (qhull, options ``QbB Pp Qt``, its
vertices merged as trimesh does) without trimesh's winding repair, which neither user needs: the same
vertices in the same order, each hull face unoriented (``tests/test_dense.py`` checks both against
``mesh.convex_hull``).

It is kept per mesh object in the process, and a mesh of more than :data:`SHARED_FACES` faces also writes it
to a file named by the mesh's content in the system's temporary folder, which the other processes of the
machine read instead of computing it; the process that wrote the file removes it when it exits. A file
named by the content can only hold that content's hull, so one left behind by a killed process is still
right, only disk space.
"""

from __future__ import annotations

import atexit
import contextlib
import hashlib
import os
import tempfile
import threading
import weakref
from pathlib import Path

import numpy as np

__all__ = ["hull_arrays", "SHARED_FACES"]

SHARED_FACES = 100_000  # meshes with more faces share their hull between the processes of a machine

_LOCK = threading.Lock()
_HULLS: dict[int, tuple] = {}  # id(mesh) -> (weak reference to the mesh, vertices, faces)
_WRITTEN: list[Path] = []  # the files this process wrote, removed at its exit


@atexit.register
def _remove_written() -> None:
    for path in _WRITTEN:
        with contextlib.suppress(OSError):
            path.unlink()


def hull_arrays(mesh) -> tuple[np.ndarray, np.ndarray]:
    """The convex hull of ``mesh``'s vertices: vertices (h, 3) float64 and triangles (t, 3) int64, read-only.
    Raises what qhull raises for a flat or degenerate mesh (the callers have their fallbacks)."""
    key = id(mesh)
    with _LOCK:
        entry = _HULLS.get(key)
        if entry is not None and entry[0]() is mesh:
            return entry[1], entry[2]
    vertices, faces = _shared(mesh) if len(mesh.faces) > SHARED_FACES else _compute(mesh)
    vertices.flags.writeable = False
    faces.flags.writeable = False
    with _LOCK:
        _HULLS[key] = (weakref.ref(mesh, lambda _ref, key=key: _HULLS.pop(key, None)), vertices, faces)
    return vertices, faces


def _compute(mesh) -> tuple[np.ndarray, np.ndarray]:
    from trimesh.convex import convex_hull

    hull = convex_hull(np.asarray(mesh.vertices, dtype=np.float64), repair=False)
    return np.ascontiguousarray(hull.vertices, dtype=np.float64), np.ascontiguousarray(hull.faces, dtype=np.int64)


def _shared(mesh) -> tuple[np.ndarray, np.ndarray]:
    """The hull from this machine's file for the mesh's content, or computed and written there."""
    digest = hashlib.sha1(np.ascontiguousarray(mesh.vertices, dtype=np.float64).tobytes())
    digest.update(np.ascontiguousarray(mesh.faces, dtype=np.int64).tobytes())
    path = Path(tempfile.gettempdir()) / f"optipose-hull-{digest.hexdigest()}.npz"
    with contextlib.suppress(Exception):  # missing, or being replaced: compute it
        with np.load(path) as data:
            return np.array(data["vertices"]), np.array(data["faces"])
    vertices, faces = _compute(mesh)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        with open(tmp, "wb") as fh:
            np.savez(fh, vertices=vertices, faces=faces)
        os.replace(tmp, path)
        _WRITTEN.append(path)
    except OSError:  # a full or read-only temporary folder: every process computes its own
        with contextlib.suppress(OSError):
            tmp.unlink()
    return vertices, faces
