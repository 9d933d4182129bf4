"""A scan folder: a protocol's raw profiles in the device's format, one file per scan and sensor, and the
``manifest.toml`` that says what they are (docs/scans.md).

The same folder comes from a simulated cell (``optipose scan --raw``) and from a real one: the manifest
names the part (and the fingerprint of its mesh, so another part's scans are refused), the sensors' poses
as the cell believes them, each sensor's model, each scan's set orientation (degrees) and offset (mm), the
travel between two profiles (mm), and the files. A file holds ``points_per_profile`` heights a profile
(mm, -9999.9999 empty; :mod:`optipose.scan.profiles`): ``.npy`` float64, which reads back the simulated
cloud bit for bit, or the device's CSV (``%.4f``).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from optipose.errors import ConfigError, read_toml
from optipose.model.layout import Layout, SensorPose
from optipose.model.motion import ScanMotion
from optipose.model.sensor import load_sensor
from optipose.scan.cloud import Scan
from optipose.scan.profiles import profiles_to_points, read_profiles, write_profiles
from optipose.transforms import validate_pose

__all__ = [
    "MANIFEST",
    "FORMATS",
    "ScanEntry",
    "Manifest",
    "part_fingerprint",
    "write_manifest",
    "read_manifest",
    "ProfileWriter",
    "ProfileReader",
]

MANIFEST = "manifest.toml"
FORMAT = "optipose-scans 1"
FORMATS = ("npy", "csv")


def part_fingerprint(vertices: np.ndarray) -> str:
    """A mesh's fingerprint: the SHA-256 of its distinct vertices (m) rounded to 1 µm and sorted, so the
    same part loaded from another file, in other units or with its triangles in another order matches."""
    v = np.unique(np.round(np.asarray(vertices, dtype=np.float64) * 1e6).astype(np.int64), axis=0)
    return "sha256:" + hashlib.sha256(np.ascontiguousarray(v).tobytes()).hexdigest()[:16]


@dataclass(frozen=True)
class ScanEntry:
    """One scan of the protocol: its label (the sequence), set orientation ``rpy_deg`` (3,) and offset
    ``offset_mm`` (3,), and one file per sensor, in the layout's order (names relative to the folder)."""

    label: str
    rpy_deg: tuple[float, float, float]
    offset_mm: tuple[float, float, float]
    files: tuple[str, ...]


@dataclass(frozen=True)
class Manifest:
    """What a scan folder holds. ``layout``: the sensors' poses as the cell believes them, each naming its
    model; ``step``: the travel along +x_O between two profiles (m); ``profiles``: profiles a scan;
    ``objective``, ``cell``, ``seed``: the protocol's objective (a name or a path), the cell scanned in, the
    run's seed; ``settings``: the objective as resolved when the folder was written (``Objective.to_dict``),
    which an evaluation of the folder takes as it is (empty in a folder written by hand)."""

    part: str
    fingerprint: str
    layout: Layout
    step: float
    profiles: int
    objective: str
    cell: str
    seed: int
    scans: tuple[ScanEntry, ...]
    settings: dict = field(default_factory=dict, repr=False)

    def motion(self) -> ScanMotion:
        """The scan's travel: ``profiles`` profiles ``step`` apart, centred on the nominal pose."""
        return ScanMotion(self.profiles * self.step, self.step)


def write_manifest(folder: Path, manifest: Manifest) -> Path:
    """Write ``manifest.toml`` into ``folder`` (floats as Python writes them, so they read back exactly)."""
    import tomli_w

    from optipose.files import write_text

    table = {
        "format": FORMAT,
        "part": manifest.part,
        "part_fingerprint": manifest.fingerprint,
        "layout": manifest.layout.name,
        "objective": manifest.objective,
        "cell": manifest.cell,
        "seed": manifest.seed,
        "units": {"heights": "mm", "empty": -9999.9999, "T_O_S": "m", "angles": "deg", "offsets": "mm"},
        "motion": {"step_mm": manifest.step * 1e3, "profiles": manifest.profiles},
        "sensors": [
            {"name": s.name, "sensor": s.sensor, "T_O_S": np.asarray(s.T_O_S, dtype=float).tolist()}
            for s in manifest.layout.sensors
        ],
        "scans": [
            {"label": e.label, "rpy_deg": list(e.rpy_deg), "offset_mm": list(e.offset_mm), "files": list(e.files)}
            for e in manifest.scans
        ],
    }
    if manifest.settings:
        table["objective_settings"] = _plain(manifest.settings)
    return write_text(Path(folder) / MANIFEST, tomli_w.dumps(table))


