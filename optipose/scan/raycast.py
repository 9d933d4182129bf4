"""Ray casting back-ends behind one interface: Embree through embreex, or Open3D's RaycastingScene.

Both build the acceleration structure once per mesh and then answer batches of rays. Embree works in
float32; the scanner recomputes each hit in float64 from the triangle Embree names (:func:`face_planes`).
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from typing import Protocol

import numpy as np
from numba import njit

from optipose.model.grouping import unique_rows

__all__ = [
    "default_threads",
    "RayCaster",
    "EmbreeCaster",
    "Open3DCaster",
    "make_caster",
    "face_planes",
    "edge_planes",
    "plane_numbers",
    "shared_planes",
    "BACKENDS",
]


class RayCaster(Protocol):
    name: str

    def first_hit(
        self, origins: np.ndarray, directions: np.ndarray, tfar: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Distance (n,) float64 (inf on a miss) and triangle index (n,) int64 (-1 on a miss).

        origins, directions : (n, 3); directions need not be unit (distance is in units of |d|).
        tfar : (n,) optional, hits beyond it count as misses.
        """

    def first_triangle(self, origins: np.ndarray, directions: np.ndarray, tfar: np.ndarray | None = None) -> np.ndarray:
        """Triangle index (n,) int32 of the first hit, -1 on a miss: :meth:`first_hit` without distances."""

    def occluded(self, origins: np.ndarray, directions: np.ndarray, tfar: np.ndarray) -> np.ndarray:
        """(n,) bool: something is hit on the ray between 0 and ``tfar`` (n,)."""


def default_threads() -> int:
    """Worker threads for one batch of rays: OPTIPOSE_RAY_THREADS, else every core this process may use."""
    env = os.environ.get("OPTIPOSE_RAY_THREADS")
    if env:
        return max(1, int(env))
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1)


