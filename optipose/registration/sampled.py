"""A sampled reference for registration: a point cloud with unit normals, searched on a grid over it and
by a KD-tree (:class:`SampledReference`) — a CAD sample at a given spacing (``cad-sample``,
:func:`sample_surface`) or the scan at the nominal orientation (``nominal-scan``) — and the closest samples of
one ICP's cloud step after step (:class:`SampleTracker`), each point searched again only once it may have left
its nearest sample's bisector planes, and then first among that sample's neighbours. The compiled searches are
:mod:`optipose.registration.closest_samples`; the CAD surface's own reference is
:mod:`optipose.registration.reference`.
"""

from __future__ import annotations

import numpy as np

from optipose.registration.surface_index import MAX_CELLS

__all__ = ["SampledReference", "SampleTracker", "sample_surface"]

_NEIGHBOURS = 16  # per sample point: where an ICP's point that left its nearest sample looks first
_REACH = 2  # cells: how far the grid is searched (SampleTracker) before the KD-tree is asked


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
        cell = max(2.5 * spacing, float(np.prod(hi - lo + 1e-9) / MAX_CELLS) ** (1 / 3), 1e-6)
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
