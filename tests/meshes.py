"""Meshes for the tests: the same surface in other triangles, and the exact distance from a point to every face."""

import numpy as np
import trimesh


def centroid_split(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Each triangle split in three at its centroid: the same surface, other triangles and other edges."""
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    c = np.arange(len(v), len(v) + len(f))
    faces = np.concatenate([np.stack([f[:, a], f[:, b], c], 1) for a, b in ((0, 1), (1, 2), (2, 0))])
    return trimesh.Trimesh(np.vstack([v, v[f].mean(axis=1)]), faces, process=False)


def midpoint_split(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Each triangle split in four at its edges' midpoints: the same surface."""
    return mesh.subdivide()


def distance_to_every_face(triangles: np.ndarray, point: np.ndarray) -> np.ndarray:
    """The distance (m) from one point to each triangle (f, 3, 3): to its plane where the point projects
    inside it (barycentric coordinates), else to the nearest of its three edges."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    normal = np.cross(b - a, c - a)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-300)
    h = np.einsum("ij,ij->i", point - a, normal)
    x = point - h[:, None] * normal - a
    e0, e1 = b - a, c - a
    d00, d01, d11 = (np.einsum("ij,ij->i", u, v) for u, v in ((e0, e0), (e0, e1), (e1, e1)))
    d20, d21 = np.einsum("ij,ij->i", x, e0), np.einsum("ij,ij->i", x, e1)
    den = np.where(d00 * d11 - d01**2 > 0, d00 * d11 - d01**2, 1.0)
    v, w = (d11 * d20 - d01 * d21) / den, (d00 * d21 - d01 * d20) / den
    inside = (v >= 0) & (w >= 0) & (v + w <= 1) & (d00 * d11 - d01**2 > 1e-20 * d00 * d11)  # a sliver: its edges answer

    def to_segment(s, t):
        d = t - s
        u = np.clip(np.einsum("ij,ij->i", point - s, d) / np.maximum(np.einsum("ij,ij->i", d, d), 1e-300), 0.0, 1.0)
        return np.linalg.norm(point - (s + u[:, None] * d), axis=1)

    edges = np.minimum(np.minimum(to_segment(a, b), to_segment(b, c)), to_segment(c, a))
    return np.where(inside, np.abs(h), edges)


# part B's hand S1 and S2 as a layout file, as its part file gives them (the small two-sensor case of the scan
# folder and calibration tests)
TWO_SENSORS = """[[sensors]]
name = "S1"
T_O_S = [[0.0, 1.0, 0.0, 0.030], [0.7071, 0.0, 0.7071, -0.023], [0.7071, 0.0, -0.7071, 0.015], [0.0, 0.0, 0.0, 1.0]]

[[sensors]]
name = "S2"
T_O_S = [[0.0, 1.0, 0.0, 0.030], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0175], [0.0, 0.0, 0.0, 1.0]]
"""
