"""The evaluator: scan a layout at every orientation of a protocol, register every sensor subset, and
assign each axis its best subset (paper Algorithms 3–4, Table 1).

Per orientation the sensors are scanned once (one ``Scanner.scan_many`` call), each sensor's scan is
voxel-down-sampled once, and each subset's floating cloud is the union of its sensors' down-sampled
scans; the reference and its search structure are built once per part (per worker process), and the
first closest-point search at identity is done once per sensor and shared by every subset. Orientations
are spread over ``jobs`` processes; each scan's noise seed comes from the run's seed and its index, so the
result does not depend on ``jobs``.

For the search, :class:`Evaluator` keeps the part, objective and workers' state between calls:
``Evaluator(part, objective)(layout) -> EvaluationResult``.
"""

from __future__ import annotations

import logging
import time
import uuid
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from optipose.evaluate.assignment import Choice, all_subsets, best_choices, subset_name
from optipose.model.layout import Layout, SensorPose
from optipose.evaluate.objective import AXES, Objective, RegistrationConfig, load_objective
from optipose.seeds import nominal_reference_seed
from optipose.evaluate.protocol import Perturbations, perturbations
from optipose.registration.icp import Matches, register, remove_outliers, voxel_down
from optipose.evaluate.statistics import summarize, unobservable_axes
from optipose.transforms import invert_T, matrix_to_rpy, part_motion

__all__ = ["Evaluator", "EvaluationResult", "evaluate"]

log = logging.getLogger(__name__)
_TRANSLATION = ("x", "y", "z")


@dataclass
class EvaluationResult:
    """A layout evaluated under an objective. Angles in radians, lengths in metres.

    per_scan : one row per (scan, subset): set and estimated orientation, signed errors, registration
        outcome (ok, converged, failure, iterations, fitness, rmse), observability flags.
    points : one row per (scan, sensor): points returned and left after down-sampling (paper Fig. 9).
    stats : per (subset, axis): median, p75, mean, max of |error|, n_ok, n_failed, unobservable.
    table : the best choice for k = 1 … n sensors, each axis with its subset (paper Table 1).
    timings : seconds of CPU work summed over workers ("scan", "register") and the wall time ("wall").
    """

    part: str
    layout: Layout
    objective: Objective
    seed: int
    per_scan: pd.DataFrame = field(repr=False)
    points: pd.DataFrame = field(repr=False)
    stats: pd.DataFrame = field(repr=False)
    table: list[Choice] = field(repr=False)
    timings: dict = field(repr=False, default_factory=dict)

    @property
    def n_failed(self) -> int:
        return int((~self.per_scan["ok"]).sum())

    def score(self, k: int | None = None) -> float:
        """The objective's score (rad) of the best choice of k sensors (default: all of them)."""
        return self.table[(k or len(self.layout)) - 1].score

    def __repr__(self) -> str:
        n_scans = self.per_scan["scan"].nunique()
        lines = [
            f"EvaluationResult(part={self.part!r}, layout={self.layout.name!r} {self.layout.names}, "
            f"objective={self.objective.name!r}, seed={self.seed}, {n_scans} scans x {2 ** len(self.layout) - 1} subsets, "
            f"{self.n_failed} failed registrations, wall {self.timings.get('wall', float('nan')):.1f} s)"
        ]
        lines += [f"  {choice!r}" for choice in self.table]
        return "\n".join(lines)


def evaluate(part, layout: Layout | None = None, objective: Objective | str = "paper", seed: int = 0, jobs: int = 1) -> EvaluationResult:
    """Evaluate ``layout`` (default: the part's hand-placed one) on ``part`` (a :class:`optipose.model.part.Part`)."""
    if layout is None:
        if "hand" not in part.layouts:
            from optipose.errors import ConfigError

            raise ConfigError(f"part '{part.name}' has no hand-placed layout; give one with --layout")
        layout = part.layouts["hand"]
    with Evaluator(part, objective, seed=seed, jobs=jobs) as evaluator:
        return evaluator(layout)


