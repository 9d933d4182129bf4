"""ICP written here, on a reference built once per part (:mod:`optipose.registration.reference`):
point-to-point (Kabsch on closest points, the paper's method) or point-to-plane (a linearised 6×6 solve
per step), from identity.

:class:`FastBackend` (``fast``) runs each step as three compiled passes (:mod:`optipose.registration.normal_equations`):
move the cloud, find closest points from the faces of the previous step (``reference.nearest``), sum the
normal equations, whose ``AᵀA`` at the last step is also the information matrix.
A point-to-plane step too large to be the linearisation's answer gives way to one within a trust region
(:func:`_damped`): its weakest motions held.
:class:`PlainBackend` (``plain``) is the same loop in numpy on ``closest``/``follow``: the readable
reference the compiled one is tested against (same iterations, same pose up to summation order).
Generalized ICP has no path here (:mod:`optipose.registration.open3d_icp` runs it).
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial.transform import Rotation

from optipose.registration.config import FITNESS_CHANGE, RMSE_CHANGE
from optipose.registration.preprocess import information_matrix, scaled_information
from optipose.transforms import mean_pose
from optipose.registration.result import MIN_POINTS, Matches, Registration

if TYPE_CHECKING:
    from optipose.registration.config import RegistrationConfig

__all__ = ["FastBackend", "PlainBackend"]

_TWIST_LENGTH = 0.03  # m: weighs rotation against translation when comparing ICP steps
_TURNING = 1e-3  # a free motion (unit, scaled) whose turn is smaller than this is a shift
# the ICP takes no step along a motion whose smooth-surface information is below the observability tolerance times
# this: far below it (a sphere's rotation at 10⁻⁹–10⁻¹⁰ of the largest, a plate's yaw at 10⁻¹⁷), not near it, where
# whether a facet's turn or the surface decides would move with the tessellation (a bent sheet's bend, part C)
STEP_NULL = 1e-2
# the trust region of a point-to-plane step (:func:`_damped`): the largest turn (rad) of one step, well beyond the
# turns the registration is asked to recover (the paper's ±2° about each axis, 3.5° together, and a cell's hundredths
# of a degree; start offsets of ±10° about each axis, 17° together, in the stress tests), so a registration that
# moves as they do is never damped; the step's shift is held to the correspondence distance
MAX_TURN = np.deg2rad(30.0)


class FastBackend:
    """Compiled ICP (``fast``): point-to-point or point-to-plane; see the module doc."""

    methods = ("point_to_point", "point_to_plane")
    takes_initial = True

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"

    def register(
        self,
        source: np.ndarray,
        reference,
        cfg: RegistrationConfig,
        initial: Matches | None = None,
        start: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> Registration:
        """Register ``source`` (n, 3) m onto ``reference`` from identity; ``initial``: its matches at identity.
        ``start``: (T (4, 4), ids (n,)) a pose to start from instead, and each point's match there as a hint."""
        from optipose.registration.normal_equations import cross_covariance, kabsch, normal_equations, transform

        source = np.ascontiguousarray(source, dtype=np.float64)
        T, ids = (np.eye(4), None) if start is None else (np.array(start[0], dtype=float), np.array(start[1]))
        initial = initial if start is None else None
        max_d2 = cfg.max_correspondence_distance**2
        converged, it, history, before = False, 0, None, None
        cycle = Cycle(cfg)
        track = reference.tracker(ids, initial)
        smooth = _smooth(reference, cfg)
        seen, free = (
            None,
            False,
        )  # the motions stepped along (None: all six), and whether the smooth surface leaves any free
        p = np.empty_like(source)  # every step's moved cloud, in one buffer
        for it in range(1, cfg.max_iterations + 1):
            p = transform(source, T, p)
            q, n, ids = track(p)
            if it == 1 and smooth is not None:
                seen, free = _seen(smooth, p, q, ids, max_d2, cfg.null_tolerance)
            if cfg.method == "point_to_point":  # the information matrix is summed once, after the last step
                n_in, sum_d2, c, mq, H = cross_covariance(p, q, max_d2)
            else:
                inlier, c, AtA, Atb, sum_d2 = normal_equations(p, q, n, max_d2)
                n_in = int(inlier.sum())
            if n_in < MIN_POINTS:
                return Registration.failed(len(source), f"{n_in} points within the correspondence distance", T, it)
            if cfg.stop == "fitness":  # Open3D's test, on the matches at T against those before the last step
                now = (n_in / len(source), float(np.sqrt(sum_d2 / n_in)))
                if (
                    before is not None
                    and abs(now[0] - before[0]) < FITNESS_CHANGE
                    and abs(now[1] - before[1]) < RMSE_CHANGE
                ):
                    converged = True
                    break
                before = now
            if cfg.method == "point_to_point":
                delta = kabsch(H, c, mq)
            else:
                delta = _solve_point_to_plane(AtA, Atb, c, seen, cfg.max_correspondence_distance)
            if delta is None:
                return Registration.failed(len(source), "degenerate step", T, it)
            T = delta @ T
            if cfg.stop == "fitness":
                converged = it == cfg.max_iterations  # as Open3D: the cap ends the ICP, it does not fail it
                continue
            if _small_step(delta, cfg):
                converged = True
                break
            if (middle := cycle(T)) is not None:
                T, converged = middle, True
                break
            if cfg.method == "point_to_point":
                T, history = _accelerate(T, delta, c, history)
        if cfg.method == "point_to_point":
            AtA = normal_equations(p, q, n, max_d2)[2]
        if free:  # free motions where it started: those at its end leave the information
            AtA = _without_unseen(AtA, smooth, p, q, ids, max_d2, cfg.null_tolerance)
        return Registration(
            T_target_source=T,
            converged=converged,
            iterations=it,
            fitness=n_in / len(source),
            rmse=float(np.sqrt(sum_d2 / n_in)),
            n_points=len(source),
            information=AtA,
            failure="" if converged else f"no convergence in {cfg.max_iterations} iterations",
            matched=ids.copy(),
        )


