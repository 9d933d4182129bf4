"""The virtual LLT scanner (SPEC §2–3, paper Algorithms 1–3).

The part is set to an orientation about a rotation centre and carried along ``+x_O`` in steps while the
sensors stay still. Rather than moving the mesh, the scanner moves the rays into the part's frame, so
the mesh's Embree scene is built once per part and every profile of every sensor in a scan goes to
Embree in one call. A point is measured when

1. the laser ray's first hit lies inside the measuring trapezoid,
2. the receiver sees the hit (no triangulation shadow), and
3. the material's intensity at the angle of incidence clears the detection threshold.

Noise is Gaussian along the laser ray with σ growing as intensity falls, then Z is quantised to the
device's output resolution. Profiles are turned into points in O with the motion undone (paper eq. 4),
through the same code that reads real raw profiles (:mod:`optipose.profiles`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from optipose.materials import Material, load_material
from optipose.profiles import EMPTY, profiles_to_points
from optipose.raycast import face_planes, make_caster, refine_hits
from optipose.sensor import SensorModel, load_sensor
from optipose.transforms import part_motion, validate_pose

__all__ = ["ScanMotion", "Scan", "Scanner"]

_SHADOW_OFFSET = 1e-6  # m: start shadow rays this far off the surface, along the normal


@dataclass(frozen=True)
class ScanMotion:
    """The part's travel along ``+x_O``: ``length`` (m) in ``step`` (m) increments, centred on the nominal pose.

    Profile k is taken with the part shifted by ``offsets()[k]``; the sensor poses are given at shift 0,
    so a sensor aimed at the middle of the part sweeps the whole scanning length.
    """

    length: float
    step: float = 0.5e-3

    def __post_init__(self) -> None:
        if not (self.length > 0 and self.step > 0):
            raise ValueError("scan length and step must be positive")

    @property
    def n_profiles(self) -> int:
        return max(1, int(round(self.length / self.step)))

    def offsets(self) -> np.ndarray:
        """Part shifts along +x_O (n_profiles,), m."""
        n = self.n_profiles
        return (np.arange(n) + 0.5) * self.step - 0.5 * n * self.step


@dataclass
class Scan:
    """One sensor's scan of the part at one orientation.

    points : (n, 3) float64, metres, in O with the scan motion undone (a cloud of the rotated part).
    profile, column : (n,) int32, which profile and which of the sensor's columns each point came from.
    intensity : (n,) float32, relative returned intensity.
    raw : (n_profiles, points_per_profile) float64, device-format heights in mm (EMPTY where nothing).
    """

    points: np.ndarray
    profile: np.ndarray
    column: np.ndarray
    intensity: np.ndarray
    raw: np.ndarray
    T_O_S: np.ndarray = field(repr=False)
    rpy: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __len__(self) -> int:
        return len(self.points)

    def __repr__(self) -> str:
        n_prof, n_col = self.raw.shape
        return f"Scan({len(self)} points from {n_prof} profiles x {n_col} columns, rpy_deg={np.rad2deg(self.rpy).round(3).tolist()})"


class Scanner:
    """A part seen by sensors of one model; the ray-casting scene is built here, once.

    mesh : a ``trimesh.Trimesh`` in metres (or anything with ``vertices`` (v, 3) and ``faces`` (f, 3)).
    sensor, material : models or preset names.
    backend : ray-casting back-end, see :func:`optipose.raycast.make_caster`.
    """

    def __init__(self, mesh, sensor: SensorModel | str, material: Material | str, backend: str = "auto"):
        self.vertices = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
        self.faces = np.ascontiguousarray(mesh.faces, dtype=np.int64)
        self.sensor = load_sensor(sensor)
        self.material = load_material(material)
        self.caster = make_caster(self.vertices, self.faces, backend)
        self._ray_o_S, self._ray_d_S = self.sensor.laser_rays()
        self._normals, self._offsets = face_planes(self.vertices, self.faces)
        self._on_hull = _supporting_faces(mesh, self._normals, self._offsets)

    # ------------------------------------------------------------------------------------------------
    def scan(
        self,
        T_O_S: np.ndarray,
        motion: ScanMotion,
        rpy: np.ndarray = (0.0, 0.0, 0.0),
        centre: np.ndarray = (0.0, 0.0, 0.0),
        offset: np.ndarray | None = None,
        rng: np.random.Generator | int | None = 0,
        noise: bool = True,
    ) -> Scan:
        """Scan with one sensor; see :meth:`scan_many`."""
        return self.scan_many([T_O_S], motion, rpy, centre, offset, rng, noise)[0]

    def scan_many(
        self,
        poses: list[np.ndarray],
        motion: ScanMotion,
        rpy: np.ndarray = (0.0, 0.0, 0.0),
        centre: np.ndarray = (0.0, 0.0, 0.0),
        offset: np.ndarray | None = None,
        rng: np.random.Generator | int | None = 0,
        noise: bool = True,
    ) -> list[Scan]:
        """Scan the part at orientation ``rpy`` (radians, about ``centre`` in m) with every sensor in ``poses``.

        poses : list of 4×4 ``T_O_S`` (sensor poses in O at the nominal scan position).
        offset : (3,) m, an extra translation of the part (protocols with translation offsets).
        rng : a Generator or a seed; ``noise=False`` gives exact surface points (still quantised to
            the output resolution only when noise is on).
        """
        poses = [validate_pose(T, f"sensor pose {i + 1}") for i, T in enumerate(poses)]
        rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        T_O_P = part_motion(np.asarray(rpy, float), np.asarray(centre, float), offset)
        shifts = motion.offsets()
        R_PO = T_O_P[:3, :3].T  # rotation taking O directions into the part's frame
        step_P = R_PO[:, 0]  # the +x_O motion, seen from the part

        n_prof, n_col = len(shifts), self.sensor.points_per_profile
        origins, dirs, receivers = [], [], []
        for T_O_S in poses:
            o_P = (self._ray_o_S @ T_O_S[:3, :3].T + T_O_S[:3, 3] - T_O_P[:3, 3]) @ R_PO.T  # at shift 0
            d_P = self._ray_d_S @ (R_PO @ T_O_S[:3, :3]).T
            origins.append(o_P[None, :, :] - shifts[:, None, None] * step_P)  # (n_prof, n_col, 3)
            dirs.append(np.broadcast_to(d_P, (n_prof, n_col, 3)))
            receivers.append(R_PO @ (T_O_S[:3, :3] @ self.sensor.receiver + T_O_S[:3, 3] - T_O_P[:3, 3]))
        rays = _Rays(
            origins=np.stack(origins).reshape(-1, 3),
            dirs=np.stack(dirs).reshape(-1, 3),
            receivers=np.asarray(receivers),
            shifts_P=shifts[:, None] * step_P,
            n_col=n_col,
            n_prof=n_prof,
        )

        t_S = np.full(len(rays.origins), np.nan)  # distance along the ray from the window, NaN = empty
        intensity = np.zeros(len(rays.origins), dtype=np.float32)
        idx, t, inten = self._measure(rays)
        if noise and len(idx):
            sigma = self.sensor.noise_sigma / np.sqrt(np.clip(inten, self.sensor.detection_threshold, 1.0))
            t = t + rng.normal(0.0, 1.0, len(idx)) * sigma
        t_S[idx] = t
        intensity[idx] = inten

        per_sensor = n_prof * n_col
        scans = []
        for j, T_O_S in enumerate(poses):
            sl = slice(j * per_sensor, (j + 1) * per_sensor)
            raw = self._to_raw(t_S[sl].reshape(n_prof, n_col), quantise=noise)
            pts, prof, col = profiles_to_points(raw, self.sensor, T_O_S, shifts)
            inten_j = intensity[sl].reshape(n_prof, n_col)[prof, col]
            scans.append(Scan(pts, prof, col, inten_j, raw, T_O_S, np.asarray(rpy, float)))
        return scans

    # ------------------------------------------------------------------------------------------------
    def _measure(self, rays: "_Rays") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Indices of measured rays (m,), their exact float64 distances from the window (m,) and
        intensities (m,)."""
        s = self.sensor
        col = np.tile(np.arange(rays.n_col), len(rays.origins) // rays.n_col)
        rate = self._ray_d_S[:, 2]  # d z_S / d t per column
        t_max = (s.z_far - s.window_z) / rate[col]  # nothing past the far end of the range is measured
        _, tri = self.caster.first_hit(rays.origins, rays.dirs, t_max)
        idx = np.flatnonzero(tri >= 0)
        tri = tri[idx]
        o, d = rays.origins[idx], rays.dirs[idx]
        t, normal = refine_hits(o, d, tri, self._normals, self._offsets)
        z = s.window_z + t * rate[col[idx]]
        cos_aoi = -np.einsum("ij,ij->i", normal, d)
        inten = self.material.intensity(np.arccos(np.clip(cos_aoi, -1.0, 1.0)))
        keep = (z >= s.z_near) & (z <= s.z_far) & (cos_aoi > 0) & (inten >= s.detection_threshold)
        if s.saturation > 0:
            keep &= inten <= s.saturation
        idx, t, normal, inten, tri = idx[keep], t[keep], normal[keep], inten[keep], tri[keep]

        p = rays.origins[idx] + t[:, None] * rays.dirs[idx]
        visible = self._receiver_sees(p, normal, rays.receiver_of(idx), self._on_hull[tri])
        return idx[visible], t[visible], inten[visible].astype(np.float32)

    def _receiver_sees(
        self, p: np.ndarray, normal: np.ndarray, receiver: np.ndarray, on_hull: np.ndarray
    ) -> np.ndarray:
        """(n,) bool: the segment from each hit ``p`` to the ``receiver`` (both (n, 3), part frame) is free.

        A hit on a face that lies in a supporting plane of the part (``on_hull``) and faces the receiver
        cannot be shadowed: the whole part is behind that plane. Only the other hits need a shadow ray.
        """
        front = np.einsum("ij,ij->i", receiver - p, normal) > 0
        test = np.flatnonzero(front & ~on_hull)
        visible = front.copy()
        if len(test):
            start = p[test] + _SHADOW_OFFSET * normal[test]
            visible[test] = ~self.caster.occluded(start, receiver[test] - start, np.ones(len(test)))
        return visible

    def _to_raw(self, t: np.ndarray, quantise: bool) -> np.ndarray:
        """Device-format heights (n_prof, n_col) in mm from ray distances (NaN = empty)."""
        s = self.sensor
        z = s.window_z + t * self._ray_d_S[:, 2]
        if quantise and s.z_resolution > 0:
            z = np.round(z / s.z_resolution) * s.z_resolution
        return np.where(np.isnan(z), EMPTY, -z * 1e3)


@dataclass
class _Rays:
    """All rays of one scan, sensor-major then profile then column, in the part's frame."""

    origins: np.ndarray  # (n, 3)
    dirs: np.ndarray  # (n, 3), unit
    receivers: np.ndarray  # (n_sensors, 3), receiver position at shift 0
    shifts_P: np.ndarray  # (n_prof, 3), the part's motion seen from the part
    n_col: int
    n_prof: int

    def receiver_of(self, idx: np.ndarray) -> np.ndarray:
        """Receiver position (m, 3) for rays ``idx`` (m,) at the time of their profile."""
        sensor, prof = np.divmod(idx // self.n_col, self.n_prof)
        return self.receivers[sensor] - self.shifts_P[prof]


def _supporting_faces(mesh, normals: np.ndarray, offsets: np.ndarray, tol: float = 1e-9) -> np.ndarray:
    """(f,) bool: the face's plane has the whole part behind it (the face lies on the convex hull)."""
    try:
        hull = np.asarray(mesh.convex_hull.vertices, dtype=np.float64)
    except Exception:  # qhull fails on flat or degenerate meshes: then test every hit
        return np.zeros(len(normals), dtype=bool)
    out = np.zeros(len(normals), dtype=bool)
    for a in range(0, len(normals), 4096):  # bounded memory: (chunk, hull vertices)
        b = min(a + 4096, len(normals))
        height = hull @ normals[a:b].T - offsets[a:b]
        out[a:b] = height.max(axis=0) <= tol
    return out & (np.linalg.norm(normals, axis=1) > 0.5)
