"""The LLT sensor model: measuring trapezoid, laser fan, receiver and head box (docs/sensor.md).

Sensor frame S: origin at the middle-range point R, ``z_S`` from the head toward the part, ``x_S`` along
the laser line, ``y_S = z_S × x_S``. The emitter window is at ``z_S = -reference_distance``. The laser
fan is modelled as rays from a virtual apex on the ``-z_S`` axis, placed so the fan's width matches the
datasheet at both ends of the Z range. The receiver is a pinhole at ``(0, baseline, -reference_distance)``
looking at R.
"""

from __future__ import annotations

import tomllib
from dataclasses import asdict, dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from optipose.errors import ConfigError, read_toml

__all__ = ["SensorModel", "load_sensor", "sensor_presets"]

_MM = 1e-3


@dataclass(frozen=True)
class SensorModel:
    """An LLT profile sensor, SI units (metres).

    The numbers behind the measuring trapezoid are ``z_half_range`` (±Z about R) and the fan widths at
    the near and far ends of that range; ``width_reference`` is kept for documentation and for checks
    (a straight fan through both ends gives a slightly different width at R).
    """

    name: str
    reference_distance: float
    z_half_range: float
    width_near: float
    width_reference: float
    width_far: float
    points_per_profile: int = 3200
    imager_rows: int = 2230
    z_resolution: float = 1.6e-6
    repeatability_z: float = 0.5e-6
    repeatability_x: float = 1e-6
    baseline: float = 0.030
    head_box: tuple[float, float, float] = (0.090, 0.030, 0.070)
    noise_sigma: float = 2e-6
    detection_threshold: float = 0.05
    saturation: float = 0.0
    description: str = ""

    def __post_init__(self) -> None:
        problems = []
        if not (self.reference_distance > self.z_half_range > 0):
            problems.append("need reference_distance > z_half_range > 0")
        if not (0 < self.width_near <= self.width_far):
            problems.append("need 0 < width_near <= width_far")
        if self.points_per_profile < 2:
            problems.append("points_per_profile must be at least 2")
        if self.baseline <= 0 or min(self.head_box) <= 0:
            problems.append("baseline and head_box must be positive")
        if self.noise_sigma < 0 or self.z_resolution < 0:
            problems.append("noise_sigma and z_resolution must be >= 0")
        if not (0 <= self.detection_threshold < 1):
            problems.append("detection_threshold must be in [0, 1)")
        if problems:
            raise ConfigError(f"sensor '{self.name}': " + "; ".join(problems))

    # --- geometry in S -------------------------------------------------------------------------------
    @property
    def z_near(self) -> float:
        """Near end of the Z range in S (m, negative: toward the head)."""
        return -self.z_half_range

    @property
    def z_far(self) -> float:
        return self.z_half_range

    @property
    def apex_z(self) -> float:
        """z_S of the fan's virtual apex (m), behind the window when the fan widens with distance."""
        slope = (self.width_far - self.width_near) / (2.0 * (self.z_far - self.z_near))  # half-width per m
        if slope <= 0:
            return -np.inf  # parallel beam (equal widths): no apex
        return self.z_near - 0.5 * self.width_near / slope

    @property
    def window_z(self) -> float:
        return -self.reference_distance

    @property
    def receiver(self) -> np.ndarray:
        """Receiver pinhole position in S, (3,) m."""
        return np.array([0.0, self.baseline, -self.reference_distance])

    def half_width(self, z: np.ndarray) -> np.ndarray:
        """Half-width of the fan (m) at depth ``z`` in S."""
        t = (np.asarray(z) - self.z_near) / (self.z_far - self.z_near)
        return 0.5 * (self.width_near + t * (self.width_far - self.width_near))

    def laser_rays(self) -> tuple[np.ndarray, np.ndarray]:
        """Origins (n, 3) and unit directions (n, 3) of the profile's laser rays in S, n = points_per_profile.

        Ray i passes through x_i at the far end, with x_i evenly spaced over the far width, so the
        columns are evenly spaced along the line. Origins sit on the window plane (the fan starts at the
        emitter, so nothing between apex and window can be hit).
        """
        n = self.points_per_profile
        x_far = np.linspace(-0.5 * self.width_far, 0.5 * self.width_far, n)
        if np.isfinite(self.apex_z):
            apex = np.array([0.0, 0.0, self.apex_z])
            target = np.column_stack([x_far, np.zeros(n), np.full(n, self.z_far)])
            d = target - apex
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            s = (self.window_z - self.apex_z) / d[:, 2]
            origins = apex + s[:, None] * d
        else:
            d = np.tile([0.0, 0.0, 1.0], (n, 1))
            origins = np.column_stack([x_far, np.zeros(n), np.full(n, self.window_z)])
        return origins, d

    def head_box_corners(self) -> np.ndarray:
        """The 8 corners (8, 3) of the head box in S: behind the window, centred on the laser axis."""
        hx, hy, hz = self.head_box
        xs = np.array([-hx / 2, hx / 2])
        # The head holds both the emitter (y_S = 0) and the receiver (y_S = baseline): centre between them.
        ys = np.array([-hy / 2, hy / 2]) + 0.5 * self.baseline
        zs = np.array([self.window_z - hz, self.window_z])
        return np.array([[x, y, z] for x in xs for y in ys for z in zs])

    def to_dict(self) -> dict:
        return asdict(self)


