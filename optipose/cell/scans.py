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

Per run seed one cell instance (the part as made, the calibration); per scan (the orientation's noise
seed) one robot path and the material's draws — the same at every noise level of the scan, so the
levels differ by the sensor's noise alone.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from optipose.cell.asmade import AsMade, Process
from optipose.cell.config import Cell
from optipose.cell.robot import calibrated_poses, orientation_error, path_draw
from optipose.model.material import MaterialEffects
from optipose.seeds import derived_seed

__all__ = ["CellSetup", "LiveCell", "GRAZING"]

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


class LiveCell:
    """One cell instance in a worker: the part as made and the calibration drawn from the run's ``seed``."""

    def __init__(self, setup: CellSetup, vertices: np.ndarray, faces: np.ndarray, centre: np.ndarray, seed: int):
        self.setup, self.centre, self.seed = setup, np.asarray(centre, float), int(seed)
        self.as_made = None
        if not setup.process.exact:
            from optipose.model.planes import face_planes, plane_numbers

            plane = plane_numbers(*face_planes(vertices, faces))
            self.as_made = AsMade(setup.process, vertices, faces, plane, derived_seed(seed, _CELL + _INSTANCE))
        self.edges = None
        if setup.effects.concave_fraction:
            from scipy.spatial import cKDTree

            samples = _concave_edge_samples(vertices, faces)
            self.edges = None if samples is None else cKDTree(samples)

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
    ) -> list[list]:
        """Each scan of ``levels`` (per noise level, per sensor) with the cell's displacements added along
        its rays. ``normals_P``: per sensor, its scanner's outward unit face normals in the part's frame;
        ``apex_z``: the sensor's laser apex on its z axis (m; inf: parallel rays); ``shifts``: the motion's
        offsets; ``T_O_P``: the part's pose as the robot set it."""
        from optipose.cell.kernels import along_rays

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
            if not len(scan.points):
                continue
            T = scan.T_O_S
            apex = (
                T[:3, :3] @ np.array([0.0, 0.0, apex_z[j]]) + T[:3, 3] if np.isfinite(apex_z[j]) else np.full(3, np.nan)
            )
            extra = self._material(effects, scan, R, t, np.random.default_rng([int(scan_seed), _CELL, _SCAN, 2, j]))
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
                moved,
            )
            out[0][j] = replace(scan, points=moved)
            if len(out) > 1:  # the other noise levels: the same rays, the same moves
                delta = moved - scan.points
                for level in out[1:]:
                    level[j] = replace(level[j], points=level[j].points + delta)
        return out

    def _material(self, e: MaterialEffects, scan, R: np.ndarray, t: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """The material's shift of each point of ``scan`` along its ray (m, positive: deeper)."""
        m = len(scan.points)
        s = np.full(m, e.subsurface_bias)
        sigma = np.hypot(e.speckle, e.subsurface_sigma)
        if sigma:
            s += rng.normal(size=m) * sigma
        if e.spurious_fraction:  # anywhere: in front of the surface or behind it
            spurious = rng.random(m) < e.spurious_fraction
            s[spurious] += rng.uniform(-1.0, 1.0, int(spurious.sum())) * e.spurious_range
        if self.edges is not None:  # multipath: the reflected light's path is longer, the ghost lies behind
            drawn = np.flatnonzero(rng.random(m) < e.concave_fraction)  # drawn first: only these are looked up
            x_P = (scan.points[drawn] - t) @ R
            ghost = drawn[self.edges.query(x_P, distance_upper_bound=e.concave_distance)[0] < e.concave_distance]
            s[ghost] += rng.uniform(0.0, 1.0, len(ghost)) * e.spurious_range
        return s


def _concave_edge_samples(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray | None:
    """Points every :data:`_EDGE_SAMPLE` along the mesh's concave edges (faces meeting at an inside angle
    under 180° − :data:`_CONCAVE_DEG`), (m, 3) m; ``None`` when it has none."""
    import trimesh

    mesh = trimesh.Trimesh(vertices, faces, process=False)
    concave = (~mesh.face_adjacency_convex) & (mesh.face_adjacency_angles > np.deg2rad(_CONCAVE_DEG))
    edges = vertices[mesh.face_adjacency_edges[concave]]
    if not len(edges):
        return None
    out = []
    for a, b in edges:
        k = max(2, int(np.ceil(np.linalg.norm(b - a) / _EDGE_SAMPLE)) + 1)
        out.append(a + np.linspace(0.0, 1.0, k)[:, None] * (b - a))
    return np.vstack(out)
