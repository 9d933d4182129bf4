"""Compiled nearest reference samples (numba, ``nogil``): a grid over a sampled reference's points, each
point's nearest sample in it, each sample's neighbours, and an ICP's points tracked from step to step
(searched again only once they may have left their sample's bisector planes). The arithmetic is documented
in :mod:`optipose.registration.sampled` (:class:`~optipose.registration.sampled.SampledReference`);
compiled once per machine and cached next to this file (``cache=True``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["point_grid", "grid_nearest", "sample_neighbours", "tracked_nearest", "WALK", "SLACK", "SETTLE"]


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
SETTLE = (
    1.0 / 64
)  # cells: a point that moved less than this since its last search is settling: its exact margin is worth the work


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
def tracked_nearest(
    p, ids, anchor, margin, q, n, ref_points, ref_normals, neighbours, rho, reach, origin, cell, shape, start
):
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
                        sg = np.sqrt(
                            (ref_points[k, 0] - ref_points[g, 0]) ** 2
                            + (ref_points[k, 1] - ref_points[g, 1]) ** 2
                            + (ref_points[k, 2] - ref_points[g, 2]) ** 2
                        )
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
