"""The same surface in other triangles, for the tests that check an answer does not depend on them."""

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
