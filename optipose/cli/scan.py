"""``optipose scan``: scan a part once with one or more sensors, print a summary, write the cloud."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Optional, Sequence

import typer

from optipose.cli.options import (
    CellOption,
    Jobs,
    LayoutFile,
    Part,
    Seed,
    Units,
    check_output,
    friendly_errors,
    parse_floats,
)
from optipose.errors import ConfigError

if TYPE_CHECKING:
    import numpy as np

    from optipose.model.layout import Layout

__all__ = ["scan", "scan_command", "protocol_command", "poses_from_cli", "write_cloud", "CLOUD_SUFFIXES"]

log = logging.getLogger(__name__)

CLOUD_SUFFIXES = (".ply", ".pcd", ".xyz", ".npy")


@friendly_errors
def scan(
    part: Part,
    sensor_pose: Annotated[
        Optional[list[str]],
        typer.Option(
            "--sensor-pose", "-p", help="A 4x4 T_O_S as 16 comma-separated numbers, row-major, metres. Repeatable."
        ),
    ] = None,
    layout: LayoutFile = None,
    material: Annotated[
        Optional[str], typer.Option(help="Material preset or a CSV (aoi_deg,intensity); default: the part's.")
    ] = None,
    sensor: Annotated[Optional[str], typer.Option(help="Sensor preset or TOML file; default: the part's.")] = None,
    rpy: Annotated[str, typer.Option(help="Part orientation roll,pitch,yaw in degrees.")] = "0,0,0",
    seed: Seed = 0,
    noise: Annotated[bool, typer.Option("--noise/--no-noise", help="Sensor noise and Z quantisation.")] = True,
    out: Annotated[Optional[Path], typer.Option(help="Write the merged cloud (PLY, PCD, XYZ or NPY), metres.")] = None,
    raw: Annotated[
        Optional[Path],
        typer.Option(
            help="Write each sensor's raw profiles (device format) into this folder; with --protocol, the scan folder."
        ),
    ] = None,
    units: Units = "auto",
    protocol: Annotated[
        Optional[str],
        typer.Option(
            help="Scan every orientation of this objective's protocol (a name in objectives/ or a TOML path), "
            "in its cell, and write the scan folder into --raw."
        ),
    ] = None,
    cell: CellOption = None,
    format: Annotated[
        str, typer.Option("--format", help="With --protocol: npy (float64, reads back exactly) or csv (%.4f).")
    ] = "npy",
    jobs: Jobs = 1,
) -> None:
    """Scan a part with one or more sensors and print what each sees; with --protocol, write a whole protocol.

    With --protocol, the layout (--sensor-pose, --layout, else the part's hand one) is scanned at every
    orientation of the objective's protocol in the cell (--cell, else the objective's), as an evaluation
    scans it, and --raw gets one file of raw profiles per scan and sensor and a manifest.toml
    (docs/scans.md); `optipose evaluate PART --scans DIR` reads it back."""
    if protocol is not None:
        given = [flag for flag, value in (("--out", out), ("--material", material), ("--sensor", sensor)) if value]
        if given or not noise:
            raise ConfigError(
                f"{(given or ['--no-noise'])[0]} is not for --protocol: a protocol is scanned as evaluated"
            )
        protocol_command(part, protocol, raw, sensor_pose, layout, cell, seed, format, jobs or 1, units)
        return
    if cell is not None:
        raise ConfigError("--cell needs --protocol (a single scan is the ideal cell's)")
    scan_command(
        part, sensor_pose, layout, material, sensor, parse_floats(rpy, 3, "--rpy"), seed, noise, out, raw, units
    )


def protocol_command(
    part: str,
    objective: str,
    raw_dir: Path | None,
    sensor_pose: list[str] | None = None,
    layout: Path | None = None,
    cell: str | None = None,
    seed: int = 0,
    format: str = "npy",
    jobs: int = 1,
    units: str = "auto",
) -> Path:
    """Write the scan folder ``raw_dir`` of the layout under ``objective``'s protocol in ``cell``; returns it."""
    import time

    from rich.console import Console

    from optipose.evaluate.objective import load_objective
    from optipose.evaluate.recorded import record_protocol
    from optipose.model.collision import check_sensors_outside
    from optipose.model.part import load_part

    if raw_dir is None:
        raise ConfigError("--protocol needs --raw DIR, the folder to write the scans into")
    check_output(raw_dir, what="--raw")
    the_part = load_part(part, units=units)
    the_layout = poses_from_cli(sensor_pose, layout, the_part)
    check_sensors_outside(the_part, the_layout)
    the_objective = load_objective(objective).in_cell(cell)
    t0 = time.perf_counter()
    manifest = record_protocol(the_part, the_layout, the_objective, raw_dir, seed=seed, jobs=jobs, format=format)
    size = sum(f.stat().st_size for f in raw_dir.iterdir() if f.is_file())
    Console().print(
        f"scans: {raw_dir}/ ({len(manifest.scans)} scans x {len(the_layout)} sensors of {manifest.profiles} "
        f"profiles, {format}, {size / 1e6:.0f} MB; objective '{the_objective.name}', cell "
        f"'{the_objective.cell.name}', seed {seed}; {time.perf_counter() - t0:.1f} s) and {raw_dir}/manifest.toml"
    )
    return raw_dir


