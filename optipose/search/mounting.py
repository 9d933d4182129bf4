"""The surrogate's bracket mounting-error term: how much a zeroed cell's estimate moves with the part's
orientation when the sensors' brackets are off their drawings (docs/conditions.md, issue #13).

A sensor whose true pose is ``T_O_S @ E`` (E a small rigid error, rotation r and translation t in the
sensor's frame) measures a surface point y (where it was, in O, when its profile was taken) as
``E⁻¹ T_O_S⁻¹ y``; the cell rebuilds it with the drawn pose and undoes the scan's travel s along x_O
(:func:`optipose.scan.cloud.rebuilt_with`). To first order the rebuilt point moves by

    u = (y − o) × (R_S r) − R_S t,   y = p + s(p)·x_O,   s(p) = y_S·(o − p) / (y_S·x_O)

with o, R_S, y_S the drawn pose's origin, rotation and laser-plane normal, and s(p) the travel at which the
laser plane met p. This is a rigid motion of the point *where it was measured*, so for a cloud it is a
rigid motion plus a shear along the scan (a head turned on its bracket reads every profile at its own
travel); both are linear in ξ = (r, t). One point-to-plane Gauss–Newton step of a subset then settles on

    δ(R) = −(Σ_j A_j(R))⁻¹ Σ_j N_j(R) ξ_j,   N_j = Σ_i Jᵢᵀ nᵢᵀ Lᵢ   (u = Lᵢ ξ at point i)

with A_j(R) = ΣJᵀJ the sensor's unweighted normal matrix at the part's orientation R. One sensor's
rigid error is a rigid motion of its whole cloud and the master-part zeroing takes it off; between
sensors, the estimate is a compromise whose weights change with R, and δ(R) − δ(nominal) stays. The
surrogate treats the bracket errors as random, uniform within the tolerance (variance t²/3, r²/3 per
axis, independent between sensors), and adds the variance of the zeroed rotation error,
Σ_j W_j Cov(ξ) W_jᵀ with W_j = [(ΣA(R))⁻¹N_j(R) − (ΣA(0))⁻¹N_j(0)]_rot, per axis to the noise variance at
each turn (it does not scale with the noise level).

What it leaves out: the turns are the nominal scan turned (see :mod:`optipose.search.surrogate`), so
the weights change only through the frame turning and the voxel grid, not through points that appear or
vanish as faces tilt; ICP's later steps (re-matching) and its convergence, which the evaluator measures
to be slow under mounting errors; the master scan's own noise; and the fixed draws of the evaluator
(its worst over a few draws can exceed the spread this variance implies).
"""

from __future__ import annotations

import numpy as np

__all__ = ["displacement", "mounting_maps", "mounting_variance", "scaled_solve"]

_X = np.array([1.0, 0.0, 0.0])
_MAX_STD = np.deg2rad(5.0)  # as the surrogate's weak prior: beyond it an error is not small


def _cross_matrices(a: np.ndarray) -> np.ndarray:
    """(n, 3, 3) matrices [a]× with [a]× b = a × b, for a (n, 3)."""
    z = np.zeros(len(a))
    return np.stack(
        [np.stack([z, -a[:, 2], a[:, 1]], 1), np.stack([a[:, 2], z, -a[:, 0]], 1), np.stack([-a[:, 1], a[:, 0], z], 1)],
        1,
    )


def displacement(points: np.ndarray, T_O_S: np.ndarray) -> np.ndarray:
    """(n, 3, 6): how each rebuilt point (n, 3) m in O moves per unit bracket error (r rad, t m), sensor frame."""
    R, o, y_S = T_O_S[:3, :3], T_O_S[:3, 3], T_O_S[:3, 1]
    across = float(y_S @ _X)
    across = np.copysign(max(abs(across), 1e-3), across)  # a line along the motion never sweeps: no shear
    s = (o - points) @ y_S / across
    y = points + s[:, None] * _X
    return np.concatenate([_cross_matrices(y - o) @ R, np.broadcast_to(-R, (len(points), 3, 3))], axis=2)


def mounting_maps(
    v: np.ndarray, n: np.ndarray, R: np.ndarray, centre: np.ndarray, T_O_S: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """A sensor's normal matrix A (6, 6) and mounting map N (6, 6) at one turn, in O about ``centre``.

    v, n : (m, 3) voxel centroids and CAD normals in the part's frame; R : (3, 3) the part's turn.
    N maps the bracket error ξ (6,) to ΣJᵀr, the right-hand side of the Gauss–Newton step.
    """
    p, n_O = (v - centre) @ R.T + centre, n @ R.T
    J = np.hstack([np.cross(p - centre, n_O), n_O])
    a = np.einsum("ij,ijk->ik", n_O, displacement(p, T_O_S))  # (m, 6): the residual per unit ξ
    return J.T @ J, J.T @ a


def scaled_solve(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """pinv(A) @ B for stacks A (..., 6, 6), B (..., 6, q), rotation and translation rows scaled to one size
    first (as :func:`optipose.search.surrogate.bias_rotation`): directions no point pins down get nothing."""
    d = np.diagonal(A, axis1=-2, axis2=-1)
    floor = 1e-12 * np.maximum(d.max(axis=-1, keepdims=True), 1e-300)
    scale = np.sqrt(np.clip(d, floor, None))
    As = A / (scale[..., :, None] * scale[..., None, :])
    return (np.linalg.pinv(As, rcond=1e-9) @ (B / scale[..., :, None])) / scale[..., :, None]


def mounting_variance(A: list[np.ndarray], N: list[np.ndarray], translation: float, rotation: float) -> np.ndarray:
    """Per turn, the variance (turns, 3) rad² of a zeroed subset's rotation error from its brackets.

    A, N : per sensor of the subset, (turns + 1, 6, 6) normal matrices and mounting maps in O, index 0 the
    nominal orientation (:class:`optipose.search.surrogate.SensorInfo` ``A_turns``, ``N_turns``).
    translation (m), rotation (rad) : the tolerance, ± per axis, uniform.
    """
    if translation <= 0 and rotation <= 0:
        return np.zeros((len(A[0]) - 1, 3))
    cov = np.array([rotation**2 / 3] * 3 + [translation**2 / 3] * 3)
    P = scaled_solve(sum(A), np.concatenate(N, axis=2))[:, :3]  # (turns + 1, 3, 6·sensors)
    W = P[1:] - P[:1]  # zeroed on the master scan at the nominal orientation
    var = (W**2 * np.tile(cov, len(N))).sum(axis=2)
    return np.minimum(var, _MAX_STD**2)
