"""Compiled kernels of registration (numba, ``nogil``): voxel centroids, closest points on a planar-faced
mesh and the point-to-plane normal equations, each one pass over the cloud instead of a dozen numpy
temporaries. The arithmetic is documented in :mod:`optipose.registration.fast` and :mod:`optipose.registration.reference`;
compiled once per machine and cached next to this file (``cache=True``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

_WALK = 4  # faces a point that left its face's guess walks across before the grid is searched


@njit(cache=True, nogil=True)
def voxel_centroids(points, size, origin):
    """Centroids (m, 3) of the points (n, 3) in each cube of side ``size`` of the grid whose corner is at
    ``origin`` (3,), in the voxels' sorted key order.

    Same sums in the same order as ``np.unique`` + ``np.bincount`` (each voxel adds its points in input
    order), so the result is bit-identical. A scan runs along its profiles, so consecutive points mostly
    share a voxel: only the first point of each run is looked up, in a hash table sized by the runs.
    """
    n = points.shape[0]
    if n == 0:
        return np.empty((0, 3), np.float64)
    lo = np.empty(3, np.int64)
    hi = np.empty(3, np.int64)
    low = np.empty(3, np.float64)
    high = np.empty(3, np.float64)
    for j in range(3):
        low[j] = np.inf
        high[j] = -np.inf
    for i in range(n):
        for j in range(3):
            low[j] = min(low[j], points[i, j])
            high[j] = max(high[j], points[i, j])
    for j in range(3):  # floor((x - origin) / size) never decreases with x: the extreme cells are the extremes'
        lo[j] = np.int64(np.floor((low[j] - origin[j]) / size))
        hi[j] = np.int64(np.floor((high[j] - origin[j]) / size))
    d1 = hi[1] - lo[1] + 1
    d2 = hi[2] - lo[2] + 1
    key = np.empty(n, np.int64)
    runs = 0
    for i in range(n):
        c0 = np.int64(np.floor((points[i, 0] - origin[0]) / size)) - lo[0]
        c1 = np.int64(np.floor((points[i, 1] - origin[1]) / size)) - lo[1]
        c2 = np.int64(np.floor((points[i, 2] - origin[2]) / size)) - lo[2]
        key[i] = (c0 * d1 + c1) * d2 + c2
        if i == 0 or key[i] != key[i - 1]:
            runs += 1
    cap = 16
    while cap < 2 * runs:
        cap *= 2
    table = np.full(cap, -1, np.int64)  # slot -> voxel
    keys = np.empty(runs, np.int64)  # voxel -> key
    sums = np.zeros((runs, 3), np.float64)
    counts = np.zeros(runs, np.int64)
    m = 0
    v = -1
    s0 = s1 = s2 = 0.0  # the current run's voxel sums, in registers: the same additions in the same order
    c = 0
    for i in range(n):
        if i == 0 or key[i] != key[i - 1]:
            if v >= 0:
                sums[v, 0], sums[v, 1], sums[v, 2] = s0, s1, s2
                counts[v] = c
            h = (key[i] * np.int64(-7_046_029_254_386_353_131)) >> 20 & (cap - 1)
            while True:
                v = table[h]
                if v < 0:
                    v = m
                    table[h] = v
                    keys[v] = key[i]
                    m += 1
                    break
                if keys[v] == key[i]:
                    break
                h = (h + 1) & (cap - 1)
            s0, s1, s2, c = sums[v, 0], sums[v, 1], sums[v, 2], counts[v]
        s0 += points[i, 0]
        s1 += points[i, 1]
        s2 += points[i, 2]
        c += 1
    sums[v, 0], sums[v, 1], sums[v, 2] = s0, s1, s2
    counts[v] = c
    order = np.argsort(keys[:m])
    out = np.empty((m, 3), np.float64)
    for k in range(m):
        v = order[k]
        for j in range(3):
            out[k, j] = sums[v, j] / counts[v]
    return out


@njit(cache=True, nogil=True)
def transform(points, T, out=None):
    """``points @ T[:3, :3].T + T[:3, 3]`` (n, 3), into ``out`` when given."""
    n = points.shape[0]
    if out is None:
        out = np.empty((n, 3), np.float64)
    r00, r01, r02, t0 = T[0, 0], T[0, 1], T[0, 2], T[0, 3]  # in registers: out may not alias T, the compiler can't know
    r10, r11, r12, t1 = T[1, 0], T[1, 1], T[1, 2], T[1, 3]
    r20, r21, r22, t2 = T[2, 0], T[2, 1], T[2, 2], T[2, 3]
    for i in range(n):
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        out[i, 0] = r00 * x + r01 * y + r02 * z + t0
        out[i, 1] = r10 * x + r11 * y + r12 * z + t1
        out[i, 2] = r20 * x + r21 * y + r22 * z + t2
    return out


@njit(cache=True, nogil=True, inline="always")
def _closest_on_triangle(px, py, pz, a, b, c):
    """Closest point of triangle (a, b, c) to p (Ericson, Real-Time Collision Detection §5.1.5)."""
    abx, aby, abz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    acx, acy, acz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    apx, apy, apz = px - a[0], py - a[1], pz - a[2]
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return a[0], a[1], a[2]
    bpx, bpy, bpz = px - b[0], py - b[1], pz - b[2]
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return b[0], b[1], b[2]
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return a[0] + v * abx, a[1] + v * aby, a[2] + v * abz
    cpx, cpy, cpz = px - c[0], py - c[1], pz - c[2]
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return c[0], c[1], c[2]
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return a[0] + w * acx, a[1] + w * acy, a[2] + w * acz
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return b[0] + w * (c[0] - b[0]), b[1] + w * (c[1] - b[1]), b[2] + w * (c[2] - b[2])
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return a[0] + abx * v + acx * w, a[1] + aby * v + acy * w, a[2] + abz * v + acz * w


@njit(cache=True, nogil=True, inline="always")
def _project(p, i, f, planes, plane_c, q):
    """Project p[i] on face f's plane into q[i]; True when it lies inside the face by more than 2|d|."""
    h0 = planes[f, 0, 0] * p[i, 0] + planes[f, 0, 1] * p[i, 1] + planes[f, 0, 2] * p[i, 2] - plane_c[f, 0]
    inset = np.inf
    for k in range(1, 4):
        hk = planes[f, k, 0] * p[i, 0] + planes[f, k, 1] * p[i, 1] + planes[f, k, 2] * p[i, 2] - plane_c[f, k]
        inset = min(inset, hk)
    for j in range(3):
        q[i, j] = p[i, j] - h0 * planes[f, 0, j]
    return inset > 2.0 * abs(h0), inset >= 0.0


