"""A cell's error sources applied to the scanner's clouds, in a worker (docs/cell.md).

The scanner casts the CAD at the orientation the robot really set, from the poses where the sensors
really stand, and builds each cloud with the poses the cell believes (:meth:`LiveCell.rpy`,
:meth:`LiveCell.poses`). What moves a measured point off that CAD hit is then added along its laser ray:

- a surface that lies ``d`` off the CAD along its outward normal ``n`` (the part as made, or the part
  moved by the robot's path error at that profile) is hit ``d / (n·r)`` further along the ray ``r``
  (to first order in ``d`` over the surface's curvature radius; the factor is capped at grazing
  incidence, where the point would drop out);
- the material puts the spot's centroid below the surface (sub-surface scattering), spreads it (speckle,
  the sub-surface spread), and returns spurious points (anywhere, and more near concave edges: the
  line's reflection off the other face), each along the ray.

Per run seed one cell instance (its magnitudes first, drawn from the cell's ranges when it has any:
:meth:`optipose.cell.config.Cell.instance`; then the part as made, the calibration); per scan (the orientation's
noise seed) one robot path and the material's draws — the same at every noise level of the scan, so the
levels differ by the sensor's noise alone.

What a point draws depends on the seeds and the surface, not on the mesh's triangles: the part as made's
draws are the surface's (:mod:`optipose.cell.asmade`); the material's are hashed from the scan's seed, the
sensor and the point's ray (its profile and column: :func:`optipose.cell.kernels.ray_draws`), never from
its place among the scan's points, which another triangulation may change; and multipath ghosts are the
points within the material's distance of the concave edges as segments (:class:`ConcaveEdges`), the same
line whatever the edges it is split into. The calibration and the robot's draws take no mesh at all (the
rotation centre is the part file's, else its bounding box's).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from optipose.cell.asmade import AsMade, Process
from optipose.cell.config import Cell
from optipose.cell.robot import calibrated_poses, orientation_error, path_draw
from optipose.model.material import MaterialEffects
from optipose.seeds import derived_seed

__all__ = ["CellSetup", "LiveCell", "ConcaveEdges", "GRAZING"]

GRAZING = 0.2  # |cos| of the angle between ray and normal below which a displacement's factor is capped
_CELL, _INSTANCE, _SCAN, _CALIBRATION = 0xCE11, 1, 2, 3
_EDGE_SAMPLE = 1e-4  # m between the samples of a concave edge that the multipath test measures to
_CONCAVE_DEG = 20.0  # faces meeting at an inside angle this far below 180° form a concave edge
# the kernel's part-as-made arguments when the part is its CAD: no form grid, no planes, no scale, warp or layers
_NO_PART = (
    np.zeros((0, 0, 0)),
    np.zeros(3),
    np.ones(3),
    np.zeros(0, np.int64),
    np.zeros((0, 3)),
    np.zeros(0),
    np.zeros((0, 3)),
    np.zeros(3),
    np.zeros(3),
    0.0,
    0,
    1.0,
    1.0,
    0.0,
    0.0,
    0.5,
)


_NO_RAYS = (np.zeros(0), np.zeros(0))  # the kernel's rays when the moved points are not placed on any


@dataclass(frozen=True)
class CellSetup:
    """What a worker needs of the cell (picklable): the cell, the part's process as the cell scales it,
    and the part material's effects when the cell has them on."""

    cell: Cell
    process: Process
    effects: MaterialEffects

    @property
    def ideal(self) -> bool:
        """Every source a no-op (an ideal cell's process is the CAD and its material has no effects)."""
        robot, calibration = self.cell.robot, self.cell.calibration
        return not (robot.moves or robot.orientation or calibration.off) and self.process.exact and self.effects.none

    @classmethod
    def of(cls, cell: Cell, part) -> "CellSetup":
        from optipose.model.material import load_material

        effects = load_material(part.material).effects if cell.material else MaterialEffects()
        return cls(cell, cell.process(getattr(part, "process", "") or None), effects)

    def instance(self, seed: int) -> "CellSetup":
        """The setup of the cell instance of run seed ``seed``: the cell's magnitudes drawn from its ranges
        (:meth:`optipose.cell.config.Cell.instance`), the part's process scaled by the drawn ``process_scale``;
        itself when the cell has no range."""
        return self._as(self.cell.instance(seed))

    def middle(self) -> "CellSetup":
        """The setup of the cell of the ranges' middles (:meth:`optipose.cell.config.Cell.middle`)."""
        return self._as(self.cell.middle())

    def _as(self, cell: Cell) -> "CellSetup":
        if cell is self.cell:
            return self
        # the process was scaled by the range's middle (never 0 for a range): rescale it to the drawn factor
        factor = cell.process_scale / self.cell.process_scale if cell.process_scale != self.cell.process_scale else 1.0
        return CellSetup(cell, self.process.scaled(factor) if factor != 1.0 else self.process, self.effects)


