"""Compiled passes of one ICP step (numba, ``nogil``): the cloud moved by the current pose, then the
point-to-plane normal equations, or the point-to-point cross-covariance and its Kabsch solution, each one
pass over the cloud instead of a dozen numpy temporaries. The arithmetic is documented in
:mod:`optipose.registration.fast`; compiled once per machine and cached next to this file (``cache=True``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["transform", "normal_equations", "cross_covariance", "kabsch"]


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
