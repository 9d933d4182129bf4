"""Reference (fixed, target) clouds for registration, each with its search structure built once.

Every reference answers ``closest(points) -> (q, n, ids)``: the closest reference point, its unit normal
and an id. Two kinds:

- :class:`SurfaceReference` — the CAD triangles themselves (``cad-surface``): exact (float64) closest
  points on the surface, normals of the faces (off an edge or a corner, the direction to the closest
  point, whatever the triangles). This is a dense CAD sample in the limit of zero spacing, so the
  reference adds no sampling error. A point within a millimetre of the part is answered by an exact
  search of the faces listed in the grid cells around it (each face listed in the cells it crosses, so
  the grid is linear in the faces); the rest, far from the part, by Open3D's ``RaycastingScene`` (a
  float32 BVH built on first use). Its arrays can be written and mapped back read-only
  (:func:`save_reference`, :func:`load_reference`), one copy for the processes of a machine. Between ICP steps, a point that still
  projects well inside the face it was matched to keeps that face (:meth:`SurfaceReference.follow`),
  which makes an iteration near convergence cost a projection rather than a search.
- :class:`SampledReference` — a point cloud with normals and a KD-tree: a CAD sample at a given spacing
  (``cad-sample``) or the scan at the nominal orientation (``nominal-scan``).

An ICP asks ``reference.tracker(ids, initial)`` for its closest points at every step. The surface's
:class:`SurfaceTracker` calls ``nearest_into`` with the last step's faces, into arrays of its own; a sample's :class:`SampleTracker` keeps, per
point, how far it may move and keep its nearest sample, and searches only the points that moved farther
(the literal point-to-point ICP crawls for up to 100 steps, most of them moving most points by far less).
"""

from __future__ import annotations

import numpy as np

from optipose.model.planes import edge_planes

__all__ = ["SurfaceReference", "SampledReference", "sample_surface", "save_reference", "load_reference"]

