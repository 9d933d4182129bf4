"""Does a sensor head hit the part (swept along the scan) or a keep-out box? (docs/method.md, "Constraints")

The head is the sensor's oriented box (:meth:`SensorModel.head_box_corners`, in S) placed by ``T_O_S``.
During a scan the part travels along ``+x_O`` by the motion's offsets, and so do its keep-outs (the flange
that holds it). The obstacles are therefore

* the convex hull of the part swept over the scan: the hull of the part's hull vertices shifted to the
  first and the last scan offset (the Minkowski sum of a convex set and a segment), and
* each keep-out box stretched along x by the same travel.

Each obstacle is tested against the head box with the separating-axis theorem over the obstacle's face
normals, the box's three axes and the cross products of their edge directions — exact for two convex
polytopes. The test is **conservative on the convex hull**: a head that dips into a concavity of the part
(inside a U bracket, over a pocket) counts as a collision even when it would miss the real surface.

A part whose hull has more than :data:`EXACT_HULL_VERTICES` vertices (a round CAD export: most of its
vertices are on the hull) is bounded instead by a polytope of fixed size that contains its swept hull: the
planes of a fixed set of directions (:func:`bounding_directions`: evenly spread ones, the axes and the
normals of the part's large flat faces) each moved out to the swept part's extent along it. Its clearances
are the same test on that polytope, lower than the hull's by at most how far the polytope stands out of the
hull (:data:`BOUND_LOOSENESS` of the part's radius for a sphere), and cost memory and time linear in the
mesh; a hull that small is the part's own (the shipped parts).

The signed clearance is the largest gap found along any tested axis: positive means separated by at least
that much (a lower bound on the true distance), negative is minus the smallest overlap (the depth to push
the head out along the best axis). A head *collides* when its clearance is below ``margin`` (default
:data:`DEFAULT_MARGIN`, 2 mm: a ±2° orientation offset moves points 57 mm from the rotation centre by
2 mm). Once the obstacles of a part are built (cached per part) a call's work is their vertices times their
edge directions: a few hundred each for a bounding polytope, fewer for the shipped parts' hulls.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

from optipose.model.convex import hull_arrays
from optipose.model.grouping import unique_rows
from optipose.model.sensor import SensorModel, load_sensor

__all__ = [
    "DEFAULT_MARGIN",
    "EXACT_HULL_VERTICES",
    "BOUND_LOOSENESS",
    "Clearance",
    "ConvexSet",
    "CollisionModel",
    "bounding_directions",
    "collision_model",
    "clearance",
    "collides",
    "heads_clearance",
    "check_sensors_outside",
    "contains",
]

DEFAULT_MARGIN = 2e-3  # m
_DEDUP_DECIMALS = 9
# A hull of at most this many vertices is tested itself: the SAT's per-call work is its vertices times its
# edge directions, a hull this size keeps that small (the shipped parts' hulls have 8 to 140 vertices).
EXACT_HULL_VERTICES = 256
_EVEN_DIRECTIONS = 320  # the bounding polytope's evenly spread planes
_FLAT_DIRECTIONS = 64  # ... and at most this many of the part's own large flat faces' planes
_FLAT_SHARE = 0.005  # a flat face counts as large from this share of the mesh's area
_THICKEN = 1e-6  # m, every bounding plane moved out this much more: a flat part still bounds a solid
BOUND_LOOSENESS = 0.01  # how far the bounding polytope may stand out of a sphere, in its radius (see the tests)
_CHUNK = 1 << 20  # floats per block of a streamed product: memory stays linear in the mesh


class Clearance(NamedTuple):
    """Signed clearance (m) of a head to the nearest obstacle, and that obstacle's name."""

    distance: float
    obstacle: str


