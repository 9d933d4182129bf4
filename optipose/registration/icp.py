"""Registration of a scan (source, floating) onto a reference (target, fixed): ICP from identity.

One API, two back-ends (chosen by ``RegistrationConfig.backend``):

- ``fast`` — ICP written here on top of a :mod:`optipose.registration.reference` built once per part: point-to-point
  (Kabsch on closest points, the paper's method) or point-to-plane (a linearised 6×6 solve per step).
  Each step is three compiled passes (:mod:`optipose.registration.kernels`): move the cloud, find closest points
  from the faces of the previous step (``reference.nearest``), sum the normal equations.
  :func:`_register_plain` is the same loop in numpy, kept as the reference the tests compare with.
  Generalized ICP has no fast path and goes to Open3D.
- ``open3d`` — ``o3d.pipelines.registration.registration_icp`` / ``registration_generalized_icp`` against
  a dense sample of the reference, as the paper ran it. Open3D rebuilds its KD-tree on every call, which
  is why it is not the default; the contract tests check both back-ends agree.

The result is ``T_target_source`` (the reference frame O from the scan's frame O', i.e. the inverse of
the part's applied motion), whether the step fell below the tolerances before ``max_iterations``
(``converged``), the inlier fraction and RMS distance, and the point-to-plane information matrix
``H = Σ Jᵢᵀ Jᵢ``, ``Jᵢ = [((pᵢ − c) × nᵢ)ᵀ, nᵢᵀ]`` about the cloud's centroid c, for observability.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from optipose.evaluate.objective import RegistrationConfig

__all__ = ["Registration", "Matches", "register", "voxel_down", "remove_outliers", "information_matrix"]

log = logging.getLogger(__name__)
_MIN_POINTS = 6
_TWIST_LENGTH = 0.03  # m: weighs rotation against translation when comparing ICP steps


@dataclass
class Matches:
    """Closest reference points (n, 3), normals (n, 3) and ids (n,) for a cloud: reused across subsets."""

    q: np.ndarray
    n: np.ndarray
    ids: np.ndarray

    @staticmethod
    def concat(parts: list["Matches"]) -> "Matches":
        return Matches(*(np.concatenate([getattr(m, k) for m in parts]) for k in ("q", "n", "ids")))


@dataclass
class Registration:
    """Result of one registration; ``T_target_source`` (4, 4) maps scan points onto the reference."""

    T_target_source: np.ndarray = field(repr=False)
    converged: bool
    iterations: int
    fitness: float  # inlier fraction within the max correspondence distance
    rmse: float  # m, over inliers
    n_points: int
    information: np.ndarray = field(repr=False)  # (6, 6), see the module doc
    failure: str = ""

    @property
    def ok(self) -> bool:
        return self.converged and not self.failure


def register(source: np.ndarray, reference, cfg: RegistrationConfig, initial: Matches | None = None) -> Registration:
    """Register ``source`` (n, 3) m onto ``reference`` from identity.

    initial : the reference matches of ``source`` at identity, if already known (they are the same for
        every subset that contains a sensor, so the evaluator searches them once per sensor).
    """
    if len(source) < _MIN_POINTS:
        return _failed(len(source), f"only {len(source)} points")
    if cfg.backend == "open3d" or cfg.method == "generalized":
        return _register_open3d(source, reference, cfg)
    return _register_fast(source, reference, cfg, initial)


def voxel_down(points: np.ndarray, size: float) -> np.ndarray:
    """Centroid of the points in each cube of side ``size`` (m) of a grid anchored at O's origin.

    The grid is fixed in O (Open3D's moves with the cloud's bounding box), so a voxel's content does not
    depend on what else was scanned. Output order is the voxels' sorted keys: deterministic.
    """
    from optipose.registration.kernels import voxel_centroids

    points = np.asarray(points, dtype=np.float64)
    if size <= 0 or len(points) == 0:
        return points
    return voxel_centroids(np.ascontiguousarray(points), float(size))


def remove_outliers(points: np.ndarray, neighbors: int = 20, std_ratio: float = 2.0) -> np.ndarray:
    """Open3D's statistical outlier removal: drop points whose mean neighbour distance is unusually large."""
    import open3d as o3d

    if len(points) <= neighbors:
        return points
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    _, keep = pcd.remove_statistical_outlier(nb_neighbors=neighbors, std_ratio=std_ratio)
    return points[np.sort(np.asarray(keep, dtype=np.int64))]


