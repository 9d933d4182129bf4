"""Surface materials: returned laser intensity as a function of the angle of incidence (docs/sensor.md, "Materials").

A material is a curve ``intensity(AoI)``; AoI is the angle between the laser ray and the surface
normal, in radians (0 = head-on). Intensity is relative to a white diffuse reference. A curve comes
either from a parametric preset (diffuse ``cos`` term plus a Gaussian specular lobe) or from a measured
table (CSV with columns ``aoi_deg,intensity``), interpolated linearly and zero past its last angle.
"""

from __future__ import annotations

import csv
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from optipose.errors import ConfigError, read_toml

__all__ = ["Material", "MaterialEffects", "load_material", "material_presets"]


@dataclass(frozen=True)
class MaterialEffects:
    """What the sensor's physics adds on this material in a real cell (docs/cell.md, "The sensor on the
    material"), SI; zero: the ideal sensor. Lengths are along the laser ray.

    speckle : σ (m) of the speckle noise added to every point (metals: coherent light on a rough surface).
    subsurface_bias, subsurface_sigma : how far below the surface the spot's centroid lies (m; plastics:
        the light scatters inside before it comes back), and its point-to-point spread (m).
    spurious_fraction, spurious_range : the fraction of points that are spurious returns anywhere, moved
        along their ray by up to ± ``spurious_range`` (m).
    concave_fraction, concave_distance : the fraction of points within ``concave_distance`` (m) of a concave
        edge that are multipath returns (the line's reflection off the other face), moved the same way.
    """

    speckle: float = 0.0
    subsurface_bias: float = 0.0
    subsurface_sigma: float = 0.0
    spurious_fraction: float = 0.0
    spurious_range: float = 0.0
    concave_fraction: float = 0.0
    concave_distance: float = 0.0

    @property
    def none(self) -> bool:
        return not any(
            (self.speckle, self.subsurface_bias, self.subsurface_sigma, self.spurious_fraction, self.concave_fraction)
        )


@dataclass(frozen=True)
class Material:
    """A material's intensity curve.

    Parametric: ``diffuse·cos(AoI)^diffuse_exponent + specular·exp(-½(AoI/lobe)²)``.
    Tabulated: ``table_aoi`` (m,) radians ascending and ``table_intensity`` (m,).
    """

    name: str
    diffuse: float = 1.0
    diffuse_exponent: float = 1.0
    specular: float = 0.0
    lobe: float = np.deg2rad(10.0)
    table_aoi: tuple[float, ...] = field(default=())
    table_intensity: tuple[float, ...] = field(default=())
    description: str = ""
    effects: MaterialEffects = field(default_factory=MaterialEffects)  # a real cell's (``[<name>.cell]``)

    def intensity(self, aoi: np.ndarray) -> np.ndarray:
        """Relative intensity (n,) at angles of incidence ``aoi`` (n,) radians; 0 at or past 90°."""
        aoi = np.abs(np.asarray(aoi, dtype=float))
        if self.table_aoi:
            out = np.interp(aoi, self.table_aoi, self.table_intensity, left=self.table_intensity[0], right=0.0)
        else:
            c = np.clip(np.cos(aoi), 0.0, 1.0)
            out = self.diffuse * c**self.diffuse_exponent + self.specular * np.exp(-0.5 * (aoi / self.lobe) ** 2)
        return np.where(aoi < np.pi / 2, out, 0.0)

    def max_aoi(self, threshold: float) -> float:
        """Largest AoI (radians) whose intensity clears ``threshold`` (the dropout angle), by bisection on a grid."""
        grid = np.linspace(0.0, np.pi / 2, 9001)
        ok = self.intensity(grid) >= threshold
        return float(grid[ok].max()) if ok.any() else 0.0


