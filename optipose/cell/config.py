"""Cell files: which error sources of a real cell an evaluation runs under, and how large (docs/cell.md).

A cell file (``cells/<name>.toml``, or a path) has four tables, one per model it sets; every magnitude
names its source in the file::

    name = "ur10e"
    [robot]                        # the robot that carries the part (optipose.cell.robot)
    path_mm = 0.01                 # per-profile path error, σ per axis
    path_rotation_deg = 0.0        # ... and its rotation about the rotation centre
    path_correlation_mm = 5.0      # correlation length along the travel
    step = 0.0005                  # relative error of the scan step, σ per scan
    orientation_deg = 0.003        # error of each orientation it sets, σ per axis
    [calibration]                  # the sensors' poses as the cell's calibration leaves them
    sensor_translation_mm = 0.05   # σ per axis, each sensor its own
    sensor_rotation_deg = 0.02
    frame_translation_mm = 0.1     # σ per axis, every sensor together
    frame_rotation_deg = 0.01
    zeroed = false                 # true: the cell is zeroed on a master part (what it adds there is taken off)
    [part]
    as_made = true                 # scan the part as made by its process (the part file's `process`)
    default_process = "milled"     # for a part that names none (optipose/data/processes.toml)
    process_scale = 1.0            # every magnitude of the process times this
    [material]
    effects = true                 # the material preset's `cell` table: speckle, sub-surface, spurious

The cell ``ideal`` (every source off) is the model without a cell, bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from optipose.cell.asmade import Process
from optipose.cell.robot import CalibrationErrors, RobotErrors
from optipose.errors import ConfigError, read_toml, shipped_toml

__all__ = ["Cell", "CELLS_DIR", "load_cell", "load_process", "process_names", "IDEAL"]

CELLS_DIR = Path(__file__).resolve().parents[2] / "cells"
_PROCESSES = Path(__file__).resolve().parents[1] / "data" / "processes.toml"
_MM, _DEG = 1e-3, np.pi / 180
# The largest σ a cell can have, in file units: a part moved or made 10 mm off (twice the 5 mm correspondence
# distance of every shipped objective, half the LJ-X8080's ±20.5 mm measuring range) or turned 5° (more than the
# ±2° protocol itself) is not scanned and registered but lost; a scan step 10 % off is no calibrated axis. Beyond
# them a cell file holds a typo, not a cell (a path error of 50 mm ran for minutes without an end).
_LENGTH, _ANGLE, _SHARE = 10.0, 5.0, 0.1

_ROBOT = {
    "path_mm": ("path", _MM, _LENGTH),
    "path_rotation_deg": ("path_rotation", _DEG, _ANGLE),
    "path_correlation_mm": ("path_correlation", _MM, 1e4),  # up to 10 m: a path error constant over any scan
    "step": ("step", 1.0, _SHARE),
    "orientation_deg": ("orientation", _DEG, _ANGLE),
}
_CALIBRATION = {
    "sensor_translation_mm": ("sensor_translation", _MM, _LENGTH),
    "sensor_rotation_deg": ("sensor_rotation", _DEG, _ANGLE),
    "frame_translation_mm": ("frame_translation", _MM, _LENGTH),
    "frame_rotation_deg": ("frame_rotation", _DEG, _ANGLE),
}
_PROCESS = {
    "form_rms_mm": ("form_rms", _MM, _LENGTH),
    "face_offset_mm": ("face_offset", _MM, _LENGTH),
    "face_tilt_deg": ("face_tilt", _DEG, _ANGLE),
    "scale": ("scale", 1.0, _SHARE),
    "warp_mm": ("warp", _MM, _LENGTH),
    "layer_height_mm": ("layer_height", _MM, _LENGTH),
    "layer_amplitude_mm": ("layer_amplitude", _MM, _LENGTH),
}


@dataclass(frozen=True)
class Cell:
    """A cell's error sources (SI). The default is the ideal cell."""

    name: str = "ideal"
    description: str = ""
    robot: RobotErrors = field(default_factory=RobotErrors)
    calibration: CalibrationErrors = field(default_factory=CalibrationErrors)
    as_made: bool = False
    default_process: str = "cad"
    process_scale: float = 1.0
    material: bool = False
    source_text: str = field(default="", repr=False, compare=False)

    @property
    def ideal(self) -> bool:
        """Every source off: the evaluation is the one without a cell."""
        r, c = self.robot, self.calibration
        return not (r.moves or r.orientation or c.off or self.as_made or self.material)

    def process(self, name: str | None) -> Process:
        """The process a part of process ``name`` (``None``/empty: the cell's default) is made by, as
        this cell scales it; the CAD itself when the cell does not scan parts as made."""
        if not self.as_made:
            return Process()
        return load_process(name or self.default_process).scaled(self.process_scale)


IDEAL = Cell()


