"""How a sensor's rebuilt cloud moves when the sensor is off the pose its cell believes (its calibration, its
bracket): the first-order map the surrogate's cell term builds on (:mod:`optipose.search.cell_terms`).

A sensor whose true pose is ``T_O_S @ E`` (E a small rigid error, rotation r and translation t in the
sensor's frame) measures a surface point y (where it was, in O, when its profile was taken) as
``E⁻¹ T_O_S⁻¹ y``; the cell rebuilds it with the believed pose and undoes the scan's travel s along x_O
(:func:`optipose.scan.cloud.rebuilt_with`). To first order the rebuilt point moves by

    u = (y − o) × (R_S r) − R_S t,   y = p + s(p)·x_O,   s(p) = y_S·(o − p) / (y_S·x_O)

with o, R_S, y_S the believed pose's origin, rotation and laser-plane normal, and s(p) the travel at which the
laser plane met p. This is a rigid motion of the point *where it was measured*, so for a cloud it is a
rigid motion plus a shear along the scan (a head turned on its bracket reads every profile at its own
travel); both are linear in ξ = (r, t) (:func:`displacement`). One point-to-plane Gauss–Newton step then settles
on a compromise between sensors whose clouds disagree (:func:`scaled_solve` solves its equations).
"""

from __future__ import annotations

import numpy as np

__all__ = ["displacement", "scaled_solve"]

_X = np.array([1.0, 0.0, 0.0])


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


def scaled_solve(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """pinv(A) @ B for stacks A (..., 6, 6), B (..., 6, q), rotation and translation rows scaled to one size
    first (as :func:`optipose.search.surrogate.bias_rotation`): directions no point pins down get nothing."""
    d = np.diagonal(A, axis1=-2, axis2=-1)
    floor = 1e-12 * np.maximum(d.max(axis=-1, keepdims=True), 1e-300)
    scale = np.sqrt(np.clip(d, floor, None))
    As = A / (scale[..., :, None] * scale[..., None, :])
    return (np.linalg.pinv(As, rcond=1e-9) @ (B / scale[..., :, None])) / scale[..., :, None]
