"""How fast is the virtual LLT scanner, and what does its speed rest on? One run, the same rays for everyone.

Part B's envelope (a 60 × 41 × 17.6 mm block, x from 0 to 60 mm, y centred, z from 0 to 17.6 mm) is
scanned by the ``keyence-lj-x8080`` over ``ScanMotion(0.060)``: 120 profiles × 3200 points = 384,000
laser rays, black PLA, from the paper's S2 (straight down at the top face) and S1 (diagonal). Timed:

* ``scanner``       — ``Scanner.scan`` at full fidelity (trapezoid, AoI intensity, shadow, noise,
                      quantisation, raw profiles, points in O).
* ``bare embreex``  — only the primary rays, exactly as the scanner builds them in the part frame, through
                      ``EmbreeCaster.first_triangle`` with the scanner's thread count: the floor the
                      scanner's overhead is measured against (ray-rate ratio, target >= 0.7).
* ``bare open3d``   — the same rays through ``Open3DCaster`` (Open3D's RaycastingScene): backs the choice of
                      ``raycast.DEFAULT_BACKEND``.
* ``naive loop``    — an in-process baseline: one embreex call per profile plus one for its shadow rays,
                      per-profile numpy for hits, AoI and intensity (how one would write it on trimesh).
* ``engeom``        — the peer simulator's ``PanningLaserProfile`` (Rust, parry3d BVH) with the same fan,
                      trapezoid, receiver, 3200 points, 120 steps of 0.5 mm.

Contenders run interleaved (A B C … A B C …, the start rotated each round) so a noisy, shared machine hits
them all alike; the table shows medians. Usage::

    .venv/bin/python benchmarks/bench_scanner.py [--repeats N]

Set ``OPTIPOSE_RAY_THREADS`` to change the scanner's (and the bare embreex cast's) thread count.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
import tracemalloc
from importlib.metadata import version

import numpy as np
import trimesh
from rich.console import Console
from rich.table import Table

from optipose.scan.raycast import EmbreeCaster, Open3DCaster
from optipose.model.motion import ScanMotion
from optipose.scan.scanner import Scanner

BLOCK_EXTENTS = (0.060, 0.041, 0.0176)  # m, part B's envelope
SENSOR, MATERIAL = "keyence-lj-x8080", "black-pla"
POSES = {  # T_O_S, the paper's eqs. (1)-(2) (0.175 read as 0.0175)
    "S2": np.array([[0, 1, 0, 0.030], [1, 0, 0, 0], [0, 0, -1, 0.0175], [0, 0, 0, 1]], dtype=float),
    "S1": np.array(
        [[0, 1, 0, 0.03], [0.7071, 0, 0.7071, -0.023], [0.7071, 0, -0.7071, 0.015], [0, 0, 0, 1]], dtype=float
    ),
}
_SHADOW_OFFSET = 1e-6  # m, as in the scanner


def make_block() -> trimesh.Trimesh:
    """The block in metres: x in [0, 60] mm, y centred, z in [0, 17.6] mm."""
    box = trimesh.creation.box(extents=BLOCK_EXTENTS)
    box.apply_translation([BLOCK_EXTENTS[0] / 2, 0.0, BLOCK_EXTENTS[2] / 2])
    return box


def scanner_rays(scanner: Scanner, T_O_S: np.ndarray, motion: ScanMotion):
    """The primary rays of a whole scan (part frame, float32): origins (n, 3), directions (n, 3), tfar (n,)."""
    return scanner.primary_rays(T_O_S, motion)


# ---------------------------------------------------------------------------------------------------------
class NaiveScanner:
    """The straightforward way: per profile, build its rays, cast them (one embreex call), then shadow-cast
    every candidate hit to the receiver (a second call), with per-profile numpy for the rest.

    Same model as :class:`optipose.scan.scanner.Scanner` (same rays, trapezoid, AoI intensity, receiver-side
    and shadow tests, noise, quantisation, raw profiles, points in O), so point counts must agree.
    """

    def __init__(self, mesh: trimesh.Trimesh, scanner: Scanner):
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        self.scene = rtcore_scene.EmbreeScene()
        TriangleMesh(self.scene, np.asarray(mesh.vertices[mesh.faces], dtype=np.float32))
        self.normals = np.asarray(mesh.face_normals, dtype=np.float64)
        self.sensor, self.material = scanner.sensor, scanner.material
        self.o_S, self.d_S = self.sensor.laser_rays()
        self.t_max = ((self.sensor.z_far - self.sensor.window_z) / self.d_S[:, 2]).astype(np.float32)

    def scan(self, T_O_S: np.ndarray, motion: ScanMotion, seed: int = 0):
        """Raw profiles (n_profiles, n_col) mm and points (n, 3) in O."""
        s, rng = self.sensor, np.random.default_rng(seed)
        R, t = T_O_S[:3, :3], T_O_S[:3, 3]
        o_O, d_O = self.o_S @ R.T + t, self.d_S @ R.T
        receiver_O = R @ s.receiver + t
        slope = self.d_S[:, 0] / self.d_S[:, 2]
        x0 = self.o_S[:, 0] - self.o_S[:, 2] * slope
        raws, clouds = [], []
        for shift in motion.offsets():
            back = np.array([shift, 0.0, 0.0])  # the part moved +shift along x_O: rays move back in its frame
            origins = o_O - back
            hit = self.scene.run(origins.astype(np.float32), d_O.astype(np.float32), dists=self.t_max.copy(), output=1)
            col = np.flatnonzero(hit["primID"] >= 0)
            tri = hit["primID"][col]
            location = origins[col] + hit["tfar"][col, None].astype(np.float64) * d_O[col]
            normal = self.normals[tri]
            cos_aoi = -np.einsum("ij,ij->i", normal, d_O[col])
            intensity = self.material.intensity(np.arccos(np.clip(cos_aoi, -1.0, 1.0)))
            z = (location - (t - back)) @ R[:, 2]
            to_receiver = receiver_O - back - location
            keep = (z >= s.z_near) & (z <= s.z_far) & (cos_aoi > 0) & (intensity >= s.detection_threshold)
            keep &= np.einsum("ij,ij->i", normal, to_receiver) > 0
            cand = np.flatnonzero(keep)
            start = location[cand] + _SHADOW_OFFSET * normal[cand]
            blocked = self.scene.run(
                start.astype(np.float32),
                (receiver_O - back - start).astype(np.float32),
                dists=np.ones(len(cand), np.float32),
                query="OCCLUDED",
            )
            keep[cand[np.asarray(blocked) != -1]] = False
            col, z, intensity = col[keep], z[keep], intensity[keep]
            sigma = s.noise_sigma / np.sqrt(np.clip(intensity, s.detection_threshold, 1.0))
            z = np.round((z + rng.standard_normal(len(z)) * sigma * self.d_S[col, 2]) / s.z_resolution) * s.z_resolution
            raw = np.full(s.points_per_profile, -9999.9999)
            raw[col] = -1e3 * z
            x_S = x0[col] + z * slope[col]
            clouds.append(np.outer(x_S, R[:, 0]) + np.outer(z, R[:, 2]) + t - back)
            raws.append(raw)
        return np.array(raws), np.concatenate(clouds)


# ---------------------------------------------------------------------------------------------------------
class EngeomScanner:
    """engeom's ``PanningLaserProfile`` set up with the optipose sensor's geometry.

    engeom's sensor frame E has +Z toward the emitter, X along the line, and pans the target by -y_step
    along Y_E per step. With E = S turned 180° about x_S (x_E = x_S, y_E = -y_S, z_E = -z_S), the part's
    +x_O travel is -Y_E for sensors whose y_S is +x_O (both of the paper's poses), so y_step = +0.5 mm.
    The fan: emitter = our virtual apex, width at R = our straight fan's width there, rays evenly spaced
    across it (a fan evenly spaced at one depth is evenly spaced at all depths: the same rays as ours).
    """

    def __init__(self, mesh: trimesh.Trimesh, scanner: Scanner, motion: ScanMotion):
        from engeom.geom3 import Iso3, Mesh3
        from engeom.sensors import LaserProfile, PanningLaserProfile

        s = scanner.sensor
        line = LaserProfile(
            emitter_z=-s.apex_z,
            detector_y=-s.baseline,
            detector_z=s.reference_distance,
            volume_width=2 * float(s.half_width(0.0)),
            volume_z_min=s.z_near,
            volume_z_max=s.z_far,
            resolution=s.points_per_profile,
        )
        self.sensor = PanningLaserProfile(line, motion.step, motion.n_profiles)
        self.mesh = Mesh3(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.uint32))
        self._Iso3, self._first_shift = Iso3, motion.offsets()[0]

    def target_pose(self, T_O_S: np.ndarray) -> np.ndarray:
        """The part's pose in E at the first profile, T_E_O (4×4); engeom's ``iso`` argument."""
        if not np.allclose(T_O_S[:3, 1], [1.0, 0.0, 0.0], atol=1e-3):
            raise ValueError("this mapping needs y_S = +x_O (the scan direction)")
        T_O_E = T_O_S @ np.diag([1.0, -1.0, -1.0, 1.0])
        u, _, vt = np.linalg.svd(T_O_E[:3, :3])  # 0.7071 is not quite orthonormal; Iso3 wants a rotation
        T_O_E[:3, :3] = u @ vt
        T_shift = np.eye(4)
        T_shift[0, 3] = self._first_shift
        return np.linalg.inv(T_O_E) @ T_shift

    def scan(self, T_E_O: np.ndarray) -> np.ndarray:
        """Points (n, 3) in O."""
        points_E = np.asarray(self.sensor.get_points(self.mesh, None, self._Iso3(T_E_O)).points)
        return (points_E - T_E_O[:3, 3]) @ T_E_O[:3, :3]


# ---------------------------------------------------------------------------------------------------------
def run_interleaved(tasks: dict, repeats: int) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Time every task ``repeats`` times, one of each per round, the order rotated each round; warm up first.

    Returns wall-clock and process CPU seconds (repeats,) per task. CPU time sums all threads; on a shared
    machine it moves less than wall-clock when other jobs steal the cores.
    """
    names = list(tasks)
    for name in names:
        tasks[name]()
    wall, cpu = {name: [] for name in names}, {name: [] for name in names}
    for r in range(repeats):
        for name in names[r % len(names) :] + names[: r % len(names)]:
            c0, t0 = time.process_time(), time.perf_counter()
            tasks[name]()
            wall[name].append(time.perf_counter() - t0)
            cpu[name].append(time.process_time() - c0)
    return {n: np.array(v) for n, v in wall.items()}, {n: np.array(v) for n, v in cpu.items()}


def peak_traced_mb(fn) -> float:
    """Peak Python + numpy heap (MB) while ``fn`` runs (tracemalloc; Embree's own memory is not traced)."""
    tracemalloc.start()
    fn()
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak / 1e6


def header(args, scanner: Scanner, n_rays: int) -> str:
    cmd = " ".join([os.path.relpath(sys.executable)] + sys.argv)
    libs = ", ".join(f"{p} {version(p)}" for p in ("numpy", "embreex", "open3d-cpu", "engeom"))
    return (
        f"$ {cmd}\n{platform.processor() or platform.machine()}, {len(os.sched_getaffinity(0))} cores, "
        f"Python {platform.python_version()}; {libs}\n"
        f"block {' x '.join(f'{1e3 * e:g}' for e in BLOCK_EXTENTS)} mm, {SENSOR}, {MATERIAL}, "
        f"{n_rays:,} rays per scan; scanner threads = {scanner.threads}; {args.repeats} interleaved repeats, medians"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=11, help="timed rounds after one warm-up (default 11)")
    args = parser.parse_args()

    mesh, motion = make_block(), ScanMotion(0.060)
    scanner = Scanner(mesh, SENSOR, MATERIAL)
    embree = EmbreeCaster(scanner.vertices, scanner.faces, threads=scanner.threads)
    open3d = Open3DCaster(scanner.vertices, scanner.faces)
    naive, engeom = NaiveScanner(mesh, scanner), EngeomScanner(mesh, scanner, motion)
    rays = {name: scanner_rays(scanner, T, motion) for name, T in POSES.items()}
    n_rays = len(rays["S2"][0])

    tasks, counts = {}, {}
    for name, T in POSES.items():
        o, d, tfar = rays[name]
        T_E_O = engeom.target_pose(T)
        tasks[f"scanner {name}"] = lambda T=T: scanner.scan(T, motion)
        tasks[f"bare embreex {name}"] = lambda o=o, d=d, tfar=tfar: embree.first_triangle(o, d, tfar)
        tasks[f"bare open3d {name}"] = lambda o=o, d=d, tfar=tfar: open3d.first_triangle(o, d, tfar)
        tasks[f"naive loop {name}"] = lambda T=T: naive.scan(T, motion)
        tasks[f"engeom {name}"] = lambda T_E_O=T_E_O: engeom.scan(T_E_O)
        counts[f"scanner {name}"] = len(scanner.scan(T, motion))
        counts[f"bare embreex {name}"] = int((embree.first_triangle(o, d, tfar) >= 0).sum())
        counts[f"bare open3d {name}"] = int((open3d.first_triangle(o, d, tfar) >= 0).sum())
        counts[f"naive loop {name}"] = len(naive.scan(T, motion)[1])
        counts[f"engeom {name}"] = len(engeom.scan(T_E_O))
    times, cpu = run_interleaved(tasks, args.repeats)
    peak_mb = peak_traced_mb(lambda: scanner.scan(POSES["S2"], motion))
    report(args, scanner, n_rays, times, cpu, counts, peak_mb)


def report(args, scanner, n_rays, times, cpu, counts, peak_mb) -> None:
    console = Console(width=120, highlight=False)
    console.print(header(args, scanner, n_rays))
    table = Table(show_edge=False, pad_edge=False)
    for col in ("contender", "median ms", "min–max ms", "CPU ms", "Mrays/s", "points / hits", "time vs scanner"):
        table.add_column(col, justify="left" if col == "contender" else "right")
    for name, t in times.items():
        pose = name.split()[-1]
        ratio = np.median(t) / np.median(times[f"scanner {pose}"])
        table.add_row(
            name,
            f"{1e3 * np.median(t):.1f}",
            f"{1e3 * t.min():.0f}–{1e3 * t.max():.0f}",
            f"{1e3 * np.median(cpu[name]):.0f}",
            f"{n_rays / np.median(t) / 1e6:.2f}",
            f"{counts[name]:,}",
            f"{ratio:.2f}x",
        )
    console.print(table)
    med = {name: np.median(t) for name, t in times.items()}
    for pose in POSES:
        console.print(
            f"{pose}: scanner / bare embreex ray rate = {med[f'bare embreex {pose}'] / med[f'scanner {pose}']:.2f} "
            f"(target >= 0.7);  open3d / embreex ray rate = {med[f'bare embreex {pose}'] / med[f'bare open3d {pose}']:.2f};  "
            f"speed-up over naive loop {med[f'naive loop {pose}'] / med[f'scanner {pose}']:.1f}x, "
            f"over engeom {med[f'engeom {pose}'] / med[f'scanner {pose}']:.1f}x"
        )
    console.print(
        f"scan S2 median {1e3 * med['scanner S2']:.1f} ms (aim <= 50 ms); peak traced heap of one S2 scan "
        f"{peak_mb:.0f} MB; engeom and naive-loop point counts are checked against the scanner above"
    )


if __name__ == "__main__":
    main()
