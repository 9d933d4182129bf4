"""The registration's settings (SI units), as an objective file's ``[registration]`` table resolves them."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["RegistrationConfig", "FITNESS_CHANGE", "RMSE_CHANGE"]

_MM, _DEG = 1e-3, np.pi / 180
FITNESS_CHANGE, RMSE_CHANGE = 1e-9, 1e-12  # the "fitness" stop, and the criteria given to Open3D's ICP (m for the RMSE)


@dataclass(frozen=True)
class RegistrationConfig:
    """ICP settings (SI). See :mod:`optipose.registration`; ``backend`` names one of its registry."""

    method: str = "point_to_plane"
    backend: str = "fast"
    reference: str = "cad-surface"
    reference_spacing: float = 0.2 * _MM
    voxel_size: float = 0.5 * _MM
    # where the down-sampling grid lies: "part" (a corner at O's origin) or "random" (each scan's grid
    # shifted by a seeded offset within one voxel, :func:`optipose.registration.preprocess.grid_origin`)
    voxel_grid: str = "part"
    outlier_removal: bool = False
    outlier_neighbors: int = 20
    outlier_std_ratio: float = 2.0
    max_correspondence_distance: float = 5 * _MM
    max_iterations: int = 100
    tolerance_rotation: float = 1e-5 * _DEG
    tolerance_translation: float = 1e-5 * _MM
    # when an ICP is done: "step" (a step below the tolerances; a cycle settles on its mean) or "fitness"
    # (Open3D's: the inlier fraction and RMSE stop changing, by FITNESS_CHANGE and RMSE_CHANGE; the
    # iteration cap ends the ICP without failing it)
    stop: str = "step"
    # a registration that converges with an RMSE over this (m) fails ("rmse ... over max_rmse_mm"): a wrong
    # basin or a wrong reference, which the ICP's own tests pass; 0 = no such test
    max_rmse: float = 0.0
    # motions whose information on the smooth surface (the CAD's curved regions as curved, not as facets) is below
    # this times the largest are not stepped along and are left out of the reported information: the
    # statistic's observability tolerance (the evaluator sets it); 0 = every motion the faces' normals see
    null_tolerance: float = 1e-6
    subset_start: str = "identity"  # every subset from identity, or "combined": a subset of several sensors starts where its sensors' own registrations put it