@njit(cache=True, nogil=True)
def face_grid(tri, normals, offsets, lo, hi, origin, cell, shape, margin):
    """Faces listed per cell of a grid (origin (3,), cube side ``cell``, ``shape`` (3,) cells): every face
    within ``margin`` of the cell (bounding box and plane within margin of the cell's box, a superset).
    Returns CSR start (cells + 1,), the face list and each listed face's ``bound`` (m): no point of the
    cell is nearer the face than that (the gap between the cell's box and the face's bounding box
    ``lo``/``hi`` (f, 3), or its plane's distance from the cell's centre less the half-diagonal). Each
    cell's faces are in ascending order of bound (ties by face id), so a search can stop at the first face
    bound farther than its best."""
    n_cells = shape[0] * shape[1] * shape[2]
    start = np.zeros(n_cells + 1, np.int64)
    _grid_pass(tri, normals, offsets, origin, cell, shape, margin, start[1:], np.empty(0, np.int64))
    for c in range(n_cells):
        start[c + 1] += start[c]
    faces = np.empty(start[n_cells], np.int64)
    _grid_pass(tri, normals, offsets, origin, cell, shape, margin, start[:-1].copy(), faces)
    bound = np.empty(faces.shape[0], np.float64)
    half_diag = 0.5 * np.sqrt(3.0) * cell
    for c in range(n_cells):
        if start[c + 1] == start[c]:
            continue
        i, rest = c // (shape[1] * shape[2]), c % (shape[1] * shape[2])
        j, k = rest // shape[2], rest % shape[2]
        box_lo = (origin[0] + i * cell, origin[1] + j * cell, origin[2] + k * cell)
        for e in range(start[c], start[c + 1]):
            g = faces[e]
            gap2 = 0.0
            for a in range(3):
                gap = max(lo[g, a] - (box_lo[a] + cell), box_lo[a] - hi[g, a], 0.0)
                gap2 += gap * gap
            centre = normals[g, 0] * (box_lo[0] + 0.5 * cell) + normals[g, 1] * (box_lo[1] + 0.5 * cell) + normals[g, 2] * (box_lo[2] + 0.5 * cell)
            bound[e] = max(max(np.sqrt(gap2), abs(centre - offsets[g]) - half_diag) * (1.0 - 1e-9) - 1e-15, 0.0)  # a hair under, for rounding
        order = np.argsort(bound[start[c] : start[c + 1]], kind="mergesort")
        faces[start[c] : start[c + 1]] = faces[start[c] : start[c + 1]][order]
        bound[start[c] : start[c + 1]] = bound[start[c] : start[c + 1]][order]
    return start, faces, bound


