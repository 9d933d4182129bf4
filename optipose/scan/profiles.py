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
from optipose.scan.heights import heights_to_points

__all__ = ["EMPTY", "profiles_to_points", "ray_lines", "write_profiles", "read_profiles"]

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
    prof, col = np.nonzero(raw > EMPTY + 1.0)  # profile-major, columns ascending: the scanner's order of points
    x0, slope = ray_lines(*sensor.laser_rays())
    T = np.asarray(T_O_S, dtype=np.float64)
    points = heights_to_points(
        np.ascontiguousarray(raw[prof, col]),
        prof,
        col,
        np.ascontiguousarray(shifts, dtype=np.float64),
        x0,
        slope,
        np.ascontiguousarray(T[:3, :3]),
        np.ascontiguousarray(T[:3, 3]),
    )
    return points, prof.astype(np.int32), col.astype(np.int32)


def ray_lines(o_S: np.ndarray, d_S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each column's laser ray as ``x_S = x0 + slope·z_S`` in the laser plane: x0 (n_col,), slope (n_col,).

    o_S, d_S : (n_col, 3) ray origins and directions in S (:meth:`SensorModel.laser_rays`).
    """
    slope = d_S[:, 0] / d_S[:, 2]
    return o_S[:, 0] - o_S[:, 2] * slope, slope


def write_profiles(path: str | Path, raw: np.ndarray, header: str = "", format: str | None = None) -> Path:
    """Write raw profiles (n, m) as ``.npy`` or as device-style text (``.csv`` / ``.txt``); ``format``
    ("npy", "csv"): which, whatever the name (default: by its suffix)."""
    path = Path(path)
    raw = np.asarray(raw, dtype=np.float64)
    if (format or path.suffix.lstrip(".")) == "npy":
        with open(path, "wb") as f:  # a file, not a name: numpy would add ".npy" to one without it
            np.save(f, raw)
    else:
        np.savetxt(path, raw, fmt="%.4f", delimiter=",", header=header, comments="# ")
    return path


def read_profiles(path: str | Path, points_per_profile: int | None = None) -> np.ndarray:
    """Raw profiles (n, points_per_profile) mm read from a file written by :func:`write_profiles` or exported
    from a device (one profile a line). A missing file, a profile of another length than
    ``points_per_profile`` (when given) or a value that is no number (NaN: the empty point is -9999.9999)
    is one :class:`ConfigError` naming the file and the profile (counting from 0)."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"profile file not found: {path}")
    if path.suffix == ".npy":
        try:
            raw = np.load(path, allow_pickle=False)
        except (ValueError, OSError, EOFError) as exc:
            raise ConfigError(f"{path}: not a .npy array of profiles ({exc})") from None
        raw = np.atleast_2d(raw) if raw.ndim == 1 else raw
        if raw.ndim != 2 or not np.issubdtype(raw.dtype, np.number):
            raise ConfigError(f"{path}: expected an array (profiles, values) of numbers, got {raw.dtype} {raw.shape}")
        rows = [raw.shape[1]] * len(raw)
    else:
        raw, rows = _read_text(path)
    n = points_per_profile or (rows[0] if rows else 0)
    wrong = next((k for k, m in enumerate(rows) if m != n), None)
    if wrong is not None:
        raise ConfigError(f"{path}: profile {wrong} has {rows[wrong]} values, the sensor gives {n} a profile")
    raw = np.asarray(raw, dtype=np.float64).reshape(len(rows), n)
    bad = np.flatnonzero(~np.isfinite(raw).all(axis=1))
    if len(bad):
        raise ConfigError(f"{path}: profile {bad[0]} holds NaN or infinity (an empty point is {EMPTY})")
    return raw


def _read_text(path: Path) -> tuple[list, list[int]]:
    """The numbers of a device-style text file, one profile a line (``#`` lines are comments), and each
    profile's count."""
    values, rows = [], []
    with open(path, encoding="utf-8", errors="replace") as f:
        for line in f:
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            try:
                row = np.array(line.replace(";", ",").split(","), dtype=np.float64)
            except ValueError:
                raise ConfigError(f"{path}: profile {len(rows)} holds a value that is not a number") from None
            values.append(row)
            rows.append(len(row))
    if not rows:
        raise ConfigError(f"{path}: no profiles")
    if len(set(rows)) > 1:
        return values, rows  # the caller names the profile of the wrong length
    return np.concatenate(values), rows
