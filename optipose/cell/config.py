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

Any magnitude of ``[robot]`` and ``[calibration]``, and ``process_scale``, may be a range ``[low, high]`` instead
of a point (:mod:`optipose.cell.ranges`): a :class:`Cell` keeps its ranges beside point records that hold their
middles, and :meth:`Cell.instance` draws the point cell of a run's seed (log-uniform between low and high when
low > 0, uniform on [0, high] when low is 0). ``--cell NAME:zeroed`` is a cell zeroed on a master part.

The cell ``ideal`` (every source off) is the model without a cell, bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from optipose.cell.asmade import Process
from optipose.cell.ranges import draws, magnitude, middle
from optipose.cell.robot import CalibrationErrors, RobotErrors
from optipose.errors import ConfigError, read_toml, shipped_toml

__all__ = ["Cell", "CELLS_DIR", "load_cell", "cell_names", "load_process", "process_names", "IDEAL", "file_key"]

CELLS_DIR = Path(__file__).resolve().parents[2] / "cells"
_PROCESSES = Path(__file__).resolve().parents[1] / "data" / "processes.toml"
_MM, _DEG = 1e-3, np.pi / 180
# The largest σ a cell can have, in file units: a part moved or made 10 mm off (twice the 5 mm correspondence
# distance of every shipped objective, half the LJ-X8080's ±20.5 mm measuring range) or turned 5° (more than the
# ±2° protocol itself) is not scanned and registered but lost; a scan step 10 % off is no calibrated axis. Beyond
# them a cell file holds a typo, not a cell (a path error of 50 mm ran for minutes without an end).
_LENGTH, _ANGLE, _SHARE = 10.0, 5.0, 0.1
# a process ten times worse than its preset: bent sheet's 0.3° face tilt becomes 3°, beyond the protocol's ±2°
_PROCESS_SCALE = 10.0

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


def file_key(name: str) -> tuple[str, str, float]:
    """Where a magnitude's field (``robot.path``, ``calibration.frame_rotation``, ``process_scale``) is in a cell file:
    its table, its key and the key's unit in SI (``("robot", "path_mm", 1e-3)``)."""
    if name == "process_scale":
        return "part", "process_scale", 1.0
    table, attr = name.split(".")
    keys = {"robot": _ROBOT, "calibration": _CALIBRATION}[table]
    key = next(k for k, (a, _, _) in keys.items() if a == attr)
    return table, key, keys[key][1]


@dataclass(frozen=True)
class Cell:
    """A cell's error sources (SI). The default is the ideal cell.

    ranges : ``(field, low, high)`` rows (SI), sorted by field (``robot.path``, ``calibration.frame_rotation``,
    ``process_scale``): the magnitudes known only to a bracket; the point records hold their middles
    (:func:`optipose.cell.ranges.middle`), and :meth:`instance` draws them per run seed.
    """

    name: str = "ideal"
    description: str = ""
    robot: RobotErrors = field(default_factory=RobotErrors)
    calibration: CalibrationErrors = field(default_factory=CalibrationErrors)
    as_made: bool = False
    default_process: str = "cad"
    process_scale: float = 1.0
    material: bool = False
    source_text: str = field(default="", repr=False, compare=False)
    ranges: tuple = ()

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

    def instance(self, seed: int) -> "Cell":
        """The point cell of the run seed ``seed``: each range's magnitude drawn (:func:`optipose.cell.ranges.draws`);
        the cell itself when it has no range (no draw is made)."""
        return self if not self.ranges else self._with(draws(self.ranges, seed))

    def middle(self) -> "Cell":
        """The point cell of the ranges' middles (what the surrogate scores); the cell itself without ranges."""
        return self if not self.ranges else self._with({f: middle(lo, hi) for f, lo, hi in self.ranges})

    def at(self, end: str) -> "Cell":
        """The point cell with every range at its ``end`` (``"low"`` or ``"high"``): the best and the worst cell of
        its kind; the cell itself without ranges."""
        if end not in ("low", "high"):
            raise ValueError(f"a range's end is 'low' or 'high', got {end!r}")
        return self if not self.ranges else self._with({f: lo if end == "low" else hi for f, lo, hi in self.ranges})

    def _with(self, values: dict) -> "Cell":
        """This cell with the fields ``values`` names (``robot.path``, ..., ``process_scale``) set, and no range."""
        robot = {k.split(".")[1]: v for k, v in values.items() if k.startswith("robot.")}
        calibration = {k.split(".")[1]: v for k, v in values.items() if k.startswith("calibration.")}
        return replace(
            self,
            robot=replace(self.robot, **robot),
            calibration=replace(self.calibration, **calibration),
            process_scale=values.get("process_scale", self.process_scale),
            ranges=(),
        )


IDEAL = Cell()


def load_cell(spec: "str | Path | Cell | None") -> Cell:
    """A cell from a shipped name (``ur10e``, ``ideal``), a TOML path, or a :class:`Cell` (as is)."""
    if isinstance(spec, Cell):
        return spec
    if spec is None or spec == "ideal":
        return IDEAL
    if isinstance(spec, str) and ":" in spec and not Path(spec).exists():
        return _suffixed(spec)
    path = shipped_toml(spec, CELLS_DIR, "cell")
    table, text = read_toml(path, "cell file")
    return cell_from_table(table, str(path), default_name=path.stem, source_text=text)


