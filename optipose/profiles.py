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
from optipose.sensor import SensorModel

__all__ = ["EMPTY", "profiles_to_points", "write_profiles", "read_profiles"]

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
    z = -raw[prof, col] * 1e-3
    o_S, d_S = sensor.laser_rays()
    t = (z - o_S[col, 2]) / d_S[col, 2]
    p_S = o_S[col] + t[:, None] * d_S[col]
    p_O = p_S @ T_O_S[:3, :3].T + T_O_S[:3, 3]
    p_O[:, 0] -= np.asarray(shifts, dtype=np.float64)[prof]
    return p_O, prof.astype(np.int32), col.astype(np.int32)


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
