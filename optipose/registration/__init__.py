"""Registration of a scan (source, floating) onto a reference (target, fixed): ICP from identity.

- :mod:`~optipose.registration.reference` — the CAD surface's reference, its search structure built once per part
  (:mod:`~optipose.registration.surface_index`), and :mod:`~optipose.registration.sampled` — a sampled one;
- :mod:`~optipose.registration.preprocess` — voxel down-sampling, outlier removal, the information matrix;
- :mod:`~optipose.registration.backends` — :func:`register` and the back-ends by name
  (:mod:`~optipose.registration.fast`, :mod:`~optipose.registration.open3d_icp`);
- :mod:`~optipose.registration.result` — the :class:`Registration` and :class:`Matches` records;
- :mod:`~optipose.registration.config` — :class:`RegistrationConfig`, the settings an objective file resolves to;
- the compiled kernels, one module per concept: :mod:`~optipose.registration.voxels` (voxel centroids),
  :mod:`~optipose.registration.closest_surface` and :mod:`~optipose.registration.closest_samples` (closest
  points on the CAD surface, nearest reference samples), :mod:`~optipose.registration.normal_equations` (one ICP step's passes).

Importing this package is light: SciPy, numba and Open3D load when a back-end first runs.
"""

from optipose.registration.backends import (
    BACKENDS,
    RegistrationBackend,
    backend_for,
    get_backend,
    register,
    register_backend,
)
from optipose.registration.preprocess import grid_origin, information_matrix, remove_outliers, voxel_down
from optipose.registration.result import Matches, Registration

__all__ = [
    "register",
    "Registration",
    "Matches",
    "RegistrationBackend",
    "BACKENDS",
    "get_backend",
    "register_backend",
    "backend_for",
    "voxel_down",
    "grid_origin",
    "remove_outliers",
    "information_matrix",
]
