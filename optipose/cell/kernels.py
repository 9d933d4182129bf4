"""The cell's kernels (numba): each measured point moved along its laser ray by what the cell adds
(:mod:`optipose.cell.scans` says what and why), in one pass over the points, no temporaries (a scan has
10⁵–10⁶ points per sensor, far more than the voxels the registration keeps); and the cell's counter-based
draws: the part as made's per plane (:func:`lattice_normals`, a function of the plane itself) and the
material's per ray (:func:`ray_draws`, a function of the ray), never a place in a sequence of draws whose
length or order follows the mesh's triangles or the scan's points."""

from __future__ import annotations

import numpy as np
from numba import njit

from optipose.scan.heights import place

__all__ = ["along_rays", "trilinear", "lattice_normals", "ray_draws"]


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
    column,
    x0,
    slope,
    R_S,
    t_S,
    raw,
    n_col,
    out,
):
    """``out`` (n, 3): ``points`` (n, 3) in O (the part at pose ``R``, ``t``; the motion undone: profile k
    taken at ``shifts[k]`` along x) each moved along its ray by ``d / cos`` + ``extra`` (m), where ``d``
    is the surface's normal offset there: the part as made (``form`` a grid, empty (0, 0, 0) for none;
    each face's plane offset and tilt, the scale, the warp, the layers) and the robot's pose error at the
    profile (``path_t``, ``path_w`` (profiles, 3), empty for none, about ``centre_O``), and ``cos`` the
    cosine between ray and normal, kept at least ``grazing`` in size. The ray comes from the laser's
    ``apex`` in O (nan: parallel rays along ``view``). Each moved point is then what the device reports: the
    point its height gives on its column's ray (:func:`optipose.scan.heights.place`, the sensor believed at
    ``R_S``, ``t_S``, its rays ``x0``, ``slope``; empty ``x0``: the moved point), the height written into
    ``raw`` (flat, profile × ``n_col`` + column, mm) unless it is empty."""
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
        if x0.shape[0] == 0 or s == 0.0:  # no rays given, or not moved (the scanner placed it): the point itself
            out[i, 0], out[i, 1], out[i, 2] = px + rx * s, py + ry * s, pz + rz * s
            continue
        # the moved point's height on the ray, as in optipose.scan.heights.through_heights, and its point
        dx, dy, dz = px + rx * s + sh - t_S[0], py + ry * s - t_S[1], pz + rz * s - t_S[2]
        height = -1e3 * (R_S[0, 2] * dx + R_S[1, 2] * dy + R_S[2, 2] * dz)
        if raw.shape[0] > 0:
            raw[profile[i] * n_col + column[i]] = height
        place(height, column[i], sh, x0, slope, R_S, t_S, out, i)


_TWO_TO_MINUS_53, _TWO_TO_MINUS_32 = 2.0**-53, 2.0**-32
_NODE_OFFSET = 1 << 40  # added to a lattice node's coordinates: a positive integer for any plane


# Counter-based draws: a draw is a hash of what it belongs to (a plane's place, a ray), never a position in a
# sequence, so that it does not move when the mesh has other triangles or the scan other points before it.
@njit(cache=True, nogil=True, inline="always")
def _mix(z):
    """splitmix64's finaliser: 64 bits → 64 well-mixed bits."""
    z = z + np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


@njit(cache=True, nogil=True, inline="always")
def _uniform(z):
    """A uniform in (0, 1) from the top 53 bits of ``z``."""
    return (np.float64(z >> np.uint64(11)) + 0.5) * _TWO_TO_MINUS_53


@njit(cache=True, nogil=True, inline="always")
def _gauss(z):
    """A standard normal from 64 bits (Box-Muller on its two 32-bit halves)."""
    u = (np.float64(z >> np.uint64(32)) + 0.5) * _TWO_TO_MINUS_32
    v = (np.float64(z & np.uint64(0xFFFFFFFF)) + 0.5) * _TWO_TO_MINUS_32
    return np.sqrt(-2.0 * np.log(u)) * np.cos(2.0 * np.pi * v)


@njit(cache=True, nogil=True)
def lattice_normals(coords, key, fields):
    """(p, fields): at each point of ``coords`` (p, d) (in lattice units), ``fields`` standard normal draws,
    continuous in the point. Each node of the integer lattice holds independent normals hashed from ``key``
    and its place; a point takes its cell's 2^d nodes' weighted by their multilinear weights w, divided by
    √Σw² (so that it is standard normal wherever it lies). Points two cells apart along some axis share no
    node and draw independently; a point moved by δ of a cell moves its draws by about δ."""
    p, d = coords.shape
    out = np.zeros((p, fields))
    for i in range(p):
        total = 0.0
        for corner in range(1 << d):
            w, h = 1.0, key
            for j in range(d):
                base = np.floor(coords[i, j])
                frac = coords[i, j] - base
                bit = (corner >> j) & 1
                w *= frac if bit else 1.0 - frac
                h = _mix(h ^ np.uint64(np.int64(base) + bit + _NODE_OFFSET))  # a node's place, positive
            if w == 0.0:
                continue
            total += w * w
            for f in range(fields):
                out[i, f] += w * _gauss(_mix(h ^ np.uint64(f + 1)))
        scale = 1.0 / np.sqrt(total)
        for f in range(fields):
            out[i, f] *= scale
    return out


@njit(cache=True, nogil=True)
def ray_draws(profile, column, key, bias, sigma, spurious_fraction, spurious_range, concave_fraction, shift, ghost):
    """The material's draws per point, each hashed from ``key`` (a scan's sensor) and the point's ray
    (``profile``, ``column``): ``shift`` (n,) m along the ray — ``bias``, a normal of ``sigma``, and with
    probability ``spurious_fraction`` a uniform in ± ``spurious_range`` —; ``ghost`` (n,): with probability
    ``concave_fraction`` a uniform in (0, 1) (the point is a multipath ghost if it lies near a concave edge),
    else -1."""
    for i in range(profile.shape[0]):
        h = _mix(_mix(key ^ np.uint64(profile[i])) ^ np.uint64(column[i]))
        s = bias
        if sigma != 0.0:
            s += sigma * _gauss(_mix(h ^ np.uint64(1)))
        if spurious_fraction != 0.0 and _uniform(_mix(h ^ np.uint64(2))) < spurious_fraction:
            s += (2.0 * _uniform(_mix(h ^ np.uint64(3))) - 1.0) * spurious_range
        shift[i] = s
        ghost[i] = -1.0
        if concave_fraction != 0.0 and _uniform(_mix(h ^ np.uint64(4))) < concave_fraction:
            ghost[i] = _uniform(_mix(h ^ np.uint64(5)))
