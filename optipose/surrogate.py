"""The cheap surrogate for the global search: predicted per-axis orientation error of a layout (SPEC §6).

For one nominal scan per sensor, the point-to-plane information matrix

    H = Σ_i JᵢᵀJᵢ / σᵢ²,  Jᵢ = [(pᵢ − c) × nᵢ, nᵢ]   (rotation about the rotation centre c, translation)

tells how well a registration pins the six pose parameters down. Information adds over sensors, so one
6×6 matrix per sensor pose is all a layout needs: a subset's matrix is the sum of its sensors'. The
rotation block of (H + prior)⁻¹ gives per-axis standard deviations σ; for Gaussian errors the median
|e| is 0.674σ and the 75th percentile 1.150σ.

What the surrogate models, and why:

* the scan runs at reduced fidelity (a few hundred columns, coarser steps), then is thinned to one point
  per registration voxel, because ICP runs on voxel-down-sampled clouds: the number of *voxels* seen, not
  raw points, sets the information;
* each voxel point gets σᵢ² = σ_noise² / (intensity · mᵢ): the voxel's point is the mean of the mᵢ raw
  points a full-fidelity scan puts in it, so its noise along the normal averages down; moving along the
  surface does not change a point-to-surface residual. A sampled reference adds its own variance
  (``extra_variance``, spacing²/12);
* a weak prior (rotation 5°, translation 5 mm: what bin picking already knows) keeps H invertible when
  a layout leaves some direction unobservable; such an axis then gets a σ near the prior's, a poor score.

It ranks layouts; the full ICP protocol (:mod:`optipose.evaluate`) gives the numbers that are reported.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, replace

import numpy as np

from optipose.scanner import Scanner, ScanMotion

__all__ = ["Surrogate", "SensorInfo", "MEDIAN_PER_SIGMA", "P75_PER_SIGMA", "predicted_stats"]

MEDIAN_PER_SIGMA = 0.6745  # median of |N(0, 1)|
P75_PER_SIGMA = 1.1503  # 75th percentile of |N(0, 1)|
_PRIOR_ROTATION = np.deg2rad(5.0)
_PRIOR_TRANSLATION = 5e-3


@dataclass(frozen=True)
class SensorInfo:
    """What one sensor pose contributes: its information matrix (6, 6) and how much it sees."""

    H: np.ndarray
    n_points: int  # points a full-fidelity scan would return (estimated from the reduced scan)
    n_voxels: int


class Surrogate:
    """Per-sensor information matrices from reduced nominal scans of a part.

    part : a loaded :class:`optipose.part.Part`.
    voxel : m, the registration voxel size of the objective.
    columns : laser columns per profile in the reduced scan; ``step_factor`` : profile step multiplier.
    """

    def __init__(
        self, part, voxel: float = 0.5e-3, columns: int = 400, step_factor: float = 2.0,
        threads: int | None = None, extra_variance: float = 0.0,
    ):  # fmt: skip
        from optipose.sensor import load_sensor

        self.part = part
        self.full_sensor = load_sensor(part.sensor)
        sensor = replace(self.full_sensor, points_per_profile=min(columns, self.full_sensor.points_per_profile))
        self.scanner = Scanner(part.mesh, sensor, part.material, threads=threads, occluders=getattr(part, "occluders", None))
        self.motion = ScanMotion(part.motion.length, part.motion.step * step_factor)
        self.voxel = voxel
        self.extra_variance = extra_variance  # m², e.g. a sampled reference's spacing²/12
        # a reduced scan sees 1/scale of the points of a full-fidelity one
        self.scale = (self.full_sensor.points_per_profile / sensor.points_per_profile) * (
            part.motion.n_profiles / self.motion.n_profiles
        )
        self.centre = np.asarray(part.rotation_centre, dtype=float)

    def info(self, T_O_S: np.ndarray) -> SensorInfo:
        """Information matrix of one sensor pose from a noise-free nominal scan."""
        scan = self.scanner.scan(T_O_S, self.motion, centre=self.centre, noise=False)
        if len(scan) == 0:
            return SensorInfo(np.zeros((6, 6)), 0, 0)
        normals = self.scanner.normals(scan)
        first, inverse, counts = _voxels(scan.points, self.voxel)
        p, n = scan.points[first] - self.centre, normals[first]
        inten = np.bincount(inverse, weights=scan.intensity.astype(float)) / counts
        inten = np.clip(inten, self.full_sensor.detection_threshold, 1.0)
        # a voxel's point is the mean of the raw points in it: its noise along the normal shrinks with
        # the number of points a full-fidelity scan puts there; its tangential spread does not matter
        var = self.full_sensor.noise_sigma**2 / inten / (counts * self.scale) + self.extra_variance
        J = np.hstack([np.cross(p, n), n]) / np.sqrt(var)[:, None]
        return SensorInfo(J.T @ J, int(round(len(scan) * self.scale)), len(first))


def _voxels(points: np.ndarray, voxel: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Occupied voxels: index of one point in each (v,), each point's voxel (n,), points per voxel (v,)."""
    ijk = np.floor((points - points.min(axis=0)) / voxel).astype(np.int64)
    dims = ijk.max(axis=0) + 1
    keys = (ijk[:, 0] * dims[1] + ijk[:, 1]) * dims[2] + ijk[:, 2]
    _, first, inverse, counts = np.unique(keys, return_index=True, return_inverse=True, return_counts=True)
    return first, inverse, counts


def rotation_sigma(H: np.ndarray) -> np.ndarray:
    """Per-axis rotation standard deviation (3,) rad from an information matrix, with the weak prior."""
    prior = np.diag([1 / _PRIOR_ROTATION**2] * 3 + [1 / _PRIOR_TRANSLATION**2] * 3)
    cov = np.linalg.inv(H + prior)
    return np.sqrt(np.clip(np.diag(cov)[:3], 0.0, None))


def predicted_stats(infos: list[SensorInfo], weights=(1.0, 1.0, 1.0), median_weight=1.0, p75_weight=1.0) -> dict:
    """The surrogate's Table 1 for a layout: every non-empty subset's predicted per-axis median and 75th
    percentile (degrees), each axis's best subset, and the weighted score of the per-axis best."""
    k = len(infos)
    subsets = [c for r in range(1, k + 1) for c in itertools.combinations(range(k), r)]
    sigma = np.array([rotation_sigma(sum(infos[i].H for i in c)) for c in subsets])  # (n_subsets, 3)
    median, p75 = np.rad2deg(sigma * MEDIAN_PER_SIGMA), np.rad2deg(sigma * P75_PER_SIGMA)
    best = [min(range(len(subsets)), key=lambda s: (median[s, a], p75[s, a])) for a in range(3)]
    score = sum(
        w * (median_weight * median[s, a] + p75_weight * p75[s, a]) for a, (w, s) in enumerate(zip(weights, best))
    )
    return {
        "subsets": subsets,
        "median_deg": median,
        "p75_deg": p75,
        "best_subset": [subsets[s] for s in best],
        "score": float(score),
    }