class Evaluator:
    """A part and an objective, ready to evaluate layouts; the costly set-up is done once.

    part : :class:`optipose.model.part.Part`. objective : an :class:`Objective` or a name/path.
    jobs : worker processes over orientations (1 = in this process).
    quiet : report failed registrations at INFO instead of WARNING (a search's hundreds of internal
        evaluations; the counts stay in ``per_scan`` and ``stats``).
    """

    def __init__(self, part, objective: Objective | str = "paper", seed: int = 0, jobs: int = 1, quiet: bool = False):
        self.part = part
        self.objective = objective if isinstance(objective, Objective) else load_objective(objective)
        self.seed = int(seed)
        self.jobs = max(1, int(jobs))
        self._failure_level = logging.INFO if quiet else logging.WARNING
        self.perturbations: Perturbations = perturbations(self.objective.protocol, self.seed)
        self._setup = _Setup(
            token=uuid.uuid4().hex,
            vertices=np.asarray(part.mesh.vertices, dtype=np.float64),
            faces=np.asarray(part.mesh.faces, dtype=np.int64),
            sensor=part.sensor,
            material=part.material,
            motion=part.motion,
            centre=np.asarray(part.rotation_centre, dtype=float),
            registration=self.objective.registration,
            observability_tolerance=self.objective.statistic.observability_tolerance,
            seed=self.seed,
            threads=None if self.jobs == 1 else 1,
            occluders=tuple(getattr(part, "occluders", ())),
        )
        self._pool = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self) -> None:
        self._pool = None

    def __call__(self, layout: Layout | list[np.ndarray]) -> EvaluationResult:
        """Evaluate a layout (or a list of 4×4 ``T_O_S``, named S1, S2, …)."""
        if not isinstance(layout, Layout):
            layout = Layout(tuple(SensorPose(f"S{i + 1}", np.asarray(T, float)) for i, T in enumerate(layout)), name="poses")
        t0 = time.perf_counter()
        p = self.perturbations
        tasks = [(i, p.rpy[i], p.offset[i], int(p.seeds[i]), str(p.label[i])) for i in range(len(p))]
        poses, names = layout.poses, layout.names
        if self.jobs == 1:
            outputs = [_run_chunk(self._setup, poses, names, tasks)]
        else:
            from joblib import Parallel, delayed

            if self._pool is None:
                self._pool = Parallel(n_jobs=self.jobs, backend="loky")
            chunks = [tasks[j :: self.jobs * 2] for j in range(self.jobs * 2)]
            outputs = self._pool(delayed(_run_chunk)(self._setup, poses, names, c) for c in chunks if c)
        rows = [r for out in outputs for r in out[0]]
        point_rows = [r for out in outputs for r in out[1]]
        per_scan = pd.DataFrame(rows).sort_values(["scan", "subset_index"], kind="stable").reset_index(drop=True)
        points = pd.DataFrame(point_rows).sort_values(["scan", "sensor_index"], kind="stable").reset_index(drop=True)
        stats = summarize(per_scan, self.objective.statistic)
        table = best_choices(stats, names, self.objective.statistic, len(p))
        timings = {k: float(sum(out[2][k] for out in outputs)) for k in ("scan", "register")}
        timings["wall"] = time.perf_counter() - t0
        failed = int((~per_scan["ok"]).sum())
        if failed:
            reasons = per_scan.loc[~per_scan["ok"], "failure"].value_counts().to_dict()
            log.log(self._failure_level, "%d of %d registrations failed or did not converge: %s", failed, len(per_scan), reasons)
        return EvaluationResult(self.part.name, layout, self.objective, self.seed, per_scan, points, stats, table, timings)


# --------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Setup:
    """Everything a worker process needs to rebuild the scanner and reference (picklable)."""

    token: str
    vertices: np.ndarray
    faces: np.ndarray
    sensor: object
    material: object
    motion: object
    centre: np.ndarray
    registration: RegistrationConfig
    observability_tolerance: float
    seed: int
    threads: int | None
    occluders: tuple = ()  # the part's keep-outs, (lo, hi) boxes that hide what they cover


_STATE: dict[str, "_Worker"] = {}  # per process: the live scanner and reference of each evaluator


class _Worker:
    def __init__(self, setup: _Setup):
        import trimesh

        from optipose.registration.reference import SampledReference, SurfaceReference, sample_surface
        from optipose.scan.scanner import Scanner

        self.setup = setup
        mesh = trimesh.Trimesh(setup.vertices, setup.faces, process=False)
        self.scanner = Scanner(mesh, setup.sensor, setup.material, threads=setup.threads, occluders=list(setup.occluders))
        cfg = setup.registration
        if cfg.reference == "cad-sample":
            self.reference = SampledReference(*sample_surface(setup.vertices, setup.faces, cfg.reference_spacing), kind="cad-sample")
        else:  # the CAD surface; also answers the observability normals for nominal-scan references
            self.reference = SurfaceReference(setup.vertices, setup.faces)
        self._nominal: dict[bytes, list] = {}

    def references(self, poses: list[np.ndarray], subsets) -> list:
        """The reference of each subset: the part's, or the nominal scan of the subset's sensors."""
        if self.setup.registration.reference != "nominal-scan":
            return [self.reference] * len(subsets)
        key = np.asarray(poses).tobytes()
        if key not in self._nominal:
            self._nominal[key] = self._nominal_references(poses, subsets)
        return self._nominal[key]

    def _nominal_references(self, poses, subsets) -> list:
        from optipose.registration.reference import SampledReference

        cfg = self.setup.registration
        seed = nominal_reference_seed(self.setup.seed)
        scans = self.scanner.scan_many(poses, self.setup.motion, centre=self.setup.centre, rng=seed)
        clouds = [_with_normals(voxel_down(s.points, cfg.reference_spacing), T[:3, 2]) for s, T in zip(scans, poses)]
        return [
            SampledReference(np.vstack([clouds[i][0] for i in s]), np.vstack([clouds[i][1] for i in s]), kind="nominal-scan")
            for s in subsets
        ]