class LiveCell:
    """One cell instance in a worker: its magnitudes (from the cell's ranges), the part as made and the
    calibration drawn from the run's ``seed``; two layouts evaluated with one seed get the same instance."""

    def __init__(self, setup: CellSetup, vertices: np.ndarray, faces: np.ndarray, centre: np.ndarray, seed: int):
        setup = setup.instance(seed)  # a cell of points: itself, no draw made
        self.setup, self.centre, self.seed = setup, np.asarray(centre, float), int(seed)
        self.as_made = None
        if not setup.process.exact:
            self.as_made = AsMade(setup.process, vertices, faces, derived_seed(seed, _CELL + _INSTANCE))
        self.edges = ConcaveEdges.of(vertices, faces) if setup.effects.concave_fraction else None

    def rpy(self, rpy: np.ndarray, scan_seed: int) -> np.ndarray:
        """The orientation the robot sets when the protocol commands ``rpy`` (rad) in the scan of ``scan_seed``."""
        rng = np.random.default_rng([int(scan_seed), _CELL, _SCAN, 0])
        return np.asarray(rpy, float) + orientation_error(self.setup.cell.robot, rng)

    def poses(self, poses: list[np.ndarray]) -> list[np.ndarray]:
        """Where the sensors the cell believes at ``poses`` truly stand (one calibration per run)."""
        if not self.setup.cell.calibration.off:
            return [np.asarray(T, float) for T in poses]
        rng = np.random.default_rng([self.seed, _CELL, _CALIBRATION])
        return calibrated_poses(self.setup.cell.calibration, poses, self.centre, rng)

    def perturb(
        self,
        levels: list[list],
        normals_P: list[np.ndarray],
        apex_z: list[float],
        shifts: np.ndarray,
        T_O_P: np.ndarray,
        step: float,
        scan_seed: int,
        lines: list[tuple[np.ndarray, np.ndarray]] | None = None,
    ) -> list[list]:
        """Each scan of ``levels`` (per noise level, per sensor) with the cell's displacements added along
        its rays, each point then what its reported height gives (:mod:`optipose.scan.heights`), as a reader
        of the profiles gets it, and the scan's raw profiles (when kept) those heights. ``normals_P``: per
        sensor, its scanner's outward unit face normals in the part's frame; ``apex_z``: the sensor's laser
        apex on its z axis (m; inf: parallel rays); ``shifts``: the motion's offsets; ``T_O_P``: the part's
        pose as the robot set it; ``lines``: per sensor, its columns' rays (``Scanner.lines``; ``None``: the
        moved points as they are, on no sensor's rays)."""
        from optipose.cell.kernels import along_rays
        from optipose.scan.heights import as_reported

        cell, effects = self.setup.cell, self.setup.effects
        path = (np.zeros((0, 3)), np.zeros((0, 3)))
        if cell.robot.moves:
            path = path_draw(cell.robot, shifts, step, np.random.default_rng([int(scan_seed), _CELL, _SCAN, 1]))
        R, t = np.ascontiguousarray(T_O_P[:3, :3]), np.ascontiguousarray(T_O_P[:3, 3])
        centre_O = R @ self.centre + t  # the rotation centre, about which the robot's rotations are
        part = self.as_made.kernel_args() if self.as_made is not None else _NO_PART
        shifts = np.ascontiguousarray(shifts, dtype=float)
        out = [list(level) for level in levels]
        for j, scan in enumerate(levels[0]):
            if scan is None or not len(scan.points):  # not scanned here (its cloud is known), or nothing seen
                continue
            T = scan.T_O_S
            apex = (
                T[:3, :3] @ np.array([0.0, 0.0, apex_z[j]]) + T[:3, 3] if np.isfinite(apex_z[j]) else np.full(3, np.nan)
            )
            key = np.uint64(np.random.default_rng([int(scan_seed), _CELL, _SCAN, 2, j]).integers(1, 2**63))
            extra = self._material(effects, scan, R, t, key)
            moved = np.empty_like(scan.points)
            along_rays(
                scan.points,
                scan.face,
                scan.profile,
                shifts,
                normals_P[j],
                R,
                t,
                apex,
                np.ascontiguousarray(T[:3, 2]),
                GRAZING,
                *part,
                *path,
                centre_O,
                extra,
                np.ascontiguousarray(scan.column),
                *(lines[j] if lines else _NO_RAYS),
                np.ascontiguousarray(T[:3, :3]),
                np.ascontiguousarray(T[:3, 3]),
                scan.raw.reshape(-1),
                scan.raw.shape[1],
                moved,
            )
            out[0][j] = replace(scan, points=moved)
            if len(out) > 1:  # the other noise levels: the same rays, the same moves
                delta = moved - scan.points
                for level in out[1:]:
                    if lines:
                        level[j] = as_reported(
                            replace(level[j], points=level[j].points.copy()), delta, lines[j], shifts
                        )
                    else:
                        level[j] = replace(level[j], points=level[j].points + delta)
        return out

    def _material(self, e: MaterialEffects, scan, R: np.ndarray, t: np.ndarray, key: np.uint64) -> np.ndarray:
        """The material's shift of each point of ``scan`` along its ray (m, positive: deeper), each point's
        draws hashed from ``key`` and its ray (:func:`optipose.cell.kernels.ray_draws`)."""
        from optipose.cell.kernels import ray_draws

        m = len(scan.points)
        s, ghost = np.empty(m), np.empty(m)
        sigma = float(np.hypot(e.speckle, e.subsurface_sigma))
        concave = e.concave_fraction if self.edges is not None else 0.0
        profile, column = np.ascontiguousarray(scan.profile), np.ascontiguousarray(scan.column)
        ray_draws(
            profile, column, key, e.subsurface_bias, sigma, e.spurious_fraction, e.spurious_range, concave, s, ghost
        )
        if concave:  # multipath: the reflected light's path is longer, the ghost lies behind
            drawn = np.flatnonzero(ghost >= 0.0)  # drawn first: only these are looked up
            near = drawn[self.edges.near((scan.points[drawn] - t) @ R, e.concave_distance)]
            s[near] += ghost[near] * e.spurious_range
        return s