@njit(cache=True, nogil=True)
def _grid_pass(tri, normals, offsets, origin, cell, shape, margin, slot, faces):
    """Count faces per cell into ``slot`` (faces empty), or write them at ``slot`` (advanced)."""
    write = faces.shape[0] > 0
    half_diag = 0.5 * np.sqrt(3.0) * cell
    lo_c = np.empty(3, np.int64)
    hi_c = np.empty(3, np.int64)
    for f in range(tri.shape[0]):
        for j in range(3):
            lo_v = min(tri[f, 0, j], tri[f, 1, j], tri[f, 2, j]) - margin
            hi_v = max(tri[f, 0, j], tri[f, 1, j], tri[f, 2, j]) + margin
            lo_c[j] = max(0, np.int64(np.floor((lo_v - origin[j]) / cell)))
            hi_c[j] = min(shape[j] - 1, np.int64(np.floor((hi_v - origin[j]) / cell)))
        for i in range(lo_c[0], hi_c[0] + 1):
            for j in range(lo_c[1], hi_c[1] + 1):
                for k in range(lo_c[2], hi_c[2] + 1):
                    cx = origin[0] + (i + 0.5) * cell
                    cy = origin[1] + (j + 0.5) * cell
                    cz = origin[2] + (k + 0.5) * cell
                    if abs(normals[f, 0] * cx + normals[f, 1] * cy + normals[f, 2] * cz - offsets[f]) > half_diag + margin:
                        continue
                    c = (i * shape[1] + j) * shape[2] + k
                    if write:
                        faces[slot[c]] = f
                    slot[c] += 1


@njit(cache=True, nogil=True, inline="always")
def _inset2(p, i, f, planes, plane_c):
    """The square of how far inside face f's edges p[i] projects, or -1 where it projects outside."""
    inset = np.inf
    for k in range(1, 4):
        inset = min(inset, planes[f, k, 0] * p[i, 0] + planes[f, k, 1] * p[i, 1] + planes[f, k, 2] * p[i, 2] - plane_c[f, k])
    return inset * inset if inset > 0.0 else -1.0


@njit(cache=True, nogil=True, inline="always")
def _walk(p, i, f, planes, plane_c, adjacent, q):
    """From face f toward the face p[i] projects into: across the edge it lies farthest outside of, to the
    face on the other side (``adjacent`` (f, 3): across edge k, -1 for none), at most ``_WALK`` faces. Returns
    the first face p[i] lies inside of by more than 2|d| (its projection in q[i]), or -1."""
    g = f
    for _ in range(_WALK):
        worst, k_out = np.inf, -1
        for k in range(1, 4):
            hk = planes[g, k, 0] * p[i, 0] + planes[g, k, 1] * p[i, 1] + planes[g, k, 2] * p[i, 2] - plane_c[g, k]
            if hk < worst:
                worst, k_out = hk, k - 1
        if worst >= 0.0:  # it projects inside g, only too near an edge for its distance: no face is surer
            return -1
        g = adjacent[g, k_out]
        if g < 0:
            return -1
        if _project(p, i, g, planes, plane_c, q)[0]:
            return g
    return -1