def _with_normals(points: np.ndarray, view: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Normals of a scanned cloud (Open3D, 20 neighbours), turned back toward the sensor (against ``view``)."""
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    pcd.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(20))
    normals = np.asarray(pcd.normals)
    normals[normals @ view > 0] *= -1
    return points, normals


def _run_chunk(setup: _Setup, poses, names, tasks):
    """Scan and register a list of orientations; rows per (scan, subset), rows per (scan, sensor), timings."""
    worker = _STATE.get(setup.token)
    if worker is None:
        _STATE.clear()  # one evaluator's state per process at a time
        worker = _STATE[setup.token] = _Worker(setup)
    subsets = all_subsets(len(poses))
    references = worker.references(poses, subsets)
    rows, point_rows, timing = [], [], {"scan": 0.0, "register": 0.0}
    for i, rpy, offset, seed, label in tasks:
        t0 = time.perf_counter()
        scans = worker.scanner.scan_many(poses, setup.motion, rpy=rpy, centre=setup.centre, offset=offset, rng=seed)
        t1 = time.perf_counter()
        rows += _register_subsets(worker, setup, scans, subsets, references, names, i, rpy, offset, label, point_rows)
        timing["scan"] += t1 - t0
        timing["register"] += time.perf_counter() - t1
    return rows, point_rows, timing


def _register_subsets(worker, setup, scans, subsets, references, names, i, rpy, offset, label, point_rows) -> list[dict]:
    cfg = setup.registration
    clouds = []
    for j, scan in enumerate(scans):
        cloud = voxel_down(scan.points, cfg.voxel_size)
        if cfg.outlier_removal:
            cloud = remove_outliers(cloud, cfg.outlier_neighbors, cfg.outlier_std_ratio)
        clouds.append(cloud)
        point_rows.append({"scan": i, "label": label, "sensor_index": j, "sensor": names[j],
                           "n_points": len(scan.points), "n_points_down": len(cloud)})  # fmt: skip
    shared = references[0] is references[-1] and cfg.backend == "fast"
    initial = [Matches(*worker.reference.nearest(c)) if shared and len(c) else None for c in clouds]
    T_O_P = part_motion(rpy, setup.centre, offset)
    rows = []
    for s_index, (subset, reference) in enumerate(zip(subsets, references)):
        source = np.vstack([clouds[j] for j in subset])
        start = Matches.concat([initial[j] for j in subset]) if shared and all(initial[j] for j in subset) else None
        reg = register(source, reference, cfg, start)
        T_est = invert_T(reg.T_target_source)  # the part's estimated motion T_O_P
        est = matrix_to_rpy(T_est[:3, :3])
        scale = float(np.sqrt(((source - source.mean(axis=0)) ** 2).sum(axis=1).mean())) if len(source) else 1.0
        blind = unobservable_axes(reg.information, scale, setup.observability_tolerance)
        row = {"scan": i, "label": label, "subset_index": s_index, "subset": subset_name(subset, names),
               "n_points": len(source), "ok": reg.ok, "converged": reg.converged, "failure": reg.failure,
               "iterations": reg.iterations, "fitness": reg.fitness, "rmse": reg.rmse}  # fmt: skip
        for a, axis in enumerate(AXES):
            row[f"{axis}_set"], row[f"{axis}_est"] = float(rpy[a]), float(est[a])
            row[f"err_{axis}"] = float(_wrap(est[a] - rpy[a]))
        for a, axis in enumerate(_TRANSLATION):
            row[f"err_{axis}"] = float(T_est[a, 3] - T_O_P[a, 3])
        for a, axis in enumerate(AXES + _TRANSLATION):
            row[f"unobservable_{axis}"] = bool(blind[a])
        rows.append(row)
    return rows


def _wrap(angle: float) -> float:
    return (angle + np.pi) % (2 * np.pi) - np.pi