def _from_table(name: str, table: dict) -> SensorModel:
    mm_keys = {
        "reference_distance_mm": "reference_distance",
        "z_half_range_mm": "z_half_range",
        "width_near_mm": "width_near",
        "width_reference_mm": "width_reference",
        "width_far_mm": "width_far",
        "z_resolution_mm": "z_resolution",
        "repeatability_z_mm": "repeatability_z",
        "repeatability_x_mm": "repeatability_x",
        "baseline_mm": "baseline",
        "noise_sigma_mm": "noise_sigma",
    }
    plain = {"points_per_profile", "imager_rows", "detection_threshold", "saturation", "description"}
    kwargs: dict = {"name": name}
    for key, value in table.items():
        if key in mm_keys:
            kwargs[mm_keys[key]] = float(value) * _MM
        elif key == "head_box_mm":
            if len(value) != 3:
                raise ConfigError(f"sensor '{name}': head_box_mm needs 3 numbers")
            kwargs["head_box"] = tuple(float(v) * _MM for v in value)
        elif key in plain:
            kwargs[key] = value
        else:
            raise ConfigError(f"sensor '{name}': unknown key '{key}'")
    required = {"reference_distance", "z_half_range", "width_near", "width_reference", "width_far"}
    missing = required - kwargs.keys()
    if missing:
        raise ConfigError(f"sensor '{name}': missing {', '.join(sorted(k + '_mm' for k in missing))}")
    try:
        return SensorModel(**kwargs)
    except TypeError as exc:  # wrong value types in the TOML
        raise ConfigError(f"sensor '{name}': {exc}") from None


def _preset_tables() -> dict[str, dict]:
    text = resources.files("optipose.data").joinpath("sensors.toml").read_text()
    return tomllib.loads(text)


def sensor_presets() -> list[str]:
    """Names of the shipped sensor presets."""
    return sorted(_preset_tables())


def load_sensor(spec: str | Path | SensorModel) -> SensorModel:
    """A sensor from a preset name, or from a user TOML file holding one ``[name]`` table in the preset format."""
    if isinstance(spec, SensorModel):
        return spec
    presets = _preset_tables()
    if str(spec) in presets:
        return _from_table(str(spec), presets[str(spec)])
    path = Path(spec)
    if path.suffix == ".toml" and path.is_file():
        tables, _ = read_toml(path, "sensor file")
        if len(tables) != 1:
            raise ConfigError(f"sensor file {path}: expected exactly one [sensor-name] table")
        ((name, table),) = tables.items()
        return _from_table(name, table)
    raise ConfigError(f"unknown sensor '{spec}' (presets: {', '.join(sorted(presets))}, or a .toml file)")
