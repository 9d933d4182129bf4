"""The virtual LLT scanner (docs/sensor.md, docs/method.md; paper Algorithms 1–3).

The part is set to an orientation about a rotation centre and carried along ``+x_O`` in steps while the
sensors stay still. Rather than moving the mesh, the scanner moves the rays into the part's frame, so
the mesh's Embree scene is built once per part and every profile of every sensor in a scan goes to
Embree in one call. A point is measured when

1. the laser ray's first hit lies inside the measuring trapezoid,
2. the receiver sees the hit (no triangulation shadow), and
3. the material's intensity at the angle of incidence clears the detection threshold.

Noise is Gaussian along the laser ray with σ growing as intensity falls, then Z is quantised to the
device's output resolution. Profiles are turned into points in O with the motion undone (paper eq. 4),
through the same code that reads real raw profiles (:mod:`optipose.scan.profiles`). Each sensor is cast
through its view from the part (:class:`optipose.scan.view.SensorView`); each scan is a
:class:`optipose.scan.cloud.Scan`.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from optipose.model.material import Material, load_material
from optipose.model.motion import ScanMotion
from optipose.scan.cloud import Scan
from optipose.scan.kernels import (
    NORMAL_QUANTILES,
    fill_columns,
    measure_hits,
    shadow_rays,
    split_at_anchors,
    unsure_between_anchors,
    write_points,
)
from optipose.scan.hull import face_arrays
from optipose.scan.pose import NOMINAL, PartPose
from optipose.scan.profiles import EMPTY, ray_lines
from optipose.scan.raycast import default_threads, make_caster, scene_mesh
from optipose.scan.view import SensorView
from optipose.model.sensor import SensorModel, load_sensor
from optipose.transforms import part_motion, validate_pose

__all__ = [
    "Scanner",
    "PartPose",
    "part_scanner",
    "nominal_scans",
    "SCAN_PROFILES",
    "registered_motion",
]

_SHADOW_OFFSET = 1e-6  # m: start shadow rays this far off the surface, along the normal
_BLOCK_PROFILES = (
    8  # profiles per unit of work on a thread pool (each point's noise draw is keyed by its ray, not its block)
)
_SERIAL_BLOCK_PROFILES = 32  # ... and on one thread, where smaller blocks only add per-block overhead
COLUMN_STRIDE = 16  # cast every this many columns, and the columns between only where their anchors disagree
# Profiles of a registered scan at most (:func:`registered_motion`): 64 mm at the default 0.5 mm step; the
# shipped parts' scans (12-60 mm of travel) take 24-120.
SCAN_PROFILES = 128


class Scanner:
    """A part seen by sensors of one model; the ray-casting scene is built here, once.

    mesh : a ``trimesh.Trimesh`` in metres (or anything with ``vertices`` (v, 3) and ``faces`` (f, 3)).
    sensor, material : models or preset names.
    backend : ray-casting back-end, see :func:`optipose.scan.raycast.make_caster`.
    threads : worker threads for one scan (default: the cores this process may use, or
        ``OPTIPOSE_RAY_THREADS``). Results do not depend on it.
    occluders : axis-aligned boxes ``(lo (3,), hi (3,))`` in the part's frame, m, that travel with the part
        (a part's keep-outs: the flange it is held by). They cast shadows and hide what is behind them but
        are never measured.
    column_stride : cast every ``column_stride``-th column of a profile (the anchors); the columns between
        two anchors that hit the same triangle (or two triangles of one plane, where the ray's point on it
        lies inside one of them) hit it too and are not cast (:func:`fill_columns`), the others are. 1 casts
        every column. The points are the same either way, but for a feature thinner than the anchors'
        spacing (stride × the column pitch).
    """

    def __init__(
        self,
        mesh,
        sensor: SensorModel | str,
        material: Material | str,
        backend: str = "auto",
        threads: int | None = None,
        occluders: list[tuple[np.ndarray, np.ndarray]] | None = None,
        column_stride: int = COLUMN_STRIDE,
    ):
        self.n_part_faces = len(mesh.faces)
        mesh = scene_mesh(mesh, occluders)  # keep-outs (the flange) block the laser and the receiver
        self.vertices = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
        self._bounds = (
            self.vertices.min(axis=0) - 1e-6,
            self.vertices.max(axis=0) + 1e-6,
        )  # the scene's box, keep-outs included
        self.faces = np.ascontiguousarray(mesh.faces, dtype=np.int64)
        self.sensor = load_sensor(sensor)
        self.material = load_material(material)
        self.caster = make_caster(self.vertices, self.faces, backend, threads=1)
        self.threads = threads or default_threads()
        self._pool = ThreadPoolExecutor(self.threads) if self.threads > 1 else None
        self._block = _BLOCK_PROFILES if self._pool else _SERIAL_BLOCK_PROFILES
        self._plane, self._normals, self._offsets, self._edge_n, self._edge_c, self._on_hull = face_arrays(
            mesh, self.vertices, self.faces
        )
        self._ray_o_S, self._ray_d_S = self.sensor.laser_rays()
        self._ray_cos, self._ray_sin = self._ray_d_S[:, 2].copy(), self._ray_d_S[:, 0].copy()
        self._ray_lines = ray_lines(self._ray_o_S, self._ray_d_S)
        s = self.sensor
        t_max = ((s.z_far - s.window_z) / self._ray_d_S[:, 2]).astype(np.float32)
        self._t_max = t_max
        n_col, stride = self.sensor.points_per_profile, max(1, int(column_stride))
        self.column_stride = stride
        self._anchors = np.unique(np.r_[np.arange(0, n_col, stride), n_col - 1]) if stride > 1 else None
        # intensity as a function of cos(AoI), tabulated once: one interp per hit instead of a formula
        self._intensity_grid = self.material.intensity(np.arccos(np.linspace(0.0, 1.0, 8193)))

    # ------------------------------------------------------------------------------------------------
    def scan(
        self,
        T_O_S: np.ndarray,
        motion: ScanMotion,
        part_pose: PartPose = NOMINAL,
        rng: np.random.Generator | int | None = 0,
        noise: bool = True,
    ) -> Scan:
        """Scan with one sensor; see :meth:`scan_many`."""
        return self.scan_many([T_O_S], motion, part_pose, rng, noise)[0]

    def scan_many(
        self,
        poses: list[np.ndarray],
        motion: ScanMotion,
        part_pose: PartPose = NOMINAL,
        rng: np.random.Generator | int | None = 0,
        noise: bool = True,
        raw: bool = True,
    ) -> list[Scan]:
        """Scan the part, standing at ``part_pose`` (its orientation about its rotation centre, and an offset),
        with every sensor in ``poses``.

        poses : list of 4×4 ``T_O_S`` (sensor poses in O at the nominal scan position).
        part_pose : a :class:`~optipose.scan.pose.PartPose` (default: unturned, about O's origin).
        rng : a seed or a Generator (one draw is taken from it); the same seed gives the same clouds
            whatever the thread count. ``noise=False`` gives exact, unquantised surface points.
        raw : ``False`` (the evaluator's: it reads only the points) leaves ``Scan.raw`` empty, (0, columns).
        """
        return self.scan_levels(poses, motion, (1.0,), part_pose, rng, noise, raw)[0]

    def scan_levels(
        self,
        poses: list[np.ndarray],
        motion: ScanMotion,
        noise_scales: tuple[float, ...],
        part_pose: PartPose = NOMINAL,
        rng: np.random.Generator | int | None = 0,
        noise: bool = True,
        raw: bool = True,
        built: list[np.ndarray] | None = None,
        only: list[int] | None = None,
    ) -> list[list[Scan]]:
        """:meth:`scan_many` at several noise levels at once: one list of scans per scale of ``noise_scales``,
        each as a scanner whose sensor's ``noise_sigma`` is that many times this one's would take it. The
        rays are cast once (where they hit does not depend on the noise), and every level draws the same
        standard normals per ray, scaled by its σ.

        built : per sensor, the pose (4×4 ``T_O_S``) its cloud is built with when it is not the pose it scans
            from — a bracket off its drawing: the device measures in its own frame and the cell turns that into
            O with the pose it believes (:func:`optipose.scan.cloud.rebuilt_with` of the scan, without the round
            trip through the true pose); each scan's ``T_O_S`` is then that pose.
        only : the indices of ``poses`` to scan (default every one), each as it is scanned among them all (its noise
            key is its index's): the scans of these alone."""
        if not isinstance(part_pose, PartPose):  # a caller of the old (rpy, centre, offset) arguments
            raise TypeError(f"part_pose must be a PartPose, not {type(part_pose).__name__}")
        poses = [validate_pose(T, f"sensor pose {i + 1}") for i, T in enumerate(poses)]
        seed = int(rng.integers(2**63)) if isinstance(rng, np.random.Generator) else int(rng or 0)
        T_O_P = part_pose.T_O_P
        shifts = motion.offsets()
        # one nonzero 64-bit noise key per sensor of this scan (0 means no noise)
        keys = [np.uint64(int(k) | 1) for k in np.random.default_rng([seed, 0x5CA7]).integers(1, 2**63, len(poses))]
        keys = keys if noise else [np.uint64(0)] * len(poses)
        if only is not None:
            poses, keys = [poses[i] for i in only], [keys[i] for i in only]
            built = None if built is None else [built[i] for i in only]
        views = [self._view(T, T_O_P) for T in poses]
        blocks = [
            (j, k0, min(k0 + self._block, len(shifts)))
            for j in range(len(poses))
            for k0 in range(0, len(shifts), self._block)
        ]

        run = self._pool.map if self._pool else map
        hits = list(run(lambda blk: self._block_hits(views[blk[0]], shifts, blk[1], blk[2]), blocks))
        built = poses if built is None else [validate_pose(T, f"built pose {i + 1}") for i, T in enumerate(built)]
        return [
            self._written(built, blocks, hits, keys, shifts, T_O_P, part_pose.rpy, raw, self.sensor.noise_sigma * scale)
            for scale in noise_scales
        ]

    def _written(self, poses, blocks, hits, keys, shifts, T_O_P, rpy, raw: bool, sigma: float) -> list[Scan]:
        """Phase 2 of a scan: every block's hits written straight into its slice of the scans' arrays (no
        concatenation), with noise of ``sigma`` (m) at full intensity, each sensor's points in O by ``poses``."""
        run = self._pool.map if self._pool else map
        n_col, scans, jobs = self.sensor.points_per_profile, [], []
        for j, T_O_S in enumerate(poses):
            mine = [(blk, h) for blk, h in zip(blocks, hits) if blk[0] == j]
            n = sum(len(h[0]) for _, h in mine)
            scan = Scan(
                points=np.empty((n, 3)),
                profile=np.empty(n, np.int32),
                column=np.empty(n, np.int32),
                intensity=np.empty(n, np.float32),
                raw=np.full((len(shifts) if raw else 0, n_col), EMPTY),
                T_O_S=T_O_S,
                rpy=np.asarray(rpy, float),
                face=np.empty(n, np.int32),
                T_O_P=T_O_P,
            )
            start = 0
            for blk, h in mine:
                jobs.append((scan, blk, h, slice(start, start + len(h[0]))))
                start += len(h[0])
            scans.append(scan)

        def write(job):
            scan, (j, k0, k1), (idx, T, inten, tri), sl = job
            s = self.sensor
            write_points(
                idx,
                T,
                inten,
                keys[j],
                NORMAL_QUANTILES,
                n_col,
                k0,
                shifts[k0:k1],
                self._ray_cos,
                *self._ray_lines,
                s.apex_z,
                sigma,
                s.detection_threshold,
                s.z_resolution,
                scan.T_O_S[:3, :3],
                scan.T_O_S[:3, 3],
                scan.raw[k0:k1].reshape(-1),
                scan.points[sl],
                scan.profile[sl],
                scan.column[sl],
            )
            scan.intensity[sl] = inten
            scan.face[sl] = tri

        list(run(write, jobs))
        return scans

    def _view(self, T_O_S: np.ndarray, T_O_P: np.ndarray) -> SensorView:
        """One sensor at ``T_O_S`` seen from the part at ``T_O_P`` (:class:`~optipose.scan.view.SensorView`)."""
        return SensorView.build(self.sensor, self._ray_o_S, self._ray_d_S, self._t_max, T_O_S, T_O_P)

    def primary_rays(self, T_O_S: np.ndarray, motion: ScanMotion) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The laser rays of a whole scan at the nominal orientation, as the scanner casts them (part frame,
        float32): origins (n, 3), directions (n, 3) and far limits (n,), n = profiles × points per profile.
        For benchmarks that cast the same rays with another ray caster."""
        view = self._view(T_O_S, part_motion(np.zeros(3), np.zeros(3)))
        shifts = motion.offsets()
        return view.rays(np.arange(len(shifts) * self.sensor.points_per_profile), shifts, self._t_max)

    @property
    def lines(self) -> tuple[np.ndarray, np.ndarray]:
        """Each column's laser ray in the laser plane, ``x_S = x0 + slope·z_S``: x0 (n_col,), slope (n_col,)."""
        return self._ray_lines

    @property
    def face_normals(self) -> np.ndarray:
        """(f, 3): each face's outward unit normal in the part's frame (a plane's faces share one), keep-outs' faces after the part's."""
        return self._normals

    def normals(self, scan: Scan) -> np.ndarray:
        """Unit surface normals (n, 3) in O at a scan's points (outward, of the rotated part)."""
        return self._normals[scan.face] @ scan.T_O_P[:3, :3].T

    # ------------------------------------------------------------------------------------------------
    def _block_hits(self, view: SensorView, shifts: np.ndarray, k0: int, k1: int):
        """Profiles k0..k1-1 of one sensor: the measured hits as (ray index in the block (n,), distance from
        the apex (n,) float64, intensity (n,), triangle (n,)).

        Every ray of a view lies in the laser plane and starts on a line through the fan's apex, so the
        float64 hit on triangle f along ray c at shift s reduces to per-face and per-column scalars:
        ``T = (q_f + s·b_f) / (cos_c·nu_f + sin_c·nw_f)`` (distance from the apex); the compiled kernel
        :func:`measure_hits` applies the range, angle, intensity and receiver-side tests in one pass.
        3-vectors are formed only for the hits that still need a shadow ray.
        """
        s, n_col, m = self.sensor, self.sensor.points_per_profile, k1 - k0
        shift_b = shifts[k0:k1]
        ray_tri = self._first_triangles(view, shift_b)
        idx, T, inten, tri, test = measure_hits(
            ray_tri,
            self.n_part_faces,
            n_col,
            shift_b,
            self._ray_cos,
            self._ray_sin,
            self._normals,
            self._offsets,
            view.frame,
            self._on_hull,
            s.apex_z,
            s.z_near,
            s.z_far,
            self._intensity_grid,
            s.detection_threshold,
            s.saturation,
        )
        test = np.flatnonzero(test)
        if len(test):
            keep = np.ones(len(idx), dtype=bool)
            if (
                self._anchors is not None
            ):  # anchors first; between two that see the receiver on one triangle, so does every hit
                test = self._shadows_between_anchors(view, idx, T, tri, test, ray_tri, shift_b, keep)
            sub = idx[test]
            keep[test] = self._receiver_sees(view, T[test], sub % n_col, shift_b[sub // n_col], tri[test])
            idx, T, inten, tri = idx[keep], T[keep], inten[keep], tri[keep]
        return idx, T, inten, tri

    def _shadows_between_anchors(self, view, idx, T, tri, test, ray_tri, shift_b, keep) -> np.ndarray:
        """Trace the shadow rays of the anchor columns' hits (into ``keep``) and return the hits still to
        trace: those whose two anchors are not both seen by the receiver on the hit's own triangle. Between
        two such anchors the hits lie on one segment of one triangle, and a shadow edge would have to
        cross it and come back within the anchors' spacing."""
        n_col, stride = self.sensor.points_per_profile, self.column_stride
        first, rest = split_at_anchors(idx, test, n_col, stride)
        sub = idx[first]
        keep[first] = self._receiver_sees(view, T[first], sub % n_col, shift_b[sub // n_col], tri[first])
        return unsure_between_anchors(idx, tri, keep, rest, ray_tri, n_col, stride, self._plane) if len(rest) else rest

    def _first_triangles(self, view: SensorView, shift_b: np.ndarray) -> np.ndarray:
        """The first triangle (-1: none) of each ray of a block's profiles × columns (see ``column_stride``).
        A profile whose fan (a trapezoid) lies outside the scene's box cannot hit anything and casts no ray."""
        n_col, caster, t_max, m = self.sensor.points_per_profile, self.caster, self._t_max, len(shift_b)
        moved = shift_b[:, None] * view.step_P
        live = np.flatnonzero(
            np.all(view.fan_hi - moved >= self._bounds[0], axis=1)
            & np.all(view.fan_lo - moved <= self._bounds[1], axis=1)
        )
        cols = self._anchors if self._anchors is not None else np.arange(n_col)
        anchor_tri = np.full((m, len(cols)), -1, dtype=np.int32)
        if len(live):
            rays = (live[:, None] * n_col + cols[None]).ravel()
            anchor_tri[live] = np.asarray(caster.first_triangle(*view.rays(rays, shift_b, t_max))).reshape(
                len(live), len(cols)
            )
        if self._anchors is None:
            return anchor_tri.ravel()
        tri, need = fill_columns(
            anchor_tri,
            self._anchors,
            n_col,
            self._plane,
            shift_b,
            self._ray_cos,
            self._ray_sin,
            self._normals,
            self._offsets,
            view.frame,
            view.d_P,
            self._edge_n,
            self._edge_c,
        )
        if len(need):
            tri[need] = caster.first_triangle(*view.rays(need, shift_b, t_max))
        return tri

    def _receiver_sees(self, view, T, col, shift, tri) -> np.ndarray:
        """(n,) bool: nothing blocks the segment from each hit to the receiver (no triangulation shadow).

        Only hits on faces off the convex hull come here: a face in a supporting plane of the part that
        faces the receiver cannot be shadowed, since the whole part lies behind that plane.
        """
        start, direction = shadow_rays(
            T, col, shift, tri, view.apex_P, view.d_P, view.step_P, view.receiver_P, self._normals, _SHADOW_OFFSET
        )
        return ~self.caster.occluded(start, direction, np.ones(len(T), dtype=np.float32))


def registered_motion(motion: ScanMotion) -> ScanMotion:
    """The motion a scan that is registered (an evaluation's) takes: ``motion`` itself up to
    :data:`SCAN_PROFILES` profiles, else the same travel in the least whole multiple of its step that
    brings it under. A registration's cost grows with the voxels a scan fills, that is with its profiles:
    a metre-long part at 0.5 mm would fill a thousand times a shipped part's, most of them along the same
    few faces; in longer steps its scans cost what a 64 mm part's do (each voxel as a shipped part's:
    every column of its profile)."""
    k = -(-motion.n_profiles // SCAN_PROFILES)
    return motion if k <= 1 else ScanMotion(motion.length, motion.step * k)


def part_scanner(part, sensor=None, material=None, **kwargs) -> Scanner:
    """The :class:`Scanner` of a :class:`~optipose.model.part.Part` (its sensor and material unless given),
    its keep-outs as occluders (the flange hides what it covers)."""
    return Scanner(part.mesh, sensor or part.sensor, material or part.material, occluders=part.occluders, **kwargs)


def nominal_scans(part, layout: str = "hand") -> dict:
    """One scan per sensor of ``part.layouts[layout]`` at the nominal orientation: {sensor name: Scan}.

    Each sensor uses its own model when the layout names one, else the part's.
    """
    from optipose.errors import ConfigError

    if layout not in part.layouts:
        have = ", ".join(part.layouts) or "none"
        raise ConfigError(f"part '{part.name}' has no layout '{layout}' (layouts: {have})")
    scanners: dict = {}
    out = {}
    for pose in part.layouts[layout].sensors:
        model = pose.sensor or part.sensor
        if model not in scanners:
            scanners[model] = part_scanner(part, model)
        out[pose.name] = scanners[model].scan(pose.T_O_S, part.motion, PartPose(centre=part.rotation_centre))
    return out
