"""The cheap surrogate for the global search: predicted per-axis orientation error of a layout (docs/method.md, "The surrogate").

For one nominal scan per sensor, the point-to-plane information matrix

    H = Σ_i JᵢᵀJᵢ / σᵢ²,  Jᵢ = [(pᵢ − c) × nᵢ, nᵢ]   (rotation about the rotation centre c, translation)

tells how well a registration pins the six pose parameters down. Information adds over sensors, so one
6×6 matrix per sensor pose is all a layout needs: a subset's matrix is the sum of its sensors'. The
rotation block of (H + prior)⁻¹ gives per-axis standard deviations σ; for Gaussian errors the median
|e| is 0.674σ and the 75th percentile 1.150σ.

What the surrogate models, and why:

* the scan runs at reduced fidelity (a few hundred columns, coarser steps), then is thinned to one point
  per registration voxel, because ICP runs on voxel-down-sampled clouds: the number of *voxels* seen, not
  raw points, sets the information;
* each voxel point gets σᵢ² = σ_noise² / (intensity · mᵢ): the voxel's point is the mean of the mᵢ raw
  points a full-fidelity scan puts in it, so its noise along the normal averages down; moving along the
  surface does not change a point-to-surface residual. A sampled reference adds its own variance
  (``extra_variance``, spacing²/12);
* a weak prior (rotation 5°, translation 5 mm: what bin picking already knows) keeps H invertible when
  a layout leaves some direction unobservable; such an axis then gets a σ near the prior's, a poor score;
* **the voxel bias.** Noise is not what limits the evaluator: a voxel that holds points of two faces
  (an edge, a step, a hole's rim) has its centroid off the surface, by up to a quarter voxel, and these
  residuals pull the registration systematically. Along an edge parallel to the scan axis every voxel
  sits at the same offset from the edge, so the pulls add up instead of averaging out: with noise off,
  part B's hand S1 still ends off in roll by far more than with noise but no voxels
  (``tests/test_surrogate.py`` checks both). The surrogate therefore turns the noise-free nominal scan
  by ``turns`` of the objective's protocol orientations (each with a random shift of the voxel grid: a
  turn of the part about its centre moves every edge across the grid), voxelises it in the fixed grid,
  turns the centroids back, measures each one's signed distance rᵢ to the CAD surface and takes the
  first Gauss–Newton step of the unweighted point-to-plane ICP, δ = −(ΣJᵢᵀJᵢ)⁻¹ ΣJᵢᵀrᵢ, as the
  registration's error at that orientation. Sums over sensors give a subset's δ exactly (one grid for
  all sensors). The predicted errors are |δ + σ·z| over the turns and fixed standard-normal quantiles z.
  Turning a scan is not re-scanning the turned part (which points are seen and how densely change a
  little), but it moves the edges through the grid as the protocol does; how close it comes to ICP is
  measured by ``benchmarks/bench_surrogate_ranking.py`` (figures in docs/method.md, 'How well the surrogate ranks layouts').
* **the noise's own bias.** A voxel's point is the equal-weight centroid of the raw points that fall in it,
  and the noise along each ray decides which do: where a face cuts a voxel obliquely the points pushed in
  and out do not balance, a bias that grows as σ² and that the information matrix cannot see (a grazing
  view of few voxels suffers most; ``benchmarks/bench_noise_voxels.py``). At the preset's noise it is small
  beside the voxel bias, and the surrogate leaves it out.
* **the cell.** Under an objective's real cell (``Objective.cell``), its error sources (calibration, the
  robot's path, the part as made, the material) are propagated to the estimate the same way and added as a
  variance and a bias (:mod:`optipose.search.cell_terms`, which says what it leaves out); the ideal cell adds nothing.

It ranks layouts; the full ICP protocol (:mod:`optipose.evaluate.evaluator`) gives the numbers that are reported.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace

import numpy as np

from optipose.model.motion import ScanMotion
from optipose.scan.pose import PartPose
from optipose.scan.scanner import Scanner
from optipose.search.cell_terms import CellMaps, CellModel, sensor_maps, subset_terms
from optipose.search.prediction import (
    MEDIAN_PER_SIGMA,
    P75_PER_SIGMA,
    Prediction,
    across_instances,
    axis_stats,
    best_subsets,
    instance_stats,
)
from optipose.transforms import part_motion

__all__ = [
    "Surrogate",
    "SensorInfo",
    "Prediction",
    "protocol_turns",
    "bias_rotation",
    "MEDIAN_PER_SIGMA",
    "P75_PER_SIGMA",
    "predicted_stats",
]

# Rays of one reduced scan at most: a part longer than about 300 mm (at the default 400 columns and twice
# the part's step) is scanned in longer steps instead, so a pose costs what a 300 mm part's does; the
# shipped parts' reduced scans cast a fifth of it.
SURROGATE_RAYS = 1 << 17
_PRIOR_ROTATION = np.deg2rad(5.0)
_PRIOR_TRANSLATION = 5e-3
# ±2° about each axis, and the protocol's corners: the turns when no objective is given
DEFAULT_TURNS = np.deg2rad(
    [[2, 0, 0], [-2, 0, 0], [0, 2, 0], [0, -2, 0], [0, 0, 2], [0, 0, -2], [2, 2, 2], [-2, -2, -2]]
)


def protocol_turns(objective, n: int = 8) -> np.ndarray:
    """``n`` of the objective's protocol orientations (rad), a fixed draw without repeats (a regular
    stride would land on the same step of every sequence)."""
    from optipose.evaluate.protocol import perturbations

    rpy = perturbations(objective.protocol, 0).rpy
    return rpy[np.sort(np.random.default_rng(1536).choice(len(rpy), min(n, len(rpy)), replace=False))]


@dataclass(frozen=True)
class SensorInfo:
    """What one sensor pose contributes: its information matrix (6, 6) and how much it sees."""

    H: np.ndarray
    n_points: int  # points a full-fidelity scan would return (estimated from the reduced scan)
    n_voxels: int
    A: np.ndarray | None = None  # (6, 6) unweighted point-to-plane normal matrix ΣJᵀJ of the voxel centroids
    G: np.ndarray | None = None  # (turns, 6) ΣJᵀr of the voxel centroids' residuals, per turn
    cell: CellMaps | None = None  # the cell's error sources (:mod:`optipose.search.cell_terms`); None: the ideal cell


class Surrogate:
    """Per-sensor information matrices from reduced nominal scans of a part.

    part : a loaded :class:`optipose.model.part.Part`.
    voxel : m, the registration voxel size of the objective.
    turns : (m, 3) roll, pitch, yaw (rad) of the part at which the voxel bias is sampled, e.g.
        :func:`protocol_turns` of the objective; default: eight turns of ±2° (empty: no bias model).
    columns : laser columns per profile in the reduced scan; ``step_factor`` : profile step multiplier.
    threads : the scanner's threads for one scan (default one: a reduced scan is a few ten thousand rays, too
        few to share; the search scores several poses at once instead, :meth:`optipose.search.problem.SurrogateProblem.prefetch`).
    cell : a :class:`optipose.cell.scans.CellSetup` whose sources the layouts are scored under (the cell
        term, :mod:`optipose.search.cell_terms`); None or an ideal one: none, today's surrogate bit for bit.
    """

    def __init__(
        self,
        part,
        voxel: float = 0.5e-3,
        columns: int = 400,
        step_factor: float = 2.0,
        threads: int | None = 1,
        extra_variance: float = 0.0,
        turns: np.ndarray | None = None,
        cell=None,
    ):
        from optipose.model.sensor import load_sensor

        self.part = part
        self.full_sensor = load_sensor(part.sensor)
        sensor = replace(self.full_sensor, points_per_profile=min(columns, self.full_sensor.points_per_profile))
        self.scanner = Scanner(
            part.mesh, sensor, part.material, threads=threads, occluders=getattr(part, "occluders", None)
        )
        step = part.motion.step * step_factor
        profiles = max(1, SURROGATE_RAYS // sensor.points_per_profile)
        if ScanMotion(part.motion.length, step).n_profiles > profiles:  # a long part: as many rays as a 300 mm one
            step = part.motion.length / profiles
        self.motion = ScanMotion(part.motion.length, step)
        self.voxel = voxel
        self.extra_variance = extra_variance  # m², e.g. a sampled reference's spacing²/12
        # a reduced scan sees 1/scale of the points of a full-fidelity one
        self.scale = (self.full_sensor.points_per_profile / sensor.points_per_profile) * (
            part.motion.n_profiles / self.motion.n_profiles
        )
        self.centre = np.asarray(part.rotation_centre, dtype=float)
        # the turns' grid shifts are fixed (not the search's seed), so a pose always scores the same
        turns = DEFAULT_TURNS if turns is None else np.asarray(turns, dtype=float).reshape(-1, 3)
        shifts = np.random.default_rng(2022_1536).random((len(turns), 3)) * voxel
        self.turns = turns
        self.motions = [part_motion(rpy, self.centre, shift) for rpy, shift in zip(turns, shifts)]
        self.cell = None
        if cell is not None and not cell.ideal and len(self.motions):
            self.cell = CellModel(
                cell, part.mesh.vertices, part.mesh.faces, self.centre, self.motion.offsets(), self.full_sensor.apex_z
            )
        self._reference = None

    def ready(self) -> None:
        """Build what :meth:`info` builds on first use (the CAD reference), e.g. before calling it from threads."""
        if self._reference is None and len(self.motions):
            from optipose.parallel import shared

            self._reference = shared.surface(
                self.part.mesh.vertices, self.part.mesh.faces
            )  # a search's one, when it holds it

    def info(self, T_O_S: np.ndarray) -> SensorInfo:
        """Information matrix of one sensor pose from a noise-free nominal scan."""
        scan = self.scanner.scan(T_O_S, self.motion, PartPose(centre=self.centre), noise=False)
        if len(scan) == 0:
            return SensorInfo(np.zeros((6, 6)), 0, 0)
        normals = self.scanner.normals(scan)
        first, inverse, counts = _voxels(scan.points, self.voxel)
        p, n = scan.points[first] - self.centre, normals[first]
        inten = np.bincount(inverse, weights=scan.intensity.astype(float)) / counts
        inten = np.clip(inten, self.full_sensor.detection_threshold, 1.0)
        # a voxel's point is the mean of the raw points in it: its noise along the normal shrinks with
        # the number of points a full-fidelity scan puts there; its tangential spread does not matter
        var = self.full_sensor.noise_sigma**2 / inten / (counts * self.scale) + self.extra_variance
        J = np.hstack([np.cross(p, n), n]) / np.sqrt(var)[:, None]
        A, G, turned = self._bias(scan.points)
        cell = None if self.cell is None else sensor_maps(self.cell, turned, T_O_S, float(np.mean(counts)) * self.scale)
        return SensorInfo(J.T @ J, int(round(len(scan) * self.scale)), len(first), A, G, cell=cell)

    def _bias(self, points: np.ndarray) -> tuple:
        """ΣJᵀJ and, per turn, ΣJᵀr of the voxel centroids against the CAD surface (see module doc); and, for the
        cell term, the centroids, normals, faces and turn at the nominal orientation and each turn."""
        if not len(self.motions):
            return None, None, []
        self.ready()
        A, G, turned = np.zeros((6, 6)), np.zeros((len(self.motions), 6)), []
        for m, T in enumerate([np.eye(4), *self.motions]):  # the master scan's nominal orientation first
            if m == 0 and self.cell is None:
                continue
            v, n, r, J, face = self._turned(points, T)
            if self.cell is not None:
                turned.append((v, n, face, T[:3, :3]))
            if m > 0:
                G[m - 1] = J.T @ r
                A += J.T @ J / len(self.motions)
        return A, G, turned

    def _turned(self, points: np.ndarray, T: np.ndarray) -> tuple:
        """The points turned by ``T``, voxelised on the grid at O's origin and turned back: the voxel
        centroids v (in the part's frame), their surface normals n, signed distances r to the CAD surface,
        point-to-plane rows J = [(v − c) × n, n] about the rotation centre c, and their closest faces."""
        from optipose.registration.voxels import voxel_centroids

        turned = voxel_centroids(np.ascontiguousarray(points @ T[:3, :3].T + T[:3, 3]), self.voxel, np.zeros(3))
        v = (turned - T[:3, 3]) @ T[:3, :3]  # back in the part's frame
        # searched, not guessed from the faces the scan hit: a centroid on a crease's edge (part A's scans put some there)
        # lies at distance 0 from both faces; a kept guess is the other face than the search's (the lowest id), with
        # another normal, and the search moves
        q, n, face = self._reference.nearest(v)
        return v, n, np.einsum("ij,ij->i", v - q, n), np.hstack([np.cross(v - self.centre, n), n]), face


def _voxels(points: np.ndarray, voxel: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Occupied voxels: index of one point in each (v,), each point's voxel (n,), points per voxel (v,)."""
    ijk = np.floor((points - points.min(axis=0)) / voxel).astype(np.int64)
    dims = ijk.max(axis=0) + 1
    keys = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    _, first, inverse, counts = np.unique(keys, return_index=True, return_inverse=True, return_counts=True)
    return first, inverse, counts


def rotation_sigma(H: np.ndarray) -> np.ndarray:
    """Per-axis rotation standard deviation (3,) rad from an information matrix, with the weak prior."""
    prior = np.diag([1 / _PRIOR_ROTATION**2] * 3 + [1 / _PRIOR_TRANSLATION**2] * 3)
    cov = np.linalg.inv(H + prior)
    return np.sqrt(np.clip(np.diag(cov)[:3], 0.0, None))


def bias_rotation(A: np.ndarray, G: np.ndarray) -> np.ndarray:
    """Per turn, the rotation part (turns, 3) rad of the first Gauss–Newton step δ = −A⁻¹g; directions
    the points do not pin down (A singular there) get no step, as ICP leaves them where they start."""
    d = np.diag(A)
    scale = np.sqrt(np.clip(d, 1e-12 * max(d.max(), 1e-300), None))  # rotation rows are m², translation rows 1
    step = np.linalg.pinv(A / np.outer(scale, scale), rcond=1e-9) @ (G / scale).T
    # ICP starts within the protocol's few degrees; a step beyond the weak prior's 5° is not a small error
    return np.clip(-(step / scale[:, None])[:3].T, -_PRIOR_ROTATION, _PRIOR_ROTATION)


def predicted_stats(
    infos: list[SensorInfo],
    weights=(1.0, 1.0, 1.0),
    median_weight=1.0,
    p75_weight=1.0,
    memo: dict | None = None,
    keys: list | None = None,
) -> Prediction:
    """The surrogate's Table 1 for a layout (:class:`Prediction`): every non-empty subset's predicted
    per-axis median and 75th percentile (degrees), each axis's best subset, its per-axis score and the
    weighted score of the per-axis best.

    The cell's error sources (:mod:`optipose.search.cell_terms`), when the sensors carry them (``cell``), add
    their variance to the noise's at each turn and their bias to the voxel bias's.
    memo, keys : a dict kept between calls and one key per sensor (its pose's): a subset's statistics depend
    only on its sensors, in order, so a subset met before (a screen adds one new sensor to the same placed
    ones thousands of times) is looked up instead of computed again — the same numbers, bit for bit.
    """
    k = len(infos)
    subsets = [c for r in range(1, k + 1) for c in itertools.combinations(range(k), r)]
    cells = [i.cell for i in infos if i.cell is not None]
    instances = len(cells[0].magnitudes) if cells else 1  # a cell of ranges: its magnitude instances
    # each magnitude instance's own median and p75 (rad), at the preset's noise (one level)
    levels = np.zeros((1, instances, len(subsets), 2, 3))
    for s, c in enumerate(subsets):
        key = None if memo is None else tuple(keys[i] for i in c)
        if key is not None and key in memo:
            levels[:, :, s] = memo[key]
            continue
        H = sum(infos[i].H for i in c)
        have_bias = all(infos[i].G is not None for i in c)
        A = sum(infos[i].A for i in c) if have_bias else None
        delta = bias_rotation(A, sum(infos[i].G for i in c)) if have_bias else None
        mount, cell_bias = None, 0.0
        if delta is not None and all(infos[i].cell is not None for i in c):
            mount, cell_bias = subset_terms([infos[i].cell for i in c])
        sigma = rotation_sigma(H)
        dd = delta if delta is None else delta + cell_bias
        if mount is not None and np.ndim(mount) == 3:  # per magnitude instance, at once
            levels[0, :, s] = np.stack(instance_stats(np.sqrt(sigma**2 + mount), dd), axis=1)
        else:
            levels[0, :, s] = axis_stats(sigma if mount is None else np.sqrt(sigma**2 + mount), dd)
        if key is not None:
            memo[key] = levels[:, :, s].copy()
    if instances > 1:
        return across_instances(subsets, levels, weights, median_weight, p75_weight)
    levels = levels[:, 0]
    median, p75 = np.rad2deg(levels.max(axis=0)).transpose(1, 0, 2)  # the worst over the levels
    best = best_subsets(median, p75)
    axis = np.array([median_weight * median[s, a] + p75_weight * p75[s, a] for a, s in enumerate(best)])
    # each level alone, its axes on that level's own best subsets: what the comparison with the hand layout
    # level by level sees (one level: the same numbers as ``axis_score``)
    per_level = np.rad2deg(levels)
    level_stats = np.array([[lv[s, :, a] for a, s in enumerate(best_subsets(lv[:, 0], lv[:, 1]))] for lv in per_level])
    level_axis = median_weight * level_stats[:, :, 0] + p75_weight * level_stats[:, :, 1]
    return Prediction(
        subsets=tuple(subsets),
        median_deg=median,
        p75_deg=p75,
        best_subset=tuple(subsets[s] for s in best),
        axis_score=axis,
        level_axis_score=level_axis,
        level_axis_stats=level_stats,
        score=float(np.dot(weights, axis)),
    )
