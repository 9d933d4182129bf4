"""``optipose scan``: scan a part once with one or more sensors, print a summary, write the cloud."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from optipose.errors import ConfigError
from optipose.model.layout import Layout, SensorPose, load_layout
from optipose.transforms import validate_pose

log = logging.getLogger(__name__)

CLOUD_SUFFIXES = (".ply", ".pcd", ".xyz", ".npy")


def poses_from_cli(sensor_pose: list[str] | None, layout_path: Path | None, part) -> Layout:
    """The layout to scan with: ``--sensor-pose`` matrices, else ``--layout``, else the part's hand layout."""
    if sensor_pose and layout_path:
        raise ConfigError("give either --sensor-pose or --layout, not both")
    if sensor_pose:
        poses = []
        for i, text in enumerate(sensor_pose):
            try:
                values = [float(v) for v in text.replace(";", ",").replace(" ", ",").split(",") if v]
            except ValueError:
                raise ConfigError(f"--sensor-pose {i + 1}: not a list of numbers: '{text}'") from None
            if len(values) != 16:
                raise ConfigError(f"--sensor-pose {i + 1}: expected 16 numbers (4x4, row-major), got {len(values)}")
            T = validate_pose(np.reshape(values, (4, 4)), f"--sensor-pose {i + 1}")
            poses.append(SensorPose(f"S{i + 1}", T))
        return Layout(tuple(poses), name="cli")
    if layout_path:
        return load_layout(layout_path)
    if "hand" in part.layouts:
        return part.layouts["hand"]
    if part.layouts:
        return next(iter(part.layouts.values()))
    raise ConfigError(f"part '{part.name}' has no layout: give --sensor-pose or --layout")


def write_cloud(path: Path, points: np.ndarray) -> Path:
    """Write points (n, 3) metres to PLY/PCD/XYZ (Open3D) or NPY."""
    suffix = path.suffix.lower()
    if suffix not in CLOUD_SUFFIXES:
        raise ConfigError(f"--out {path}: unsupported cloud format (use {', '.join(CLOUD_SUFFIXES)})")
    path.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".npy":
        np.save(path, points)
        return path
    import open3d as o3d

    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.ascontiguousarray(points)))
    if not o3d.io.write_point_cloud(str(path), cloud):
        raise ConfigError(f"could not write {path}")
    return path


def run_scan(part_spec, sensor_pose, layout_path, material, sensor, rpy_deg, seed, noise, out, raw_dir, units):
    from rich.console import Console
    from rich.table import Table

    from optipose.model.part import load_part
    from optipose.scan.profiles import write_profiles

    if out and out.suffix.lower() not in CLOUD_SUFFIXES:  # refuse before the work, not after
        raise ConfigError(f"--out {out}: unsupported cloud format (use {', '.join(CLOUD_SUFFIXES)})")
    part = load_part(part_spec, units=units)
    layout = poses_from_cli(sensor_pose, layout_path, part)
    scanner = part.scanner(sensor, material)
    rpy = np.deg2rad(rpy_deg)
    scans = scanner.scan_many(layout.poses, part.motion, rpy, part.rotation_centre, rng=seed, noise=noise)

    console = Console()
    table = Table(title=f"{part.name}: {scanner.sensor.name}, {scanner.material.name}, rpy = {rpy_deg} deg")
    for col in ("sensor", "points", "profiles hit", "fill %", "x range mm", "mean intensity"):
        table.add_column(col, justify="right" if col != "sensor" else "left")
    n_prof, n_col = part.motion.n_profiles, scanner.sensor.points_per_profile
    for name, s in zip(layout.names, scans):
        hit_profiles = len(np.unique(s.profile))
        x = f"{s.points[:, 0].min() * 1e3:.1f} .. {s.points[:, 0].max() * 1e3:.1f}" if len(s) else "-"
        inten = f"{float(s.intensity.mean()):.3f}" if len(s) else "-"
        table.add_row(name, f"{len(s):,}", f"{hit_profiles}/{n_prof}", f"{100 * len(s) / (n_prof * n_col):.1f}", x, inten)
    console.print(table)
    if not any(len(s) for s in scans):
        log.warning("no sensor returned a point: check the poses, the units and the material")

    if raw_dir:
        raw_dir.mkdir(parents=True, exist_ok=True)
        for name, s in zip(layout.names, scans):
            header = f"optipose raw profiles: part={part.name} sensor={scanner.sensor.name} pose={name} step_mm={part.motion.step * 1e3}"
            write_profiles(raw_dir / f"{name}.csv", s.raw, header=header)
        console.print(f"raw profiles: {raw_dir}/<sensor>.csv ({n_prof} x {n_col} heights in mm, -9999.9999 = empty)")
    if out:
        merged = np.concatenate([s.points for s in scans]) if scans else np.zeros((0, 3))
        write_cloud(out, merged)
        console.print(f"cloud: {out} ({len(merged):,} points, metres, frame O)")