def _plain(value):
    """TOML-safe: tuples to lists, numpy to Python, None dropped."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items() if v is not None}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in value]
    return value.item() if isinstance(value, np.generic) else value


def read_manifest(folder: str | Path) -> Manifest:
    """The manifest of the scan folder ``folder``; a missing or malformed one is one :class:`ConfigError`."""
    folder = Path(folder)
    path = folder / MANIFEST
    if not folder.is_dir():
        raise ConfigError(f"--scans {folder}: no such folder")
    if not path.is_file():
        raise ConfigError(f"--scans {folder}: no {MANIFEST} (a scan folder as `optipose scan --raw` writes it)")
    table, _ = read_toml(path, "scan manifest")
    where = str(path)
    try:
        sensors = tuple(
            SensorPose(
                str(s["name"]),
                validate_pose(np.array(s["T_O_S"], dtype=float), f"{where}: sensor {s['name']}"),
                s["sensor"],
            )
            for s in table["sensors"]
        )
        scans = tuple(
            ScanEntry(str(e["label"]), _three(e["rpy_deg"]), _three(e.get("offset_mm", [0, 0, 0])), tuple(e["files"]))
            for e in table["scans"]
        )
        manifest = Manifest(
            part=str(table["part"]),
            fingerprint=str(table["part_fingerprint"]),
            layout=Layout(sensors, name=str(table.get("layout", "scans"))),
            step=float(table["motion"]["step_mm"]) * 1e-3,
            profiles=int(table["motion"]["profiles"]),
            objective=str(table["objective"]),
            cell=str(table.get("cell", "ideal")),
            seed=int(table.get("seed", 0)),
            scans=scans,
            settings=dict(table.get("objective_settings", {})),
        )
    except KeyError as exc:
        raise ConfigError(f"{where}: missing key {exc.args[0]!r}") from None
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{where}: {exc}") from None
    if not sensors or not scans:
        raise ConfigError(f"{where}: needs at least one [[sensors]] and one [[scans]]")
    for e in scans:
        if len(e.files) != len(sensors):
            raise ConfigError(
                f"{where}: scan {e.label} {list(e.rpy_deg)} names {len(e.files)} files for {len(sensors)} sensors"
            )
    if manifest.step <= 0 or manifest.profiles <= 0:
        raise ConfigError(f"{where}: motion.step_mm and motion.profiles must be positive")
    return manifest


def _three(values) -> tuple[float, float, float]:
    out = tuple(float(v) for v in values)
    if len(out) != 3:
        raise ValueError(f"expected 3 numbers, got {list(values)}")
    return out


@dataclass(frozen=True)
class ProfileWriter:
    """Writes scan ``i``'s raw profiles of sensor ``j`` into ``folder`` (picklable: a worker process calls it):
    ``{i:03d}_{label}_{sensor}.npy`` (or ``.csv``, the device's text, ``%.4f``). Returns the file's name."""

    folder: Path
    labels: tuple[str, ...]
    names: tuple[str, ...]
    format: str = "npy"

    def name(self, i: int, j: int) -> str:
        return f"{i:03d}_{self.labels[i]}_{self.names[j]}.{self.format}"

    def __call__(self, i: int, j: int, raw: np.ndarray) -> str:
        from optipose.files import atomic_path

        name = self.name(i, j)
        with atomic_path(Path(self.folder) / name) as tmp:
            write_profiles(tmp, raw, format=self.format)
        return name


@dataclass(frozen=True)
class ProfileReader:
    """Reads a scan folder's scans (picklable: a worker process calls it): ``reader(i)`` is scan ``i`` of the
    protocol, one :class:`~optipose.scan.cloud.Scan` per sensor of ``layout``, each from the file
    ``files[i][j]`` through the sensor's model (``sensors[j]``: a name or a path) and pose, the motion's
    ``shifts`` undone (:func:`optipose.scan.profiles.profiles_to_points`)."""

    folder: Path
    layout: Layout
    sensors: tuple
    files: dict
    shifts: np.ndarray
    rpy: dict

    def check(self) -> None:
        """Before the work: every file the manifest names is there, and each ``.npy`` file (read mapped) has
        the manifest's profiles of the sensor's length and no NaN; a device's text files are checked as read."""
        lengths = [load_sensor(s).points_per_profile for s in self.sensors]
        for i in sorted(self.files):
            for j, name in enumerate(self.files[i]):
                path = self._path(i, j)
                if path.suffix != ".npy":
                    continue
                try:
                    raw = np.load(path, mmap_mode="r", allow_pickle=False)
                except (ValueError, OSError, EOFError) as exc:
                    raise ConfigError(f"{path}: not a .npy array of profiles ({exc})") from None
                if raw.ndim != 2 or raw.shape[1] != lengths[j]:
                    raise ConfigError(
                        f"{path}: profiles of shape {raw.shape[1:]}, the sensor gives {lengths[j]} values a profile"
                    )
                self._count(path, len(raw))
                bad = np.flatnonzero(~np.isfinite(raw).all(axis=1))
                if len(bad):
                    raise ConfigError(f"{path}: profile {bad[0]} holds NaN or infinity (an empty point is -9999.9999)")

    def _path(self, i: int, j: int) -> Path:
        path = Path(self.folder) / self.files[i][j]
        if not path.is_file():
            name = self.layout.sensors[j].name
            raise ConfigError(f"{self.folder}: {self.files[i][j]} (scan {i}, sensor {name} in the manifest) is missing")
        return path

    def _count(self, path: Path, n: int) -> None:
        if n != len(self.shifts):
            raise ConfigError(f"{path}: {n} profiles, the manifest says {len(self.shifts)}")

    def __call__(self, i: int) -> list[Scan]:
        scans = []
        for j, pose in enumerate(self.layout.sensors):
            path = self._path(i, j)
            sensor = load_sensor(self.sensors[j])
            raw = read_profiles(path, sensor.points_per_profile)
            self._count(path, len(raw))
            points, profile, column = profiles_to_points(raw, sensor, pose.T_O_S, self.shifts)
            n = len(points)
            scans.append(
                Scan(
                    points=points,
                    profile=profile,
                    column=column,
                    intensity=np.ones(n, np.float32),  # the device's intensities are not kept
                    raw=raw,
                    T_O_S=pose.T_O_S,
                    rpy=np.asarray(self.rpy[i], dtype=float),
                )
            )
        return scans
