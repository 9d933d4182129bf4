"""Compiled voxel down-sampling (numba, ``nogil``): the centroid of the points in each voxel of a grid, one
pass over the cloud instead of a dozen numpy temporaries (:func:`optipose.registration.preprocess.voxel_down`
and the surrogate's voxel bias). Compiled once per machine and cached next to this file (``cache=True``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["voxel_centroids"]


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