@njit(cache=True, nogil=True)
def nearest_into(p, ids, q, nrm, open_, planes, plane_c, tri, adjacent, plane_id, lo, hi, origin, cell, shape, margin, start, faces,
                 bound):  # fmt: skip
    """Closest points of p (n, 3) on a mesh into q (n, 3), their face normals into ``nrm`` (n, 3); ``ids``
    (n,) holds a guess of each point's face (-1: none) and gets the answer. Returns how many points are
    ``open`` (n,) (set True for them, left as they were for the rest).

    A point inside its guessed face by more than 2|d| keeps it (as ``follow``); one that left it walks
    across the edges it left by (``adjacent``, :func:`_walk`) and takes the first face it lies inside of
    by more than 2|d| — the test that keeps a guess. Otherwise the faces
    listed for its grid cell (:func:`face_grid`) are searched exactly: they hold every face within
    ``margin`` of the cell, so the answer is certain when the closest point found is within ``margin``
    (faces whose bounding box (lo, hi) is farther than the best so far are skipped; the guessed face
    starts the search, which prunes more). A point inside the face found by more than 2|d| gets its
    projection on the face's plane, like a followed point; a point closest to an edge or a corner gets
    the closest point of that face, in float64 (where faces tie exactly, at their common edge, the lowest
    face id takes the point, whatever the guess: the point is the same, the normal the face's). Points left
    to the global search (outside the grid or farther than ``margin`` from the surface) are marked in
    ``open``. The tests that keep a guess or a walked-to face trust a point to lie nearer its face than any
    face not adjacent to it (true near a part's surface; not for a point past the middle of a thin sheet,
    or in a slot narrower than twice its distance): the search's answer otherwise.
    """
    n = p.shape[0]
    m2 = margin * margin
    n_open = 0
    for i in range(n):
        f = ids[i]
        if f >= 0:
            g = f if _project(p, i, f, planes, plane_c, q)[0] else _walk(p, i, f, planes, plane_c, adjacent, q)
            if g >= 0:
                ids[i] = g
                nrm[i, 0], nrm[i, 1], nrm[i, 2] = planes[g, 0, 0], planes[g, 0, 1], planes[g, 0, 2]
                continue
        c = 0
        outside = False
        for j in range(3):
            cj = np.int64(np.floor((p[i, j] - origin[j]) / cell))
            if cj < 0 or cj >= shape[j]:
                outside = True
            c = c * shape[j] + cj
        if outside:
            open_[i] = True
            n_open += 1
            continue
        px, py, pz = p[i, 0], p[i, 1], p[i, 2]
        best = m2
        g_best = -1
        bx, by, bz = 0.0, 0.0, 0.0
        if f < 0 and i > 0:  # no guess: the last point's face (a neighbour in a voxel-ordered cloud) seeds the search
            f = ids[i - 1]
        inset2 = -1.0  # squared: how far inside the best face p projects (-1: not inside)
        if f >= 0:  # a seed only prunes: every listed face is still searched, ties go to the lowest id
            gx, gy, gz = _closest_on_triangle(px, py, pz, tri[f, 0], tri[f, 1], tri[f, 2])
            d2 = (px - gx) ** 2 + (py - gy) ** 2 + (pz - gz) ** 2
            if d2 <= best:
                best, g_best, bx, by, bz = d2, f, gx, gy, gz
                inset2 = _inset2(p, i, f, planes, plane_c)
        for k in range(start[c], start[c + 1]):
            if bound[k] * bound[k] > best:  # this face and every one after it are farther than the best
                break
            g = faces[k]
            if g == g_best or (planes[g, 0, 0] == 0.0 and planes[g, 0, 1] == 0.0 and planes[g, 0, 2] == 0.0):
                continue  # the seed again; or a zero-area face (no normal), on its neighbours' edges: they answer for it
            if plane_id[g] == plane_id[g_best] and inset2 > best * 1e-6 + 1e-18:
                continue  # in the plane of the best face, which p projects well inside of: farther by at least that inset
            box = 0.0
            for j in range(3):
                gap = max(lo[g, j] - p[i, j], p[i, j] - hi[g, j], 0.0)
                box += gap * gap
            if box > best:
                continue
            h = planes[g, 0, 0] * px + planes[g, 0, 1] * py + planes[g, 0, 2] * pz - plane_c[g, 0]
            if h * h > best * (1.0 + 1e-6) + 1e-22:  # its plane alone is farther (with room for rounding: no tie is lost)
                continue
            gx, gy, gz = _closest_on_triangle(px, py, pz, tri[g, 0], tri[g, 1], tri[g, 2])
            d2 = (px - gx) ** 2 + (py - gy) ** 2 + (pz - gz) ** 2
            if d2 < best or (d2 == best and (g_best < 0 or g < g_best)):
                best, g_best, bx, by, bz = d2, g, gx, gy, gz
                inset2 = _inset2(p, i, g, planes, plane_c)
        if g_best < 0:
            open_[i] = True
            n_open += 1
            continue
        ids[i] = g_best
        nrm[i, 0], nrm[i, 1], nrm[i, 2] = planes[g_best, 0, 0], planes[g_best, 0, 1], planes[g_best, 0, 2]
        if not _project(p, i, g_best, planes, plane_c, q)[0]:  # on or near an edge: the face's closest point
            q[i, 0], q[i, 1], q[i, 2] = bx, by, bz
    return n_open


@njit(cache=True, nogil=True)
def normal_equations(p, q, n, max_d2):
    """Point-to-plane normal equations over the pairs within ``sqrt(max_d2)``, about their centroid c.

    Returns inlier (n,) bool, c (3,), ``AᵀA`` (6, 6), ``Aᵀb`` (6,) and Σ d² over inliers, with rows
    ``Aᵢ = [((pᵢ − c) × nᵢ)ᵀ, nᵢᵀ]``, ``bᵢ = (qᵢ − pᵢ)·nᵢ`` — so ``AᵀA`` is also the information matrix.
    """
    m = p.shape[0]
    inlier = np.empty(m, np.bool_)
    c = np.zeros(3)
    count = 0
    sum_d2 = 0.0
    for i in range(m):
        d2 = (p[i, 0] - q[i, 0]) ** 2 + (p[i, 1] - q[i, 1]) ** 2 + (p[i, 2] - q[i, 2]) ** 2
        inlier[i] = d2 <= max_d2
        if inlier[i]:
            count += 1
            sum_d2 += d2
            for j in range(3):
                c[j] += p[i, j]
    AtA = np.zeros((6, 6))
    Atb = np.zeros(6)
    if count == 0:
        return inlier, c, AtA, Atb, sum_d2
    c /= count
    c0, c1, c2 = c[0], c[1], c[2]
    # every sum a register of its own, each summed over the points in order (the same sums as a loop
    # over the (6, 6) array, bit for bit, without its loads and stores per point)
    a00 = a01 = a02 = a03 = a04 = a05 = a11 = a12 = a13 = a14 = a15 = a22 = a23 = a24 = a25 = 0.0
    a33 = a34 = a35 = a44 = a45 = a55 = 0.0
    b0 = b1 = b2 = b3 = b4 = b5 = 0.0
    for i in range(m):
        if not inlier[i]:
            continue
        x, y, z = p[i, 0] - c0, p[i, 1] - c1, p[i, 2] - c2
        nx, ny, nz = n[i, 0], n[i, 1], n[i, 2]
        j0, j1, j2 = y * nz - z * ny, z * nx - x * nz, x * ny - y * nx
        b = (q[i, 0] - p[i, 0]) * nx + (q[i, 1] - p[i, 1]) * ny + (q[i, 2] - p[i, 2]) * nz
        b0 += j0 * b
        b1 += j1 * b
        b2 += j2 * b
        b3 += nx * b
        b4 += ny * b
        b5 += nz * b
        a00 += j0 * j0
        a01 += j0 * j1
        a02 += j0 * j2
        a03 += j0 * nx
        a04 += j0 * ny
        a05 += j0 * nz
        a11 += j1 * j1
        a12 += j1 * j2
        a13 += j1 * nx
        a14 += j1 * ny
        a15 += j1 * nz
        a22 += j2 * j2
        a23 += j2 * nx
        a24 += j2 * ny
        a25 += j2 * nz
        a33 += nx * nx
        a34 += nx * ny
        a35 += nx * nz
        a44 += ny * ny
        a45 += ny * nz
        a55 += nz * nz
    Atb[0], Atb[1], Atb[2], Atb[3], Atb[4], Atb[5] = b0, b1, b2, b3, b4, b5
    upper = (a00, a01, a02, a03, a04, a05, a11, a12, a13, a14, a15, a22, a23, a24, a25, a33, a34, a35, a44, a45, a55)
    k = 0
    for r in range(6):
        for s in range(r, 6):
            AtA[r, s] = upper[k]
            AtA[s, r] = upper[k]
            k += 1
    return inlier, c, AtA, Atb, sum_d2


