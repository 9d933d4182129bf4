"""Raw profiles in the device's format, and turning profiles into points in O (paper eq. 4).

A profile is ``points_per_profile`` Z values (3200 for the LJ-X8080), in millimetres, as the device
reports them: height above the reference plane through R, positive toward the head (``Z = -z_S``),
``-9999.9999`` where no point was measured. X is not stored: as on the device, it follows from the
column and the height through the sensor's optics (:meth:`SensorModel.laser_rays`).

Files: ``.csv`` / ``.txt`` — one profile per line, comma-separated, ``%.4f``, lines starting with ``#``
are comments; ``.npy`` — an array (n_profiles, points_per_profile) float64.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from optipose.errors import ConfigError
from optipose.model.sensor import SensorModel

__all__ = ["EMPTY", "profiles_to_points", "heights_to_points", "ray_lines", "write_profiles", "read_profiles"]

EMPTY = -9999.9999


def profiles_to_points(
    raw: np.ndarray, sensor: SensorModel, T_O_S: np.ndarray, shifts: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points in O (n, 3) m, with their profile (n,) and column (n,) indices, from raw profiles.

    raw : (n_profiles, points_per_profile) heights in mm, EMPTY where nothing was measured.
    T_O_S : 4×4 sensor pose in O at the nominal scan position.
    shifts : (n_profiles,) m, how far the part had travelled along +x_O for each profile; undone here.
    """
    raw = np.asarray(raw, dtype=np.float64)
    if raw.ndim != 2 or raw.shape[1] != sensor.points_per_profile:
        raise ConfigError(
            f"raw profiles must be (n, {sensor.points_per_profile}) for sensor '{sensor.name}', got {raw.shape}"
        )
    if len(shifts) != len(raw):
        raise ConfigError(f"{len(raw)} profiles but {len(shifts)} scan positions")
    prof, col = np.nonzero(raw > EMPTY + 1.0)
    shift = np.asarray(shifts, dtype=np.float64)[prof]
    points = heights_to_points(-raw[prof, col] * 1e-3, col, shift, ray_lines(*sensor.laser_rays()), T_O_S)
    return points, prof.astype(np.int32), col.astype(np.int32)


def ray_lines(o_S: np.ndarray, d_S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each column's laser ray as ``x_S = x0 + slope·z_S`` in the laser plane: x0 (n_col,), slope (n_col,).

    o_S, d_S : (n_col, 3) ray origins and directions in S (:meth:`SensorModel.laser_rays`).
    """
    slope = d_S[:, 0] / d_S[:, 2]
    return o_S[:, 0] - o_S[:, 2] * slope, slope


def heights_to_points(
    z_S: np.ndarray, col: np.ndarray, shift: np.ndarray, lines: tuple[np.ndarray, np.ndarray], T_O_S: np.ndarray
) -> np.ndarray:
    """Points in O (n, 3) from depths ``z_S`` (n,) m on the laser rays ``col`` (n,), motion undone.

    lines : the columns' rays from :func:`ray_lines`.
    shift : (n,) m, the part's travel along +x_O when each point was taken (paper eq. 4 undoes it).
    """
    x0, slope = lines
    x_S = x0[col] + z_S * slope[col]
    R, t = T_O_S[:3, :3], T_O_S[:3, 3]
    p_O = np.empty((3, len(z_S))).T  # column-major: each coordinate is one contiguous 1-D pass
    for i in range(3):
        p_O[:, i] = t[i]
        if R[i, 0] != 0.0:  # axis-aligned sensors skip the zero terms
            p_O[:, i] += x_S * R[i, 0]
        if R[i, 2] != 0.0:
            p_O[:, i] += z_S * R[i, 2]
    p_O[:, 0] -= shift
    return p_O


def write_profiles(path: str | Path, raw: np.ndarray, header: str = "") -> Path:
    """Write raw profiles (n, m) as ``.npy`` or as device-style text (``.csv`` / ``.txt``)."""
    path = Path(path)
    raw = np.asarray(raw, dtype=np.float64)
    if path.suffix == ".npy":
        np.save(path, raw)
    else:
        np.savetxt(path, raw, fmt="%.4f", delimiter=",", header=header, comments="# ")
    return path


def read_profiles(path: str | Path, points_per_profile: int | None = None) -> np.ndarray:
    """Read raw profiles written by :func:`write_profiles` or exported from a device (one profile a line)."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"profile file not found: {path}")
    try:
        raw = np.load(path) if path.suffix == ".npy" else np.loadtxt(path, delimiter=",", comments="#", ndmin=2)
    except ValueError as exc:
        raise ConfigError(f"cannot read profiles from {path}: {exc}") from None
    if raw.ndim != 2 or (points_per_profile and raw.shape[1] != points_per_profile):
        raise ConfigError(f"{path}: expected rows of {points_per_profile} values, got shape {raw.shape}")
    return raw
