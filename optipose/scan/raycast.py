"""Ray casting back-ends behind one interface: Embree through embreex, or Open3D's RaycastingScene; and the
scene a scanner casts into, the part with its keep-outs (:func:`scene_mesh`).

Both build the acceleration structure once per mesh and then answer batches of rays. Embree works in
float32; the scanner recomputes each hit in float64 from the triangle Embree names (:func:`optipose.model.planes.face_planes`).
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from typing import Protocol

import numpy as np


__all__ = [
    "default_threads",
    "RayCaster",
    "EmbreeCaster",
    "Open3DCaster",
    "make_caster",
    "scene_mesh",
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


def scene_mesh(mesh, occluders: list[tuple[np.ndarray, np.ndarray]] | None = None):
    """The mesh a scanner casts its rays into: ``mesh`` itself, or with ``occluders`` (axis-aligned boxes
    ``(lo (3,), hi (3,))`` m, the part's keep-outs) a ``trimesh.Trimesh`` of the part's faces and then each
    box's. The boxes block the laser and the receiver but return no points (the scanner measures only the
    part's faces, the first ``len(mesh.faces)``)."""
    if not occluders:
        return mesh
    import trimesh

    boxes = []
    for lo, hi in occluders:
        box = trimesh.creation.box(np.asarray(hi, float) - np.asarray(lo, float))
        box.apply_translation((np.asarray(lo, float) + np.asarray(hi, float)) / 2)
        boxes.append(box)
    parts = [(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int64))]
    parts += [(np.asarray(box.vertices, dtype=np.float64), np.asarray(box.faces, dtype=np.int64)) for box in boxes]
    first = np.cumsum([0] + [len(v) for v, _ in parts[:-1]])  # each body's first vertex
    return trimesh.Trimesh(
        np.concatenate([v for v, _ in parts]),
        np.concatenate([f + o for (_, f), o in zip(parts, first)]),
        process=False,
    )