@njit(cache=True, nogil=True)
def point_grid(points, origin, cell, shape):
    """The points (n, 3) listed per cell of a grid (origin (3,), cube side ``cell``, ``shape`` (3,) cells,
    covering every point): CSR ``start`` (cells + 1,) and ``order`` (n,), point indices ascending in each cell."""
    n = points.shape[0]
    n_cells = shape[0] * shape[1] * shape[2]
    key = np.empty(n, np.int64)
    start = np.zeros(n_cells + 1, np.int64)
    for i in range(n):
        c = 0
        for j in range(3):
            c = c * shape[j] + min(max(np.int64(np.floor((points[i, j] - origin[j]) / cell)), 0), shape[j] - 1)
        key[i] = c
        start[c + 1] += 1
    for c in range(n_cells):
        start[c + 1] += start[c]
    slot = start[:-1].copy()
    order = np.empty(n, np.int64)
    for i in range(n):
        order[slot[key[i]]] = i
        slot[key[i]] += 1
    return start, order


@njit(cache=True, nogil=True)
def grid_nearest(p, hint, points, origin, cell, shape, start):
    """The nearest of the grid's points to each of p (n, 3), searched in the 27 cells around p's cell of
    :func:`point_grid` (``points`` stored in the grid's cell order, ``start`` its CSR): exact when the
    nearest found is closer than ``cell`` (any point outside those cells is at least a cell away).
    ``hint`` (n,): each point's nearest at the previous ICP step (-1: none); the distance to it bounds the
    search, so a cell farther than that is not opened. Returns ids (n,) int64 and ``open`` (n,) bool: points
    with no grid point that close (or outside the grid), left to a global search."""
    n = p.shape[0]
    ids = np.full(n, -1, np.int64)
    open_ = np.zeros(n, np.bool_)
    limit = cell * cell
    s0, s1, s2 = shape[0], shape[1], shape[2]
    for i in range(n):
        px, py, pz = p[i, 0], p[i, 1], p[i, 2]
        fx, fy, fz = (px - origin[0]) / cell, (py - origin[1]) / cell, (pz - origin[2]) / cell
        c0, c1, c2 = np.int64(np.floor(fx)), np.int64(np.floor(fy)), np.int64(np.floor(fz))
        if c0 < 0 or c0 >= s0 or c1 < 0 or c1 >= s1 or c2 < 0 or c2 >= s2:
            open_[i] = True
            continue
        best, g = limit, -1
        if hint[i] >= 0:
            k = hint[i]
            d2 = (px - points[k, 0]) ** 2 + (py - points[k, 1]) ** 2 + (pz - points[k, 2]) ** 2
            if d2 < best:
                best, g = d2, k
        for a in range(max(c0 - 1, 0), min(c0 + 2, s0)):
            gx = (max(a - fx, 0.0, fx - a - 1.0) * cell) ** 2  # p's distance to the cell's slab along x, squared
            if gx >= best:
                continue
            for b in range(max(c1 - 1, 0), min(c1 + 2, s1)):
                gy = gx + (max(b - fy, 0.0, fy - b - 1.0) * cell) ** 2
                if gy >= best:
                    continue
                row = (a * s1 + b) * s2
                for d in range(max(c2 - 1, 0), min(c2 + 2, s2)):
                    if gy + (max(d - fz, 0.0, fz - d - 1.0) * cell) ** 2 >= best:
                        continue
                    for k in range(start[row + d], start[row + d + 1]):
                        d2 = (px - points[k, 0]) ** 2 + (py - points[k, 1]) ** 2 + (pz - points[k, 2]) ** 2
                        if d2 < best or (d2 == best and g >= 0 and k < g):
                            best, g = d2, k
        if g < 0:
            open_[i] = True
        else:
            ids[i] = g
    return ids, open_


