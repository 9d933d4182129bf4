"""What a scan gives: the :class:`Scan` record, one sensor's points in O with where each came from, and
:func:`rebuilt_with`, a scan rebuilt with the pose a cell believes its sensor stands at."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

__all__ = ["Scan", "rebuilt_with"]


@dataclass
class Scan:
    """One sensor's scan of the part at one orientation.

    points : (n, 3) float64, metres, in O with the scan motion undone (a cloud of the rotated part).
    profile, column : (n,) int32, which profile and which of the sensor's columns each point came from.
    intensity : (n,) float32, relative returned intensity.
    raw : (n_profiles, points_per_profile) float64, device-format heights in mm (EMPTY where nothing); (0, points_per_profile) when not kept.
    face : (n,) int32, the mesh triangle each point lies on (see :meth:`optipose.scan.scanner.Scanner.normals`).
    """

    points: np.ndarray
    profile: np.ndarray
    column: np.ndarray
    intensity: np.ndarray
    raw: np.ndarray
    T_O_S: np.ndarray = field(repr=False)
    rpy: np.ndarray = field(default_factory=lambda: np.zeros(3))
    face: np.ndarray | None = field(default=None, repr=False)  # (n,) int32, the mesh triangle of each point
    T_O_P: np.ndarray | None = field(default=None, repr=False)  # the part's pose (rotation about the centre)

    def __len__(self) -> int:
        return len(self.points)

    def __repr__(self) -> str:
        n_prof, n_col = self.raw.shape
        where = f"{n_prof} profiles x {n_col} columns" if n_prof else f"{n_col} columns (raw profiles not kept)"
        return f"Scan({len(self)} points from {where}, rpy_deg={np.rad2deg(self.rpy).round(3).tolist()})"


def rebuilt_with(scan: Scan, T_O_S: np.ndarray, shifts: np.ndarray) -> Scan:
    """The scan of a sensor that stood at ``scan.T_O_S`` rebuilt as if it stood at ``T_O_S``: what a cell
    reports when a bracket is off its drawing (the device measures in its own frame; the cell turns that
    into O with the pose it believes). ``shifts`` (n_profiles,) m are the motion's offsets."""
    T_true, s = scan.T_O_S, np.asarray(shifts, dtype=float)[scan.profile]
    moved = scan.points.copy()
    moved[:, 0] += s  # back to where the part was when the profile was taken
    p_S = (moved - T_true[:3, 3]) @ T_true[:3, :3]
    points = p_S @ T_O_S[:3, :3].T + T_O_S[:3, 3]
    points[:, 0] -= s
    return replace(scan, points=points, T_O_S=T_O_S)
