"""The Open3D back-end (``open3d``): ``o3d.pipelines.registration.registration_icp`` /
``registration_generalized_icp`` against a dense sample of the reference, as the paper ran it.

Open3D rebuilds its KD-tree on every call, which is why it is not the default; it is the only back-end
with generalized ICP. Open3D is imported on first use, so importing this module costs nothing.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from optipose.registration.preprocess import information_matrix
from optipose.registration.result import Matches, Registration

if TYPE_CHECKING:
    from optipose.registration.config import RegistrationConfig

__all__ = ["Open3DBackend"]


class Open3DBackend:
    """Open3D's ICP: point-to-point, point-to-plane or generalized, from identity.

    Open3D does not say whether it stopped on its criteria or on ``max_iterations``: a result with any
    correspondence counts as converged, and ``iterations`` is -1. The information matrix and the inliers
    are taken against the reference's exact closest points at the final pose.
    """

    methods = ("point_to_point", "point_to_plane", "generalized")
    takes_initial = False

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"

    def register(
        self, source: np.ndarray, reference, cfg: RegistrationConfig, initial: Matches | None = None
    ) -> Registration:
        """Register ``source`` (n, 3) m onto ``reference`` from identity (``initial`` is not used)."""
        import open3d as o3d

        reg = o3d.pipelines.registration
        target = _open3d_target(reference, cfg)
        src = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(source))
        from optipose.registration.config import FITNESS_CHANGE, RMSE_CHANGE

        criteria = reg.ICPConvergenceCriteria(
            relative_fitness=FITNESS_CHANGE, relative_rmse=RMSE_CHANGE, max_iteration=cfg.max_iterations
        )
        dist = cfg.max_correspondence_distance
        if cfg.method == "generalized":
            result = reg.registration_generalized_icp(
                src, target, dist, np.eye(4), reg.TransformationEstimationForGeneralizedICP(), criteria
            )
        else:
            est = (
                reg.TransformationEstimationPointToPoint()
                if cfg.method == "point_to_point"
                else reg.TransformationEstimationPointToPlane()
            )
            result = reg.registration_icp(src, target, dist, np.eye(4), est, criteria)
        T = np.asarray(result.transformation).copy()
        p = source @ T[:3, :3].T + T[:3, 3]
        q, n, _ = reference.closest(p)
        inlier = np.einsum("ij,ij->i", p - q, p - q) <= dist**2
        ok = result.fitness > 0
        return Registration(
            T,
            bool(ok),
            -1,
            float(result.fitness),
            float(result.inlier_rmse),
            len(source),
            information_matrix(p[inlier], n[inlier]),
            "" if ok else "no correspondences",
        )


def _open3d_target(reference, cfg: RegistrationConfig):
    """Open3D point cloud of the reference (a dense sample for a surface), cached on the reference."""
    import open3d as o3d

    key = ("_o3d_target", cfg.reference_spacing, cfg.method == "generalized")
    cache = reference.__dict__.setdefault("_o3d_cache", {})
    if key not in cache:
        points, normals = reference.sample(cfg.reference_spacing)
        pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
        pcd.normals = o3d.utility.Vector3dVector(normals)
        if cfg.method == "generalized":
            pcd.estimate_covariances(o3d.geometry.KDTreeSearchParamKNN(20))
        cache[key] = pcd
    return cache[key]