def information_matrix(points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Point-to-plane information ``H = Σ JᵢᵀJᵢ`` (6, 6), ``Jᵢ = [((pᵢ − c) × nᵢ)ᵀ, nᵢᵀ]``, c = centroid.

    Rotation first (rad), then translation (m); taken about the centroid so a rotation the cloud cannot
    see is not mixed with a translation by the choice of origin.
    """
    if len(points) == 0:
        return np.zeros((6, 6))
    J = np.hstack([np.cross(points - points.mean(axis=0), normals), normals])
    return J.T @ J


# ---------------------------------------------------------------------------------------------------------
def _register_fast(source, reference, cfg: RegistrationConfig, initial: Matches | None) -> Registration:
    """ICP with compiled passes: transform, closest points (:meth:`nearest` from the previous step's faces),
    and the normal equations, whose ``AᵀA`` at the last step is also the information matrix."""
    from optipose.registration import kernels

    source = np.ascontiguousarray(source, dtype=np.float64)
    T = np.eye(4)
    ids = None
    max_d2 = cfg.max_correspondence_distance**2
    converged, it, history = False, 0, None
    for it in range(1, cfg.max_iterations + 1):
        p = kernels.transform(source, T)
        if it == 1 and initial is not None:
            q, n, ids = initial.q, initial.n, initial.ids.copy()
        else:
            q, n, ids = reference.nearest(p, ids)
        inlier, c, AtA, Atb, sum_d2 = kernels.normal_equations(p, q, n, max_d2)
        n_in = int(inlier.sum())
        if n_in < _MIN_POINTS:
            return _failed(len(source), f"{n_in} points within the correspondence distance", T, it)
        if cfg.method == "point_to_point":
            delta = _kabsch(p[inlier], q[inlier])
        else:
            delta = _solve_point_to_plane(AtA, Atb, c)
        if delta is None:
            return _failed(len(source), "degenerate step", T, it)
        T = delta @ T
        if _small_step(delta, cfg):
            converged = True
            break
        if cfg.method == "point_to_point":
            T, history = _accelerate(T, delta, c, history)
    return Registration(
        T_target_source=T,
        converged=converged,
        iterations=it,
        fitness=n_in / len(source),
        rmse=float(np.sqrt(sum_d2 / n_in)),
        n_points=len(source),
        information=AtA,
        failure="" if converged else f"no convergence in {cfg.max_iterations} iterations",
    )


def _register_plain(source, reference, cfg: RegistrationConfig, initial: Matches | None = None) -> Registration:
    """The same ICP in plain numpy on ``closest``/``follow`` (Open3D answers near edges): the readable
    reference the compiled :func:`_register_fast` is tested against."""
    T = np.eye(4)
    ids = None
    max_d2 = cfg.max_correspondence_distance**2
    step = _kabsch if cfg.method == "point_to_point" else _point_to_plane
    converged, it, history = False, 0, None
    for it in range(1, cfg.max_iterations + 1):
        p = source @ T[:3, :3].T + T[:3, 3]
        if it == 1 and initial is not None:
            q, n, ids = initial.q, initial.n, initial.ids.copy()
        elif ids is None:
            q, n, ids = reference.closest(p)
        else:
            q, n, ok = reference.follow(p, ids)
            stale = np.flatnonzero(~ok)
            if len(stale):
                q[stale], n[stale], ids[stale] = reference.closest(p[stale])
        inlier = np.einsum("ij,ij->i", p - q, p - q) <= max_d2
        if inlier.sum() < _MIN_POINTS:
            return _failed(len(source), f"{int(inlier.sum())} points within the correspondence distance", T, it)
        delta = step(p[inlier], q[inlier], n[inlier])
        if delta is None:
            return _failed(len(source), "degenerate step", T, it)
        T = delta @ T
        if _small_step(delta, cfg):
            converged = True
            break
        if cfg.method == "point_to_point":
            T, history = _accelerate(T, delta, p[inlier].mean(axis=0), history)
    d2 = np.einsum("ij,ij->i", p - q, p - q)
    inlier = d2 <= max_d2
    return Registration(
        T_target_source=T,
        converged=converged,
        iterations=it,
        fitness=float(inlier.mean()),
        rmse=float(np.sqrt(d2[inlier].mean())),
        n_points=len(source),
        information=information_matrix(p[inlier], n[inlier]),
        failure="" if converged else f"no convergence in {cfg.max_iterations} iterations",
    )


def _small_step(delta: np.ndarray, cfg: RegistrationConfig) -> bool:
    """The ICP step turned less than the rotation tolerance and moved less than the translation one."""
    angle = np.arccos(np.clip(0.5 * (np.trace(delta[:3, :3]) - 1.0), -1.0, 1.0))
    return bool(angle < cfg.tolerance_rotation and np.linalg.norm(delta[:3, 3]) < cfg.tolerance_translation)


def _accelerate(T: np.ndarray, delta: np.ndarray, c: np.ndarray, previous: np.ndarray | None):
    """Besl & McKay's accelerated ICP: when two successive steps point the same way and shrink by a
    steady ratio ρ, jump ahead by the rest of the geometric series, ρ/(1−ρ) steps (at most 20).

    Point-to-point ICP crawls toward its fixed point (ρ ≈ 0.8 here); the jump lands near the same fixed
    point and plain iterations take over again, so convergence is still judged on unextrapolated steps.
    A step is the twist (rotation vector, motion of the centroid ``c`` of the matched points).
    Returns the new ``T`` and the step to compare the next one with.
    """
    R = delta[:3, :3]
    c_new = R @ c + delta[:3, 3]
    w = Rotation.from_matrix(R).as_rotvec()
    x = np.concatenate([w * _TWIST_LENGTH, c_new - c])
    if previous is not None:
        norm = np.linalg.norm(x) * np.linalg.norm(previous)
        rho = np.linalg.norm(x) / max(np.linalg.norm(previous), 1e-300)
        if norm > 0 and x @ previous / norm > 0.99 and rho < 0.98:
            s = min(rho / (1.0 - rho), 20.0)
            R_jump = Rotation.from_rotvec(s * w).as_matrix()
            return _make_T(R_jump, c_new + s * (c_new - c) - R_jump @ c_new) @ T, None
    return T, x


def _kabsch(p: np.ndarray, q: np.ndarray, _n=None) -> np.ndarray | None:
    """Rigid transform (4, 4) minimising Σ |R pᵢ + t − qᵢ|² (Arun / Umeyama without scale)."""
    mp, mq = p.mean(axis=0), q.mean(axis=0)
    U, _, Vt = np.linalg.svd((p - mp).T @ (q - mq))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return _make_T(R, mq - R @ mp)


def _point_to_plane(p: np.ndarray, q: np.ndarray, n: np.ndarray) -> np.ndarray | None:
    """One Gauss-Newton step of Σ ((R pᵢ + t − qᵢ)·nᵢ)², linearised about the centroid c of p.

    Directions the normals cannot see (a plate's in-plane motion) get no motion: minimum-norm solution.
    """
    c = p.mean(axis=0)
    A = np.hstack([np.cross(p - c, n), n])
    b = np.einsum("ij,ij->i", q - p, n)
    return _solve_point_to_plane(A.T @ A, A.T @ b, c)


def _solve_point_to_plane(AtA: np.ndarray, Atb: np.ndarray, c: np.ndarray) -> np.ndarray | None:
    """The step (4, 4) from the normal equations about c: rotation vector then translation."""
    x, *_ = np.linalg.lstsq(AtA, Atb, rcond=1e-12)
    if not np.all(np.isfinite(x)):
        return None
    R = Rotation.from_rotvec(x[:3]).as_matrix()
    return _make_T(R, c + x[3:] - R @ c)


def _register_open3d(source, reference, cfg: RegistrationConfig) -> Registration:
    import open3d as o3d

    reg = o3d.pipelines.registration
    target = _open3d_target(reference, cfg)
    src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(source))
    criteria = reg.ICPConvergenceCriteria(relative_fitness=1e-9, relative_rmse=1e-12, max_iteration=cfg.max_iterations)
    dist = cfg.max_correspondence_distance
    if cfg.method == "generalized":
        result = reg.registration_generalized_icp(src, target, dist, np.eye(4), reg.TransformationEstimationForGeneralizedICP(), criteria)
    else:
        est = reg.TransformationEstimationPointToPoint() if cfg.method == "point_to_point" else reg.TransformationEstimationPointToPlane()
        result = reg.registration_icp(src, target, dist, np.eye(4), est, criteria)
    T = np.asarray(result.transformation).copy()
    p = source @ T[:3, :3].T + T[:3, 3]
    q, n, _ = reference.closest(p)
    inlier = np.einsum("ij,ij->i", p - q, p - q) <= dist**2
    ok = result.fitness > 0
    # Open3D does not say whether it stopped on its criteria or on max_iteration: counted as converged
    return Registration(T, bool(ok), -1, float(result.fitness), float(result.inlier_rmse), len(source),
                        information_matrix(p[inlier], n[inlier]), "" if ok else "no correspondences")  # fmt: skip


def _open3d_target(reference, cfg: RegistrationConfig):
    """Open3D point cloud of the reference (a dense sample for a surface), cached on the reference."""
    import open3d as o3d

    key = ("_o3d_target", cfg.reference_spacing, cfg.method == "generalized")
    cache = reference.__dict__.setdefault("_o3d_cache", {})
    if key not in cache:
        points, normals = reference.sample(cfg.reference_spacing)
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
        pcd.normals = o3d.utility.Vector3dVector(normals)
        if cfg.method == "generalized":
            pcd.estimate_covariances(o3d.geometry.KDTreeSearchParamKNN(20))
        cache[key] = pcd
    return cache[key]


def _failed(n: int, why: str, T: np.ndarray | None = None, iterations: int = 0) -> Registration:
    return Registration(np.eye(4) if T is None else T, False, iterations, 0.0, float("nan"), n, np.zeros((6, 6)), why)


def _make_T(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T