class EmbreeCaster:
    """Embree 4 through embreex (the same engine trimesh's ray module uses).

    embreex traces one ray at a time but releases the GIL, so a batch is split over threads.
    """

    name = "embreex"
    _MIN_CHUNK = 32_768  # below this, a thread costs more than it saves

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, threads: int | None = None):
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        self._scene = rtcore_scene.EmbreeScene()
        TriangleMesh(self._scene, np.ascontiguousarray(vertices[faces], dtype=np.float32))
        self.threads = threads or default_threads()
        self._pool = ThreadPoolExecutor(self.threads) if self.threads > 1 else None

    def _run(self, origins, directions, dists, **kw):
        o = np.ascontiguousarray(origins, dtype=np.float32)
        d = np.ascontiguousarray(directions, dtype=np.float32)
        t = None if dists is None else np.ascontiguousarray(dists, dtype=np.float32)
        n = len(o)
        k = min(self.threads, max(1, n // self._MIN_CHUNK))
        if k == 1 or self._pool is None:
            return [self._scene.run(o, d, dists=t, **kw)]
        cuts = np.linspace(0, n, k + 1).astype(int)
        jobs = [
            self._pool.submit(self._scene.run, o[a:b], d[a:b], None if t is None else t[a:b], **kw)
            for a, b in zip(cuts[:-1], cuts[1:])
        ]
        return [j.result() for j in jobs]

    def first_hit(self, origins, directions, tfar=None):
        parts = self._run(origins, directions, tfar, output=1)
        tri = np.concatenate([p["primID"] for p in parts]).astype(np.int64)
        dist = np.concatenate([p["tfar"] for p in parts]).astype(np.float64)
        dist[tri < 0] = np.inf
        return dist, tri

    def first_triangle(self, origins, directions, tfar=None):
        parts = self._run(origins, directions, tfar)
        return parts[0] if len(parts) == 1 else np.concatenate(parts)

    def occluded(self, origins, directions, tfar):
        parts = self._run(origins, directions, tfar, query="OCCLUDED")
        return np.concatenate([np.asarray(p) for p in parts]) != -1


class Open3DCaster:
    """Embree through Open3D's ``RaycastingScene`` (tensor API)."""

    name = "open3d"

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        import open3d as o3d

        self._o3d = o3d
        self._scene = o3d.t.geometry.RaycastingScene()
        self._scene.add_triangles(
            o3d.core.Tensor(np.asarray(vertices, dtype=np.float32)),
            o3d.core.Tensor(np.asarray(faces, dtype=np.uint32)),
        )

    def _rays(self, origins, directions):
        rays = np.hstack([origins, directions]).astype(np.float32)
        return self._o3d.core.Tensor(rays)

    def first_hit(self, origins, directions, tfar=None):
        ans = self._scene.cast_rays(self._rays(origins, directions))
        dist = ans["t_hit"].numpy().astype(np.float64)
        tri = ans["primitive_ids"].numpy().astype(np.int64)
        miss = ~np.isfinite(dist)
        if tfar is not None:
            miss |= dist > tfar
        tri[miss] = -1
        dist[miss] = np.inf
        return dist, tri

    def first_triangle(self, origins, directions, tfar=None):
        return self.first_hit(origins, directions, tfar)[1].astype(np.int32)

    def occluded(self, origins, directions, tfar):
        # test_occlusions takes one scalar tfar; scale directions so every segment ends at t = 1.
        d = directions * np.asarray(tfar, dtype=np.float64)[:, None]
        ans = self._scene.test_occlusions(self._rays(origins, d), tnear=0.0, tfar=1.0)
        return ans.numpy().astype(bool)


BACKENDS = {"embreex": EmbreeCaster, "open3d": Open3DCaster}
# Measured by benchmarks/bench_scanner.py on the same rays: embreex is the faster of the two here.
DEFAULT_BACKEND = "embreex"


def make_caster(
    vertices: np.ndarray, faces: np.ndarray, backend: str = "auto", threads: int | None = None
) -> RayCaster:
    """Build a caster once per mesh. ``backend``: ``auto`` (the measured-faster one), ``embreex``, ``open3d``.

    threads : embreex threads per batch (default: all cores); Open3D manages its own threads.
    """
    name = DEFAULT_BACKEND if backend == "auto" else backend
    if name not in BACKENDS:
        raise ValueError(f"unknown ray-casting backend '{backend}' (use auto, embreex or open3d)")
    return EmbreeCaster(vertices, faces, threads) if name == "embreex" else BACKENDS[name](vertices, faces)


def face_planes(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (f, 3) and plane offsets (f,) ``n·x = offset`` of every face, float64 (a degenerate face's
    normal is zero)."""
    return _face_planes(np.ascontiguousarray(vertices, dtype=np.float64), np.ascontiguousarray(faces, dtype=np.int64))


def edge_planes(tris: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each face's inward edge planes ``edge_n`` (f, 3, 3), ``edge_c`` (f, 3) from its corners ``tris``
    (f, 3, 3) and unit normals (f, 3): a point of the face's plane lies inside the face where
    ``edge_n·x >= edge_c`` for its three edges (edge k runs from corner k to corner k + 1)."""
    tris = np.ascontiguousarray(tris, dtype=np.float64)
    corners = np.arange(3 * len(tris), dtype=np.int64).reshape(-1, 3)
    return _edge_planes(tris.reshape(-1, 3), corners, np.ascontiguousarray(normals, dtype=np.float64))


# The two kernels compute what numpy's cross, norm and einsum did, in their order of operations (einsum's sum of
# three products adds the first and the third, then the second), so that every plane is the same to the bit,
# in one pass over the faces and without the (f, 3, 3) temporaries (a 5 M-face mesh's were 2 GB).
@njit(cache=True, nogil=True)
def _face_planes(vertices, faces):
    normal, offset = np.empty((faces.shape[0], 3)), np.empty(faces.shape[0])
    for i in range(faces.shape[0]):
        a, b, c = faces[i, 0], faces[i, 1], faces[i, 2]
        e0, e1, e2 = vertices[b, 0] - vertices[a, 0], vertices[b, 1] - vertices[a, 1], vertices[b, 2] - vertices[a, 2]
        f0, f1, f2 = vertices[c, 0] - vertices[a, 0], vertices[c, 1] - vertices[a, 1], vertices[c, 2] - vertices[a, 2]
        n0, n1, n2 = e1 * f2 - e2 * f1, e2 * f0 - e0 * f2, e0 * f1 - e1 * f0
        length = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        if length > 0:
            n0, n1, n2 = n0 / length, n1 / length, n2 / length
        normal[i, 0], normal[i, 1], normal[i, 2] = n0, n1, n2
        offset[i] = (n0 * vertices[a, 0] + n2 * vertices[a, 2]) + n1 * vertices[a, 1]
    return normal, offset


@njit(cache=True, nogil=True)
def _edge_planes(vertices, faces, normals):
    edge_n, edge_c = np.empty((faces.shape[0], 3, 3)), np.empty((faces.shape[0], 3))
    for i in range(faces.shape[0]):
        n0, n1, n2 = normals[i, 0], normals[i, 1], normals[i, 2]
        for k in range(3):
            p, q = faces[i, k], faces[i, (k + 1) % 3]
            d0, d1, d2 = (
                vertices[q, 0] - vertices[p, 0],
                vertices[q, 1] - vertices[p, 1],
                vertices[q, 2] - vertices[p, 2],
            )
            x0, x1, x2 = n1 * d2 - n2 * d1, n2 * d0 - n0 * d2, n0 * d1 - n1 * d0
            length = max(np.sqrt(x0 * x0 + x1 * x1 + x2 * x2), 1e-300)
            x0, x1, x2 = x0 / length, x1 / length, x2 / length
            edge_n[i, k, 0], edge_n[i, k, 1], edge_n[i, k, 2] = x0, x1, x2
            edge_c[i, k] = (x0 * vertices[p, 0] + x2 * vertices[p, 2]) + x1 * vertices[p, 1]
    return edge_n, edge_c


def plane_numbers(normals: np.ndarray, offsets: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """(f,) int64: faces whose planes (unit ``normals`` (f, 3), ``offsets`` (f,) m) agree to ``tol`` and
    ``tol`` × 0.01 m share a number, numbered in the order of their sorted keys; a degenerate face (normal
    of length < 0.5) has one of its own, after them. Sorted in memory linear in the faces."""
    key = _plane_keys(normals, offsets, tol)
    order = np.lexsort(key.T[::-1])
    new = np.ones(len(key), dtype=bool)
    new[1:] = np.any(key[order[1:]] != key[order[:-1]], axis=1)
    plane = np.empty(len(key), dtype=np.int64)
    plane[order] = np.cumsum(new) - 1
    degenerate = np.flatnonzero(np.linalg.norm(normals, axis=1) < 0.5)
    plane[degenerate] = plane.max(initial=-1) + 1 + np.arange(len(degenerate))
    return plane


def _plane_keys(normals: np.ndarray, offsets: np.ndarray, tol: float) -> np.ndarray:
    """(f, 4) int64: a face's plane in steps of ``tol`` (normal) and ``tol`` × 0.01 m (offset)."""
    return np.rint(np.c_[normals / tol, offsets / (0.01 * tol)]).astype(np.int64)


def shared_planes(vertices: np.ndarray, faces: np.ndarray, tol: float = 1e-9):
    """Faces that lie in one plane, given one plane: returns ``plane`` (f,) int64 (faces in one plane share a
    number; a degenerate face has one of its own), the normals (f, 3) and offsets (f,) of
    :func:`face_planes` with every face of a plane given its first face's, and each face's inward edge
    planes (:func:`edge_planes`).

    Faces are one plane when their normals agree to ``tol`` and their offsets to ``tol`` × 0.01 m: the
    faces of a CAD face, split into triangles, whose computed planes differ only by rounding. Giving them
    one plane makes a hit's float64 position the same whichever of them Embree names.
    """
    normals, offsets = face_planes(vertices, faces)
    # numbered in the order planes first occur (the scanner only compares them), by hashing: linear in the faces
    first, plane = unique_rows(_plane_keys(normals, offsets, tol))
    degenerate = np.flatnonzero(np.linalg.norm(normals, axis=1) < 0.5)
    plane[degenerate] = len(first) + np.arange(len(degenerate))
    rep = np.concatenate([first, degenerate])[plane]  # each plane's first face (a degenerate face: itself)
    normals, offsets = np.ascontiguousarray(normals[rep]), offsets[rep]
    edge_n, edge_c = _edge_planes(
        np.ascontiguousarray(vertices, dtype=np.float64), np.ascontiguousarray(faces, dtype=np.int64), normals
    )
    return plane, normals, offsets, edge_n, edge_c