def load_cell(spec: "str | Path | Cell | None") -> Cell:
    """A cell from a shipped name (``ur10e``, ``ideal``), a TOML path, or a :class:`Cell` (as is)."""
    if isinstance(spec, Cell):
        return spec
    if spec is None or spec == "ideal":
        return IDEAL
    path = shipped_toml(spec, CELLS_DIR, "cell")
    table, text = read_toml(path, "cell file")
    return cell_from_table(table, str(path), default_name=path.stem, source_text=text)


def cell_from_table(table: dict, where: str, default_name: str = "cell", source_text: str = "") -> Cell:
    """A cell file's table as a :class:`Cell`; every mistake one :class:`ConfigError` naming the key. A file that
    sets none of the four tables is refused (the ideal cell is ``--cell ideal``, not an empty file)."""
    _keys(table, {"name", "description", "robot", "calibration", "part", "material"}, where)
    if not {"robot", "calibration", "part", "material"} & set(table):
        raise ConfigError(
            f"{where}: no [robot], [calibration], [part] or [material] table (an empty cell file; the cell without "
            "error sources is --cell ideal)"
        )
    robot = RobotErrors(**_numbers(table.get("robot", {}), _ROBOT, f"{where} [robot]"))
    if robot.path_correlation <= 0:
        raise ConfigError(f"{where} [robot]: path_correlation_mm must be > 0")
    calibration_table = dict(_table(table.get("calibration", {}), f"{where} [calibration]"))
    zeroed = calibration_table.pop("zeroed", False)
    if not isinstance(zeroed, bool):
        raise ConfigError(f"{where} [calibration]: zeroed must be true or false, got {zeroed!r}")
    calibration = CalibrationErrors(
        **_numbers(calibration_table, _CALIBRATION, f"{where} [calibration]"), zeroed=zeroed
    )
    part = _table(table.get("part", {}), f"{where} [part]")
    _keys(part, {"as_made", "default_process", "process_scale"}, f"{where} [part]")
    material = _table(table.get("material", {}), f"{where} [material]")
    _keys(material, {"effects"}, f"{where} [material]")
    as_made, effects = part.get("as_made", False), material.get("effects", False)
    if not isinstance(as_made, bool) or not isinstance(effects, bool):
        raise ConfigError(f"{where}: [part] as_made and [material] effects must be true or false")
    scale = part.get("process_scale", 1.0)
    if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not 0 <= scale < 1e3:
        raise ConfigError(f"{where} [part]: process_scale must be a number >= 0, got {scale!r}")
    default_process = str(part.get("default_process", "cad"))
    load_process(default_process)  # an unknown name fails here, with the file named
    return Cell(
        str(table.get("name", default_name)),
        str(table.get("description", "")),
        robot,
        calibration,
        as_made,
        default_process,
        float(scale),
        effects,
        source_text,
    )


def process_names() -> list[str]:
    """The shipped manufacturing processes (optipose/data/processes.toml)."""
    return sorted(read_toml(_PROCESSES, "process presets")[0])


def load_process(name: str) -> Process:
    """A manufacturing process preset by name (``cad``: the CAD exactly)."""
    if name == "cad":
        return Process()
    tables = read_toml(_PROCESSES, "process presets")[0]
    if name not in tables:
        raise ConfigError(f"unknown manufacturing process '{name}' (presets: cad, {', '.join(sorted(tables))})")
    t = dict(tables[name])
    where = f"process '{name}'"
    band = t.pop("form_wavelengths_mm", [10.0, 40.0])
    t = {k: v for k, v in t.items() if k != "description" and not k.endswith("source")}
    values = _numbers(t, _PROCESS, where)
    try:
        lo, hi = (float(x) * _MM for x in band)
    except (TypeError, ValueError):
        raise ConfigError(f"{where}: form_wavelengths_mm must be two numbers") from None
    if not 0 < lo <= hi:
        raise ConfigError(f"{where}: form_wavelengths_mm must be 0 < low <= high")
    return Process(name=name, form_wavelengths=(lo, hi), **values)


def _table(value, where: str) -> dict:
    if not isinstance(value, dict):
        raise ConfigError(f"{where} must be a table")
    return value


def _keys(table: dict, allowed: set, where: str) -> None:
    unknown = {k for k in set(table) - allowed if not k.endswith("source")}
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {', '.join(sorted(unknown))} (known: {', '.join(sorted(allowed))})")


def _numbers(table, keys: dict, where: str) -> dict:
    """The table's numbers (file units) as record fields (SI); each must be finite, >= 0 and at most the largest
    a cell can have (the third entry of its ``keys`` row)."""
    table = _table(table, where)
    _keys(table, set(keys), where)
    out = {}
    for key, value in table.items():
        if key.endswith("source"):
            continue
        attr, unit, most = keys[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or value < 0:
            raise ConfigError(f"{where}: {key} must be a number >= 0, got {value!r}")
        if value > most:
            raise ConfigError(f"{where}: {key} = {value:g} is more than any cell has (at most {most:g})")
        out[attr] = float(value) * unit
    return out
