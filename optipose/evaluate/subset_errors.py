"""One orientation's scans turned into rows of errors, as a worker does it (:mod:`optipose.evaluate.worker`):
each sensor's scan down-sampled (:func:`scan_clouds`), every sensor subset registered on its reference
(:func:`register_subset`; with ``subset_start = "combined"`` a subset of several sensors starts where its
sensors' own registrations put it together), and each registration's estimate, the cell's zero taken off,
compared with the set orientation: the set and estimated angles, the signed errors and the observability
flags of one row per subset (:func:`subset_rows`).
"""

from __future__ import annotations

import numpy as np

from optipose.evaluate.assignment import subset_name
from optipose.evaluate.objective import AXES, RegistrationConfig
from optipose.evaluate.statistics import unobservable_axes
from optipose.registration import Matches, backend_for, grid_origin, register, remove_outliers, voxel_down
from optipose.registration.backends import combined_start
from optipose.transforms import invert_T, matrix_to_rpy, part_motion

__all__ = ["scan_clouds", "register_subset", "subset_rows"]

_TRANSLATION = ("x", "y", "z")


def scan_clouds(cfg: RegistrationConfig, scans, seed: int) -> list[np.ndarray]:
    """Each sensor's scan down-sampled (and cleaned of outliers when the objective asks): (m, 3) m each.
    ``seed`` is the orientation's noise seed; under ``voxel_grid = "random"`` it places the grid, one
    grid for all the sensors of a scan (the cell merges their clouds in one frame)."""
    origin = grid_origin(seed, cfg.voxel_size) if cfg.voxel_grid == "random" else None
    clouds = []
    for scan in scans:
        cloud = voxel_down(scan.points, cfg.voxel_size, origin)
        if cfg.outlier_removal:
            cloud = remove_outliers(cloud, cfg.outlier_neighbors, cfg.outlier_std_ratio)
        clouds.append(cloud)
    return clouds


def register_subset(worker, clouds, subset, reference, initial=None, start=None):
    """One subset's floating cloud registered onto its reference (``initial``: each sensor's matches at
    identity; ``start``: a pose to start from and the matches there, see :func:`_start`)."""
    source = np.vstack([clouds[j] for j in subset])
    matches = Matches.concat([initial[j] for j in subset]) if initial and all(initial[j] for j in subset) else None
    return register(source, reference, worker.setup.registration, matches, start), source


def subset_rows(
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
    given=None,
    kept=None,
) -> list[dict]:
    """The rows of scan ``i`` (set at ``rpy`` rad, ``offset`` m; noise seed ``seed``), one per subset of
    ``subsets`` (numbered ``numbers`` among them all), each registered on its reference and its cell's
    ``zero`` taken off; each sensor's point counts are appended to ``point_rows``. ``given``: sensor index ->
    (down-sampled cloud, point count) of the sensors not scanned (``None`` in ``scans``); ``kept``: a dict that
    gets the scanned sensors' (i, j) -> (cloud, point count)."""
    cfg = setup.registration
    down = iter(scan_clouds(cfg, [s for s in scans if s is not None], seed))
    clouds = []
    for j, scan in enumerate(scans):
        cloud, count = given[j] if scan is None else (next(down), len(scan.points))
        if kept is not None and scan is not None:
            kept[(i, j)] = (cloud, count)
        clouds.append(cloud)
        point_rows.append(
            {
                "scan": i,
                "label": label,
                "sensor_index": j,
                "sensor": names[j],
                "n_points": count,
                "n_points_down": len(cloud),
            }
        )
    # every subset against the part's reference: each sensor's matches at identity are searched once
    shared = all(r is worker.reference for r in references) and backend_for(cfg).takes_initial
    initial = [worker.reference.matches(c) if len(c) else None for c in clouds] if shared else None
    own: dict = {}  # sensor -> its single registration and centroid, where several sensors start from
    moments = [_moments(c) for c in clouds]
    T_O_P = part_motion(rpy, setup.centre, offset)
    rows = []
    for s_index, subset, reference, zero in zip(numbers, subsets, references, zeros):
        start = _start(own, subset) if shared and len(subset) > 1 and cfg.subset_start == "combined" else None
        reg, source = register_subset(worker, clouds, subset, reference, initial, start)
        if shared and len(subset) == 1 and reg.ok and reg.matched is not None:
            own[subset[0]] = (
                reg,
                reg.T_target_source[:3, :3] @ clouds[subset[0]].mean(axis=0) + reg.T_target_source[:3, 3],
            )
        row = {
            "scan": i,
            "label": label,
            "subset_index": s_index,
            "subset": subset_name(subset, names),
            "n_points": len(source),
            "ok": reg.ok,
            "converged": reg.converged,
            "failure": reg.failure,
            "iterations": reg.iterations,
            "fitness": reg.fitness,
            "rmse": reg.rmse,
        }
        scale = _rms_radius([moments[j] for j in subset])
        rows.append(row | _errors(reg, scale, rpy, T_O_P, setup.observability_tolerance, zero))
    return rows