def _from_table(name: str, table: dict) -> Material:
    known = {"diffuse", "diffuse_exponent", "specular", "lobe_deg", "description", "csv", "cell"}
    unknown = set(table) - known
    if unknown:
        raise ConfigError(f"material '{name}': unknown key(s) {', '.join(sorted(unknown))}")
    if "csv" in table:
        return _from_csv(Path(table["csv"]), name)
    try:
        m = Material(
            name=name,
            diffuse=float(table.get("diffuse", 1.0)),
            diffuse_exponent=float(table.get("diffuse_exponent", 1.0)),
            specular=float(table.get("specular", 0.0)),
            lobe=np.deg2rad(float(table.get("lobe_deg", 10.0))),
            description=str(table.get("description", "")),
            effects=_effects(table.get("cell", {}), name),
        )
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"material '{name}': {exc}") from None
    if m.diffuse < 0 or m.specular < 0 or m.lobe <= 0:
        raise ConfigError(f"material '{name}': diffuse, specular must be >= 0 and lobe_deg > 0")
    return m


_EFFECT_KEYS = {
    "speckle_mm": "speckle",
    "subsurface_bias_mm": "subsurface_bias",
    "subsurface_sigma_mm": "subsurface_sigma",
    "spurious_fraction": "spurious_fraction",
    "spurious_range_mm": "spurious_range",
    "concave_fraction": "concave_fraction",
    "concave_distance_mm": "concave_distance",
}


def _effects(table, name: str) -> MaterialEffects:
    """A material's ``cell`` table (mm, fractions) as :class:`MaterialEffects` (m); ``source`` keys name
    where each value comes from and are kept out of the record."""
    if not isinstance(table, dict):
        raise ConfigError(f"material '{name}': cell must be a table")
    unknown = {k for k in set(table) - set(_EFFECT_KEYS) if not k.endswith("source")}
    if unknown:
        raise ConfigError(f"material '{name}': unknown key(s) in cell: {', '.join(sorted(unknown))}")
    values = {}
    for key, attr in _EFFECT_KEYS.items():
        v = table.get(key, 0.0)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or v < 0:
            raise ConfigError(f"material '{name}': cell.{key} must be a number >= 0, got {v!r}")
        values[attr] = float(v) * (1e-3 if key.endswith("_mm") else 1.0)
    if values["spurious_fraction"] > 1 or values["concave_fraction"] > 1:
        raise ConfigError(f"material '{name}': cell fractions must be in [0, 1]")
    return MaterialEffects(**values)


def _from_csv(path: Path, name: str | None = None) -> Material:
    if not path.is_file():
        raise ConfigError(f"material table {path} not found")
    try:
        with path.open(newline="") as fh:
            rows = list(csv.DictReader(fh))
        aoi = np.array([float(r["aoi_deg"]) for r in rows])
        val = np.array([float(r["intensity"]) for r in rows])
    except (KeyError, ValueError, TypeError) as exc:
        raise ConfigError(f"material table {path}: needs numeric columns aoi_deg,intensity ({exc})") from None
    if len(aoi) < 2 or np.any(np.diff(aoi) <= 0) or aoi[0] < 0 or aoi[-1] > 90 or np.any(val < 0):
        raise ConfigError(
            f"material table {path}: need >= 2 rows, aoi_deg strictly increasing in [0, 90], intensity >= 0"
        )
    return Material(
        name=name or path.stem,
        table_aoi=tuple(np.deg2rad(aoi)),
        table_intensity=tuple(val),
        description=f"measured table {path.name}",
    )


def _preset_tables() -> dict[str, dict]:
    return tomllib.loads(resources.files("optipose.data").joinpath("materials.toml").read_text())


def material_presets() -> list[str]:
    return sorted(_preset_tables())


def load_material(spec: str | Path | Material) -> Material:
    """A material from a preset name, a CSV table (``aoi_deg,intensity``) or a TOML file with one table."""
    if isinstance(spec, Material):
        return spec
    presets = _preset_tables()
    if str(spec) in presets:
        return _from_table(str(spec), presets[str(spec)])
    path = Path(spec)
    if path.suffix.lower() == ".csv":
        return _from_csv(path)
    if path.suffix.lower() == ".toml" and path.is_file():
        tables, _ = read_toml(path, "material file")
        if len(tables) != 1:
            raise ConfigError(f"material file {path}: expected exactly one [material-name] table")
        ((name, table),) = tables.items()
        if "csv" in table:
            table = dict(table, csv=str((path.parent / table["csv"]).resolve()))
        return _from_table(name, table)
    raise ConfigError(f"unknown material '{spec}' (presets: {', '.join(sorted(presets))}, or a .csv/.toml file)")