@njit(cache=True, nogil=True)
def sample_neighbours(points, k, reach, origin, cell, shape, start):
    """Each of ``points`` (n, 3) (in the cell order of :func:`point_grid`, ``start`` its CSR) with its ``k``
    nearest other points (n, k) int32, nearest first (ties: lowest index; -1 pads a short list), and a
    radius ``rho`` (n,): every point closer than ``rho`` is in the list (the k-th distance, or ``reach``
    cells: the (2 reach + 1)³ cells searched hold every point that close)."""
    n = points.shape[0]
    near = np.full((n, k), -1, np.int32)
    rho = np.empty(n, np.float64)
    dist = np.empty(k, np.float64)
    for i in range(n):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        c0 = np.int64(np.floor((px - origin[0]) / cell))
        c1 = np.int64(np.floor((py - origin[1]) / cell))
        c2 = np.int64(np.floor((pz - origin[2]) / cell))
        count = 0
        for a in range(max(c0 - reach, 0), min(c0 + reach + 1, shape[0])):
            for b in range(max(c1 - reach, 0), min(c1 + reach + 1, shape[1])):
                row = (a * shape[1] + b) * shape[2]
                for d in range(max(c2 - reach, 0), min(c2 + reach + 1, shape[2])):
                    for j in range(start[row + d], start[row + d + 1]):
                        if j == i:
                            continue
                        d2 = (px - points[j, 0]) ** 2 + (py - points[j, 1]) ** 2 + (pz - points[j, 2]) ** 2
                        if count == k and (d2 > dist[k - 1] or (d2 == dist[k - 1] and j > near[i, k - 1])):
                            continue
                        s = count if count < k else k - 1  # insert, keeping (distance, index) ascending
                        while s > 0 and (dist[s - 1] > d2 or (dist[s - 1] == d2 and near[i, s - 1] > j)):
                            dist[s] = dist[s - 1]
                            near[i, s] = near[i, s - 1]
                            s -= 1
                        dist[s] = d2
                        near[i, s] = j
                        if count < k:
                            count += 1
        rho[i] = min(np.sqrt(dist[k - 1]), reach * cell) if count == k else reach * cell
    return near, rho


WALK = 4  # hops from a point's last nearest reference point toward its new one before the grid is searched
SLACK = 1e-13  # m off every margin: far above the rounding of coordinates within metres of O, so a point that close to a bisector is searched again
SETTLE = 1.0 / 64  # cells: a point that moved less than this since its last search is settling: its exact margin is worth the work


@njit(cache=True, nogil=True, inline="always")
def _grid_two(px, py, pz, h, reach, two, points, origin, cell, shape, start):
    """The nearest grid point to (px, py, pz) within ``reach`` cells (searched in the (2 reach + 1)³ cells
    around its cell, starting from grid point ``h``, -1: none) and, when ``two``, the second-nearest
    distance (capped at ``reach`` cells: any point outside those cells is farther). Returns (best d²,
    second d², grid index of the nearest, -1 when none is within reach). Ties: lowest point index."""
    limit = (reach * cell) ** 2
    fx, fy, fz = (px - origin[0]) / cell, (py - origin[1]) / cell, (pz - origin[2]) / cell
    c0, c1, c2 = np.int64(np.floor(fx)), np.int64(np.floor(fy)), np.int64(np.floor(fz))
    best, second, g = limit, limit, -1
    if c0 < 0 or c0 >= shape[0] or c1 < 0 or c1 >= shape[1] or c2 < 0 or c2 >= shape[2]:
        return best, second, g
    if h >= 0:
        d2 = (px - points[h, 0]) ** 2 + (py - points[h, 1]) ** 2 + (pz - points[h, 2]) ** 2
        if d2 < best:
            best, g = d2, h
    for a in range(max(c0 - reach, 0), min(c0 + reach + 1, shape[0])):
        gx = (max(a - fx, 0.0, fx - a - 1.0) * cell) ** 2
        if gx >= (second if two else best):
            continue
        for b in range(max(c1 - reach, 0), min(c1 + reach + 1, shape[1])):
            gy = gx + (max(b - fy, 0.0, fy - b - 1.0) * cell) ** 2
            if gy >= (second if two else best):
                continue
            row = (a * shape[1] + b) * shape[2]
            for d in range(max(c2 - reach, 0), min(c2 + reach + 1, shape[2])):
                if gy + (max(d - fz, 0.0, fz - d - 1.0) * cell) ** 2 >= (second if two else best):
                    continue
                for k in range(start[row + d], start[row + d + 1]):
                    if k == h:
                        continue
                    d2 = (px - points[k, 0]) ** 2 + (py - points[k, 1]) ** 2 + (pz - points[k, 2]) ** 2
                    if d2 < best or (d2 == best and g >= 0 and k < g):
                        second = min(second, best)
                        best, g = d2, k
                    elif d2 < second:
                        second = d2
    return best, second, g


