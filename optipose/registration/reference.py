"""Reference (fixed, target) clouds for registration, each with its search structure built once.

Every reference answers ``closest(points) -> (q, n, ids)``: the closest reference point, its unit normal
and an id. Two kinds:

- :class:`SurfaceReference` (here) — the CAD triangles themselves (``cad-surface``): exact (float64) closest
  points on the surface, normals of the faces (off an edge or a corner, the direction to the closest
  point, whatever the triangles). This is a dense CAD sample in the limit of zero spacing, so the
  reference adds no sampling error. A point within a millimetre of the part is answered by an exact
  search of the faces listed in the grid cells around it (each face listed in the cells it crosses, so
  the grid is linear in the faces: :mod:`optipose.registration.surface_index`); the rest, far from the part,
  by Open3D's ``RaycastingScene`` (a float32 BVH built on first use). Its arrays can be written and mapped
  back read-only (:func:`save_reference`, :func:`load_reference`), one copy for the processes of a machine.
  Between ICP steps, a point that still projects well inside the face it was matched to keeps that face
  (:meth:`SurfaceReference.follow`), which makes an iteration near convergence cost a projection rather than
  a search.
- :class:`~optipose.registration.sampled.SampledReference` — a point cloud with normals and a KD-tree: a CAD
  sample at a given spacing (``cad-sample``) or the scan at the nominal orientation (``nominal-scan``).

An ICP asks ``reference.tracker(ids, initial)`` for its closest points at every step. The surface's
:class:`SurfaceTracker` calls ``nearest_into`` with the last step's faces, into arrays of its own; a sample's
:class:`~optipose.registration.sampled.SampleTracker` keeps, per point, how far it may move and keep its
nearest sample, and searches only the points that moved farther (the literal point-to-point ICP crawls for up
to 100 steps, most of them moving most points by far less).
"""

from __future__ import annotations

import numpy as np

from optipose.registration.sampled import sample_surface
from optipose.registration.surface_index import ARRAY_NAMES, search_reach, surface_arrays

__all__ = ["SurfaceReference", "SurfaceTracker", "save_reference", "load_reference"]


class SurfaceReference:
    """Closest points on a triangle mesh (metres). vertices (v, 3), faces (f, 3)."""

    kind = "cad-surface"

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, arrays: dict | None = None):
        if arrays is None:
            arrays = surface_arrays(vertices, faces)
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
        return dict(zip(ARRAY_NAMES, values))

    def _grid(self) -> tuple:
        """The grid's origin (3,), cell (m), shape (3,), the search's reach in cells, and the CSR start and
        face list of the faces that cross each cell (:func:`optipose.registration.surface_index.face_grid`)."""
        meta = self._meta
        return (
            meta[1:4],
            float(meta[4]),
            meta[5:8].astype(np.int64),
            search_reach(float(meta[4])),
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
        None, None, {name: np.load(Path(folder) / f"{name}.npy", mmap_mode="r") for name in ARRAY_NAMES}
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