class ConcaveEdges:
    """A mesh's concave edges (faces meeting at an inside angle under 180° − :data:`_CONCAVE_DEG`) as the
    segments they are, whatever their split into edges: which points lie within a distance of them."""

    def __init__(self, start: np.ndarray, end: np.ndarray):
        from scipy.spatial import cKDTree

        self.start, self.end = start, end
        count = np.maximum(2, np.ceil(np.linalg.norm(end - start, axis=1) / _EDGE_SAMPLE).astype(np.int64) + 1)
        self.segment = np.repeat(np.arange(len(start)), count)
        u = (np.arange(len(self.segment)) - np.repeat(np.cumsum(count) - count, count)) / np.repeat(count - 1, count)
        self.tree = cKDTree(start[self.segment] + u[:, None] * (end - start)[self.segment])

    @classmethod
    def of(cls, vertices: np.ndarray, faces: np.ndarray) -> "ConcaveEdges | None":
        """The concave edges of a mesh; ``None`` when it has none."""
        import trimesh

        mesh = trimesh.Trimesh(vertices, faces, process=False)
        concave = (~mesh.face_adjacency_convex) & (mesh.face_adjacency_angles > np.deg2rad(_CONCAVE_DEG))
        edges = np.asarray(vertices, float)[mesh.face_adjacency_edges[concave]]
        return cls(edges[:, 0], edges[:, 1]) if len(edges) else None

    def near(self, x: np.ndarray, distance: float) -> np.ndarray:
        """(m,) bool: whether each point of ``x`` (m, 3) lies within ``distance`` of a concave edge, exactly
        (to rounding): the samples, at most :data:`_EDGE_SAMPLE` apart on each segment, decide all but the
        points whose nearest sample is between ``distance`` and ``distance`` + half that, which the segments
        of the samples within that reach decide."""
        reach = distance + 0.5 * _EDGE_SAMPLE
        d = self.tree.query(x, distance_upper_bound=reach)[0]
        out = d < distance
        band = np.flatnonzero(~out & (d < reach))
        for i, around in zip(band, self.tree.query_ball_point(x[band], reach)):
            seg = np.unique(self.segment[around])
            a, ab = self.start[seg], self.end[seg] - self.start[seg]
            u = np.einsum("ij,ij->i", x[i] - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300)
            u = np.clip(u, 0.0, 1.0)
            out[i] = np.min(np.linalg.norm(x[i] - (a + u[:, None] * ab), axis=1)) < distance
        return out