@njit(cache=True, nogil=True)
def tracked_nearest(p, ids, anchor, margin, q, n, ref_points, ref_normals, neighbours, rho, reach, origin, cell, shape,
                    start):  # fmt: skip
    """The nearest reference point to each point of an ICP's cloud p (n, 3), as :func:`grid_nearest` finds
    it, searching again only the points that may have changed theirs since they were last searched.

    Per point, kept between calls (updated in place): ``ids`` its nearest (-1: none yet, or left to the
    global search), ``anchor`` (n, 3) where it was when searched, ``margin`` how far it may move from there
    and keep its nearest (0: unknown). A point closer to its anchor than its margin is not searched.

    Any other point walks from its last nearest c: among c and c's ``neighbours`` (ref, K) (the reference
    points nearest c; the list holds every one closer than ``rho[c]``, :func:`sample_neighbours`), every
    reference point not listed is at least rho(c) − |p − c| from p, so the nearest g found is certain when
    it is closer than that; if not, the walk moves on to g while g is nearer than c (:data:`WALK` hops).
    The margin of a certain answer is its distance to the nearest bisector plane between g and another
    point s, (|p − s|² − |p − g|²) / (2 |s − g|), over the listed points and (bound − |p − g|) / 2 for the
    rest: a move shorter than that keeps g the nearest. A point the walk cannot settle is searched on the
    grid from the walk's nearest (within ceil(|p − c| / cell) cells, then ``reach`` cells), with the margin
    (half the gap between the nearest and second-nearest distances) only when it moved less than
    :data:`SETTLE` cells or is searched for the first time. The reference point and normal of each point
    searched are written to ``q`` and ``n``. Ties go to the lowest reference index (a tie leaves no margin).
    Returns ``open`` (n,) bool: points with no reference point within ``reach`` cells, for a global search
    (margin zero: searched again next call)."""
    m = p.shape[0]
    open_ = np.zeros(m, np.bool_)
    slow2 = (SETTLE * cell) ** 2
    K = neighbours.shape[1]
    for i in range(m):
        px, py, pz = p[i, 0], p[i, 1], p[i, 2]
        f = ids[i]
        settle = True  # no last nearest: the first search, worth its margin
        if f >= 0:
            moved = (px - anchor[i, 0]) ** 2 + (py - anchor[i, 1]) ** 2 + (pz - anchor[i, 2]) ** 2
            if moved < margin[i] * margin[i]:
                continue
            settle = moved < slow2
        margin[i] = 0.0
        anchor[i, 0], anchor[i, 1], anchor[i, 2] = px, py, pz
        found = -1
        c = f  # the walk: among c and its neighbours, then from the nearest of them while it comes closer
        for _ in range(WALK if f >= 0 else 0):
            dc = (px - ref_points[c, 0]) ** 2 + (py - ref_points[c, 1]) ** 2 + (pz - ref_points[c, 2]) ** 2
            best, second, g = dc, np.inf, c
            for j in range(K):
                k = neighbours[c, j]
                if k < 0:
                    break
                d2 = (px - ref_points[k, 0]) ** 2 + (py - ref_points[k, 1]) ** 2 + (pz - ref_points[k, 2]) ** 2
                if d2 < best or (d2 == best and k < g):
                    second = min(second, best)
                    best, g = d2, k
                elif d2 < second:
                    second = d2
            bound = rho[c] - np.sqrt(dc)
            if np.sqrt(best) < bound * (1.0 - 1e-12):
                found = g
                # how far p may move and keep g: half the gap between the nearest and the second-nearest
                # (or the unlisted points' bound); for a settling point, worth the pass, its distance to the
                # nearest bisector plane between g and a candidate s, (d_s² − d_g²) / (2 |s − g|), and
                # (bound − d_g) / 2 for any point not listed (never less than the half gap)
                m_ = 0.5 * (min(np.sqrt(second), bound) - np.sqrt(best))
                if settle:
                    m_ = 0.5 * (bound - np.sqrt(best))
                    for j in range(-1, K):
                        k = c if j < 0 else neighbours[c, j]
                        if k < 0:
                            break
                        if k == g:
                            continue
                        d2 = (px - ref_points[k, 0]) ** 2 + (py - ref_points[k, 1]) ** 2 + (pz - ref_points[k, 2]) ** 2
                        sg = np.sqrt((ref_points[k, 0] - ref_points[g, 0]) ** 2 + (ref_points[k, 1] - ref_points[g, 1]) ** 2
                                     + (ref_points[k, 2] - ref_points[g, 2]) ** 2)  # fmt: skip
                        m_ = min(m_, (d2 - best) / (2.0 * sg)) if sg > 0.0 else 0.0
                margin[i] = max(m_ * (1.0 - 1e-9) - SLACK, 0.0)
                break
            if g == c:
                break
            c = g
        if found < 0:  # on the grid, from the walk's nearest: within ceil(|p - c| / cell) cells of p
            h, r = -1, 1
            if f >= 0:
                h = c
                dc = np.sqrt((px - ref_points[c, 0]) ** 2 + (py - ref_points[c, 1]) ** 2 + (pz - ref_points[c, 2]) ** 2)
                r = min(reach, max(1, np.int64(np.ceil(dc / cell))))
            best, second, g = _grid_two(px, py, pz, h, r, settle, ref_points, origin, cell, shape, start)
            if g < 0 and reach > r:
                best, second, g = _grid_two(px, py, pz, h, reach, settle, ref_points, origin, cell, shape, start)
            if g < 0:
                ids[i] = -1
                open_[i] = True
                continue
            found = g
            if settle:
                margin[i] = max(0.5 * (np.sqrt(second) - np.sqrt(best)) * (1.0 - 1e-9) - SLACK, 0.0)
        ids[i] = found
        for j in range(3):
            q[i, j] = ref_points[found, j]
            n[i, j] = ref_normals[found, j]
    return open_