_CELL = 0.5e-3  # m: grid cells of nearest(), larger if the part would need more than _MAX_CELLS
_MAX_CELLS = 4_000_000
_SURFACE_REACH = 2  # rings of cells around a point that the surface's search looks at: exact within 2 cells
# A dense mesh gets smaller cells, about this many of its mean edges across (at least _FINE_CELL, and at most
# two cells a face in all): a cell of _CELL would list the faces of a 5 M-face sphere by the hundred, and every
# point the search answers would test them all. The reach in cells grows to keep the same reach in metres.
_EDGES_A_CELL = 4.0
_FINE_CELL = 0.1e-3
_NEIGHBOURS = 16  # per sample point: where an ICP's point that left its nearest sample looks first
_REACH = 2  # cells: how far the grid is searched (SampleTracker) before the KD-tree is asked
_ARRAYS = (
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


class SurfaceReference:
    """Closest points on a triangle mesh (metres). vertices (v, 3), faces (f, 3)."""

    kind = "cad-surface"

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, arrays: dict | None = None):
        if arrays is None:
            arrays = _surface_arrays(vertices, faces)
        self.vertices, self.faces = arrays["vertices"], arrays["faces"]
        self._tri, self._planes, self._plane_c = arrays["tri"], arrays["planes"], arrays["plane_c"]
        self._adjacent, self._paired, self._plane_id = arrays["adjacent"], arrays["paired"], arrays["plane_id"]
        self._grid_start, self._grid_faces, self._box32 = arrays["grid_start"], arrays["grid_faces"], arrays["box32"]
        self._corners = arrays["corners"]  # (f, 3, 3) float32: the smooth surface's normal at each face's corners
        self._meta = arrays["meta"]  # area, the grid's origin (3), cell, shape (3)
        self.area = float(self._meta[0])
        # views of the packed planes: the face plane (row 0) and its inward edge planes (rows 1-3); a point
        # projects inside face f iff edge_n[f, k]·x - edge_c[f, k] >= 0 for k = 0..2
        self.normals, self.offsets = self._planes[:, 0], self._plane_c[:, 0]
        self.edge_n, self.edge_c = self._planes[:, 1:], self._plane_c[:, 1:]
        self._scene = None  # Open3D's BVH, for points far from the surface: built on first use

    def arrays(self) -> dict:
        """Everything the reference is built from, as arrays: ``SurfaceReference(None, None, arrays)`` is
        the same reference (:func:`save_reference` writes them, :func:`load_reference` maps them back)."""
        values = (
            self.vertices,
            self.faces,
            self._tri,
            self._planes,
            self._plane_c,
            self._adjacent,
            self._paired,
            self._plane_id,
            self._grid_start,
            self._grid_faces,
            self._box32,
            self._corners,
            self._meta,
        )
        return dict(zip(_ARRAYS, values))

    def _grid(self) -> tuple:
        """The grid's origin (3,), cell (m), shape (3,), the search's reach in cells, and the CSR start and
        face list of the faces that cross each cell (:func:`optipose.registration.closest_surface.face_grid`)."""
        meta = self._meta
        return (
            meta[1:4],
            float(meta[4]),
            meta[5:8].astype(np.int64),
            _reach(float(meta[4])),
            self._grid_start,
            self._grid_faces,
        )

    def _bvh(self):
        """Open3D's ``RaycastingScene`` of the mesh, built on first use. The BVH is float32: built about the
        part's own centre, so a part far from O (a cell's frame metres away) keeps float32's resolution at
        the part's size rather than at its distance."""
        if self._scene is None:
            import open3d as o3d

            self._origin = 0.5 * (self.vertices.min(axis=0) + self.vertices.max(axis=0))
            mesh = o3d.t.geometry.TriangleMesh()
            mesh.vertex.positions = o3d.core.Tensor((self.vertices - self._origin).astype(np.float32))
            mesh.triangle.indices = o3d.core.Tensor(np.asarray(self.faces, dtype=np.int32))
            self._scene = o3d.t.geometry.RaycastingScene()
            self._scene.add_triangles(mesh)
        return self._scene

    def __repr__(self) -> str:
        return f"SurfaceReference({len(self.faces)} faces, {self.area * 1e6:.0f} mm^2)"

    def closest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Closest surface points (n, 3), their face normals (n, 3) and face ids (n,) int64: :meth:`nearest`
        without a guess."""
        return self.nearest(points)

    def _far(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Open3D's closest points, for points the grid does not answer (far from the surface)."""
        import open3d as o3d

        scene = self._bvh()
        ans = scene.compute_closest_points(o3d.core.Tensor((np.asarray(points) - self._origin).astype(np.float32)))
        ids = ans["primitive_ids"].numpy().astype(np.int64)
        q = ans["points"].numpy().astype(np.float64) + self._origin
        # the BVH answers in float32 (~4 nm here); on the face's interior the float64 projection is exact
        q_exact, _, inside = self.follow(points, ids)
        q[inside] = q_exact[inside]
        n = self.normals[ids]
        # off the faces' interiors, the surface's own normal (closest_surface.edge_normal): not the tied face's
        off = np.flatnonzero(~inside)
        if len(off):
            q_off = np.ascontiguousarray(q[off])
            n_off = np.ascontiguousarray(n[off])
            _edge_normals(
                np.ascontiguousarray(points[off], dtype=np.float64),
                q_off,
                n_off,
                self._plane_c[ids[off], 1:],
                np.einsum("ikj,ij->ik", self.edge_n[ids[off]], points[off]),
                self._adjacent[ids[off]],
                self.normals,
            )
            n[off] = n_off
        return q, n, ids

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
        inside its face by more than twice its distance keeps it (:meth:`follow`), as does one whose disc of that radius
        the faces of its plane around it hold (within 0.25 mm of the plane). Any other point is searched exactly among
        the faces listed in the grid cells around it, out to a millimetre (two cells of 0.5 mm)
        (:func:`optipose.registration.closest_surface.nearest_into`): it gets the closest face's float64 projection,
        or, closest to an edge or a corner, that face's closest point and the direction to it. Points outside the grid or
        farther than that from the surface get Open3D's answer (float32 off the faces' interiors).
        """
        points = np.ascontiguousarray(points, dtype=np.float64)
        ids = _face_hints(ids, len(points), len(self.faces))
        q, n, open_ = np.empty((len(points), 3)), np.empty((len(points), 3)), np.zeros(len(points), dtype=bool)
        self.nearest_into(points, ids, q, n, open_)
        return q, n, ids

    def nearest_into(
        self, points: np.ndarray, ids: np.ndarray, q: np.ndarray, n: np.ndarray, open_: np.ndarray
    ) -> None:
        """:meth:`nearest` into the caller's arrays: points (m, 3) float64 contiguous, ids (m,) int64 (the
        guesses, each -1 or a face, then the answer), q and n (m, 3), ``open_`` (m,) bool all False (and so
        again on return)."""
        from optipose.registration.closest_surface import nearest_into

        if nearest_into(
            points,
            ids,
            q,
            n,
            open_,
            self._planes,
            self._plane_c,
            self._tri,
            self._adjacent,
            self._paired,
            self._plane_id,
            *self._grid(),
            self._box32,
        ):
            far = np.flatnonzero(open_)
            q[far], n[far], ids[far] = self._far(points[far])
            open_[far] = False

    def smooth_information(
        self, p: np.ndarray, q: np.ndarray, ids: np.ndarray, max_d2: float
    ) -> tuple[np.ndarray, float]:
        """:func:`optipose.registration.smooth.smooth_information` of pairs (p, q) on faces ``ids``: (H (6, 6), RMS radius)."""
        from optipose.registration.smooth import smooth_information

        return smooth_information(p, q, np.ascontiguousarray(ids, dtype=np.int64), max_d2, self._tri, self._corners)

    def matches(self, points: np.ndarray):
        """The :class:`~optipose.registration.result.Matches` of a cloud (n, 3) where it is: searched, not
        guessed (a guess is kept by a test that trusts a point near its face; at identity a point can be a
        millimetre off, past the far face of a thin sheet)."""
        from optipose.registration.result import Matches

        return Matches(*self.nearest(points))

    def tracker(self, ids: np.ndarray | None = None, initial=None) -> "SurfaceTracker":
        """The closest points of one ICP's cloud, step after step (:class:`SurfaceTracker`: :meth:`nearest`
        each step, hinted with the last step's faces)."""
        return SurfaceTracker(self, ids, initial)

    def sample(self, spacing: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """A uniform sample of the surface, about one point per ``spacing``² (m); points and normals."""
        return sample_surface(self.vertices, self.faces, spacing, seed)


def _surface_arrays(vertices: np.ndarray, faces: np.ndarray) -> dict:
    """The arrays of :class:`SurfaceReference` (see :meth:`SurfaceReference.arrays`), about 440 bytes a face:
    the mesh, its triangles (f, 3, 3), each face's plane and inward edge planes packed (f, 4, 3) and (f, 4)
    for one gather per point, the face across each edge (int32) and whether it is the only one (a bit per edge), a number per plane (int32), the grid, and each
    face's bounding box in float32 (the search's first test, :func:`optipose.registration.closest_surface.face_boxes`),
    and the smooth surface's normals at its corners in float32 (:func:`optipose.registration.smooth.corner_normals`)."""
    from optipose.registration.closest_surface import adjacent_faces, face_boxes, face_grid
    from optipose.registration.smooth import CREASE_DEG, corner_normals
    from optipose.model.planes import plane_numbers

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
    cell = max(fine, float(np.prod(hi - lo + 4 * _CELL) / max(_MAX_CELLS, 2 * len(faces))) ** (1 / 3))
    margin = _reach(cell) * cell  # exact for points within a millimetre of the surface
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


def _reach(cell: float) -> int:
    """The rings of cells of side ``cell`` (m) the surface's search looks at: ``_SURFACE_REACH`` of the default cell's
    width in metres, or of this cell's if it is larger."""
    return max(_SURFACE_REACH, int(np.ceil(_SURFACE_REACH * _CELL / cell - 1e-9)))


def save_reference(reference: SurfaceReference, folder) -> None:
    """Write a surface reference's arrays into ``folder`` (one ``.npy`` each), for :func:`load_reference`."""
    from pathlib import Path

    for name, array in reference.arrays().items():
        np.save(Path(folder) / f"{name}.npy", np.ascontiguousarray(array))


def load_reference(folder) -> SurfaceReference:
    """The surface reference :func:`save_reference` wrote, its arrays mapped read-only from the files: the
    processes of one machine that load it share one copy in the page cache."""
    from pathlib import Path

    return SurfaceReference(
        None, None, {name: np.load(Path(folder) / f"{name}.npy", mmap_mode="r") for name in _ARRAYS}
    )


def _edge_normals(points, q, n, edge_c, edge_h, adjacent, normals) -> None:
    """:func:`optipose.registration.closest_surface.edge_normal` in place for the points (m, 3) whose
    projection falls outside their face (``edge_h - edge_c`` (m, 3), the edge planes' values, has one < 0)
    on a crease, as the compiled search decides (``closest_surface._crease``: every edge it is outside of
    has a face across, ``adjacent`` (m, 3), and one of those turns by more than a degree)."""
    from optipose.registration.closest_surface import CREASE_DEG, edge_normal

    outside = edge_h - edge_c < 0.0
    across = normals[np.maximum(adjacent, 0)]  # (m, 3, 3)
    turned = np.einsum("ij,ikj->ik", n, across) < np.cos(np.deg2rad(CREASE_DEG))
    crease = outside.any(axis=1) & ~(outside & (adjacent < 0)).any(axis=1) & (outside & turned).any(axis=1)
    for i in np.flatnonzero(crease):
        edge_normal(points, i, q, n)


def _face_hints(ids: np.ndarray | None, n_points: int, n_faces: int) -> np.ndarray:
    """Each point's guess of its face as a new int64 array: -1 (none) where not given or not a face."""
    if ids is None:
        return np.full(n_points, -1, dtype=np.int64)
    ids = np.array(ids, dtype=np.int64)
    ids[(ids >= n_faces) | (ids < 0)] = -1
    return ids


class SurfaceTracker:
    """The closest surface points of one ICP's cloud at each of its steps: ``tracker(p) -> (q, n, ids)``.

    Each step asks :meth:`SurfaceReference.nearest_into` with the last step's faces as hints (most points
    keep their face: a projection), into arrays kept for the whole ICP, which the next step overwrites;
    ``initial`` (:class:`~optipose.registration.result.Matches`, the cloud's matches where the ICP starts)
    answers the first step."""

    def __init__(self, reference: SurfaceReference, ids: np.ndarray | None = None, initial=None):
        self.reference, self._initial, self._hints = reference, initial, ids
        self.ids = self.q = self.n = self._open = None

    def __call__(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if self._initial is not None:
            initial, self._initial = self._initial, None
            self.ids = initial.ids.copy()
            return initial.q, initial.n, self.ids
        points = np.ascontiguousarray(points, dtype=np.float64)
        if self.q is None:  # the first step searched here: this ICP's own arrays
            m = len(points)
            self.ids = _face_hints(self.ids if self.ids is not None else self._hints, m, len(self.reference.faces))
            self.q, self.n, self._open = np.empty((m, 3)), np.empty((m, 3)), np.zeros(m, dtype=bool)
        self.reference.nearest_into(points, self.ids, self.q, self.n, self._open)
        return self.q, self.n, self.ids


class SampledReference:
    """A reference point cloud (n, 3) m with unit normals (n, 3) and a KD-tree built once.

    :meth:`nearest` (what ICP calls every step) first searches a grid of cells of about 2.5 × the points'
    spacing around each point, which is exact for a point that close to the cloud; the KD-tree answers
    the rest (points far from the cloud, early in an ICP)."""

    def __init__(self, points: np.ndarray, normals: np.ndarray, kind: str = "cad-sample"):
        from scipy.spatial import cKDTree

        from optipose.registration.closest_samples import point_grid

        points = np.ascontiguousarray(points, dtype=np.float64)
        self.kind = kind
        # the points are kept in the order of the cells of a grid over them, so that points near in space
        # are near in memory (a search touches a few cache lines, not a few hundred)
        lo, hi = (points.min(axis=0), points.max(axis=0)) if len(points) else (np.zeros(3), np.zeros(3))
        spacing = float(np.sqrt(_cloud_area(points, cKDTree(points)) / max(len(points), 1))) if len(points) > 1 else 0.0
        spacing = spacing if np.isfinite(spacing) else 0.0  # one point, or all on one spot
        cell = max(2.5 * spacing, float(np.prod(hi - lo + 1e-9) / _MAX_CELLS) ** (1 / 3), 1e-6)
        origin = lo - cell
        shape = np.floor((hi + cell - origin) / cell).astype(np.int64) + 1
        start, order = point_grid(points, origin, cell, shape)
        self.points = np.ascontiguousarray(points[order])
        self.normals = np.ascontiguousarray(np.asarray(normals, dtype=np.float64)[order])
        self._tree = cKDTree(self.points)
        self._point_grid = (origin, cell, shape, start)
        self._near = None

    def _grid(self) -> tuple:
        """The grid over the points, which are stored in its cell order (:func:`optipose.registration.closest_samples.point_grid`):
        origin, cell, shape and the CSR start of each cell."""
        return self._point_grid

    def _neighbours(self) -> tuple[np.ndarray, np.ndarray]:
        """Each point's :data:`_NEIGHBOURS` nearest other points (n, K), nearest first, and the radius within
        which the list is complete (:func:`optipose.registration.closest_samples.sample_neighbours`); built on first use."""
        if self._near is None:
            from optipose.registration.closest_samples import sample_neighbours

            self._near = sample_neighbours(self.points, _NEIGHBOURS, _REACH, *self._point_grid)
        return self._near

    def __repr__(self) -> str:
        return f"SampledReference({self.kind}, {len(self.points)} points)"

    def closest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        _, ids = self._tree.query(points)
        return self.points[ids], self.normals[ids], ids.astype(np.int64)

    def nearest(self, points: np.ndarray, ids: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The closest sample points, the same as :meth:`closest`'s: the grid answers the points near the
        cloud (``ids``, each point's match at the previous ICP step, bounds its search), the KD-tree the others."""
        from optipose.registration.closest_samples import grid_nearest

        points = np.ascontiguousarray(points, dtype=np.float64)
        hint = np.full(len(points), -1, dtype=np.int64) if ids is None else np.ascontiguousarray(ids, dtype=np.int64)
        found, open_ = grid_nearest(points, hint, self.points, *self._grid())
        open_ = np.flatnonzero(open_)
        if len(open_):
            found[open_] = self._tree.query(points[open_])[1]
        return self.points[found], self.normals[found], found

    def matches(self, points: np.ndarray):
        """The :class:`~optipose.registration.result.Matches` of a cloud (n, 3) where it is, with margins."""
        from optipose.registration.result import Matches

        track = SampleTracker(self)
        q, n, ids = track(points)
        return Matches(q, n, ids, track.margin)

    def tracker(self, ids: np.ndarray | None = None, initial=None) -> "SampleTracker":
        """The closest samples of one ICP's cloud, step after step, searching again only the points that
        may have changed theirs (:class:`SampleTracker`). ``ids`` are first hints; ``initial``, the cloud's
        matches where the ICP starts, answers the first step."""
        return SampleTracker(self, ids, initial)

    def follow(self, points: np.ndarray, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A sample point is only the closest one where the search says so: always search again."""
        return self.points[ids], self.normals[ids], np.zeros(len(points), dtype=bool)

    def sample(self, spacing: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
        return self.points, self.normals


class SampleTracker:
    """The closest samples of one ICP's cloud at each of its steps, exactly :meth:`SampledReference.nearest`'s,
    each point searched again only once it may have left its nearest sample's region: moved as far as the
    nearest bisector plane between that sample and another (or half the gap to the second-nearest) since it
    was last searched (:func:`optipose.registration.closest_samples.tracked_nearest`):
    an ICP near its fixed point moves its points by far less than that, so a step costs a pass over the
    cloud rather than a search per point. ``tracker(p) -> (q, n, ids)``, arrays it updates at the next call."""

    def __init__(self, reference: SampledReference, ids: np.ndarray | None = None, initial=None):
        self.reference, self._initial = reference, initial
        self._ids = None if ids is None else np.array(ids, dtype=np.int64)
        self.q = None  # per point, from the first call on: q, n, ids, anchor, margin (see tracked_nearest)

    def __call__(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        from optipose.registration.closest_samples import tracked_nearest

        points = np.ascontiguousarray(points, dtype=np.float64)
        m, ref = len(points), self.reference
        if self.q is None:
            if (
                self._initial is not None
            ):  # the cloud's matches on this reference where the ICP starts: the first step is answered
                initial, self._initial = self._initial, None
                self.ids, self.q, self.n = initial.ids.copy(), initial.q.copy(), initial.n.copy()
                self.anchor = points.copy()
                self.margin = np.zeros(m) if initial.margin is None else initial.margin.copy()
                return self.q, self.n, self.ids
            self.ids = np.full(m, -1, dtype=np.int64) if self._ids is None else self._ids
            self.ids[self.ids >= len(ref.points)] = -1  # a hint that is no point of this reference (any other is safe)
            self.anchor, self.margin = np.zeros((m, 3)), np.zeros(m)
            self.q, self.n = np.empty((m, 3)), np.empty((m, 3))
        open_ = tracked_nearest(
            points,
            self.ids,
            self.anchor,
            self.margin,
            self.q,
            self.n,
            ref.points,
            ref.normals,
            *ref._neighbours(),
            _REACH,
            *ref._grid(),
        )
        open_ = np.flatnonzero(open_)
        if len(open_):  # far from the cloud: the KD-tree, searched again next step (margin zero)
            found = ref._tree.query(points[open_])[1]
            self.ids[open_], self.q[open_], self.n[open_] = found, ref.points[found], ref.normals[found]
        return self.q, self.n, self.ids


def _cloud_area(points: np.ndarray, tree) -> float:
    """About the area a surface sample covers (m²): its points times the squared median distance to a neighbour."""
    pick = points[:: max(1, len(points) // 2000)]
    d = tree.query(pick, k=2)[0][:, 1]
    return float(len(points) * np.median(d) ** 2)


def sample_surface(
    vertices: np.ndarray, faces: np.ndarray, spacing: float, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
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
