"""The robot that carries the part, and the sensors' calibration to the cell (docs/cell.md).

Per scan the robot adds three errors to what the protocol asks of it:

- the orientation it sets is off the commanded one by a small rotation (σ ``orientation`` about each
  axis): the protocol's ground truth has this error, the estimate is compared with the command;
- its path along the linear scan motion wanders: at profile k the part is off by a translation ``t_k`` (σ
  ``path`` per axis) and a rotation ``w_k`` about its rotation centre (σ ``path_rotation`` per axis), each a
  stationary Gauss-Markov process along the travel with correlation length ``path_correlation``
  (correlation exp(-|Δs| / ℓ) between profiles Δs apart);
- the scan step is off by a relative error (σ ``step``, one per scan): profile k lands ``step`` × its
  offset further along x than the cell assumes.

The calibration leaves each sensor's pose off by a rigid error of its own (σ ``sensor_translation``,
``sensor_rotation`` per axis, in the sensor's frame) and every sensor off together by the error of the
frame they are measured in (σ ``frame_translation``, ``frame_rotation``, about the part's rotation centre):
one draw per cell instance (seed), the same for every scan of a run. A cell whose procedure zeroes it
(``zeroed``) takes off what one master scan at the nominal orientation says the cell adds there
(:meth:`optipose.evaluate.worker._Worker.zero`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from optipose.transforms import make_T, rpy_to_matrix

__all__ = ["RobotErrors", "CalibrationErrors", "path_draw", "orientation_error", "calibrated_poses"]


@dataclass(frozen=True)
class RobotErrors:
    """The robot's errors (SI: m, rad, relative); zero: the ideal robot."""

    path: float = 0.0
    path_rotation: float = 0.0
    path_correlation: float = 0.005
    step: float = 0.0
    orientation: float = 0.0

    @property
    def moves(self) -> bool:
        """Whether the path wanders at all (translation, rotation or step)."""
        return bool(self.path or self.path_rotation or self.step)


@dataclass(frozen=True)
class CalibrationErrors:
    """The calibration's errors, 1σ per axis (SI); zero: every sensor where the cell believes it is."""

    sensor_translation: float = 0.0
    sensor_rotation: float = 0.0
    frame_translation: float = 0.0
    frame_rotation: float = 0.0
    zeroed: bool = False  # the user's procedure zeroes the cell on a master part at the nominal orientation

    @property
    def off(self) -> bool:
        return bool(self.sensor_translation or self.sensor_rotation or self.frame_translation or self.frame_rotation)


def gauss_markov(
    n: int, spacing: float, length: float, sigma: float, rng: np.random.Generator, dims: int = 3
) -> np.ndarray:
    """(n, dims): a stationary Gauss-Markov (Ornstein-Uhlenbeck) process sampled every ``spacing`` (m), of
    standard deviation ``sigma`` and correlation exp(-|Δs| / ``length``)."""
    rho = float(np.exp(-spacing / length)) if length > 0 else 0.0
    e = rng.normal(size=(n, dims))
    out = np.empty((n, dims))
    out[0] = e[0]
    innovation = np.sqrt(1.0 - rho * rho)
    for k in range(1, n):
        out[k] = rho * out[k - 1] + innovation * e[k]
    return out * sigma


def path_draw(
    robot: RobotErrors, offsets: np.ndarray, step: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """The part's pose error at each profile of one scan: translations (n, 3) m and rotation vectors
    (n, 3) rad about the rotation centre. ``offsets`` (n,) m: the motion's nominal shifts along x."""
    n = len(offsets)
    t = gauss_markov(n, step, robot.path_correlation, robot.path, rng)
    w = gauss_markov(n, step, robot.path_correlation, robot.path_rotation, rng)
    t[:, 0] += rng.normal() * robot.step * np.asarray(offsets, float)
    return t, w


def orientation_error(robot: RobotErrors, rng: np.random.Generator) -> np.ndarray:
    """(3,) rad: how far the orientation the robot sets is off the commanded one, per axis."""
    return rng.normal(size=3) * robot.orientation


def calibrated_poses(
    calibration: CalibrationErrors, poses: list[np.ndarray], centre: np.ndarray, rng: np.random.Generator
) -> list[np.ndarray]:
    """Each sensor's true pose when the cell believes it at ``poses`` (4×4 ``T_O_S``): the frame's error
    (about ``centre``) and each sensor's own, drawn from ``rng`` in this order (a sensor's draw does not
    depend on how many sensors follow it)."""
    c = calibration
    R = rpy_to_matrix(rng.normal(size=3) * c.frame_rotation)
    t = rng.normal(size=3) * c.frame_translation
    frame = make_T(R, centre - R @ centre + t)
    out = []
    for T in poses:
        own = make_T(rpy_to_matrix(rng.normal(size=3) * c.sensor_rotation), rng.normal(size=3) * c.sensor_translation)
        out.append(frame @ np.asarray(T, float) @ own)
    return out
