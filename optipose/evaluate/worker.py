"""The evaluator's work on a chunk of orientations, as it runs in a worker process: scan, down-sample,
register every sensor subset, and turn each registration into a row of errors (the last three in
:mod:`optipose.evaluate.subset_errors`).

A worker rebuilds the scanner(s) and the reference from a picklable :class:`WorkerSetup` once per process
and keeps them between chunks (one evaluator's state per process at a time). Each sensor is scanned with
its own model when the layout names one (``SensorPose.sensor``), else with the part's: one
``Scanner.scan_many`` call per model. The part's model keeps the orientation's noise seed, so a layout
of the part's model alone is scanned exactly as in one call; every other model's sensors are scanned with
a seed of their own (:func:`optipose.seeds.group_seed`), so no two models share noise draws.

In a real cell (:mod:`optipose.cell`) each sensor scans from where the calibration really left it while its cloud
is built with the pose the cell believes (straight from the sensor-frame measurements: ``Scanner.scan_levels(built=...)``,
what :func:`optipose.scan.cloud.rebuilt_with` gives without the round trip through the true pose); a cell zeroed on a
master part at the nominal orientation takes what it adds to each subset's estimate there off every estimate
(:meth:`_Worker.zero`).
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass

import numpy as np

from optipose.cell.scans import CellSetup, LiveCell
from optipose.evaluate.assignment import all_subsets
from optipose.evaluate.objective import RegistrationConfig, ScanConfig
from optipose.evaluate.subset_errors import register_subset, scan_clouds, subset_rows
from optipose.model.layout import Layout
from optipose.registration import voxel_down
from optipose.scan.pose import PartPose
from optipose.seeds import group_seed, nominal_reference_seed, zeroing_seed
from optipose.transforms import invert_T

__all__ = ["WorkerSetup", "run_chunk", "run_item", "record_chunk", "sensor_groups", "worker_for"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class WorkerSetup:
    """Everything a worker process needs to rebuild the scanners and reference (picklable).

    token : identifies the evaluator (a worker keeps one evaluator's state at a time).
    vertices (v, 3) m, faces (f, 3) : the part's mesh. sensor, material : the part's models or names.
    centre : (3,) m, the rotation centre. threads : ray-casting threads per scan (None: all cores).
    occluders : the part's keep-outs, (lo, hi) boxes in m that hide what they cover.
    column_stride : the scanners' anchor columns (:class:`optipose.scan.scanner.Scanner`).
    reference_dir : where the evaluator wrote the CAD-surface reference for its workers to map
        (:mod:`optipose.parallel.shared`); ``None`` or absent on this machine: each worker builds its own.
    """

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
    occluders: tuple = ()
    column_stride: int = ScanConfig.column_stride
    reference_dir: str | None = (
        None  # the CAD-surface reference's arrays, shared by this machine's workers (parallel.shared)
    )
    cell: CellSetup | None = None  # a real cell's error sources (optipose.cell); None or an ideal one: none


def sensor_groups(models: list, default) -> list[tuple[object, list[int]]]:
    """The layout's sensors grouped by model: [(model, sensor indices)].

    models : each sensor's preset name, ``None`` (or ``default``, the part's) for the part's model.
    Group 0 is always the part's model (``None``, its list possibly empty); the other models follow in
    the order they first appear.
    """
    groups: dict = {None: []}
    for j, model in enumerate(models):
        groups.setdefault(None if model is None or model == default else model, []).append(j)
    return list(groups.items())


_STATE: dict[str, "_Worker"] = {}  # per process: the live scanners and reference of one evaluator


class _Worker:
    """One evaluator's live scanners (one per sensor model, built on first use) and reference in this process."""

    def __init__(self, setup: WorkerSetup):
        import trimesh

        from optipose.registration.reference import SurfaceReference, load_reference
        from optipose.registration.sampled import SampledReference, sample_surface

        self.setup = setup
        self.mesh = trimesh.Trimesh(setup.vertices, setup.faces, process=False)
        self.scanners: dict = {}  # model -> Scanner
        cfg = setup.registration
        if cfg.reference == "cad-sample":
            self.reference = SampledReference(
                *sample_surface(setup.vertices, setup.faces, cfg.reference_spacing), kind="cad-sample"
            )
        elif setup.reference_dir and os.path.isdir(setup.reference_dir):  # built once on this machine, mapped
            self.reference = load_reference(setup.reference_dir)
        else:  # the CAD surface; also answers the observability normals for nominal-scan references
            self.reference = SurfaceReference(setup.vertices, setup.faces)
        self.cell = (
            None
            if setup.cell is None or setup.cell.ideal
            else LiveCell(setup.cell, setup.vertices, setup.faces, setup.centre, setup.seed)
        )
        self._nominal: dict = {}
        self._zero: dict = {}

    def _scanner(self, model):
        """The scanner of a sensor model (``None``: the part's), built once."""
        from optipose.scan.scanner import Scanner

        s = self.setup
        if model not in self.scanners:
            sensor = s.sensor if model is None else model
            self.scanners[model] = Scanner(
                self.mesh,
                sensor,
                s.material,
                threads=s.threads,
                occluders=list(s.occluders),
                column_stride=s.column_stride,
            )
        return self.scanners[model]

    def scan(
        self,
        models: list,
        poses: list[np.ndarray],
        seed: int,
        rpy=(0.0, 0.0, 0.0),
        offset=None,
        exact=False,
        noise=True,
        raw=False,
        skip=(),
    ) -> list:
        """One scan per sensor (in the layout's order), each with its model (``None``: the part's), at
        orientation ``rpy`` (rad) and ``offset`` (m), in the cell; ``seed`` is the orientation's noise seed;
        ``exact``: as if the cell were ideal; ``noise=False``: exact surface points; ``raw``: keep each scan's raw
        profiles, the heights the device reports; ``skip``: the indices of sensors not scanned (``None`` in their
        place; the others' scans are those of the whole layout)."""
        groups = sensor_groups(models, self.setup.sensor)
        nominal, cell, mounted = poses, self.cell, False
        if (
            cell is not None and not exact
        ):  # each sensor where the calibration left it, the part where the robot turned it
            poses, mounted, rpy = cell.poses(poses), True, cell.rpy(rpy, seed)
        scans = [None] * len(poses)
        for g, (model, idx) in enumerate(groups):
            only = [place for place, j in enumerate(idx) if j not in skip]
            if not only:
                continue
            scanner = self._scanner(model)
            (out,) = scanner.scan_levels(
                [poses[j] for j in idx],
                self.setup.motion,
                (1.0,),
                PartPose(rpy, self.setup.centre, offset),
                rng=group_seed(seed, g),
                noise=noise,
                raw=raw,
                built=[nominal[j] for j in idx] if mounted else None,
                only=only if len(only) < len(idx) else None,
            )  # ... and the cell builds its cloud with the drawn pose
            for place, scan in zip(only, out):
                scans[idx[place]] = scan
        if cell is not None and not exact and any(scan is not None for scan in scans):
            scans = self._in_cell(models, [scans], seed)[0]
        return scans

    def _in_cell(self, models: list, scans: list[list], seed: int) -> list[list]:
        """The scans with what the cell adds along each ray (:meth:`optipose.cell.scans.LiveCell.perturb`)."""
        scanners = [self._scanner(None if m is None or m == self.setup.sensor else m) for m in models]
        normals = [sc.face_normals for sc in scanners]
        apex = [sc.sensor.apex_z for sc in scanners]
        motion = self.setup.motion
        lines = [sc.lines for sc in scanners]
        T_O_P = next(scan.T_O_P for scan in scans[0] if scan is not None)
        return self.cell.perturb(scans, normals, apex, motion.offsets(), T_O_P, motion.step, seed, lines)

    def zero(self, models: list, poses: list[np.ndarray], subsets, references) -> list[np.ndarray]:
        """Per subset, the constant bias Z (4, 4) a cell zeroed on a master part takes off, so that a later
        estimate T is reported as Z⁻¹ T: identity when the cell is not zeroed.

        Z is the estimate of the cell at the nominal orientation relative to that of the ideal cell, both from
        noise-free scans (a cell averages enough master scans that the zero's noise is negligible). The comparison
        takes off only what the cell adds; a master registration's own error (one scan's noise, and at exactly the
        nominal orientation the down-sampling grid lying along the part's edges, a bias of several millidegrees on
        part B that no other orientation shares) is not the cell's, and would shift every later measurement by one
        draw of it."""
        if self.cell is None or not self.setup.cell.cell.calibration.zeroed:
            return [np.eye(4)] * len(subsets)
        key = (np.asarray(poses).tobytes(), tuple(map(str, models)), tuple(subsets))
        if key not in self._zero:
            exact = self._master(models, poses, subsets, references, exact=True)
            mounted = self._master(models, poses, subsets, references, exact=False)
            self._zero[key] = [invert_T(off) @ on for off, on in zip(mounted, exact)]
        return self._zero[key]

    def _master(self, models, poses, subsets, references, exact: bool) -> list[np.ndarray]:
        """Per subset, ``T_target_source`` of a noise-free master scan at the nominal orientation, in the cell (one
        master scan's draw of its sources) or (``exact``) in the ideal cell."""
        seed = zeroing_seed(self.setup.seed)
        scans = self.scan(models, poses, seed, exact=exact, noise=False)
        clouds, out = scan_clouds(self.setup.registration, scans, seed), []
        for subset, reference in zip(subsets, references):
            reg, _ = register_subset(self, clouds, subset, reference)
            if not reg.ok:  # its estimate still stands in for the bias; say so
                log.warning("zeroing subset %s on the master scan: %s", subset, reg.failure or "did not converge")
            out.append(reg.T_target_source)
        return out

    def references(self, models: list, poses: list[np.ndarray], subsets) -> list:
        """The reference of each subset: the part's, or the nominal scan of the subset's sensors."""
        if self.setup.registration.reference != "nominal-scan":
            return [self.reference] * len(subsets)
        key = (np.asarray(poses).tobytes(), tuple(map(str, models)), tuple(subsets))  # taught in the cell
        if key not in self._nominal:
            self._nominal[key] = self._nominal_references(models, poses, subsets)
        return self._nominal[key]

    def _nominal_references(self, models, poses, subsets) -> list:
        from optipose.registration.sampled import SampledReference

        cfg = self.setup.registration
        scans = self.scan(models, poses, nominal_reference_seed(self.setup.seed))
        clouds = [_with_normals(voxel_down(s.points, cfg.reference_spacing), T[:3, 2]) for s, T in zip(scans, poses)]
        return [
            SampledReference(
                np.vstack([clouds[i][0] for i in s]), np.vstack([clouds[i][1] for i in s]), kind="nominal-scan"
            )
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


def worker_for(setup: WorkerSetup) -> "_Worker":
    """This process's live state of the evaluator ``setup`` belongs to (built on first use; one evaluator's
    state per process at a time)."""
    worker = _STATE.get(setup.token)
    if worker is None:
        _STATE.clear()
        worker = _STATE[setup.token] = _Worker(setup)
    return worker


def run_chunk(
    setup: WorkerSetup, layout: Layout, tasks: list[tuple], subsets=None, read=None, given=None, keep=False
) -> tuple[list[dict], list[dict], dict, dict]:
    """Scan and register a list of orientations of ``layout``.

    tasks : (scan index, rpy (3,) rad, offset (3,) m, noise seed, label) per orientation. subsets : the sensor
    subsets to register (index tuples; default every one), each row keeping its index among them all. read :
    instead of scanning, ``read(i)`` gives scan ``i``'s scans, one per sensor (recorded ones). given : scan index ->
    {sensor index: (its down-sampled cloud, its point count)} known already (not scanned again); keep : return the
    clouds of the sensors scanned here.
    Returns rows per (scan, subset), rows per (scan, sensor), the seconds spent ("scan", "register") and the kept
    clouds, (scan index, sensor index) -> (cloud, point count).
    """
    worker = worker_for(setup)
    poses, names, models = layout.poses, layout.names, [s.sensor for s in layout.sensors]
    every = all_subsets(len(poses))
    if subsets is not None and setup.registration.subset_start == "combined":  # a subset starts from its sensors' own
        subsets = [*subsets, *((j,) for s in subsets for j in s)]
    subsets = every if subsets is None else sorted(set(subsets), key=every.index)  # sorted index tuples (Evaluator.raw)
    numbers = [every.index(s) for s in subsets]
    references = worker.references(models, poses, subsets)
    zeros = worker.zero(models, poses, subsets, references)
    rows, point_rows, timing, kept = [], [], {"scan": 0.0, "register": 0.0}, {}
    for i, rpy, offset, seed, label in tasks:
        t0 = time.perf_counter()
        known = (given or {}).get(i, {})
        scans = read(i) if read else worker.scan(models, poses, seed, rpy=rpy, offset=offset, skip=known)
        t1 = time.perf_counter()
        rows += subset_rows(
            worker,
            setup,
            scans,
            seed,
            subsets,
            numbers,
            references,
            zeros,
            names,
            i,
            rpy,
            offset,
            label,
            point_rows,
            known,
            kept if keep else None,
        )
        timing["scan"] += t1 - t0
        timing["register"] += time.perf_counter() - t1
    return rows, point_rows, timing, kept


def run_item(item: tuple) -> tuple[list[dict], list[dict], dict]:
    """:func:`run_chunk` of ``item``: (setup, layout, subsets, tasks[, given, keep]), one of several layouts' or evaluators'
    chunks in one map (:func:`optipose.evaluate.evaluator.evaluate_many`)."""
    setup, layout, subsets, tasks, *given_keep = item
    return run_chunk(setup, layout, tasks, subsets, None, *given_keep)


def record_chunk(setup: WorkerSetup, layout: Layout, tasks: list[tuple], write) -> list:
    """Scan ``layout`` at the orientations ``tasks`` (as :func:`run_chunk`'s) as an evaluation does, and hand
    each scan's raw profiles, the heights its sensors report, to ``write(i, j, raw)`` (scan ``i``, sensor
    ``j``; raw (n_profiles, points_per_profile) mm); returns what ``write`` returned, per task and sensor."""
    worker = worker_for(setup)
    poses, models = layout.poses, [s.sensor for s in layout.sensors]
    out = []
    for i, rpy, offset, seed, _ in tasks:
        scans = worker.scan(models, poses, seed, rpy=rpy, offset=offset, raw=True)
        out.append([write(i, j, scan.raw) for j, scan in enumerate(scans)])
    return out