def _moments(cloud: np.ndarray) -> tuple[int, np.ndarray, float]:
    """A cloud's point count, centroid (3,) and sum of squared distances to it."""
    if not len(cloud):
        return 0, np.zeros(3), 0.0
    mean = cloud.mean(axis=0)
    return len(cloud), mean, float(((cloud - mean) ** 2).sum())


def _rms_radius(moments: list) -> float:
    """The RMS distance (m) of the union of clouds from its centroid, from each cloud's :func:`_moments`
    (the parallel-variance sum: each cloud's spread plus its centroid's offset); 1 for no points."""
    n = sum(m[0] for m in moments)
    if not n:
        return 1.0
    mean = sum(m[0] * m[1] for m in moments) / n
    return float(np.sqrt(sum(m[2] + m[0] * float(((m[1] - mean) ** 2).sum()) for m in moments) / n))


def _start(own: dict, subset) -> tuple[np.ndarray, np.ndarray] | None:
    """Where a subset of several sensors starts its ICP: its sensors' own registrations combined
    (:func:`optipose.registration.backends.combined_start`), with their last matches as hints; ``None``
    (identity) unless every sensor of the subset has registered on its own.

    From identity a subset takes ~5 steps (a 2° turn is solved to the tolerance's 10⁻⁷ rad in three
    Gauss-Newton steps and a fourth that confirms); from here one or two. Its ICP still runs to its own
    fixed point, so its estimate is its own to the tolerance: no sensor borrows another's information,
    and a direction none of its sensors sees stays at identity's."""
    if not all(j in own for j in subset):
        return None
    T = combined_start([(own[j][0].T_target_source, own[j][0].information, own[j][1]) for j in subset])
    return T, np.concatenate([own[j][0].matched for j in subset])


def _errors(reg, scale: float, rpy: np.ndarray, T_O_P: np.ndarray, tolerance: float, zero: np.ndarray) -> dict:
    """Set and estimated angles, signed errors (rad, m) and observability flags of one registration, the
    cell's ``zero`` (its estimate of the nominal pose, 4×4) taken off the estimate; ``scale`` (m): the
    floating cloud's RMS radius, which weighs rotation against translation in the observability test."""
    T_est = invert_T(reg.T_target_source)  # the part's estimated motion T_O_P
    if zero is not None and not np.array_equal(zero, np.eye(4)):
        T_est = invert_T(zero) @ T_est
    est = matrix_to_rpy(T_est[:3, :3])
    blind = unobservable_axes(reg.information, scale, tolerance)
    row = {}
    for a, axis in enumerate(AXES):
        row[f"{axis}_set"], row[f"{axis}_est"] = float(rpy[a]), float(est[a])
        row[f"err_{axis}"] = float(_wrap(est[a] - rpy[a]))
    for a, axis in enumerate(_TRANSLATION):
        row[f"err_{axis}"] = float(T_est[a, 3] - T_O_P[a, 3])
    for a, axis in enumerate(AXES + _TRANSLATION):
        row[f"unobservable_{axis}"] = bool(blind[a])
    return row


def _wrap(angle: float) -> float:
    return (angle + np.pi) % (2 * np.pi) - np.pi
