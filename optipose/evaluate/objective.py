"""Objective files: the perturbation protocol, the registration settings and the statistic, from TOML.

An objective names everything that turns a layout into a number (docs/method.md). The shipped ones live in
``objectives/<name>.toml`` (``paper`` reproduces the paper). Files speak degrees and millimetres
(``*_deg``, ``*_mm`` keys); the typed config here is SI (radians, metres). See ``objectives/paper.toml``
for every key with its meaning.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from optipose.errors import ConfigError, read_toml, shipped_toml
from optipose.registration.backends import BACKENDS as REGISTRATION_BACKENDS
from optipose.cell.config import IDEAL, Cell, load_cell
from optipose.cell.robot import CalibrationErrors, RobotErrors
from optipose.registration.config import RegistrationConfig

# what an objective's [conditions] table, the objective `robust` and a search's band_objective say now
BAND_RETIRED = (
    "the band of conditions ([conditions], objective 'robust', band_objective) was retired: a cell with ranges says "
    "what a cell does not know; use --cell cobot, industrial-arm, linear-axis or machined-bracket (docs/conditions.md)"
)

__all__ = [
    "ScanConfig",
    "ProtocolConfig",
    "RegistrationConfig",
    "StatisticConfig",
    "Objective",
    "load_objective",
    "objective_from_table",
    "reduced_objective",
    "BAND_RETIRED",
    "objective_from_dict",
    "OBJECTIVES_DIR",
    "AXES",
]

OBJECTIVES_DIR = Path(__file__).resolve().parents[2] / "objectives"
AXES = ("roll", "pitch", "yaw")
METHODS = ("point_to_point", "point_to_plane", "generalized")
REFERENCES = ("cad-surface", "cad-sample", "nominal-scan")
SEQUENCE_AXES = {"R": (0,), "P": (1,), "Y": (2,), "RP": (0, 1), "PY": (1, 2), "YR": (2, 0), "RPY": (0, 1, 2)}
_MM, _DEG = 1e-3, np.pi / 180


@dataclass(frozen=True)
class ProtocolConfig:
    """Which orientations (and offsets) the part is scanned at.

    kind "sequences": in each sequence the named angles run together from ``start`` to ``stop`` (rad) in
    ``step``; kind "random": ``count`` orientations drawn uniformly in ±``range_rpy`` (rad) and offsets in
    ±``range_offset`` (m). ``offsets`` (m, (k, 3)): each orientation is scanned at each offset.
    """

    kind: str = "sequences"
    sequences: tuple[str, ...] = ("R", "P", "Y", "RP", "PY", "YR", "RPY")
    start: float = -2 * _DEG
    stop: float = 2 * _DEG
    step: float = 0.4 * _DEG
    offsets: tuple[tuple[float, float, float], ...] = ()
    count: int = 77
    range_rpy: tuple[float, float, float] = (2 * _DEG, 2 * _DEG, 2 * _DEG)
    range_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class ScanConfig:
    """How the virtual scanner casts: ``column_stride`` (see :class:`optipose.scan.scanner.Scanner`; the
    clouds are the same for any stride but on features thinner than stride × the column pitch)."""

    column_stride: int = 16


@dataclass(frozen=True)
class StatisticConfig:
    """How per-axis errors become numbers: median and 75th percentile per axis, and a weighted score."""

    weights: tuple[float, float, float] = (1.0, 1.0, 1.0)
    median_weight: float = 1.0
    p75_weight: float = 1.0
    observability_tolerance: float = 1e-6


@dataclass(frozen=True)
class Objective:
    name: str = "paper"
    description: str = ""
    protocol: ProtocolConfig = field(default_factory=ProtocolConfig)
    registration: RegistrationConfig = field(default_factory=RegistrationConfig)
    statistic: StatisticConfig = field(default_factory=StatisticConfig)
    scan: ScanConfig = field(default_factory=ScanConfig)
    cell: Cell = IDEAL  # the real cell's error sources the layouts are evaluated in (optipose.cell; docs/cell.md)
    source_text: str = field(default="", repr=False, compare=False)  # the file as written, saved with results

    def to_dict(self) -> dict:
        """The resolved config in SI units (radians, metres), for saving beside results."""
        out = asdict(self)
        out.pop("source_text")
        out["cell"].pop("source_text")
        return out

    def in_cell(self, cell) -> "Objective":
        """This objective in ``cell`` (a :class:`Cell`, a shipped name or a path; ``None``: unchanged)."""
        return self if cell is None else replace(self, cell=load_cell(cell))


def load_objective(spec: str | Path) -> Objective:
    """An objective from a shipped name (``paper``) or a TOML path."""
    if str(spec) == "robust" and not Path(spec).exists():
        raise ConfigError(f"objective 'robust': {BAND_RETIRED}")
    path = shipped_toml(spec, OBJECTIVES_DIR, "objective")
    table, text = read_toml(path, "objective file")
    return objective_from_table(table, where=str(path), source_text=text, default_name=path.stem)


def objective_from_dict(table: dict, source_text: str = "") -> Objective:
    """The inverse of :meth:`Objective.to_dict`: a resolved (SI) objective as saved beside a result."""

    def frozen(value):  # TOML gives lists where the config holds tuples
        return tuple(frozen(v) for v in value) if isinstance(value, list) else value

    def section(cls, values: dict):
        return cls(**{k: frozen(v) for k, v in values.items() if k in cls.__dataclass_fields__})

    return Objective(
        name=str(table.get("name", "objective")),
        description=str(table.get("description", "")),
        protocol=section(ProtocolConfig, table.get("protocol", {})),
        registration=section(RegistrationConfig, table.get("registration", {})),
        statistic=section(StatisticConfig, table.get("statistic", {})),
        scan=section(ScanConfig, table.get("scan", {})),
        cell=_saved_cell(table.get("cell")),
        source_text=source_text,
    )


def _saved_cell(t: dict | None) -> Cell:
    """A cell as :meth:`Objective.to_dict` saved it (absent in folders written before cells: the ideal one)."""
    if not t:
        return IDEAL
    t = dict(t)
    robot, calibration = RobotErrors(**t.pop("robot", {})), CalibrationErrors(**t.pop("calibration", {}))
    ranges = tuple((str(name), float(low), float(high)) for name, low, high in t.pop("ranges", ()))
    return Cell(
        robot=robot,
        calibration=calibration,
        ranges=ranges,
        **{k: v for k, v in t.items() if k in Cell.__dataclass_fields__},
    )


def reduced_objective(objective: Objective) -> Objective:
    """The objective with each sequence cut to its two end angles (start and stop): the search's cheap
    protocol (14 of the paper's 77 scans); a random protocol keeps a fifth of its draws (at least 4)."""
    p = objective.protocol
    if p.kind != "sequences":
        return replace(objective, protocol=replace(p, count=max(4, p.count // 5)))
    return replace(objective, protocol=replace(p, step=max(p.stop - p.start, 1e-9)))


def objective_from_table(
    table: dict, where: str = "objective", source_text: str = "", default_name: str = "objective"
) -> Objective:
    """Validate a parsed objective table; every problem is a :class:`ConfigError` naming the key."""
    if _asks_for_a_band(table.get("conditions")):
        raise ConfigError(f"{where}: {BAND_RETIRED}")
    table = {k: v for k, v in table.items() if k != "conditions"}
    _no_unknown(table, {"name", "description", "protocol", "registration", "statistic", "scan", "cell"}, where)
    cell = table.get("cell", "ideal")
    if not isinstance(cell, str):
        raise ConfigError(f"{where}: cell must be a cell's name or a path to its file, got {cell!r}")
    if cell and not Path(cell).is_absolute() and Path(cell).suffix and where != "objective":
        cell = str(Path(where).parent / cell)  # a cell file beside the objective file
    return Objective(
        name=str(table.get("name", default_name)),
        description=str(table.get("description", "")),
        protocol=_protocol(table.get("protocol", {}), f"{where} [protocol]"),
        registration=_registration(table.get("registration", {}), f"{where} [registration]"),
        statistic=_statistic(table.get("statistic", {}), f"{where} [statistic]"),
        scan=_scan(table.get("scan", {}), f"{where} [scan]"),
        cell=load_cell(cell),
        source_text=source_text,
    )


# ---------------------------------------------------------------------------------------------------------
def _asks_for_a_band(conditions) -> bool:
    """Whether an objective's retired ``[conditions]`` table asks for a band: anything but the nominal cell alone
    (one noise level at the preset's, exact brackets), which the shipped objectives wrote out before the band was
    retired and which is what every evaluation is now, so copies of them still load."""
    if conditions is None:
        return False
    if not isinstance(conditions, dict):
        return True
    nominal = {"noise_scale": (1, [1]), "mounting_translation_mm": (0,), "mounting_rotation_deg": (0,)}
    nominal |= {"mounting_draws": (1,), "aggregate": ("worst",)}
    return any(k not in nominal or v not in nominal[k] for k, v in conditions.items())


def _protocol(t: dict, where: str) -> ProtocolConfig:
    keys = {
        "kind",
        "sequences",
        "start_deg",
        "stop_deg",
        "step_deg",
        "offsets_mm",
        "count",
        "range_deg",
        "offset_range_mm",
    }
    _no_unknown(t, keys, where)
    kind = _choice(t, "kind", ("sequences", "random"), "sequences", where)
    sequences = tuple(str(s).upper() for s in t.get("sequences", ProtocolConfig.sequences))
    bad = [s for s in sequences if s not in SEQUENCE_AXES]
    if bad or not sequences:
        raise ConfigError(
            f"{where}: sequences must be a non-empty list of {', '.join(SEQUENCE_AXES)}; got {bad or '[]'}"
        )
    start, stop, step = (_num(t, k, d, where) for k, d in (("start_deg", -2.0), ("stop_deg", 2.0), ("step_deg", 0.4)))
    if not (step > 0 and stop >= start):
        raise ConfigError(f"{where}: need step_deg > 0 and stop_deg >= start_deg (got {start}, {stop}, {step})")
    if (stop - start) / step > 10_000:
        raise ConfigError(f"{where}: {int((stop - start) / step)} steps per sequence is too many")
    count = int(_num(t, "count", 77, where))
    if count < 1:
        raise ConfigError(f"{where}: count must be >= 1")
    offsets = _vectors(t.get("offsets_mm", []), f"{where} offsets_mm")
    range_deg = _vectors([t.get("range_deg", [2.0, 2.0, 2.0])], f"{where} range_deg")[0]
    range_off = _vectors([t.get("offset_range_mm", [0.0, 0.0, 0.0])], f"{where} offset_range_mm")[0]
    if min(range_deg) < 0 or min(range_off) < 0:
        raise ConfigError(f"{where}: range_deg and offset_range_mm must be >= 0")
    return ProtocolConfig(
        kind=kind,
        sequences=sequences,
        start=start * _DEG,
        stop=stop * _DEG,
        step=step * _DEG,
        offsets=tuple(tuple(v * _MM for v in o) for o in offsets),
        count=count,
        range_rpy=tuple(v * _DEG for v in range_deg),
        range_offset=tuple(v * _MM for v in range_off),
    )


def _registration(t: dict, where: str) -> RegistrationConfig:
    keys = {
        "method",
        "backend",
        "reference",
        "reference_spacing_mm",
        "voxel_size_mm",
        "outlier_removal",
        "outlier_neighbors",
        "outlier_std_ratio",
        "max_correspondence_distance_mm",
        "max_iterations",
        "tolerance_rotation_deg",
        "tolerance_translation_mm",
        "subset_start",
        "stop",
        "voxel_grid",
        "max_rmse_mm",
    }
    _no_unknown(t, keys, where)
    d = RegistrationConfig()
    cfg = RegistrationConfig(
        method=_choice(t, "method", METHODS, d.method, where),
        backend=_choice(t, "backend", tuple(REGISTRATION_BACKENDS), d.backend, where),
        reference=_choice(t, "reference", REFERENCES, d.reference, where),
        reference_spacing=_num(t, "reference_spacing_mm", 0.2, where) * _MM,
        voxel_size=_num(t, "voxel_size_mm", 0.5, where) * _MM,
        voxel_grid=_choice(t, "voxel_grid", ("part", "random"), d.voxel_grid, where),
        outlier_removal=bool(t.get("outlier_removal", False)),
        outlier_neighbors=int(_num(t, "outlier_neighbors", 20, where)),
        outlier_std_ratio=_num(t, "outlier_std_ratio", 2.0, where),
        max_correspondence_distance=_num(t, "max_correspondence_distance_mm", 5.0, where) * _MM,
        max_iterations=int(_num(t, "max_iterations", 100, where)),
        tolerance_rotation=_num(t, "tolerance_rotation_deg", 1e-5, where) * _DEG,
        tolerance_translation=_num(t, "tolerance_translation_mm", 1e-5, where) * _MM,
        subset_start=_choice(t, "subset_start", ("combined", "identity"), d.subset_start, where),
        stop=_choice(t, "stop", ("step", "fitness"), d.stop, where),
        max_rmse=_num(t, "max_rmse_mm", 0.0, where) * _MM,
    )
    positive = (
        "reference_spacing",
        "max_correspondence_distance",
        "max_iterations",
        "outlier_neighbors",
        "outlier_std_ratio",
    )
    bad = [k for k in positive if not getattr(cfg, k) > 0]
    bad += [k for k in ("voxel_size", "tolerance_rotation", "tolerance_translation", "max_rmse") if getattr(cfg, k) < 0]
    if bad:
        raise ConfigError(f"{where}: {', '.join(bad)} must be positive")
    return cfg


def _scan(t: dict, where: str) -> ScanConfig:
    _no_unknown(t, {"column_stride"}, where)
    stride = _num(t, "column_stride", ScanConfig.column_stride, where)
    if stride < 1 or stride != int(stride):
        raise ConfigError(f"{where}: column_stride must be a whole number >= 1, got {t.get('column_stride')!r}")
    return ScanConfig(column_stride=int(stride))


def _statistic(t: dict, where: str) -> StatisticConfig:
    _no_unknown(t, {"weights", "median_weight", "p75_weight", "observability_tolerance"}, where)
    w = t.get("weights", {})
    if not isinstance(w, dict):
        raise ConfigError(f"{where}: weights must be a table like {{ roll = 1.0, pitch = 1.0, yaw = 1.0 }}")
    _no_unknown(w, set(AXES), f"{where} weights")
    weights = tuple(_num(w, a, 1.0, f"{where} weights") for a in AXES)
    cfg = StatisticConfig(
        weights=weights,
        median_weight=_num(t, "median_weight", 1.0, where),
        p75_weight=_num(t, "p75_weight", 1.0, where),
        observability_tolerance=_num(t, "observability_tolerance", 1e-6, where),
    )
    if min(weights) < 0 or cfg.median_weight < 0 or cfg.p75_weight < 0 or not sum(weights) > 0:
        raise ConfigError(f"{where}: weights must be >= 0 and not all zero")
    if not (0 < cfg.observability_tolerance < 1):
        raise ConfigError(f"{where}: observability_tolerance must be in (0, 1)")
    return cfg


def _no_unknown(t, allowed: set, where: str) -> None:
    if not isinstance(t, dict):
        raise ConfigError(f"{where}: expected a table")
    unknown = set(t) - allowed
    if unknown:
        raise ConfigError(
            f"{where}: unknown key(s) {', '.join(sorted(unknown))} (allowed: {', '.join(sorted(allowed))})"
        )


def _num(t: dict, key: str, default: float, where: str) -> float:
    value = t.get(key, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise ConfigError(f"{where}: {key} must be a number, got {value!r}")
    return float(value)


def _choice(t: dict, key: str, allowed: tuple, default: str, where: str) -> str:
    value = str(t.get(key, default)).lower().replace("-", "_") if key == "method" else str(t.get(key, default)).lower()
    if value not in allowed:
        raise ConfigError(f"{where}: {key} must be one of {', '.join(allowed)}, got {t.get(key)!r}")
    return value


def _vectors(values, where: str) -> list[tuple[float, float, float]]:
    try:
        arr = np.asarray(values, dtype=float).reshape(-1, 3) if len(values) else np.zeros((0, 3))
    except (TypeError, ValueError):
        raise ConfigError(f"{where}: expected [x, y, z] numbers") from None
    if not np.all(np.isfinite(arr)) or (len(values) and np.ndim(values[0]) != 1):
        raise ConfigError(f"{where}: expected a list of [x, y, z] numbers")
    return [tuple(map(float, v)) for v in arr]
