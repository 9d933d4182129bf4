"""The surface the triangles stand for: smooth normals on a CAD mesh, and the directions a cloud cannot observe on it.

A CAD export approximates a curved surface by flat faces. Their normals turn from face to face, and the
point-to-plane information of a cloud on them sees that turning: on a tessellated sphere it "observes" a
rotation about the centre that the sphere itself leaves free, with a strength that falls as the faces get
finer (a 327 k-face sphere looks observable, a 1.3 M-face one not), and an ICP wanders along it for as
many steps as the facets allow. Normals interpolated across each face from its corners (Phong's normals, each
corner's the angle-weighted mean of the faces around that vertex that meet it at less than :data:`CREASE_DEG`,
so a part's edges stay sharp) turn as the surface does, whatever the tessellation: a face of a flat region
keeps its own normal, a facet of a sphere gets nearly the radial one (0.07° off at 20 k faces, where the
facet's own normal is 1.3° off).

:func:`null_directions` finds the motions (rotation about the cloud's centroid, then translation) that the
smooth information does not constrain, scaled as :func:`optipose.evaluate.statistics.unobservable_axes`
scales them; the ICP (:mod:`optipose.registration.fast`) takes no step along them and reports an information
matrix without them.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from optipose.registration.normal_equations import normal_equations
from optipose.registration.preprocess import scaled_information

__all__ = ["corner_normals", "smooth_normals", "smooth_information", "null_directions", "CREASE_DEG"]

CREASE_DEG = 30.0  # faces meeting at more than this are two sides of an edge of the part, each keeping its normal


@njit(cache=True, nogil=True)
def corner_normals(vertices, faces, normals, cos_crease):
    """(f, 3, 3) float32: at each corner of each face, the angle-weighted mean normal of the faces around that
    vertex whose normals lie within the crease angle of this face's (``cos_crease``), normalised."""
    n_v, n_f = vertices.shape[0], faces.shape[0]
    count = np.zeros(n_v + 1, np.int64)
    for f in range(n_f):
        for k in range(3):
            count[faces[f, k] + 1] += 1
    for v in range(n_v):
        count[v + 1] += count[v]
    slot = count[:-1].copy()
    around = np.empty(3 * n_f, np.int64)  # per vertex, its faces and which corner of each it is
    corner = np.empty(3 * n_f, np.int8)
    for f in range(n_f):
        for k in range(3):
            v = faces[f, k]
            around[slot[v]] = f
            corner[slot[v]] = k
            slot[v] += 1
    angle = np.empty((n_f, 3), np.float32)  # the weights: float32 is plenty
    for f in range(n_f):
        for k in range(3):
            a, b, c = faces[f, k], faces[f, (k + 1) % 3], faces[f, (k + 2) % 3]
            u0, u1, u2 = (
                vertices[b, 0] - vertices[a, 0],
                vertices[b, 1] - vertices[a, 1],
                vertices[b, 2] - vertices[a, 2],
            )
            w0, w1, w2 = (
                vertices[c, 0] - vertices[a, 0],
                vertices[c, 1] - vertices[a, 1],
                vertices[c, 2] - vertices[a, 2],
            )
            x0, x1, x2 = u1 * w2 - u2 * w1, u2 * w0 - u0 * w2, u0 * w1 - u1 * w0
            angle[f, k] = np.arctan2(np.sqrt(x0 * x0 + x1 * x1 + x2 * x2), u0 * w0 + u1 * w1 + u2 * w2)
    out = np.empty((n_f, 3, 3), np.float32)
    for f in range(n_f):
        for k in range(3):
            v = faces[f, k]
            s0 = s1 = s2 = 0.0
            for j in range(count[v], count[v + 1]):
                g = around[j]
                if (
                    normals[g, 0] * normals[f, 0] + normals[g, 1] * normals[f, 1] + normals[g, 2] * normals[f, 2]
                    >= cos_crease
                ):
                    w = angle[g, corner[j]]
                    s0 += w * normals[g, 0]
                    s1 += w * normals[g, 1]
                    s2 += w * normals[g, 2]
            norm = np.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
            if norm > 0.0:
                out[f, k, 0], out[f, k, 1], out[f, k, 2] = s0 / norm, s1 / norm, s2 / norm
            else:  # a degenerate face: its own normal
                out[f, k, 0], out[f, k, 1], out[f, k, 2] = normals[f, 0], normals[f, 1], normals[f, 2]
    return out


