"""Sensor layouts: named sensor poses ``T_O_S`` in the part's frame, read from and written to TOML.

A layout file holds ``[[sensors]]`` tables, each with a ``name`` and a 4×4 ``T_O_S`` in metres (rows),
optionally a ``sensor`` preset name when a layout mixes sensor models::

    description = "hand-placed, paper eqs. (1)-(3)"
    [[sensors]]
    name = "S1"
    T_O_S = [[0, 1, 0, 0.030], [0.7071, 0, 0.7071, -0.023], [0.7071, 0, -0.7071, 0.015], [0, 0, 0, 1]]

Part files embed layouts the same way under ``[layouts.NAME]``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from optipose.errors import ConfigError, OptiposeError, read_toml
from optipose.transforms import validate_pose

__all__ = ["SensorPose", "Layout", "load_layout", "layout_from_table", "write_layout", "kept_sensors"]


@dataclass(frozen=True)
class SensorPose:
    name: str
    T_O_S: np.ndarray = field(repr=False)
    sensor: str | None = None  # preset name; None = the part's default sensor

    def __repr__(self) -> str:
        R = np.round(self.T_O_S[:3, 3] * 1e3, 2).tolist()
        z = np.round(self.T_O_S[:3, 2], 3).tolist()
        return f"SensorPose({self.name!r}, R_mm={R}, z_S={z})"


@dataclass(frozen=True)
class Layout:
    sensors: tuple[SensorPose, ...]
    name: str = "layout"
    description: str = ""

    def __len__(self) -> int:
        return len(self.sensors)

    @property
    def poses(self) -> list[np.ndarray]:
        return [s.T_O_S for s in self.sensors]

    @property
    def names(self) -> list[str]:
        return [s.name for s in self.sensors]

    def to_table(self) -> dict:
        return {
            "description": self.description,
            "sensors": [
                {"name": s.name, "T_O_S": np.round(s.T_O_S, 12).tolist(), **({"sensor": s.sensor} if s.sensor else {})}
                for s in self.sensors
            ],
        }


def layout_from_table(table: dict, name: str = "layout", where: str = "layout") -> Layout:
    """A layout from a parsed TOML table with a ``sensors`` array of tables."""
    entries = table.get("sensors")
    if not isinstance(entries, list) or not entries:
        raise ConfigError(f"{where}: needs at least one [[sensors]] entry with name and T_O_S")
    poses = []
    for i, entry in enumerate(entries):
        label = entry.get("name", f"S{i + 1}")
        if "T_O_S" not in entry:
            raise ConfigError(f"{where}: sensor '{label}' has no T_O_S")
        try:
            T = np.array(entry["T_O_S"], dtype=float)
        except (TypeError, ValueError):
            raise ConfigError(f"{where}: sensor '{label}': T_O_S must be a 4x4 array of numbers") from None
        try:
            T = validate_pose(T, f"{where}: sensor '{label}'")
        except OptiposeError as exc:
            raise ConfigError(str(exc)) from None
        poses.append(SensorPose(str(label), T, entry.get("sensor")))
    names = [p.name for p in poses]
    if len(set(names)) != len(names):
        raise ConfigError(f"{where}: sensor names must be unique, got {names}")
    return Layout(tuple(poses), name=name, description=str(table.get("description", "")))


def load_layout(path: str | Path) -> Layout:
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"layout file not found: {path}")
    table, _ = read_toml(path, "layout file")
    return layout_from_table(table, name=path.stem, where=str(path))


def write_layout(layout: Layout, path: str | Path) -> Path:
    import tomli_w

    from optipose.files import write_text

    return write_text(path, tomli_w.dumps(layout.to_table()))


def kept_sensors(layout: Layout, other: Layout, tolerance: float = 1e-6) -> dict[str, str]:
    """Each sensor of ``layout`` that stands where a sensor of ``other`` stands (every entry of ``T_O_S``
    within ``tolerance``: metres, and the rotation's unitless entries), by name → that sensor's name in ``other``:
    a found layout's hand sensors left in their brackets."""
    out = {}
    for sensor in layout.sensors:
        same = [o.name for o in other.sensors if np.allclose(sensor.T_O_S, o.T_O_S, rtol=0.0, atol=tolerance)]
        if same:
            out[sensor.name] = same[0]
    return out


def is_part_of(layout: Layout, other: Layout | None) -> bool:
    """Whether every sensor of ``layout`` is one of ``other``'s own, its name and its pose (:func:`kept_sensors`):
    a search's answer that is some of the baseline's sensors (:func:`optipose.search.validate.baseline_where_better`)."""
    return other is not None and len(layout) > 0 and kept_sensors(layout, other) == {n: n for n in layout.names}
