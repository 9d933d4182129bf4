"""Reference (fixed, target) clouds for registration, each with its search structure built once.

Every reference answers ``closest(points) -> (q, n, ids)``: the closest reference point, its unit normal
and an id. Two kinds:

- :class:`SurfaceReference` — the CAD triangles themselves (``cad-surface``): exact (float64) closest
  points on the surface, normals of the faces. This is a dense CAD sample in the limit of zero spacing,
  so the reference adds no sampling error. A point within a millimetre of the part is answered by an
  exact search of the faces listed in its cell of a grid (built once); the rest, far from the part,
  by Open3D's ``RaycastingScene`` (a float32 BVH built once). Between ICP steps, a point that still
  projects well inside the face it was matched to keeps that face (:meth:`SurfaceReference.follow`),
  which makes an iteration near convergence cost a projection rather than a search.
- :class:`SampledReference` — a point cloud with normals and a KD-tree: a CAD sample at a given spacing
  (``cad-sample``) or the scan at the nominal orientation (``nominal-scan``).
"""

from __future__ import annotations

import numpy as np

from optipose.scan.raycast import edge_planes

__all__ = ["SurfaceReference", "SampledReference", "sample_surface"]

_CELL = 0.5e-3  # m: grid cells of nearest(), larger if the part would need more than _MAX_CELLS
_MAX_CELLS = 4_000_000


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
        self.edge_n, self.edge_c = edge_planes(tri, self.normals)
        # face plane and edge planes packed: one gather and one product per point in follow()
        self._planes = np.ascontiguousarray(np.concatenate([self.normals[:, None], self.edge_n], axis=1))  # (f, 4, 3)
        self._plane_c = np.ascontiguousarray(np.concatenate([self.offsets[:, None], self.edge_c], axis=1))  # (f, 4)
        # the BVH is float32: built about the part's own centre, so a part far from O (a cell's frame
        # metres away) keeps float32's resolution at the part's size rather than at its distance
        self._origin = 0.5 * (self.vertices.min(axis=0) + self.vertices.max(axis=0))
        mesh = o3d.t.geometry.TriangleMesh()
        mesh.vertex.positions = o3d.core.Tensor((self.vertices - self._origin).astype(np.float32))
        mesh.triangle.indices = o3d.core.Tensor(self.faces.astype(np.int32))
        self._scene = o3d.t.geometry.RaycastingScene()
        self._scene.add_triangles(mesh)
        self.area = 0.5 * float(area2.sum())
        self._tri = np.ascontiguousarray(tri)
        self._face_grid = None

    def _grid(self) -> tuple:
        """The faces near each cell of a ``_CELL`` grid over the part (see :func:`optipose.registration.kernels.face_grid`),
        with the faces' bounding boxes; built on first use."""
        if self._face_grid is None:
            from optipose.registration.kernels import face_grid

            lo, hi = self._tri.min(axis=1), self._tri.max(axis=1)
            extent = hi.max(axis=0) - lo.min(axis=0)
            cell = max(_CELL, float(np.prod(extent + 4 * _CELL) / _MAX_CELLS) ** (1 / 3))
            margin = 2 * cell  # exact for points within a millimetre of the surface at the default cell
            origin = lo.min(axis=0) - margin
            shape = np.floor((hi.max(axis=0) + margin - origin) / cell).astype(np.int64) + 1
            start, faces = face_grid(self._tri, self.normals, self.offsets, origin, cell, shape, margin)
            self._face_grid = (np.ascontiguousarray(lo), np.ascontiguousarray(hi), origin, cell, shape, margin, start, faces)
        return self._face_grid

    def __repr__(self) -> str:
        return f"SurfaceReference({len(self.faces)} faces, {self.area * 1e6:.0f} mm^2)"

    def closest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Closest surface points (n, 3), their face normals (n, 3) and face ids (n,) int64: :meth:`nearest`
        without a guess."""
        return self.nearest(points)

    def _far(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Open3D's closest points, for points the grid does not answer (far from the surface)."""
        import open3d as o3d

        ans = self._scene.compute_closest_points(o3d.core.Tensor((np.asarray(points) - self._origin).astype(np.float32)))
        ids = ans["primitive_ids"].numpy().astype(np.int64)
        q = ans["points"].numpy().astype(np.float64) + self._origin
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

        ids : each point's face at the previous ICP step, if known (-1: not known). A point that lies
        inside its face by more than twice its distance keeps it (:meth:`follow`). Any other point is searched exactly among
        the faces listed for its cell of a grid over the part (every face within two cells of the cell,
        :func:`optipose.registration.kernels.nearest`): it gets the closest face's float64 projection,
        or, closest to an edge or a corner, that face's closest point. Points outside the grid or
        farther than two cells from the surface get Open3D's answer (float32 off the faces' interiors).
        """
        from optipose.registration import kernels

        points = np.ascontiguousarray(points, dtype=np.float64)
        ids = np.full(len(points), -1, dtype=np.int64) if ids is None else np.array(ids, dtype=np.int64)
        ids[ids >= len(self.faces)] = -1
        q, open_ = kernels.nearest(points, ids, self._planes, self._plane_c, self._tri, *self._grid())
        open_ = np.flatnonzero(open_)
        if len(open_):
            q[open_], _, ids[open_] = self._far(points[open_])
        return q, self.normals[ids], ids

    def sample(self, spacing: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """A uniform sample of the surface, about one point per ``spacing``² (m); points and normals."""
        return sample_surface(self.vertices, self.faces, spacing, seed)


class SampledReference:
    """A reference point cloud (n, 3) m with unit normals (n, 3) and a KD-tree built once.

    :meth:`nearest` (what ICP calls every step) first searches a grid of cells of about 2.5 × the points'
    spacing around each point, which is exact for a point that close to the cloud; the KD-tree answers
    the rest (points far from the cloud, early in an ICP)."""

    def __init__(self, points: np.ndarray, normals: np.ndarray, kind: str = "cad-sample"):
        from scipy.spatial import cKDTree

        self.points = np.ascontiguousarray(points, dtype=np.float64)
        self.normals = np.ascontiguousarray(normals, dtype=np.float64)
        self.kind = kind
        self._tree = cKDTree(self.points)
        self._point_grid = None

    def _grid(self) -> tuple:
        """The points per cell of a grid over them (:func:`optipose.registration.kernels.point_grid`), built on first use."""
        if self._point_grid is None:
            from optipose.registration import kernels

            lo, hi = self.points.min(axis=0), self.points.max(axis=0)
            spacing = float(np.sqrt(_cloud_area(self.points, self._tree) / max(len(self.points), 1)))
            cell = max(2.5 * spacing, float(np.prod(hi - lo + 1e-9) / _MAX_CELLS) ** (1 / 3), 1e-6)
            origin = lo - cell
            shape = np.floor((hi + cell - origin) / cell).astype(np.int64) + 1
            start, order = kernels.point_grid(self.points, origin, cell, shape)
            rank = np.empty_like(order)
            rank[order] = np.arange(len(order))
            self._point_grid = (np.ascontiguousarray(self.points[order]), origin, cell, shape, start, order, rank)
        return self._point_grid

    def __repr__(self) -> str:
        return f"SampledReference({self.kind}, {len(self.points)} points)"

    def closest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        _, ids = self._tree.query(points)
        return self.points[ids], self.normals[ids], ids.astype(np.int64)

    def nearest(self, points: np.ndarray, ids: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The closest sample points, the same as :meth:`closest`'s: the grid answers the points near the
        cloud (``ids``, each point's match at the previous ICP step, bounds its search), the KD-tree the others."""
        from optipose.registration import kernels

        points = np.ascontiguousarray(points, dtype=np.float64)
        hint = np.full(len(points), -1, dtype=np.int64) if ids is None else np.ascontiguousarray(ids, dtype=np.int64)
        found, open_ = kernels.grid_nearest(points, hint, *self._grid())
        open_ = np.flatnonzero(open_)
        if len(open_):
            found[open_] = self._tree.query(points[open_])[1]
        return self.points[found], self.normals[found], found

    def follow(self, points: np.ndarray, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A sample point is only the closest one where the search says so: always search again."""
        return self.points[ids], self.normals[ids], np.zeros(len(points), dtype=bool)

    def sample(self, spacing: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
        return self.points, self.normals


def _cloud_area(points: np.ndarray, tree) -> float:
    """About the area a surface sample covers (m²): its points times the squared median distance to a neighbour."""
    pick = points[:: max(1, len(points) // 2000)]
    d = tree.query(pick, k=2)[0][:, 1]
    return float(len(points) * np.median(d) ** 2)


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
