"""Equal rows of an integer array found by hashing, and a mesh's faces around each vertex found by counting, in
time linear in the rows.

``np.unique(..., axis=0)`` and trimesh's ``unique_rows`` sort the rows: n log n, and on a mesh of millions
of faces the sort leaves the caches and was the largest part of loading it (CHANGELOG.md, the dense meshes'
entries). Here each row is hashed to 64 bits (pandas' ``hash_array`` per column, combined), the
hashes are numbered by a hash table (``pandas.factorize``) and the result is checked against the rows
themselves: two different rows with one hash (about n² / 2⁶⁵, 10⁻⁶ for 5 M rows) fall back to the sort.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["unique_rows", "vertex_faces", "closed_and_wound", "bodies"]

_MIX = np.uint64(0x9E3779B97F4A7C15)  # an odd constant (the golden ratio's): a column's hash shifts the next's


def unique_rows(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Equal rows of ``keys`` (n, d) integers, numbered in the order they first occur: returns ``first``
    (u,) int64, the index of each distinct row's first occurrence (ascending), and ``inverse`` (n,) int64,
    each row's number, so that ``keys[first][inverse] == keys``. The same as trimesh's
    ``unique_rows(keys, keep_order=True)``."""
    import pandas as pd

    keys = np.asarray(keys)
    if keys.ndim != 2 or len(keys) == 0:
        raise ValueError(f"unique_rows takes a non-empty (n, d) array, not {keys.shape}")
    with np.errstate(over="ignore"):
        h = pd.util.hash_array(np.ascontiguousarray(keys[:, 0]))
        for c in range(1, keys.shape[1]):
            h = h * _MIX ^ pd.util.hash_array(np.ascontiguousarray(keys[:, c]))
    codes, uniques = pd.factorize(h)
    first = np.empty(len(uniques), dtype=np.int64)
    first[codes[::-1]] = np.arange(len(codes) - 1, -1, -1)  # the last write of each number is its first row
    inverse = codes.astype(np.int64, copy=False)
    if not np.array_equal(keys[first[inverse]], keys):  # two rows hashed alike: sort instead
        _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
        order = np.argsort(first)
        rank = np.empty_like(order)
        rank[order] = np.arange(len(order))
        first, inverse = first[order], rank[inverse.ravel()]
    return first, inverse


@njit(cache=True, nogil=True)
def vertex_faces(faces, n):
    """The faces around each of ``n`` vertices as CSR: ``indptr`` (n + 1,), ``around`` (3 f,) int64, the faces of
    vertex v ``around[indptr[v]:indptr[v + 1]]`` in ascending order (a counting sort of ``faces`` (f, 3))."""
    indptr = np.zeros(n + 1, np.int64)
    for f in range(faces.shape[0]):
        for k in range(3):
            indptr[faces[f, k] + 1] += 1
    for v in range(n):
        indptr[v + 1] += indptr[v]
    fill = indptr[:-1].copy()
    around = np.empty(indptr[n], np.int64)
    for f in range(faces.shape[0]):
        for k in range(3):
            v = faces[f, k]
            around[fill[v]] = f
            fill[v] += 1
    return indptr, around


def closed_and_wound(
    faces: np.ndarray, n: int, csr: tuple[np.ndarray, np.ndarray] | None = None
) -> tuple[bool, bool] | None:
    """trimesh's ``is_watertight`` and ``is_winding_consistent`` of a mesh's ``faces`` (f, 3) over ``n`` vertices:
    every edge in exactly two faces; every edge in two faces run the other way by the second. ``None`` for a
    mesh with a face that names a vertex twice (trimesh's then). ``csr``: the caller's :func:`vertex_faces` of
    these faces, not listed again."""
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    if len(faces) == 0 or np.any(
        (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2]) | (faces[:, 2] == faces[:, 0])
    ):
        return None
    return _closed_and_wound(faces, *(csr if csr is not None else vertex_faces(faces, n)))


@njit(cache=True, nogil=True)
def _closed_and_wound(faces, indptr, around):
    closed, wound = True, True
    for f in range(faces.shape[0]):
        for k in range(3):
            a, b = faces[f, k], faces[f, (k + 1) % 3]
            count, reversed_ = 0, True  # the faces around a that hold b hold the edge {a, b} once each
            for i in range(indptr[a], indptr[a + 1]):
                g = around[i]
                for j in range(3):
                    if faces[g, j] == b:
                        count += 1
                        if g != f and faces[g, (j + 1) % 3] != a:  # g runs b -> a only if a follows b in it
                            reversed_ = False
            if count != 2:
                closed = False
            elif not reversed_:
                wound = False
    return closed, wound


def bodies(faces: np.ndarray, n: int) -> int:
    """trimesh's ``body_count``: the groups of the ``n`` vertices joined by the edges of ``faces`` (a vertex in
    no face is a group of its own), by union-find."""
    return _bodies(np.ascontiguousarray(faces, dtype=np.int64), int(n))


@njit(cache=True, nogil=True)
def _bodies(faces, n):
    parent = np.arange(n)
    groups = n
    for f in range(faces.shape[0]):
        for k in range(3):
            a, b = faces[f, k], faces[f, (k + 1) % 3]
            while parent[a] != a:  # the roots, halving the paths on the way
                parent[a] = parent[parent[a]]
                a = parent[a]
            while parent[b] != b:
                parent[b] = parent[parent[b]]
                b = parent[b]
            if a != b:
                parent[max(a, b)] = min(a, b)
                groups -= 1
    return groups
