"""Six numbers per sensor ↔ a sensor pose ``T_O_S`` (docs/method.md, "Parameterisation").

Parameterisation, chosen for how LLT sensors are mounted around a part carried along ``+x_O``:

* ``R`` (3): the aim point (middle of the measuring range) in O, bounded to the part's box plus a margin.
* ``beta``: where around the scan axis the sensor looks from. The viewing direction is
  ``z_S = (sin α, cos α·cos β, cos α·sin β)``; β = −90° looks straight down (the paper's S2),
  −45° down from the −y side (S1), −135° down from the +y side (S3), 0° horizontally toward +y.
* ``alpha``: tilt of the view along the scan axis (fore/aft), bounded to ±``alpha_max``. Looking along the
  scan axis (α = ±90°) would put the motion inside the laser plane and sweep nothing, so the
  parameterisation's only singularity is excluded by the bounds.
* ``psi``: roll of the laser line about ``z_S``. ψ = 0 puts the line across the motion,
  ``x_S ∥ x_O × z_S`` (the paper's sensors, with the receiver on the +x side); ψ = 180° is the same line
  with the receiver on the −x side, so the receiver's side is part of the search.

The optimiser sees every variable scaled to [0, 1] (:class:`PoseSpace`). Both angles of a full turn are
mapped so that the box's faces, where a bounded optimiser cannot cross from one end of the turn to the
other, hold poses nobody mounts: β runs from +90° (looking up from under the part, through its support)
round to +90° again, with −90° (straight down) in the middle; ψ runs from −90° to 270° (both ends: the
laser line along the motion, which sweeps nothing), with the receiver on the +x side (ψ = 0) at a quarter
and on the −x side (ψ = 180°) at three quarters. With ψ in (−180°, 180°] instead, half of the
receiver-on-−x poses sat at one face and half at the other: part B's best single sensor (receiver on −x,
found by random sampling) was in a basin that ran off the box, and the search never reached it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from optipose.transforms import make_T

__all__ = ["PoseSpace", "pose_from_params", "params_from_pose", "SPACE_VERSION"]

_X = np.array([1.0, 0.0, 0.0])
# the angles at u = 0 (and, a full turn later, at u = 1): see the module doc
_BETA_AT_0 = -1.5 * np.pi  # ≡ +90°, looking up
_PSI_AT_0 = -0.5 * np.pi  # the laser line along the motion
SPACE_VERSION = 2  # bump when the [0, 1] ↔ pose map changes: cached poses keyed by u are then stale


def pose_from_params(R: np.ndarray, alpha: float, beta: float, psi: float) -> np.ndarray:
    """``T_O_S`` (4, 4) from the aim point ``R`` (3,) m and the angles (radians)."""
    ca, sa = np.cos(alpha), np.sin(alpha)
    z = np.array([sa, ca * np.cos(beta), ca * np.sin(beta)])
    e1 = np.cross(_X, z)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(z, e1)
    x = np.cos(psi) * e1 + np.sin(psi) * e2
    y = np.cross(z, x)
    return make_T(np.column_stack([x, y, z]), np.asarray(R, dtype=float))


def params_from_pose(T_O_S: np.ndarray) -> tuple[np.ndarray, float, float, float]:
    """Inverse of :func:`pose_from_params`: (R (3,), alpha, beta, psi) of a pose."""
    x, z = T_O_S[:3, 0], T_O_S[:3, 2]
    alpha = float(np.arcsin(np.clip(z[0], -1.0, 1.0)))
    beta = float(np.arctan2(z[2], z[1]))
    e1 = np.cross(_X, z)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(z, e1)
    psi = float(np.arctan2(x @ e2, x @ e1))
    return T_O_S[:3, 3].copy(), alpha, beta, psi


@dataclass(frozen=True)
class PoseSpace:
    """The search box for one sensor, and the [0, 1]^6 scaling the optimiser works in.

    lo, hi : (3,) m, the box the aim point may be in (the part's box grown by a margin).
    alpha_max : rad, the largest fore/aft tilt.
    """

    lo: np.ndarray
    hi: np.ndarray
    alpha_max: float = np.deg2rad(60.0)

    @classmethod
    def around(cls, bounds: np.ndarray, margin: float = 0.005, alpha_max_deg: float = 60.0) -> "PoseSpace":
        """A space for a part with bounding box ``bounds`` (2, 3) m."""
        return cls(np.asarray(bounds[0]) - margin, np.asarray(bounds[1]) + margin, np.deg2rad(alpha_max_deg))

    @property
    def dim(self) -> int:
        return 6

    def to_pose(self, u: np.ndarray) -> np.ndarray:
        """``T_O_S`` from 6 numbers in [0, 1]: R (3), alpha, beta, psi."""
        u = np.clip(np.asarray(u, dtype=float), 0.0, 1.0)
        R = self.lo + u[:3] * (self.hi - self.lo)
        alpha = (2 * u[3] - 1) * self.alpha_max
        beta = 2 * np.pi * u[4] + _BETA_AT_0
        psi = 2 * np.pi * u[5] + _PSI_AT_0
        return pose_from_params(R, alpha, beta, psi)

    def from_pose(self, T_O_S: np.ndarray) -> np.ndarray:
        """The 6 numbers in [0, 1] of a pose (clipped into the space when it lies outside)."""
        R, alpha, beta, psi = params_from_pose(T_O_S)
        turn = lambda angle, at_0: ((angle - at_0) % (2 * np.pi)) / (2 * np.pi)  # noqa: E731
        u = np.concatenate(
            [
                (R - self.lo) / (self.hi - self.lo),
                [alpha / self.alpha_max / 2 + 0.5, turn(beta, _BETA_AT_0), turn(psi, _PSI_AT_0)],
            ]
        )
        return np.clip(u, 0.0, 1.0)

    def to_poses(self, u: np.ndarray) -> list[np.ndarray]:
        """k poses from 6k numbers."""
        u = np.asarray(u, dtype=float)
        return [self.to_pose(u[6 * i : 6 * i + 6]) for i in range(len(u) // 6)]

    def describe(self, T_O_S: np.ndarray) -> dict:
        """Human-readable parameters of a pose: aim point in mm, angles in degrees."""
        R, alpha, beta, psi = params_from_pose(T_O_S)
        return {
            "R_mm": np.round(R * 1e3, 2).tolist(),
            "alpha_deg": round(float(np.rad2deg(alpha)), 2),
            "beta_deg": round(float(np.rad2deg(beta)), 2),
            "psi_deg": round(float(np.rad2deg(psi)), 2),
        }