def scan_command(
    part: str,
    sensor_pose: list[str] | None = None,
    layout: Path | None = None,
    material: str | None = None,
    sensor: str | None = None,
    rpy_deg: Sequence[float] = (0.0, 0.0, 0.0),
    seed: int = 0,
    noise: bool = True,
    out: Path | None = None,
    raw_dir: Path | None = None,
    units: str = "auto",
) -> None:
    """Scan ``part`` once at orientation ``rpy_deg`` (degrees), print a table per sensor, write the clouds.

    sensor_pose : 4x4 T_O_S as text, 16 numbers each (metres); else ``layout``, else the part's hand layout.
    out : the merged cloud (n, 3) in metres, frame O; raw_dir : one CSV of raw profiles per sensor.
    """
    import numpy as np
    from rich.console import Console

    from optipose.model.collision import check_sensors_outside
    from optipose.model.part import load_part
    from optipose.scan.scanner import PartPose, part_scanner

    if out and out.suffix.lower() not in CLOUD_SUFFIXES:  # refuse before the work, not after
        raise ConfigError(f"--out {out}: unsupported cloud format (use {', '.join(CLOUD_SUFFIXES)})")
    check_output(out, file=True)
    check_output(raw_dir, what="--raw")
    the_part = load_part(part, units=units)
    the_layout = poses_from_cli(sensor_pose, layout, the_part)
    check_sensors_outside(the_part, the_layout)
    scanner = part_scanner(the_part, sensor, material)
    rpy = np.deg2rad(rpy_deg)
    scans = scanner.scan_many(
        the_layout.poses, the_part.motion, PartPose(rpy, the_part.rotation_centre), rng=seed, noise=noise
    )

    console = Console()
    console.print(_summary_table(the_part, scanner, the_layout, scans, list(rpy_deg)))
    if not any(len(s) for s in scans):
        log.warning("no sensor returned a point: check the poses, the units and the material")
    if raw_dir:
        _write_raw(console, raw_dir, the_part, scanner, the_layout, scans)
    if out:
        merged = np.concatenate([s.points for s in scans]) if scans else np.zeros((0, 3))
        write_cloud(out, merged)
        console.print(f"cloud: {out} ({len(merged):,} points, metres, frame O)")


def poses_from_cli(sensor_pose: list[str] | None, layout_path: Path | None, part) -> Layout:
    """The layout to scan with: ``--sensor-pose`` matrices, else ``--layout``, else the part's hand layout."""
    from optipose.model.layout import Layout, SensorPose, load_layout

    if sensor_pose and layout_path:
        raise ConfigError("give either --sensor-pose or --layout, not both")
    if sensor_pose:
        return Layout(
            tuple(SensorPose(f"S{i + 1}", _pose(text, i + 1)) for i, text in enumerate(sensor_pose)), name="cli"
        )
    if layout_path:
        return load_layout(layout_path)
    if "hand" in part.layouts:
        return part.layouts["hand"]
    if part.layouts:
        return next(iter(part.layouts.values()))
    raise ConfigError(f"part '{part.name}' has no layout: give --sensor-pose or --layout")


def _pose(text: str, i: int) -> np.ndarray:
    """The ``i``-th ``--sensor-pose`` (counting from 1) as a checked 4x4 rigid transform."""
    import numpy as np

    from optipose.transforms import validate_pose

    try:
        values = [float(v) for v in text.replace(";", ",").replace(" ", ",").split(",") if v]
    except ValueError:
        raise ConfigError(f"--sensor-pose {i}: not a list of numbers: '{text}'") from None
    if len(values) != 16:
        raise ConfigError(f"--sensor-pose {i}: expected 16 numbers (4x4, row-major), got {len(values)}")
    return validate_pose(np.reshape(values, (4, 4)), f"--sensor-pose {i}")


def write_cloud(path: Path, points: np.ndarray) -> Path:
    """Write points (n, 3) metres to PLY/PCD/XYZ (Open3D) or NPY."""
    import numpy as np

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


def _summary_table(part, scanner, layout, scans, rpy_deg: list[float]):
    """One row per sensor: points, profiles hit, fill of the sensor's grid, x range, mean intensity."""
    import numpy as np
    from rich.table import Table

    table = Table(title=f"{part.name}: {scanner.sensor.name}, {scanner.material.name}, rpy = {rpy_deg} deg")
    for col in ("sensor", "points", "profiles hit", "fill %", "x range mm", "mean intensity"):
        table.add_column(col, justify="right" if col != "sensor" else "left")
    n_prof, n_col = part.motion.n_profiles, scanner.sensor.points_per_profile
    for name, s in zip(layout.names, scans):
        hit_profiles = len(np.unique(s.profile))
        x = f"{s.points[:, 0].min() * 1e3:.1f} .. {s.points[:, 0].max() * 1e3:.1f}" if len(s) else "-"
        inten = f"{float(s.intensity.mean()):.3f}" if len(s) else "-"
        table.add_row(
            name, f"{len(s):,}", f"{hit_profiles}/{n_prof}", f"{100 * len(s) / (n_prof * n_col):.1f}", x, inten
        )
    return table


def _write_raw(console, raw_dir: Path, part, scanner, layout, scans) -> None:
    """One CSV of raw profiles (heights in mm, device format) per sensor."""
    from optipose.scan.profiles import write_profiles

    raw_dir.mkdir(parents=True, exist_ok=True)
    for name, s in zip(layout.names, scans):
        header = f"optipose raw profiles: part={part.name} sensor={scanner.sensor.name} pose={name} step_mm={part.motion.step * 1e3}"
        write_profiles(raw_dir / f"{name}.csv", s.raw, header=header)
    n_prof, n_col = part.motion.n_profiles, scanner.sensor.points_per_profile
    console.print(f"raw profiles: {raw_dir}/<sensor>.csv ({n_prof} x {n_col} heights in mm, -9999.9999 = empty)")
