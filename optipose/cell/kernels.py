"""The cell's per-point kernel (numba): each measured point moved along its laser ray by what the cell adds
(:mod:`optipose.cell.scans` says what and why). One pass over the points, no temporaries: a scan has
10⁵–10⁶ points per sensor, far more than the voxels the registration keeps."""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["along_rays", "trilinear"]


@njit(cache=True, nogil=True, inline="always")
def _cell(u: float, n: int) -> tuple[int, float]:
    """The grid cell (0..n-2) and the fraction in it of a coordinate ``u`` in node units, clamped to the grid."""
    u = min(max(u, 0.0), float(n - 1))
    i = min(int(u), n - 2)
    return i, u - i


@njit(cache=True, nogil=True, inline="always")
def trilinear(grid: np.ndarray, lo: np.ndarray, inv_h: np.ndarray, x: float, y: float, z: float) -> float:
    """The grid's value at (x, y, z), trilinear between its nodes (``lo`` the first node, ``inv_h`` the
    inverse of the spacing per axis); a point off the grid takes its nearest face's value."""
    i, fx = _cell((x - lo[0]) * inv_h[0], grid.shape[0])
    j, fy = _cell((y - lo[1]) * inv_h[1], grid.shape[1])
    k, fz = _cell((z - lo[2]) * inv_h[2], grid.shape[2])
    c00 = grid[i, j, k] * (1 - fx) + grid[i + 1, j, k] * fx
    c10 = grid[i, j + 1, k] * (1 - fx) + grid[i + 1, j + 1, k] * fx
    c01 = grid[i, j, k + 1] * (1 - fx) + grid[i + 1, j, k + 1] * fx
    c11 = grid[i, j + 1, k + 1] * (1 - fx) + grid[i + 1, j + 1, k + 1] * fx
    return (c00 * (1 - fy) + c10 * fy) * (1 - fz) + (c01 * (1 - fy) + c11 * fy) * fz


@njit(cache=True, nogil=True)
def along_rays(
    points,
    face,
    profile,
    shifts,
    normals_P,
    R,
    t,
    apex,
    view,
    grazing,
    form,
    form_lo,
    form_h,
    plane,
    plane_centroid,
    plane_offset,
    plane_tilt,
    scale,
    part_centre,
    warp,
    warp_axis,
    warp_half,
    layer_h,
    layer_amp,
    layer_phase,
    wall,
    path_t,
    path_w,
    centre_O,
    extra,
    out,
):
    """``out`` (n, 3): ``points`` (n, 3) in O (the part at pose ``R``, ``t``; the motion undone: profile k
    taken at ``shifts[k]`` along x) each moved along its ray by ``d / cos`` + ``extra`` (m), where ``d``
    is the surface's normal offset there: the part as made (``form`` a grid, empty (0, 0, 0) for none;
    each face's plane offset and tilt, the scale, the warp, the layers) and the robot's pose error at the
    profile (``path_t``, ``path_w`` (profiles, 3), empty for none, about ``centre_O``), and ``cos`` the
    cosine between ray and normal, kept at least ``grazing`` in size. The ray comes from the laser's
    ``apex`` in O (nan: parallel rays along ``view``)."""
    n = points.shape[0]
    form_inv_h = 1.0 / form_h  # products, not quotients, in the loop: a division costs as much as the rest of it
    inv_warp, inv_layer = 1.0 / warp_half if warp != 0.0 else 0.0, 1.0 / layer_h if layer_amp != 0.0 else 0.0
    for i in range(n):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        sh = shifts[profile[i]]
        if np.isnan(apex[0]):
            rx, ry, rz = view[0], view[1], view[2]
        else:
            rx, ry, rz = px - (apex[0] - sh), py - apex[1], pz - apex[2]
            inv = 1.0 / np.sqrt(rx * rx + ry * ry + rz * rz)
            rx, ry, rz = rx * inv, ry * inv, rz * inv
        f = face[i]
        # the normal and the point in the part's frame (x_P = R^T (p - t), n_P from the mesh)
        mx, my, mz = normals_P[f, 0], normals_P[f, 1], normals_P[f, 2]
        nx = R[0, 0] * mx + R[0, 1] * my + R[0, 2] * mz
        ny = R[1, 0] * mx + R[1, 1] * my + R[1, 2] * mz
        nz = R[2, 0] * mx + R[2, 1] * my + R[2, 2] * mz
        qx, qy, qz = px - t[0], py - t[1], pz - t[2]
        x = R[0, 0] * qx + R[1, 0] * qy + R[2, 0] * qz
        y = R[0, 1] * qx + R[1, 1] * qy + R[2, 1] * qz
        z = R[0, 2] * qx + R[1, 2] * qy + R[2, 2] * qz
        d = 0.0
        if form.shape[0] > 0:
            d += trilinear(form, form_lo, form_inv_h, x, y, z)
        if plane.shape[0] > 0:
            k = plane[f]
            ax, ay, az = x - plane_centroid[k, 0], y - plane_centroid[k, 1], z - plane_centroid[k, 2]
            wx, wy, wz = plane_tilt[k, 0], plane_tilt[k, 1], plane_tilt[k, 2]
            d += plane_offset[k] + (wy * az - wz * ay) * mx + (wz * ax - wx * az) * my + (wx * ay - wy * ax) * mz
        d += (
            (x - part_centre[0]) * scale[0] * mx
            + (y - part_centre[1]) * scale[1] * my
            + (z - part_centre[2]) * scale[2] * mz
        )
        if warp != 0.0:
            s = ((x, y)[warp_axis] - part_centre[warp_axis]) * inv_warp
            d += warp * (s * s - 1.0 / 3.0) * mz
        if layer_amp != 0.0 and abs(mz) < wall:
            u = (z * inv_layer + layer_phase) % 1.0
            d += layer_amp * (abs(2.0 * u - 1.0) - 0.5)
        if path_t.shape[0] > 0:
            kk = profile[i]
            bx, by, bz = px - centre_O[0], py - centre_O[1], pz - centre_O[2]
            wx, wy, wz = path_w[kk, 0], path_w[kk, 1], path_w[kk, 2]
            ux = path_t[kk, 0] + wy * bz - wz * by
            uy = path_t[kk, 1] + wz * bx - wx * bz
            uz = path_t[kk, 2] + wx * by - wy * bx
            d += ux * nx + uy * ny + uz * nz
        c = rx * nx + ry * ny + rz * nz
        if c < 0.0:
            c = min(c, -grazing)
        else:
            c = max(c, grazing)
        s = d / c + extra[i]
        out[i, 0], out[i, 1], out[i, 2] = px + rx * s, py + ry * s, pz + rz * s
