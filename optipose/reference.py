"""Reference (fixed, target) clouds for registration, each with its search structure built once.

Every reference answers ``closest(points) -> (q, n, ids)``: the closest reference point, its unit normal
and an id. Two kinds:

- :class:`SurfaceReference` — the CAD triangles themselves (``cad-surface``): closest points on the
  surface through Open3D's ``RaycastingScene`` (a BVH built once), normals of the faces. This is a dense
  CAD sample in the limit of zero spacing, so the reference adds no sampling error. Between queries, a
  point that still projects well inside the face it was matched to keeps that face
  (:meth:`SurfaceReference.follow`), which makes an ICP iteration near convergence cost a projection
  rather than a search. :meth:`SurfaceReference.nearest` goes further for ICP: a point that leaves its
  face for a neighbouring face's interior is found there by an exact search of the faces near it, so
  the global search is left to points near edges and corners and to points that moved far.
- :class:`SampledReference` — a point cloud with normals and a KD-tree: a CAD sample at a given spacing
  (``cad-sample``) or the scan at the nominal orientation (``nominal-scan``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["SurfaceReference", "SampledReference", "sample_surface"]

_NEIGHBOUR_RADIUS = 1e-3  # m: faces listed near each face for nearest(); exact for points within half of it


class SurfaceReference:
    """Closest points on a triangle mesh (metres). vertices (v, 3), faces (f, 3)."""

    kind = "cad-surface"

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        import open3d as o3d

        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        self.faces = np.ascontiguousarray(faces, dtype=np.int64)
        tri = self.vertices[self.faces]  # (f, 3, 3)
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        area2 = np.linalg.norm(normal, axis=1)
        self.normals = normal / np.maximum(area2, 1e-300)[:, None]
        self.offsets = np.einsum("ij,ij->i", self.normals, tri[:, 0])
        # inward edge planes: a point projects inside face f iff edge_n[f, k]·x - edge_c[f, k] >= 0 for k = 0..2
        edges = np.roll(tri, -1, axis=1) - tri
        edge_n = np.cross(self.normals[:, None, :], edges)
        self.edge_n = edge_n / np.maximum(np.linalg.norm(edge_n, axis=2, keepdims=True), 1e-300)
        self.edge_c = np.einsum("fkj,fkj->fk", self.edge_n, tri)
        # face plane and edge planes packed: one gather and one product per point in follow()
        self._planes = np.ascontiguousarray(np.concatenate([self.normals[:, None], self.edge_n], axis=1))  # (f, 4, 3)
        self._plane_c = np.ascontiguousarray(np.concatenate([self.offsets[:, None], self.edge_c], axis=1))  # (f, 4)
        mesh = o3d.t.geometry.TriangleMesh()
        mesh.vertex.positions = o3d.core.Tensor(self.vertices.astype(np.float32))
        mesh.triangle.indices = o3d.core.Tensor(self.faces.astype(np.int32))
        self._scene = o3d.t.geometry.RaycastingScene()
        self._scene.add_triangles(mesh)
        self.area = 0.5 * float(area2.sum())
        self._tri = np.ascontiguousarray(tri)
        self._neighbours = None

    def _near_faces(self) -> tuple[np.ndarray, ...]:
        """Faces whose bounding boxes lie within ``_NEIGHBOUR_RADIUS`` of each face's (a superset of the faces
        that close): face boxes lo, hi (f, 3), CSR start (f + 1,) and list, built on first use."""
        if self._neighbours is None:
            from scipy.spatial import cKDTree

            lo, hi = self._tri.min(axis=1), self._tri.max(axis=1)
            centre, half = 0.5 * (lo + hi), 0.5 * np.linalg.norm(hi - lo, axis=1)
            near = cKDTree(centre).query_ball_point(centre, _NEIGHBOUR_RADIUS + half + half.max())
            lists = []
            for f, cand in enumerate(near):
                cand = np.asarray(cand, dtype=np.int64)
                gap = np.maximum(0.0, np.maximum(lo[cand] - hi[f], lo[f] - hi[cand]))
                keep = cand[(np.einsum("ij,ij->i", gap, gap) <= _NEIGHBOUR_RADIUS**2) & (cand != f)]
                lists.append(np.sort(keep))
            start = np.concatenate([[0], np.cumsum([len(x) for x in lists])]).astype(np.int64)
            self._neighbours = (np.ascontiguousarray(lo), np.ascontiguousarray(hi), start, np.concatenate(lists).astype(np.int64))
        return self._neighbours

    def __repr__(self) -> str:
        return f"SurfaceReference({len(self.faces)} faces, {self.area * 1e6:.0f} mm^2)"

    def closest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Closest surface points (n, 3), their face normals (n, 3) and face ids (n,) int64."""
        import open3d as o3d

        ans = self._scene.compute_closest_points(o3d.core.Tensor(np.asarray(points, dtype=np.float32)))
        ids = ans["primitive_ids"].numpy().astype(np.int64)
        q = ans["points"].numpy().astype(np.float64)
        # the BVH answers in float32 (~4 nm here); on the face's interior the float64 projection is exact
        q_exact, _, inside = self.follow(points, ids)
        q[inside] = q_exact[inside]
        return q, self.normals[ids], ids

    def follow(self, points: np.ndarray, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Project points (n, 3) onto the faces ``ids`` they were matched to.

        Returns the projections (n, 3), the normals (n, 3) and ok (n,) bool: the projection lies inside
        the face by more than twice the point's distance to it, so no neighbouring face (meeting at 90°
        or more) can be closer and the projection is the true closest point. Points not ok need
        :meth:`closest`.
        """
        n = self.normals[ids]
        # edge normals are perpendicular to n, so the projection's inset equals the point's
        h = np.matmul(self._planes[ids], points[:, :, None])[:, :, 0] - self._plane_c[ids]
        dist = h[:, 0]
        q = points - dist[:, None] * n
        ok = h[:, 1:].min(axis=1) > 2.0 * np.abs(dist)
        return q, n, ok

    def nearest(self, points: np.ndarray, ids: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Closest surface points (n, 3), face normals (n, 3) and face ids (n,), searching globally only
        where it must.

        ids : each point's face at the previous ICP step, or None (then this is :meth:`closest`). A point
        that lies inside its face by more than twice its distance keeps it (:meth:`follow`); one that does
        not, but does inside a face near its face (an exact search of the faces within
        ``_NEIGHBOUR_RADIUS``), takes that face and its float64 projection. The rest (points that moved
        far, or whose closest point is on or near an edge or a corner) get :meth:`closest`'s answer. Where
        the float32 search picks a face only by rounding (a point within nanometres of the edge between
        two coplanar sliver triangles, where its point can be micrometres off), this answers the nearer
        point, so distances can be smaller than :meth:`closest`'s; point-to-plane residuals agree.
        """
        from optipose import _icp_kernels as kernels

        if ids is None:
            return self.closest(points)
        points = np.ascontiguousarray(points, dtype=np.float64)
        ids = np.array(ids, dtype=np.int64)
        q, open_ = kernels.nearest(points, ids, self._planes, self._plane_c, self._tri, *self._near_faces(), _NEIGHBOUR_RADIUS)
        open_ = np.flatnonzero(open_)
        if len(open_):
            q[open_], _, ids[open_] = self.closest(points[open_])
        return q, self.normals[ids], ids

    def sample(self, spacing: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """A uniform sample of the surface, about one point per ``spacing``² (m); points and normals."""
        return sample_surface(self.vertices, self.faces, spacing, seed)


class SampledReference:
    """A reference point cloud (n, 3) m with unit normals (n, 3) and a KD-tree built once."""

    def __init__(self, points: np.ndarray, normals: np.ndarray, kind: str = "cad-sample"):
        from scipy.spatial import cKDTree

        self.points = np.ascontiguousarray(points, dtype=np.float64)
        self.normals = np.ascontiguousarray(normals, dtype=np.float64)
        self.kind = kind
        self._tree = cKDTree(self.points)

    def __repr__(self) -> str:
        return f"SampledReference({self.kind}, {len(self.points)} points)"

    def closest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        _, ids = self._tree.query(points)
        return self.points[ids], self.normals[ids], ids.astype(np.int64)

    def nearest(self, points: np.ndarray, ids: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The closest sample points: a search every time (``ids`` is ignored)."""
        return self.closest(points)

    def follow(self, points: np.ndarray, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A sample point is only the closest one where the search says so: always search again."""
        return self.points[ids], self.normals[ids], np.zeros(len(points), dtype=bool)

    def sample(self, spacing: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
        return self.points, self.normals


def sample_surface(vertices: np.ndarray, faces: np.ndarray, spacing: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Area-weighted random sample of a mesh, ``area / spacing²`` points (seeded); points, face normals."""
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces)]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area2 = np.linalg.norm(cross, axis=1)
    n = max(1, int(round(0.5 * area2.sum() / spacing**2)))
    rng = np.random.default_rng(seed)
    face = rng.choice(len(tri), size=n, p=area2 / area2.sum())
    u, v = rng.random((2, n))
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    t = tri[face]
    points = t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])
    normals = cross[face] / np.maximum(area2[face], 1e-300)[:, None]
    return points, normals
