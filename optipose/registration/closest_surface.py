"""Compiled closest points on a planar-faced mesh (numba, ``nogil``): the faces near each cell of a grid over
the part, and each point's closest point on them, starting from the face it had at the last step (walking
across the edge it left by) before its grid cell's faces are searched. The arithmetic is documented in
:mod:`optipose.registration.reference` (:class:`~optipose.registration.reference.SurfaceReference`);
compiled once per machine and cached next to this file (``cache=True``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["face_grid", "nearest_into", "edge_normal"]

_WALK = 4  # faces a point that left its face's guess walks across before the grid is searched


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
    the closest point of that face, in float64, and the direction from it to the point as its normal
    (:func:`edge_normal`; where faces tie exactly, at their common edge, the lowest face id takes the
    point, whatever the guess: the point and the normal are the same whichever face it is). Points left
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
        well_inside, inside = _project(p, i, g_best, planes, plane_c, q)
        if not well_inside:  # on or near an edge: the face's closest point
            q[i, 0], q[i, 1], q[i, 2] = bx, by, bz
            if not inside:
                edge_normal(p, i, q, nrm)
    return n_open


@njit(cache=True, nogil=True, inline="always")
def edge_normal(p, i, q, nrm):
    """Where p[i]'s closest point q[i] lies on an edge or a corner, the surface's own normal there: the
    direction from q[i] to p[i] (the distance's gradient), signed like the face normal in ``nrm[i]``.
    The faces that meet at that edge tie, and which of them answers depends on the triangulation; this
    direction does not. A point on the edge itself (no direction) keeps the face normal."""
    dx, dy, dz = p[i, 0] - q[i, 0], p[i, 1] - q[i, 1], p[i, 2] - q[i, 2]
    d = np.sqrt(dx * dx + dy * dy + dz * dz)
    if d <= 1e-9:  # within a nanometre of the edge: the direction is rounding, and the point as good as on it
        return
    if dx * nrm[i, 0] + dy * nrm[i, 1] + dz * nrm[i, 2] < 0.0:
        d = -d
    nrm[i, 0], nrm[i, 1], nrm[i, 2] = dx / d, dy / d, dz / d
