"""The device's heights and the points they give: one arithmetic for the scanner, the cell and the reader.

A measured point is a height on one column's laser ray: the device reports ``Z`` (mm, positive toward the
head, ``Z = -1e3·z_S``), and a point in O is what that height gives on the ray (paper eq. 4, the motion
undone). The scanner (:func:`optipose.scan.kernels.write_points`), a cell that moves points along their rays
(:func:`through_heights`) and a reader of raw profiles (:func:`heights_to_points`) all place a point with
:func:`place` from the height the device would report, so a cloud read back from float64 profiles is the
simulated cloud bit for bit.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["place", "heights_to_points", "through_heights", "as_reported"]


@njit(cache=True, nogil=True, inline="always")
def place(height, col, shift, x0, slope, R, t, points, h):
    """Write into ``points[h]`` the point in O (m) of ``height`` (mm, the device's Z) on column ``col``'s
    ray ``x_S = x0 + slope·z_S``, for a sensor at ``R`` (3, 3), ``t`` (3,) and a profile taken at ``shift`` (m)."""
    z = -height * 1e-3
    xs = x0[col] + z * slope[col]
    points[h, 0] = R[0, 0] * xs + R[0, 2] * z + t[0] - shift
    points[h, 1] = R[1, 0] * xs + R[1, 2] * z + t[1]
    points[h, 2] = R[2, 0] * xs + R[2, 2] * z + t[2]


@njit(cache=True, nogil=True)
def heights_to_points(heights, profile, column, shifts, x0, slope, R, t):
    """Points in O (n, 3) m of heights (n,) mm on columns ``column`` (n,) of profiles ``profile`` (n,)
    taken at ``shifts`` (n_profiles,) m, by a sensor at ``R`` (3, 3), ``t`` (3,)."""
    n = heights.shape[0]
    points = np.empty((n, 3))
    for h in range(n):
        place(heights[h], column[h], shifts[profile[h]], x0, slope, R, t, points, h)
    return points


@njit(cache=True, nogil=True)
def through_heights(points, delta, profile, column, shifts, x0, slope, R, t, raw, n_col):
    """Each point (n, 3) in O moved by ``delta`` (n, 3) along its ray (a cell's sources), in place, then
    replaced by the point its reported height gives; the height is written into ``raw`` (flat, profile ×
    ``n_col`` + column, mm) unless it is empty. A point not moved stays as it is: the scanner placed it from
    its height already. The point stays on its ray: placing it changes only rounding."""
    with_raw = raw.shape[0] > 0
    for h in range(points.shape[0]):
        if delta[h, 0] == 0.0 and delta[h, 1] == 0.0 and delta[h, 2] == 0.0:
            continue
        k = profile[h]
        shift = shifts[k]
        dx = points[h, 0] + delta[h, 0] + shift - t[0]
        dy, dz = points[h, 1] + delta[h, 1] - t[1], points[h, 2] + delta[h, 2] - t[2]
        height = -1e3 * (R[0, 2] * dx + R[1, 2] * dy + R[2, 2] * dz)
        if with_raw:
            raw[k * n_col + column[h]] = height
        place(height, column[h], shift, x0, slope, R, t, points, h)


def as_reported(scan, delta: np.ndarray, lines: tuple[np.ndarray, np.ndarray], shifts: np.ndarray):
    """``scan`` (a :class:`~optipose.scan.cloud.Scan` whose arrays are the caller's: changed in place) with its
    points moved by ``delta`` (n, 3) m along their rays and each moved one placed from its reported height,
    its ``raw`` profiles (when kept) those heights. ``lines``: the sensor's column rays
    (:func:`optipose.scan.profiles.ray_lines`); ``shifts`` (n_profiles,) m: the motion's offsets."""
    if len(scan.points):
        T = scan.T_O_S
        through_heights(
            scan.points,
            np.ascontiguousarray(delta, dtype=np.float64),
            scan.profile,
            scan.column,
            np.ascontiguousarray(shifts, dtype=np.float64),
            *lines,
            np.ascontiguousarray(T[:3, :3]),
            np.ascontiguousarray(T[:3, 3]),
            scan.raw.reshape(-1),
            scan.raw.shape[1],
        )
    return scan