@njit(cache=True, nogil=True, fastmath=True)
def cross_covariance(p, q, max_d2):
    """The sums of one point-to-point (Kabsch) step over the pairs within ``sqrt(max_d2)``, in one pass:
    their count, Σ d², the centroids of p and q (3,) and ``Σ (pᵢ − p̄)(qᵢ − q̄)ᵀ`` (3, 3) (summed about the
    first point, which is near the rest, then centred; every sum a register of its own)."""
    m = p.shape[0]
    count = 0
    sum_d2 = 0.0
    sp = np.zeros(3)
    sq = np.zeros(3)
    H = np.zeros((3, 3))
    if m == 0:
        return count, sum_d2, sp, sq, H
    o0, o1, o2 = p[0, 0], p[0, 1], p[0, 2]
    a0s = a1s = a2s = b0s = b1s = b2s = 0.0
    h00 = h01 = h02 = h10 = h11 = h12 = h20 = h21 = h22 = 0.0
    for i in range(m):
        d2 = (p[i, 0] - q[i, 0]) ** 2 + (p[i, 1] - q[i, 1]) ** 2 + (p[i, 2] - q[i, 2]) ** 2  # as normal_equations does
        if d2 <= max_d2:
            a0, a1, a2 = p[i, 0] - o0, p[i, 1] - o1, p[i, 2] - o2
            b0, b1, b2 = q[i, 0] - o0, q[i, 1] - o1, q[i, 2] - o2
            count += 1
            sum_d2 += d2
            a0s += a0
            a1s += a1
            a2s += a2
            b0s += b0
            b1s += b1
            b2s += b2
            h00 += a0 * b0
            h01 += a0 * b1
            h02 += a0 * b2
            h10 += a1 * b0
            h11 += a1 * b1
            h12 += a1 * b2
            h20 += a2 * b0
            h21 += a2 * b1
            h22 += a2 * b2
    if count == 0:
        return count, sum_d2, sp, sq, H
    sp[0], sp[1], sp[2] = a0s / count, a1s / count, a2s / count
    sq[0], sq[1], sq[2] = b0s / count, b1s / count, b2s / count
    H[0, 0], H[0, 1], H[0, 2] = h00, h01, h02
    H[1, 0], H[1, 1], H[1, 2] = h10, h11, h12
    H[2, 0], H[2, 1], H[2, 2] = h20, h21, h22
    for r in range(3):
        for c in range(3):
            H[r, c] -= count * sp[r] * sq[c]
    for j in range(3):
        sp[j] += p[0, j]
        sq[j] += p[0, j]
    return count, sum_d2, sp, sq, H


@njit(cache=True, nogil=True)
def kabsch(H, mp, mq):
    """The rigid transform (4, 4) minimising Σ |R pᵢ + t − qᵢ|², from the cross-covariance
    ``H = Σ (pᵢ − p̄)(qᵢ − q̄)ᵀ`` (3, 3) and the centroids p̄, q̄ (Arun / Umeyama without scale)."""
    U, _, Vt = np.linalg.svd(H)
    V = Vt.T
    if np.linalg.det(V @ U.T) < 0.0:
        for r in range(3):
            V[r, 2] = -V[r, 2]
    R = V @ U.T
    T = np.eye(4)
    T[:3, :3] = R
    for r in range(3):
        T[r, 3] = mq[r] - (R[r, 0] * mp[0] + R[r, 1] * mp[1] + R[r, 2] * mp[2])
    return T