def cell_names() -> list[str]:
    """The shipped cells (``cells/*.toml``), by name."""
    return sorted(p.stem for p in CELLS_DIR.glob("*.toml"))


def _suffixed(spec: str) -> Cell:
    """``NAME:zeroed``: the cell ``NAME`` (a shipped name, a path, or one with a suffix itself) zeroed on a master part;
    ``NAME:low`` / ``NAME:high``: every range at that end (:meth:`Cell.at`). Any other suffix, a cell without a
    calibration error to zero, or an end of a cell without ranges is one :class:`ConfigError`."""
    name, suffix = spec.rsplit(":", 1)
    if suffix in ("low", "high"):
        cell = load_cell(name)
        if not cell.ranges:
            raise ConfigError(f"cell '{spec}': cell '{cell.name}' has no range to take the {suffix} end of")
        return replace(cell.at(suffix), name=f"{cell.name}:{suffix}")
    if suffix != "zeroed":
        raise ConfigError(
            f"cell '{spec}': unknown suffix ':{suffix}' (a cell is NAME, NAME:zeroed for it zeroed on a master part, "
            "or NAME:low / NAME:high for every range at that end)"
        )
    cell = load_cell(name)
    if not cell.calibration.off:
        raise ConfigError(f"cell '{spec}': cell '{cell.name}' has no calibration error to zero")
    description = cell.description.removesuffix(", not zeroed") + ", zeroed on a master part"
    calibration = replace(cell.calibration, zeroed=True)
    return replace(cell, name=f"{cell.name}:zeroed", description=description, calibration=calibration)


def cell_from_table(table: dict, where: str, default_name: str = "cell", source_text: str = "") -> Cell:
    """A cell file's table as a :class:`Cell`; every mistake one :class:`ConfigError` naming the key. A file that
    sets none of the four tables is refused (the ideal cell is ``--cell ideal``, not an empty file)."""
    _keys(table, {"name", "description", "robot", "calibration", "part", "material"}, where)
    if not {"robot", "calibration", "part", "material"} & set(table):
        raise ConfigError(
            f"{where}: no [robot], [calibration], [part] or [material] table (an empty cell file; the cell without "
            "error sources is --cell ideal)"
        )
    ranges: dict[str, tuple[float, float]] = {}
    robot_table = _table(table.get("robot", {}), f"{where} [robot]")
    robot = RobotErrors(**_numbers(robot_table, _ROBOT, f"{where} [robot]", ranges, "robot."))
    if min(robot.path_correlation, *ranges.get("robot.path_correlation", (1.0,))) <= 0:
        raise ConfigError(f"{where} [robot]: path_correlation_mm must be > 0")
    calibration_table = dict(_table(table.get("calibration", {}), f"{where} [calibration]"))
    zeroed = calibration_table.pop("zeroed", False)
    if not isinstance(zeroed, bool):
        raise ConfigError(f"{where} [calibration]: zeroed must be true or false, got {zeroed!r}")
    calibration = CalibrationErrors(
        **_numbers(calibration_table, _CALIBRATION, f"{where} [calibration]", ranges, "calibration."), zeroed=zeroed
    )
    part = _table(table.get("part", {}), f"{where} [part]")
    _keys(part, {"as_made", "default_process", "process_scale"}, f"{where} [part]")
    material = _table(table.get("material", {}), f"{where} [material]")
    _keys(material, {"effects"}, f"{where} [material]")
    as_made, effects = part.get("as_made", False), material.get("effects", False)
    if not isinstance(as_made, bool) or not isinstance(effects, bool):
        raise ConfigError(f"{where}: [part] as_made and [material] effects must be true or false")
    scale = magnitude(part.get("process_scale", 1.0), "process_scale", 1.0, _PROCESS_SCALE, f"{where} [part]")
    if isinstance(scale, tuple):
        ranges["process_scale"], scale = scale, middle(*scale)
    if not any(
        k for t in (robot_table, table.get("calibration", {}), part, material) for k in t if not k.endswith("source")
    ):
        raise ConfigError(
            f"{where}: its tables set no magnitude or switch (the cell without error sources is --cell ideal)"
        )
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
        tuple((name, *ranges[name]) for name in sorted(ranges)),
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


def _numbers(table, keys: dict, where: str, ranges: dict | None = None, prefix: str = "") -> dict:
    """The table's numbers (file units) as record fields (SI); each must be finite, >= 0 and at most the largest
    a cell can have (the third entry of its ``keys`` row). With ``ranges`` (a dict), a value may be a range
    ``[low, high]`` (:func:`optipose.cell.ranges.magnitude`): its ends go to ``ranges[prefix + field]``, its
    middle to the record; without, a range is refused as any other non-number."""
    table = _table(table, where)
    _keys(table, set(keys), where)
    out = {}
    for key, value in table.items():
        if key.endswith("source"):
            continue
        attr, unit, most = keys[key]
        if ranges is None and (isinstance(value, (list, bool)) or not isinstance(value, (int, float)) or value < 0):
            raise ConfigError(f"{where}: {key} must be a number >= 0, got {value!r}")
        value = magnitude(value, key, unit, most, where)
        if isinstance(value, tuple):
            ranges[prefix + attr], value = value, middle(*value)
        out[attr] = value
    return out