@njit(cache=True, nogil=True, inline="always")
def _smooth_at(x, y, z, f, tri, corners):
    """The corners' normals of face f interpolated at (x, y, z) by its barycentric coordinates (clamped to the
    face: a point off it gets its nearest edge's or corner's), normalised."""
    a0, a1, a2 = tri[f, 0, 0], tri[f, 0, 1], tri[f, 0, 2]
    e0, e1, e2 = tri[f, 1, 0] - a0, tri[f, 1, 1] - a1, tri[f, 1, 2] - a2
    g0, g1, g2 = tri[f, 2, 0] - a0, tri[f, 2, 1] - a1, tri[f, 2, 2] - a2
    r0, r1, r2 = x - a0, y - a1, z - a2
    d00 = e0 * e0 + e1 * e1 + e2 * e2
    d01 = e0 * g0 + e1 * g1 + e2 * g2
    d11 = g0 * g0 + g1 * g1 + g2 * g2
    d20 = r0 * e0 + r1 * e1 + r2 * e2
    d21 = r0 * g0 + r1 * g1 + r2 * g2
    den = d00 * d11 - d01 * d01
    v = (d11 * d20 - d01 * d21) / den if den > 0.0 else 0.0
    w = (d00 * d21 - d01 * d20) / den if den > 0.0 else 0.0
    v, w = max(v, 0.0), max(w, 0.0)
    u = 1.0 - v - w
    if u < 0.0:
        v, w, u = v / (v + w), w / (v + w), 0.0
    s0 = u * corners[f, 0, 0] + v * corners[f, 1, 0] + w * corners[f, 2, 0]
    s1 = u * corners[f, 0, 1] + v * corners[f, 1, 1] + w * corners[f, 2, 1]
    s2 = u * corners[f, 0, 2] + v * corners[f, 1, 2] + w * corners[f, 2, 2]
    norm = np.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
    return s0 / norm, s1 / norm, s2 / norm


@njit(cache=True, nogil=True)
def smooth_normals(q, ids, tri, corners):
    """(m, 3): the smooth surface's normal at each ``q[i]`` on face ``ids[i]`` (:func:`_smooth_at`)."""
    out = np.empty((q.shape[0], 3))
    for i in range(q.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = _smooth_at(q[i, 0], q[i, 1], q[i, 2], ids[i], tri, corners)
    return out


@njit(cache=True, nogil=True)
def smooth_information(p, q, ids, max_d2, tri, corners):
    """The point-to-plane information (6, 6) of the pairs (p, q) within ``sqrt(max_d2)`` with the normals of
    :func:`smooth_normals` at q (the normal equations' ``AᵀA``, rotation about the pairs' centroid first:
    :func:`optipose.registration.normal_equations.normal_equations`), and the RMS radius (m) of those p about
    the centroid."""
    inlier, c, H, _, _ = normal_equations(p, q, smooth_normals(q, ids, tri, corners), max_d2)
    count = 0
    r2 = 0.0
    for i in range(p.shape[0]):
        if inlier[i]:
            count += 1
            r2 += (p[i, 0] - c[0]) ** 2 + (p[i, 1] - c[1]) ** 2 + (p[i, 2] - c[2]) ** 2
    return H, np.sqrt(r2 / count) if count else 1.0


def null_directions(information: np.ndarray, scale: float, tolerance: float) -> np.ndarray:
    """(6, k): the unit motions (in the scaled coordinates of ``unobservable_axes``: rotation × ``scale``,
    translation) whose information is below ``tolerance`` × the largest; k = 0 when the cloud sees all six."""
    w, V = np.linalg.eigh(scaled_information(information, scale)[0])
    if not w[-1] > 0.0:
        return np.eye(6)
    return V[:, w < tolerance * w[-1]]