class PlainBackend:
    """The same ICP in plain numpy (``plain``): slow, readable, the cross-check of :class:`FastBackend`."""

    methods = ("point_to_point", "point_to_plane")
    takes_initial = True

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"

    def register(
        self,
        source: np.ndarray,
        reference,
        cfg: RegistrationConfig,
        initial: Matches | None = None,
        start: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> Registration:
        """Register ``source`` (n, 3) m onto ``reference`` from identity; ``initial``: its matches at identity.
        ``start``: (T (4, 4), ids (n,)) a pose to start from instead (its ids are not needed here)."""
        T = np.eye(4) if start is None else np.array(start[0], dtype=float)
        initial = initial if start is None else None
        ids = None
        max_d2 = cfg.max_correspondence_distance**2
        reach = cfg.max_correspondence_distance
        step = _kabsch if cfg.method == "point_to_point" else functools.partial(_point_to_plane, reach=reach)
        converged, it, history = False, 0, None
        cycle = Cycle(cfg)
        smooth, seen, free = _smooth(reference, cfg), None, False
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
            if inlier.sum() < MIN_POINTS:
                return Registration.failed(
                    len(source), f"{int(inlier.sum())} points within the correspondence distance", T, it
                )
            if it == 1 and smooth is not None:
                seen, free = _seen(smooth, p, q, ids, max_d2, cfg.null_tolerance)
            delta = step(p[inlier], q[inlier], n[inlier], seen)
            if delta is None:
                return Registration.failed(len(source), "degenerate step", T, it)
            T = delta @ T
            if _small_step(delta, cfg):
                converged = True
                break
            if (middle := cycle(T)) is not None:
                T, converged = middle, True
                break
            if cfg.method == "point_to_point":
                T, history = _accelerate(T, delta, p[inlier].mean(axis=0), history)
        d2 = np.einsum("ij,ij->i", p - q, p - q)
        inlier = d2 <= max_d2
        information = information_matrix(p[inlier], n[inlier])
        if free:
            information = _without_unseen(information, smooth, p, q, ids, max_d2, cfg.null_tolerance)
        return Registration(
            T_target_source=T,
            converged=converged,
            iterations=it,
            fitness=float(inlier.mean()),
            rmse=float(np.sqrt(d2[inlier].mean())),
            n_points=len(source),
            information=information,
            failure="" if converged else f"no convergence in {cfg.max_iterations} iterations",
            matched=ids,
        )


# ---------------------------------------------------------------------------------------------------------
class Cycle:
    """An ICP caught in a cycle. Where the clouds of several sensors disagree (a bracket off its drawn
    pose), some points sit on the edge between two faces' closest-point regions and change sides every
    few steps: the pose then repeats with a period of a few steps, or jitters about one place, and
    the steps never fall below the tolerance. The registration has settled as far as it can when

    * the pose comes back within the tolerances to one it had up to ``window`` steps ago (a cycle), or
    * over ``window`` steps it has moved net less than one step on average (jitter; a converging or
      drifting ICP moves net about the sum of its steps);

    the mean of the poses of the cycle (or of the window) is then its estimate.
    """

    def __init__(self, cfg: RegistrationConfig, window: int = 12):
        self.cfg, self.window, self.poses, self.steps = cfg, window, [], []

    def __call__(self, T: np.ndarray) -> np.ndarray | None:
        """The mean pose of the cycle ``T`` closes (or of the jitter it ends), or None."""
        if self.poses:  # T's motion from each kept pose, oldest first, in one pass (this runs every ICP step)
            angle, shift = _motions_from(T, np.asarray(self.poses))
            back = np.flatnonzero(
                (angle[:-1] < self.cfg.tolerance_rotation) & (shift[:-1] < self.cfg.tolerance_translation)
            )
            if len(back):  # the most recent pose T is back at, two steps ago or more
                return mean_pose(self.poses[back[-1] + 1 :] + [T])
            twist = angle * _TWIST_LENGTH + shift
            self.steps = (self.steps + [float(twist[-1])])[-self.window :]
            if len(self.poses) == self.window and twist[0] < np.mean(self.steps):
                return mean_pose(self.poses[1:] + [T])
        self.poses = (self.poses + [T])[-self.window :]
        return None


def _motions_from(T: np.ndarray, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The angle (rad) and translation (m) of ``T @ inv(P)`` for each rigid ``P`` of ``poses`` (m, 4, 4)."""
    R, t = poses[:, :3, :3], poses[:, :3, 3]
    trace = np.einsum("ij,mij->m", T[:3, :3], R)  # trace(R_T Rᵀ)
    shift = T[:3, 3] - np.einsum("ij,mkj,mk->mi", T[:3, :3], R, t)  # t_T − R_T Rᵀ t
    return np.arccos(np.clip(0.5 * (trace - 1.0), -1.0, 1.0)), np.linalg.norm(shift, axis=1)


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


def _smooth(reference, cfg: RegistrationConfig):
    """The reference's information on its smooth surface's normals
    (:meth:`~optipose.registration.reference.SurfaceReference.smooth_information`), or None: a sampled
    reference has none, and ``null_tolerance`` 0 asks for none."""
    return getattr(reference, "smooth_information", None) if cfg.null_tolerance > 0 else None


def _seen(smooth, p, q, ids, max_d2: float, tolerance: float) -> tuple[np.ndarray | None, bool]:
    """The motions the ICP steps along — None when the smooth surface constrains all six by far, else a basis K
    (6, r), a step being ``K @ y`` — and whether it leaves any motion free at ``tolerance``. A facet's turn is
    no reason to move (:mod:`optipose.registration.smooth`): a motion whose information is below
    ``tolerance × STEP_NULL`` is not stepped along. One nearer the tolerance is (the ICP of a weakly seen
    direction settles where its facets put it, as it always did) and only the observability test drops it.

    Of the motions that differ by one the surface leaves free, K keeps the one that does not turn along the free
    rotations (a sphere's cloud then only shifts: its rotation about the centre stays at identity's) and does not
    shift along the free translations (a plate's in-plane shift, as the minimum-norm step has it).
    """
    from optipose.registration.smooth import null_directions

    H, scale = smooth(np.ascontiguousarray(p), np.ascontiguousarray(q), ids, max_d2)
    free = null_directions(H, scale, tolerance).shape[1] > 0
    null = null_directions(H, scale, tolerance * STEP_NULL) if free else np.zeros((6, 0))
    if null.shape[1] == 0:
        return None, free
    k = null.shape[1]
    U, S, Wt = np.linalg.svd(null[:3], full_matrices=True)  # the free motions' turns, largest first
    turning = np.zeros(k, dtype=bool)
    turning[: len(S)] = S > _TURNING
    shifts = null[3:] @ Wt[~turning].T  # the free motions that hardly turn: shifts
    held = np.zeros((6, k))
    held[:3, : turning.sum()] = U[:, : turning.sum()]
    held[3:, turning.sum() :] = shifts / np.linalg.norm(shifts, axis=0)
    return np.linalg.svd(held, full_matrices=True)[0][:, k:], True  # the motions orthogonal to what is held


def _without_unseen(AtA: np.ndarray, smooth, p, q, ids, max_d2: float, tolerance: float) -> np.ndarray:
    """``AtA`` (6, 6) with the motions the smooth surface leaves free (at the final matches) taken out, in the
    scaled coordinates of the observability test: unchanged where it constrains all six."""
    from optipose.registration.smooth import null_directions

    H, scale = smooth(np.ascontiguousarray(p), np.ascontiguousarray(q), ids, max_d2)
    null = null_directions(H, scale, tolerance)
    if null.shape[1] == 0:
        return AtA
    scaled, d = scaled_information(AtA, scale)
    P = np.eye(6) - null @ null.T
    return (P @ scaled @ P) / d[:, None] / d[None, :]


def _kabsch(p: np.ndarray, q: np.ndarray, _n=None, _seen=None) -> np.ndarray | None:
    """Rigid transform (4, 4) minimising Σ |R pᵢ + t − qᵢ|² (Arun / Umeyama without scale)."""
    mp, mq = p.mean(axis=0), q.mean(axis=0)
    U, _, Vt = np.linalg.svd((p - mp).T @ (q - mq))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return _make_T(R, mq - R @ mp)


def _point_to_plane(p: np.ndarray, q: np.ndarray, n: np.ndarray, seen=None, reach: float = np.inf) -> np.ndarray | None:
    """One Gauss-Newton step of Σ ((R pᵢ + t − qᵢ)·nᵢ)², linearised about the centroid c of p.

    Directions the normals cannot see (a plate's in-plane motion) get no motion: minimum-norm solution.
    ``reach``: the shift of the trust region (:func:`_solve_point_to_plane`).
    """
    c = p.mean(axis=0)
    A = np.hstack([np.cross(p - c, n), n])
    b = np.einsum("ij,ij->i", q - p, n)
    return _solve_point_to_plane(A.T @ A, A.T @ b, c, seen, reach)


def _solve_point_to_plane(
    AtA: np.ndarray, Atb: np.ndarray, c: np.ndarray, seen=None, reach: float = np.inf
) -> np.ndarray | None:
    """The step (4, 4) from the normal equations about c: rotation vector then translation; with ``seen``
    (:func:`_seen`), the step within the motions it allows. A step that turns more than :data:`MAX_TURN` or
    moves c farther than ``reach`` (m, the correspondence distance) is outside the trust region and gives way to
    the step within it (:func:`_damped`); any other is the Gauss-Newton step as solved."""
    if seen is None:
        x, *_ = np.linalg.lstsq(AtA, Atb, rcond=1e-12)
    else:
        y, *_ = np.linalg.lstsq(seen.T @ AtA @ seen, seen.T @ Atb, rcond=1e-12)
        x = seen @ y
    if not np.all(np.isfinite(x)):
        return None
    if not _within(x, reach):
        x = _damped(AtA, Atb, seen, reach)
    R = Rotation.from_rotvec(x[:3]).as_matrix()
    return _make_T(R, c + x[3:] - R @ c)


def _within(x: np.ndarray, reach: float) -> bool:
    """The step ``x`` (rotation vector, shift of c) turns at most :data:`MAX_TURN` and shifts at most ``reach``."""
    return bool(np.linalg.norm(x[:3]) <= MAX_TURN and np.linalg.norm(x[3:]) <= reach)


def _damped(AtA: np.ndarray, Atb: np.ndarray, seen, reach: float, rcond: float = 1e-12) -> np.ndarray:
    """The point-to-plane step within the trust region (:func:`_within`) where the Gauss-Newton step is not: that
    step without its weakest motions. The motions are the eigenvectors of ``AᵀA`` (within ``seen``) in the twist's
    own measure (a turn weighed by ``_TWIST_LENGTH`` against a shift, as the steps are compared); the weakest are
    dropped one by one until the rest's step is within the region (if even the strongest alone is not: its step,
    shortened to the region's edge).

    A motion the cloud sees only weakly (a narrow strip's turn about its length, a few facets' tilt) has an
    eigenvalue many orders below the rest, and the Gauss-Newton step divides its share of ``Aᵀb`` by it: what the
    linearisation leaves out (the pose's second order, the faces the points will match after the step) then reads
    as a turn of radians, which throws the cloud off the part. That motion is held for the step; the others take
    their Gauss-Newton step, and once they are settled the weak motion's own step, from matches that no longer
    carry their error, is small and taken. Where the surface barely sees the motion (a turn about a bore's axis)
    its step stays large from every pose, and it stays held, as a free motion is (:func:`_seen`). Damping it only
    to the region's edge (Levenberg-Marquardt's λ there) is not enough for that: asked the same turn again at each
    step, the ICP walks along the motion by the region's width a step, as far as its iterations go.
    """
    K = np.eye(6) if seen is None else seen
    C = np.linalg.cholesky(K.T @ np.diag([_TWIST_LENGTH**2] * 3 + [1.0] * 3) @ K)
    back = K @ np.linalg.inv(C).T  # from the twist's measure back to (rotation vector, shift)
    w, V = np.linalg.eigh(back.T @ AtA @ back)  # weakest first
    along = np.where(w > rcond * w[-1], (V.T @ (back.T @ Atb)) / np.where(w > 0, w, 1.0), 0.0)  # as lstsq's rcond
    for dropped in range(1, len(w)):
        x = back @ (V[:, dropped:] @ along[dropped:])
        if _within(x, reach):
            return x
    x = back @ (V[:, -1] * along[-1])  # the strongest alone is out too
    return x * min(1.0, MAX_TURN / max(np.linalg.norm(x[:3]), 1e-300), reach / max(np.linalg.norm(x[3:]), 1e-300))


def _make_T(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T
