"""What is done to a scan before and after registration: voxel down-sampling, statistical outlier removal
and the point-to-plane information matrix (observability of the six motions)."""

from __future__ import annotations

import numpy as np

__all__ = ["voxel_down", "grid_origin", "remove_outliers", "information_matrix", "scaled_information"]


def voxel_down(points: np.ndarray, size: float, origin=None) -> np.ndarray:
    """Centroid of the points in each cube of side ``size`` (m) of a grid with a corner at ``origin``
    (3,) m in O (default O's origin).

    points : (n, 3) float, m. Returns (m, 3) float64, m ≤ n; ``points`` unchanged when ``size`` ≤ 0.

    The grid is fixed in O (Open3D's moves with the cloud's bounding box), so a voxel's content does not
    depend on what else was scanned. Output order is the voxels' sorted keys: deterministic. A part drawn in
    round millimetres has faces on the planes of a grid at O's origin; :func:`grid_origin` gives a scan a
    grid of its own (``[registration] voxel_grid = "random"``).
    """
    from optipose.registration.voxels import voxel_centroids

    points = np.asarray(points, dtype=np.float64)
    if size <= 0 or len(points) == 0:
        return points
    origin = np.zeros(3) if origin is None else np.asarray(origin, dtype=np.float64)
    return voxel_centroids(np.ascontiguousarray(points), float(size), origin)


def grid_origin(seed, size: float) -> np.ndarray:
    """A scan's own voxel grid: its corner at a seeded uniform offset within one voxel (3,) m.

    Where the grid's planes fall on a part's faces is chance in a real cell (the part is placed to a tenth
    of a millimetre, the voxel is half a millimetre); a grid at O's origin puts every face drawn in round
    millimetres on a plane between two voxels, where the sensor noise splits it, and turns that coincidence
    into a constant bias of every scan whose turn leaves the face parallel to the grid.
    """
    return np.random.default_rng([int(seed), 0x70C5]).random(3) * size


def remove_outliers(points: np.ndarray, neighbors: int = 20, std_ratio: float = 2.0) -> np.ndarray:
    """Open3D's statistical outlier removal: drop points whose mean distance to their ``neighbors`` nearest
    points is more than ``std_ratio`` standard deviations above the cloud's average.

    points : (n, 3) float, m. Returns the kept points (m, 3) in their input order.
    """
    import open3d as o3d

    if len(points) <= neighbors:
        return points
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    _, keep = pcd.remove_statistical_outlier(nb_neighbors=neighbors, std_ratio=std_ratio)
    return points[np.sort(np.asarray(keep, dtype=np.int64))]


def information_matrix(points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Point-to-plane information ``H = Σ JᵢᵀJᵢ`` (6, 6), ``Jᵢ = [((pᵢ − c) × nᵢ)ᵀ, nᵢᵀ]``, c = centroid.

    points : (n, 3) m; normals : (n, 3) unit. Rotation first (rad), then translation (m); taken about the
    centroid so a rotation the cloud cannot see is not mixed with a translation by the choice of origin.
    """
    if len(points) == 0:
        return np.zeros((6, 6))
    J = np.hstack([np.cross(points - points.mean(axis=0), normals), normals])
    return J.T @ J


def scaled_information(information: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray]:
    """``H`` made unitless, rotation scaled by ``scale`` (m, the cloud's RMS radius) so that rotation and
    translation compare: (``D H D`` symmetrised (6, 6), the diagonal d (6,) of D = diag(1/scale × 3, 1 × 3))."""
    d = np.array([1.0 / max(scale, 1e-12)] * 3 + [1.0] * 3)
    H = d[:, None] * information * d[None, :]
    return 0.5 * (H + H.T), d
