"""A mesh's planes: each face's plane and inward edge planes, and the number of the plane a face lies in
(coplanar faces share one), computed in float64 whatever the mesh's own precision; and the plane faces of a
surface whatever its triangles (:func:`surface_planes`: the part as made moves each as one)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from optipose.model.grouping import unique_rows

__all__ = ["face_planes", "edge_planes", "plane_numbers", "shared_planes", "surface_planes", "SurfacePlanes"]


def face_planes(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (f, 3) and plane offsets (f,) ``n·x = offset`` of every face, float64 (a degenerate face's
    normal is zero)."""
    return _face_planes(np.ascontiguousarray(vertices, dtype=np.float64), np.ascontiguousarray(faces, dtype=np.int64))


def edge_planes(tris: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each face's inward edge planes ``edge_n`` (f, 3, 3), ``edge_c`` (f, 3) from its corners ``tris``
    (f, 3, 3) and unit normals (f, 3): a point of the face's plane lies inside the face where
    ``edge_n·x >= edge_c`` for its three edges (edge k runs from corner k to corner k + 1)."""
    tris = np.ascontiguousarray(tris, dtype=np.float64)
    corners = np.arange(3 * len(tris), dtype=np.int64).reshape(-1, 3)
    return _edge_planes(tris.reshape(-1, 3), corners, np.ascontiguousarray(normals, dtype=np.float64))


# The two kernels compute what numpy's cross, norm and einsum did, in their order of operations (einsum's sum of
# three products adds the first and the third, then the second), so that every plane is the same to the bit,
# in one pass over the faces and without the (f, 3, 3) temporaries (a 5 M-face mesh's were 2 GB).
@njit(cache=True, nogil=True)
def _face_planes(vertices, faces):
    normal, offset = np.empty((faces.shape[0], 3)), np.empty(faces.shape[0])
    for i in range(faces.shape[0]):
        a, b, c = faces[i, 0], faces[i, 1], faces[i, 2]
        e0, e1, e2 = vertices[b, 0] - vertices[a, 0], vertices[b, 1] - vertices[a, 1], vertices[b, 2] - vertices[a, 2]
        f0, f1, f2 = vertices[c, 0] - vertices[a, 0], vertices[c, 1] - vertices[a, 1], vertices[c, 2] - vertices[a, 2]
        n0, n1, n2 = e1 * f2 - e2 * f1, e2 * f0 - e0 * f2, e0 * f1 - e1 * f0
        length = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        if length > 0:
            n0, n1, n2 = n0 / length, n1 / length, n2 / length
        normal[i, 0], normal[i, 1], normal[i, 2] = n0, n1, n2
        offset[i] = (n0 * vertices[a, 0] + n2 * vertices[a, 2]) + n1 * vertices[a, 1]
    return normal, offset


@njit(cache=True, nogil=True)
def _edge_planes(vertices, faces, normals):
    edge_n, edge_c = np.empty((faces.shape[0], 3, 3)), np.empty((faces.shape[0], 3))
    for i in range(faces.shape[0]):
        n0, n1, n2 = normals[i, 0], normals[i, 1], normals[i, 2]
        for k in range(3):
            p, q = faces[i, k], faces[i, (k + 1) % 3]
            d0, d1, d2 = (
                vertices[q, 0] - vertices[p, 0],
                vertices[q, 1] - vertices[p, 1],
                vertices[q, 2] - vertices[p, 2],
            )
            x0, x1, x2 = n1 * d2 - n2 * d1, n2 * d0 - n0 * d2, n0 * d1 - n1 * d0
            length = max(np.sqrt(x0 * x0 + x1 * x1 + x2 * x2), 1e-300)
            x0, x1, x2 = x0 / length, x1 / length, x2 / length
            edge_n[i, k, 0], edge_n[i, k, 1], edge_n[i, k, 2] = x0, x1, x2
            edge_c[i, k] = (x0 * vertices[p, 0] + x2 * vertices[p, 2]) + x1 * vertices[p, 1]
    return edge_n, edge_c


def plane_numbers(normals: np.ndarray, offsets: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """(f,) int64: faces whose planes (unit ``normals`` (f, 3), ``offsets`` (f,) m) agree to ``tol`` and
    ``tol`` × 0.01 m share a number, numbered in the order of their sorted keys; a degenerate face (normal
    of length < 0.5) has one of its own, after them. Sorted in memory linear in the faces."""
    key = _plane_keys(normals, offsets, tol)
    order = np.lexsort(key.T[::-1])
    new = np.ones(len(key), dtype=bool)
    new[1:] = np.any(key[order[1:]] != key[order[:-1]], axis=1)
    plane = np.empty(len(key), dtype=np.int64)
    plane[order] = np.cumsum(new) - 1
    degenerate = np.flatnonzero(np.linalg.norm(normals, axis=1) < 0.5)
    plane[degenerate] = plane.max(initial=-1) + 1 + np.arange(len(degenerate))
    return plane


def _plane_keys(normals: np.ndarray, offsets: np.ndarray, tol: float) -> np.ndarray:
    """(f, 4) int64: a face's plane in steps of ``tol`` (normal) and ``tol`` × 0.01 m (offset)."""
    return np.rint(np.c_[normals / tol, offsets / (0.01 * tol)]).astype(np.int64)


def shared_planes(vertices: np.ndarray, faces: np.ndarray, tol: float = 1e-9):
    """Faces that lie in one plane, given one plane: returns ``plane`` (f,) int64 (faces in one plane share a
    number; a degenerate face has one of its own), the normals (f, 3) and offsets (f,) of
    :func:`face_planes` with every face of a plane given its first face's, and each face's inward edge
    planes (:func:`edge_planes`).

    Faces are one plane when their normals agree to ``tol`` and their offsets to ``tol`` × 0.01 m: the
    faces of a CAD face, split into triangles, whose computed planes differ only by rounding. Giving them
    one plane makes a hit's float64 position the same whichever of them Embree names.
    """
    normals, offsets = face_planes(vertices, faces)
    # numbered in the order planes first occur (the scanner only compares them), by hashing: linear in the faces
    first, plane = unique_rows(_plane_keys(normals, offsets, tol))
    degenerate = np.flatnonzero(np.linalg.norm(normals, axis=1) < 0.5)
    plane[degenerate] = len(first) + np.arange(len(degenerate))
    rep = np.concatenate([first, degenerate])[plane]  # each plane's first face (a degenerate face: itself)
    normals, offsets = np.ascontiguousarray(normals[rep]), offsets[rep]
    edge_n, edge_c = _edge_planes(
        np.ascontiguousarray(vertices, dtype=np.float64), np.ascontiguousarray(faces, dtype=np.int64), normals
    )
    return plane, normals, offsets, edge_n, edge_c


# The part's plane faces (surface_planes): normals in cells of _NORMAL_CELL about each axis, a face within
# _NORMAL_MARGIN of a cell's side also counted in the cell across it; offsets apart by more than _OFFSET_GAP.
_NORMAL_CELL = 1e-3  # rad
_NORMAL_MARGIN = 0.1  # of a cell: the rounding a face's normal may carry (1e-4 rad: a float32 STL's 0.3 mm faces)
_OFFSET_GAP = 1e-6  # m


class SurfacePlanes(NamedTuple):
    """The plane faces of a mesh's surface (:func:`surface_planes`): ``plane`` (f,) int64 each face's number
    (-1: a face of no area), and per plane its unit ``normal`` (p, 3), ``centroid`` (p, 3) m and ``area`` (p,) m²."""

    plane: np.ndarray
    normal: np.ndarray
    centroid: np.ndarray
    area: np.ndarray


def surface_planes(vertices: np.ndarray, faces: np.ndarray) -> SurfacePlanes:
    """The plane faces of the surface, whatever its triangles: faces whose normals agree to about 1e-3 rad and
    whose offsets along their common normal to 1 µm make one plane; its normal is the area-weighted mean of
    theirs, its centroid the area centroid of its faces.

    Unlike :func:`plane_numbers` (faces equal to the rounding of float64 arithmetic), it holds for a surface
    re-tessellated and written in float32 (an STL): a 2 mm face's normal then carries 1e-5 rad of rounding.
    Normals are grouped in cells of ``_NORMAL_CELL`` linked across a cell's side wherever a face lies within
    ``_NORMAL_MARGIN`` of it, so that no rounding splits a plane (normals further apart than two cells are
    never one group unless faces between them link them); a group's faces are then split where their offsets
    along its mean normal, sorted, jump by more than ``_OFFSET_GAP``. Linear in the faces but for one sort.
    The numbers themselves follow the mesh (what is drawn per plane must not: :mod:`optipose.cell.asmade`).
    """
    import pandas as pd
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    normal, _ = face_planes(vertices, faces)
    a, b, c = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    centre = (a + b + c) / 3.0
    del a, b, c
    live = np.flatnonzero((np.linalg.norm(normal, axis=1) > 0.5) & (area > 0))
    plane = np.full(len(faces), -1, dtype=np.int64)
    if not len(live):
        return SurfacePlanes(plane, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))
    n, w, x = normal[live], area[live], centre[live]
    # normals: a cell per face, and the cells across the sides it lies near, linked where some face has them
    u = n / _NORMAL_CELL
    cell = np.rint(u).astype(np.int64)
    side = np.where(u >= cell, 1, -1)
    near = np.abs(u - cell) > 0.5 - _NORMAL_MARGIN
    half = int(np.ceil(1.0 / _NORMAL_CELL)) + 2

    def code(c: np.ndarray) -> np.ndarray:  # a cell's three integers as one
        return ((c[:, 0] + half) * (2 * half + 1) + (c[:, 1] + half)) * (2 * half + 1) + (c[:, 2] + half)

    codes, node = np.unique(code(cell), return_inverse=True)
    index = pd.Index(codes)
    a, b = [node], [node]
    for mask in range(1, 8):
        bits = np.array([(mask >> j) & 1 for j in range(3)], dtype=bool)
        sel = np.flatnonzero(np.all(near[:, bits], axis=1))
        if len(sel):
            other = index.get_indexer(code(cell[sel] + side[sel] * bits))
            found = other >= 0
            a.append(node[sel[found]])
            b.append(other[found])
    pair = np.unique(np.concatenate(a) * len(codes) + np.concatenate(b))  # each link once (no sum of duplicates)
    a, b = np.divmod(pair, len(codes))
    links = coo_matrix((np.ones(len(pair), np.int8), (a, b)), shape=(len(codes), len(codes)))
    group = connected_components(links, directed=False)[1][node]
    mean = np.zeros((group.max() + 1, 3))
    np.add.at(mean, group, w[:, None] * n)
    mean /= np.linalg.norm(mean, axis=1, keepdims=True)
    # offsets along the group's normal: a new plane where they jump
    offset = np.einsum("ij,ij->i", mean[group], x)
    order = np.lexsort((offset, group))
    new = np.ones(len(order), dtype=bool)
    new[1:] = (group[order[1:]] != group[order[:-1]]) | (np.diff(offset[order]) > _OFFSET_GAP)
    number = np.empty(len(order), dtype=np.int64)
    number[order] = np.cumsum(new) - 1
    plane[live] = number
    count = int(number.max()) + 1
    weight = np.bincount(number, w, count)
    normal_sum = np.stack([np.bincount(number, w * n[:, j], count) for j in range(3)], axis=1)
    centroid = np.stack([np.bincount(number, w * x[:, j], count) for j in range(3)], axis=1) / weight[:, None]
    return SurfacePlanes(plane, normal_sum / np.linalg.norm(normal_sum, axis=1, keepdims=True), centroid, weight)