@dataclass(frozen=True)
class ConvexSet:
    """A convex polytope for SAT: vertices (v, 3) m, unit face normals (f, 3) with the vertices' extent
    along each, ``face_lo``/``face_hi`` (f,), and unit edge directions (e, 3)."""

    vertices: np.ndarray
    face_normals: np.ndarray
    face_lo: np.ndarray
    face_hi: np.ndarray
    edge_dirs: np.ndarray

    @classmethod
    def hull_of(cls, points: np.ndarray) -> "ConvexSet":
        """The convex hull of points (n, 3) m."""
        from scipy.spatial import ConvexHull, QhullError

        try:
            hull = ConvexHull(points)
        except (
            QhullError
        ):  # a flat part (a sheet of zero thickness) swept in its own plane: joggled, still flat to ~1e-10
            hull = ConvexHull(points, qhull_options="QJ")
        vertices = points[hull.vertices]
        normals = _unique_directions(hull.equations[:, :3])
        tri = hull.simplices
        edges = np.concatenate(
            [
                points[tri[:, 1]] - points[tri[:, 0]],
                points[tri[:, 2]] - points[tri[:, 1]],
                points[tri[:, 0]] - points[tri[:, 2]],
            ]
        )
        return cls._build(vertices, normals, _unique_directions(edges))

    @classmethod
    def bounding(cls, points: np.ndarray, directions: np.ndarray, travel: np.ndarray) -> "ConvexSet":
        """The polytope of the planes ``d·x <= h(d)`` over unit ``directions`` (k, 3), ``h`` the extent of
        ``points`` (n, 3) m swept by ``travel`` (2, 3) along ``d`` (plus :data:`_THICKEN`): it contains
        the swept points' hull. Memory linear in the points (streamed in blocks)."""
        from scipy.spatial import HalfspaceIntersection

        extent = np.full(len(directions), -np.inf)
        rows = max(1, _CHUNK // len(directions))
        for a in range(0, len(points), rows):
            np.maximum(extent, (points[a : a + rows] @ directions.T).max(axis=0), out=extent)
        extent += np.maximum(directions @ travel[0], directions @ travel[1]) + _THICKEN
        inside = points.mean(axis=0) + travel.mean(axis=0)  # strictly inside: every plane is _THICKEN beyond it
        corners = HalfspaceIntersection(np.c_[directions, -extent], inside).intersections
        return cls.hull_of(corners)

    @classmethod
    def box(cls, lo: np.ndarray, hi: np.ndarray) -> "ConvexSet":
        """An axis-aligned box, corners ``lo``, ``hi`` (3,) m."""
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        return cls._build(corners, np.eye(3), np.eye(3))

    @classmethod
    def head_of(cls, sensor: SensorModel, T_O_S: np.ndarray) -> "ConvexSet":
        """The sensor's head box placed at ``T_O_S`` (4×4), in O."""
        corners = sensor.head_box_corners() @ np.asarray(T_O_S, float)[:3, :3].T + T_O_S[:3, 3]
        axes = np.asarray(T_O_S, float)[:3, :3].T  # rows: the box's axes
        return cls._build(corners, axes, axes)

    @classmethod
    def _build(cls, vertices: np.ndarray, normals: np.ndarray, edges: np.ndarray) -> "ConvexSet":
        proj = vertices @ normals.T
        return cls(vertices, normals, proj.min(axis=0), proj.max(axis=0), edges)


class CollisionModel:
    """The obstacles of one part for one sensor model; :meth:`clearance` and :meth:`collides` per pose.

    part : an :class:`optipose.model.part.Part` (mesh, motion, keep-outs); sensor : model or preset name
    (default: the part's sensor).
    """

    def __init__(self, part, sensor: SensorModel | str | None = None):
        self.sensor = load_sensor(sensor if sensor is not None else part.sensor)
        offsets = part.motion.offsets()
        travel = np.array([[offsets.min(), 0.0, 0.0], [offsets.max(), 0.0, 0.0]])
        try:
            hull = hull_arrays(part.mesh)[0]
        except (
            Exception
        ):  # trimesh's hull of a flat mesh fails (qhull, or its winding fix): the vertices span the same hull
            hull = np.asarray(part.mesh.vertices, dtype=float)
        self.exact = len(hull) <= EXACT_HULL_VERTICES  # else the hull's bounding polytope (module doc)
        if self.exact:
            swept = ConvexSet.hull_of(np.concatenate([hull + travel[0], hull + travel[1]]))
        else:
            swept = ConvexSet.bounding(hull, bounding_directions(part.mesh), travel)
        self.obstacles: list[tuple[str, ConvexSet]] = [("part", swept)]
        for keepout in part.keepouts:
            lo, hi = np.asarray(keepout.lo, float) + travel[0], np.asarray(keepout.hi, float) + travel[1]
            self.obstacles.append((keepout.name, ConvexSet.box(lo, hi)))
        corners = self.sensor.head_box_corners()
        self._head_centre_S = 0.5 * (corners.min(axis=0) + corners.max(axis=0))
        self._head_half = 0.5 * (corners.max(axis=0) - corners.min(axis=0))

    def clearance(self, T_O_S: np.ndarray) -> Clearance:
        """Signed clearance (m) of the head at ``T_O_S`` (4×4) to the nearest obstacle (see module doc)."""
        axes = np.asarray(T_O_S, float)[:3, :3]  # columns: the head box's axes in O
        centre = axes @ self._head_centre_S + T_O_S[:3, 3]
        best = Clearance(np.inf, "")
        for name, convex in self.obstacles:
            gap = _sat_gap(convex, centre, axes, self._head_half)
            if gap < best.distance:
                best = Clearance(float(gap), name)
        return best

    def collides(self, T_O_S: np.ndarray, margin: float = DEFAULT_MARGIN) -> bool:
        """True when the head at ``T_O_S`` is closer than ``margin`` (m) to the swept part or a keep-out."""
        return self.clearance(T_O_S).distance < margin


_MODELS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def collision_model(part, sensor: SensorModel | str | None = None) -> CollisionModel:
    """The part's :class:`CollisionModel` for a sensor model, built once and cached per part object."""
    per_part = _MODELS.setdefault(part, {})
    key = sensor.name if isinstance(sensor, SensorModel) else (sensor or part.sensor)
    if key not in per_part or (isinstance(sensor, SensorModel) and per_part[key].sensor != sensor):
        per_part[key] = CollisionModel(part, sensor)
    return per_part[key]


def clearance(part, sensor: SensorModel | str | None, T_O_S: np.ndarray) -> Clearance:
    """Signed clearance (m) of the sensor head at ``T_O_S`` to the swept part and the keep-outs."""
    return collision_model(part, sensor).clearance(T_O_S)


def collides(part, sensor: SensorModel | str | None, T_O_S: np.ndarray, margin: float = DEFAULT_MARGIN) -> bool:
    """True when the sensor head at ``T_O_S`` comes within ``margin`` (m) of the swept part or a keep-out."""
    return collision_model(part, sensor).collides(T_O_S, margin)


def check_sensors_outside(part, layout) -> None:
    """Raise :class:`ConfigError` for a sensor of ``layout`` whose window (where its laser rays start) or
    head-box centre lies inside the part's material; such a sensor sees nothing. A mesh that is not
    watertight has no inside, and is not checked."""
    from optipose.errors import ConfigError

    if not part.mesh.is_watertight:
        return
    for s in layout.sensors:
        model = load_sensor(s.sensor or part.sensor)
        corners = model.head_box_corners()
        where = np.array([[0.0, 0.0, model.window_z], 0.5 * (corners.min(axis=0) + corners.max(axis=0))])
        where = where @ s.T_O_S[:3, :3].T + s.T_O_S[:3, 3]
        inside = contains(part.mesh, where)
        if inside.any():
            what = "window" if inside[0] else "head"
            at = np.round(where[int(np.argmax(inside))] * 1e3, 1).tolist()
            raise ConfigError(
                f"sensor {s.name}: its {what} is inside the part (at {at} mm in O); move it out along -z_S"
            )


_RAY = np.array([1.0, 1.0 + 1e-3, 1.0 - 2e-3])  # near the diagonal, along no edge of a CAD face


def contains(mesh, points: np.ndarray) -> np.ndarray:
    """(p,) bool: each point inside the closed ``mesh``, by the parity of the faces a ray from it crosses (as
    ``mesh.contains``), every face tested in one compiled pass per point: no ray-tracing scene is built for a
    handful of points (on a 5 M-face mesh that took longer than the scan)."""
    ray = _RAY / np.linalg.norm(_RAY)
    tris = np.asarray(mesh.vertices, dtype=np.float64), np.ascontiguousarray(mesh.faces, dtype=np.int64)
    return np.array(
        [_crossings(*tris, np.asarray(p, dtype=np.float64), ray) % 2 == 1 for p in np.atleast_2d(points)], dtype=bool
    )


@njit(cache=True, nogil=True)
def _crossings(vertices, faces, origin, d):
    """How many faces the ray ``origin + t d`` (t > 0) crosses (Möller–Trumbore)."""
    count = 0
    for f in range(faces.shape[0]):
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        e10, e11, e12 = (
            vertices[b, 0] - vertices[a, 0],
            vertices[b, 1] - vertices[a, 1],
            vertices[b, 2] - vertices[a, 2],
        )
        e20, e21, e22 = (
            vertices[c, 0] - vertices[a, 0],
            vertices[c, 1] - vertices[a, 1],
            vertices[c, 2] - vertices[a, 2],
        )
        p0, p1, p2 = d[1] * e22 - d[2] * e21, d[2] * e20 - d[0] * e22, d[0] * e21 - d[1] * e20
        det = e10 * p0 + e11 * p1 + e12 * p2
        if det == 0.0:
            continue
        s0, s1, s2 = origin[0] - vertices[a, 0], origin[1] - vertices[a, 1], origin[2] - vertices[a, 2]
        u = (s0 * p0 + s1 * p1 + s2 * p2) / det
        if u < 0.0 or u > 1.0:
            continue
        q0, q1, q2 = s1 * e12 - s2 * e11, s2 * e10 - s0 * e12, s0 * e11 - s1 * e10
        v = (d[0] * q0 + d[1] * q1 + d[2] * q2) / det
        if v < 0.0 or u + v > 1.0:
            continue
        if (e20 * q0 + e21 * q1 + e22 * q2) / det > 0.0:
            count += 1
    return count


def heads_clearance(
    sensor_a: SensorModel | str, T_O_Sa: np.ndarray, sensor_b: SensorModel | str, T_O_Sb: np.ndarray
) -> float:
    """Signed clearance (m) between two sensors' head boxes (negative: they overlap), for layouts of
    several sensors; exact for the two boxes (SAT)."""
    sb = load_sensor(sensor_b)
    corners = sb.head_box_corners()
    centre_S, half = 0.5 * (corners.min(axis=0) + corners.max(axis=0)), 0.5 * np.ptp(corners, axis=0)
    axes = np.asarray(T_O_Sb, float)[:3, :3]
    return _sat_gap(ConvexSet.head_of(load_sensor(sensor_a), T_O_Sa), axes @ centre_S + T_O_Sb[:3, 3], axes, half)


def bounding_directions(mesh) -> np.ndarray:
    """Unit directions (k, 3) of a bounding polytope's planes: :data:`_EVEN_DIRECTIONS` spread evenly over
    the sphere (a Fibonacci lattice), the six axes, and the normals of the mesh's largest flat faces (at
    most :data:`_FLAT_DIRECTIONS`, each at least :data:`_FLAT_SHARE` of the area; triangles of one plane
    summed), so that a part's big planar sides bound it exactly."""
    k = np.arange(_EVEN_DIRECTIONS) + 0.5
    z, phi = 1.0 - 2.0 * k / _EVEN_DIRECTIONS, np.pi * (1.0 + 5**0.5) * k
    rho = np.sqrt(1.0 - z * z)
    even = np.c_[rho * np.cos(phi), rho * np.sin(phi), z]
    normals, area = np.asarray(mesh.face_normals, float), np.asarray(mesh.area_faces, float)
    key = np.rint(normals * 1e6).astype(np.int64)  # normals to 6 decimals
    first, which = unique_rows(key)
    planes = key[first] / 1e6
    total = np.bincount(which, weights=area, minlength=len(planes))
    big = np.argsort(-total, kind="stable")[:_FLAT_DIRECTIONS]
    big = big[total[big] >= _FLAT_SHARE * max(area.sum(), 1e-300)]
    flat = planes[big] / np.maximum(np.linalg.norm(planes[big], axis=1, keepdims=True), 1e-300)
    return np.concatenate([even, np.eye(3), -np.eye(3), flat[np.linalg.norm(planes[big], axis=1) > 0.5]])


def _sat_gap(convex: ConvexSet, centre: np.ndarray, axes: np.ndarray, half: np.ndarray) -> float:
    """Largest separation (m) between ``convex`` and the box (centre (3,), axes (3, 3) columns, half
    extents (3,)) over all SAT axes; negative when they overlap on every axis."""
    # Obstacle face normals: the obstacle's extent is precomputed.
    n = convex.face_normals
    c, r = n @ centre, np.abs(n @ axes) @ half
    gap = max(np.max(c - r - convex.face_hi), np.max(convex.face_lo - c - r))
    # Box axes, then the cross products of edge directions with them.
    cross = np.cross(convex.edge_dirs[:, None, :], axes.T[None, :, :]).reshape(-1, 3)
    norm = np.linalg.norm(cross, axis=1)
    cross = cross[norm > 1e-9] / norm[norm > 1e-9, None]
    test = np.concatenate([axes.T, cross])
    proj = convex.vertices @ test.T  # (v, k)
    c, r = test @ centre, np.abs(test @ axes) @ half
    gap = max(gap, np.max(c - r - proj.max(axis=0)), np.max(proj.min(axis=0) - c - r))
    return float(gap)


def _unique_directions(vectors: np.ndarray) -> np.ndarray:
    """Unit directions (k, 3) of vectors (n, 3), with v and -v counted once and zero vectors dropped."""
    norm = np.linalg.norm(vectors, axis=1)
    v = vectors[norm > 1e-12] / norm[norm > 1e-12, None]
    lead = np.argmax(np.abs(v) > 1e-9, axis=1)  # first non-zero component positive: v and -v coincide
    v = v * np.sign(v[np.arange(len(v)), lead])[:, None]
    _, keep = np.unique(np.round(v, _DEDUP_DECIMALS), axis=0, return_index=True)
    return v[np.sort(keep)]
