"""Rigid transforms and the orientation convention (docs/conventions.md).

Roll, pitch, yaw are extrinsic rotations about x_O, y_O, z_O: ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``.
Poses are 4×4 homogeneous matrices named by their frames, ``T_target_source`` maps points expressed in
*source* into *target*.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from optipose.errors import PoseError

__all__ = [
    "mean_pose",
    "rpy_to_matrix",
    "matrix_to_rpy",
    "xyz_rpy",
    "make_T",
    "invert_T",
    "transform_points",
    "validate_pose",
    "part_motion",
]


def rpy_to_matrix(rpy: np.ndarray) -> np.ndarray:
    """Rotation matrix from roll, pitch, yaw.

    rpy : (3,) or (n, 3) float, radians.  Returns (3, 3) or (n, 3, 3).
    """
    return Rotation.from_euler("xyz", rpy).as_matrix()


_NEAR_GIMBAL = 1e-6  # rad from pitch ±90°: where scipy's angles may give the matrix back only to ~1e-8


def matrix_to_rpy(R: np.ndarray) -> np.ndarray:
    """Roll, pitch, yaw (radians) of a rotation matrix (3, 3) or (n, 3, 3); inverse of :func:`rpy_to_matrix`.

    scipy treats a pitch within ~1e-7 rad of ±90° as gimbal lock (yaw 0), which gives the matrix back only
    to ~1e-8; there, yaw is taken from the first column and roll from the 2×2 block given that yaw, so the
    angles give the matrix back to rounding (elsewhere scipy's angles are returned as they are)."""
    rpy = Rotation.from_matrix(R).as_euler("xyz")
    M, out = np.asarray(R, dtype=float).reshape(-1, 3, 3), rpy.reshape(-1, 3)
    near = np.abs(np.abs(out[:, 1]) - np.pi / 2) < _NEAR_GIMBAL
    for i in np.flatnonzero(near):
        m = M[i]
        if np.hypot(m[0, 0], m[1, 0]) == 0.0:  # exact gimbal lock: only roll - yaw (or + yaw) is defined
            continue
        yaw = np.arctan2(m[1, 0], m[0, 0])
        sy, cy = np.sin(yaw), np.cos(yaw)
        roll = np.arctan2(sy * m[0, 2] - cy * m[1, 2], cy * m[1, 1] - sy * m[0, 1])
        out[i] = roll, np.arctan2(-m[2, 0], np.hypot(m[0, 0], m[1, 0])), yaw
    return out.reshape(rpy.shape)


def xyz_rpy(T_O_S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A pose (4×4, metres) as a robot program takes it: the position (3,) in mm and roll, pitch, yaw (3,) in
    degrees (:func:`matrix_to_rpy`)."""
    T = np.asarray(T_O_S, dtype=float)
    return T[:3, 3] * 1e3, np.rad2deg(matrix_to_rpy(T[:3, :3]))


def make_T(R: np.ndarray | None = None, t: np.ndarray | None = None) -> np.ndarray:
    """4×4 pose from a rotation (3, 3) and a translation (3,) in metres."""
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    if t is not None:
        T[:3, 3] = t
    return T


def invert_T(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid 4×4 transform (uses Rᵀ, not a general inverse)."""
    R = T[:3, :3]
    Ti = np.eye(4)
    Ti[:3, :3] = R.T
    Ti[:3, 3] = -R.T @ T[:3, 3]
    return Ti


def transform_points(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a 4×4 transform to points (n, 3)."""
    return points @ T[:3, :3].T + T[:3, 3]


def validate_pose(T: np.ndarray, name: str = "pose", tol: float = 1e-3) -> np.ndarray:
    """Check that ``T`` is a proper rigid transform and return it re-orthonormalised (float64).

    Hand-typed poses such as the paper's (0.7071 for √½) are accepted within ``tol`` and snapped to the
    nearest rotation; a reflection, a scaled or sheared matrix, or a bad last row raises :class:`PoseError`.
    """
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4):
        raise PoseError(f"{name}: expected a 4x4 matrix, got shape {T.shape}")
    if not np.all(np.isfinite(T)):
        raise PoseError(f"{name}: matrix has NaN or infinite entries")
    if not np.allclose(T[3], [0, 0, 0, 1], atol=1e-9):
        raise PoseError(f"{name}: last row must be [0 0 0 1], got {T[3].tolist()}")
    R = T[:3, :3]
    det = np.linalg.det(R)
    if det < 0:
        raise PoseError(f"{name}: rotation part is a reflection (det = {det:.3f}); axes must be right-handed")
    if not np.allclose(R.T @ R, np.eye(3), atol=tol):
        raise PoseError(f"{name}: rotation part is not orthonormal (columns must be unit, perpendicular axes)")
    U, _, Vt = np.linalg.svd(R)
    out = T.copy()
    out[:3, :3] = U @ Vt
    return out


def part_motion(rpy: np.ndarray, centre: np.ndarray, offset: np.ndarray | None = None) -> np.ndarray:
    """Pose of the part at an orientation, ``T_O_part``: rotate by ``rpy`` about ``centre``, then translate.

    rpy : (3,) radians; centre : (3,) m; offset : (3,) m (e.g. a protocol's translation offset).
    """
    R = rpy_to_matrix(np.asarray(rpy, dtype=float))
    c = np.asarray(centre, dtype=float)
    t = c - R @ c
    if offset is not None:
        t = t + np.asarray(offset, dtype=float)
    return make_T(R, t)


def mean_pose(poses: list[np.ndarray]) -> np.ndarray:
    """The mean of nearby rigid motions (4, 4): the rotations' mean, the translations' mean."""
    from scipy.spatial.transform import Rotation

    R = Rotation.from_matrix([Q[:3, :3] for Q in poses]).mean().as_matrix()
    return make_T(R, np.mean([Q[:3, 3] for Q in poses], axis=0))
