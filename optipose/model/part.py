"""Parts: a mesh plus what the tool needs to scan it — material, sensor, scan motion, keep-outs, layouts.

A part is described by a TOML part file (``parts/<name>/part.toml`` for the shipped ones)::

    [part]
    name = "part_b"                 # optional, default: the folder's name (part.toml) or the file's stem
    description = "..."             # optional
    mesh = "part_b.stl"             # relative to this file; optional in a file beside an STL
    units = "m"                     # auto | m | mm | in (optional, default auto; see optipose.model.mesh)
    material = "black-pla"          # preset name or a .csv/.toml path (relative to this file)
    sensor = "keyence-lj-x8080"     # preset name or a .toml path
    scan_length_mm = 60.0           # optional, default: the mesh's extent along x
    scan_step_mm = 0.5              # optional, default 0.5
    rotation_centre_mm = [30.0, 0.0, 8.8]   # in O; optional, default: the bounding-box centre
    process = "fdm"                 # optional: how it is made, a preset of optipose/data/processes.toml or "cad"

    [[keepout]]                     # any number; axis-aligned boxes in O, mm
    name = "flange"
    min_mm = [-10.0, -40.0, -50.0]
    max_mm = [70.0, 40.0, 0.0]

    [layouts.hand]                  # any number of named layouts, format of optipose.model.layout
    description = "..."
    [[layouts.hand.sensors]]
    name = "S1"
    T_O_S = [[...], [...], [...], [0, 0, 0, 1]]   # metres; columns: S's axes and R's position in O

Keep-out boxes are fixed to the part (they stand for the gripper flange that holds it), so they travel
with it along the scan; :mod:`optipose.model.collision` sweeps them together with the part.

:func:`load_part` takes a shipped part's name, a part file, or a mesh file. A mesh may have a part file
beside it (``<stem>.toml``, else ``part.toml`` in its folder); with none, the defaults are: material
``milled-aluminium-ra1.6``, sensor ``keyence-lj-x8080``, scanning length = the mesh's extent along x,
0.5 mm steps, rotation centre = the bounding-box centre, no keep-outs, and as its only layout the
conventional placement (``layouts["conventional"]``, :mod:`optipose.model.baseline`), which any part
without a ``hand`` layout gets so that a search always has a baseline.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import NamedTuple

import numpy as np

from optipose.errors import ConfigError, MeshError, read_toml
from optipose.model.layout import Layout, layout_from_table
from optipose.model.material import load_material
from optipose.model.mesh import load_mesh
from optipose.model.motion import ScanMotion
from optipose.model.sensor import load_sensor

__all__ = [
    "Part",
    "Keepout",
    "load_part",
    "list_parts",
    "repo_relative",
    "PARTS_DIR",
    "DEFAULT_MATERIAL",
    "DEFAULT_SENSOR",
]

PARTS_DIR = Path(__file__).resolve().parents[2] / "parts"
DEFAULT_MATERIAL = "milled-aluminium-ra1.6"
DEFAULT_SENSOR = "keyence-lj-x8080"
DEFAULT_STEP_MM = 0.5
_MM = 1e-3
_MESH_SUFFIXES = {".stl", ".ply", ".obj", ".off", ".glb", ".gltf"}
_PART_KEYS = {
    "name",
    "description",
    "mesh",
    "units",
    "material",
    "sensor",
    "scan_length_mm",
    "scan_step_mm",
    "rotation_centre_mm",
    "process",
}


class Keepout(NamedTuple):
    """An axis-aligned box in O that no sensor head may enter; ``lo``, ``hi`` (3,) metres."""

    name: str
    lo: np.ndarray
    hi: np.ndarray


@dataclass(eq=False)  # identity semantics: a part is hashable and can key caches (optipose.model.collision)
class Part:
    """A part ready to scan. Lengths in metres, in the part's frame O.

    mesh : ``trimesh.Trimesh`` in metres.
    material, sensor : preset names (or paths) for :class:`optipose.scan.scanner.Scanner`.
    motion : the scan's travel along +x_O.
    rotation_centre : (3,) m, the centre of the orientation offsets (docs/method.md, "The scan and the protocol").
    keepouts : boxes fixed to the part that sensor heads must avoid.
    layouts : named sensor layouts, e.g. ``layouts["hand"]`` (the paper-style baseline) or, without one,
        ``layouts["conventional"]`` (:func:`optipose.model.baseline.baseline` picks).
    source : the part file, or the mesh file when there was none.
    units : the units given to :func:`load_part` (``auto`` when none were); a result folder keeps them so
        that the part is loaded again as it was (the report's views, ``search --resume``).
    """

    name: str
    mesh: object = field(repr=False)
    material: str
    sensor: str
    motion: ScanMotion
    rotation_centre: np.ndarray
    keepouts: list[Keepout] = field(default_factory=list)
    layouts: dict[str, Layout] = field(default_factory=dict)
    source: Path | None = None
    description: str = ""
    units: str = "auto"
    process: str = ""  # how it is made (optipose/data/processes.toml); a real cell scans it as made (docs/cell.md)

    @property
    def size(self) -> np.ndarray:
        """Bounding-box extents (3,) m."""
        return np.asarray(self.mesh.extents, dtype=float)

    @property
    def occluders(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """The keep-outs as boxes that block the laser and the receiver (the flange hides what it covers)."""
        return [(np.asarray(k.lo, float), np.asarray(k.hi, float)) for k in self.keepouts]


def list_parts() -> list[str]:
    """Names of the shipped parts (folders of ``parts/`` holding a ``part.toml``)."""
    if not PARTS_DIR.is_dir():
        return []
    return sorted(p.name for p in PARTS_DIR.iterdir() if (p / "part.toml").is_file())


def repo_relative(source: str | Path) -> str:
    """A part's source as a result folder's config records it: a file inside the repository relative to its root
    (``parts/part_a/part.toml``), so that the folder reads back on another clone; any other path as given."""
    path = Path(source)
    if not str(source) or not path.is_file():  # a shipped part's name, or nothing: as given
        return str(source)
    try:
        return path.resolve().relative_to(PARTS_DIR.parent).as_posix()
    except ValueError:
        return str(source)


def _in_repo(path: Path) -> Path:
    """A relative path that names no file from here but one from the repository's root (a result folder's
    :func:`repo_relative` source, read from another folder): that one; else the path as given."""
    if not path.is_absolute() and not path.exists() and (PARTS_DIR.parent / path).exists():
        return PARTS_DIR.parent / path
    return path


def load_part(spec: str | Path, units: str = "auto") -> Part:
    """A part from a shipped name (``part_a``), a part file (``.toml``) or a mesh file.

    units : ``auto`` | ``m`` | ``mm`` | ``in``; anything but ``auto`` overrides the part file's ``units``.
    Raises :class:`ConfigError` for a bad name or part file, :class:`MeshError` for a bad mesh.
    """
    text = str(spec)
    path = _in_repo(Path(spec))
    if text in list_parts():
        part = _from_part_file(PARTS_DIR / text / "part.toml", units)
    elif path.suffix.lower() == ".toml":
        if not path.is_file():
            raise ConfigError(f"part file not found: {path}")
        part = _from_part_file(path, units)
    elif path.suffix.lower() in _MESH_SUFFIXES:
        part = _from_mesh(path, units)
    else:
        part = None
    if part is not None:
        part.units = units
        return _lean(_with_baseline(part))
    shipped = ", ".join(list_parts()) or "none found"
    raise ConfigError(f"unknown part '{text}' (shipped parts: {shipped}; or a part .toml or a mesh file)")


def _lean(part: Part) -> Part:
    """A dense mesh without the arrays trimesh derived for the checks and the baseline (its edges, their
    sorting and faces, components, per-face areas and crosses: several times the mesh itself), which nothing
    after the loading reads again; each is derived again, the same, if something asks. Normals are kept (a
    file's own may differ from the derived ones), and so are the answers of the closed-solid check, two booleans
    that cost a pass over the edges."""
    from optipose.model.machine import SHARED_FACES

    if len(part.mesh.faces) > SHARED_FACES:
        cached = part.mesh._cache.cache  # trimesh's cache of derived properties, dropped by trimesh itself on any edit
        for key in [
            k for k in cached if k not in ("face_normals", "vertex_normals", "is_watertight", "is_winding_consistent")
        ]:
            del cached[key]
    return part


def _with_baseline(part: Part) -> Part:
    """A part without a hand-placed layout gets the conventional placement (:mod:`optipose.model.baseline`)
    as ``layouts["conventional"]``, so every search and report has something to compare against."""
    from optipose.model.baseline import CONVENTIONAL, conventional_layout

    if "hand" not in part.layouts and CONVENTIONAL not in part.layouts:
        try:
            part.layouts[CONVENTIONAL] = conventional_layout(part)
        except ConfigError as exc:  # a part the conventional heads cannot clear: no baseline, said once
            import logging

            logging.getLogger(__name__).warning("%s", exc)
    return part


def _from_mesh(path: Path, units: str) -> Part:
    """A bare mesh, with the part file beside it if there is one."""
    if not path.is_file():
        raise MeshError(f"mesh file not found: {path}")
    for sidecar in (path.with_suffix(".toml"), path.parent / "part.toml"):
        if sidecar.is_file():
            return _from_part_file(sidecar, units, mesh_path=path)
    mesh = load_mesh(path, units)
    return _assemble({}, mesh, path, name=path.stem, where=str(path))


def _from_part_file(path: Path, units: str, mesh_path: Path | None = None) -> Part:
    data = _read_toml(path)
    unknown = set(data) - {"part", "keepout", "layouts"}
    if unknown:
        raise ConfigError(
            f"{path}: unknown table(s) {', '.join(sorted(unknown))} (use [part], [[keepout]], [layouts.*])"
        )
    table = data.get("part")
    if not isinstance(table, dict):
        raise ConfigError(f"{path}: needs a [part] table")
    bad = set(table) - _PART_KEYS
    if bad:
        raise ConfigError(f"{path}: unknown key(s) in [part]: {', '.join(sorted(bad))}")
    if mesh_path is None:
        if "mesh" not in table:
            raise ConfigError(f'{path}: [part] needs mesh = "file.stl" (relative to the part file)')
        mesh_path = path.parent / str(table["mesh"])
    mesh_units = units if units != "auto" else str(table.get("units", "auto"))
    mesh = load_mesh(mesh_path, mesh_units)
    default_name = path.parent.name if path.name == "part.toml" else path.stem
    part = _assemble(table, mesh, path, name=str(table.get("name", default_name)), where=str(path))
    part.keepouts = _keepouts(data.get("keepout", []), str(path))
    part.layouts = _layouts(data.get("layouts", {}), str(path))
    return part


def _read_toml(path: Path) -> dict:
    try:
        return read_toml(path, "part file")[0]
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"part file {path}: cannot read ({exc})") from None


def _assemble(table: dict, mesh, source: Path, name: str, where: str) -> Part:
    """A Part from the [part] table's scalar settings (defaults where a key is missing)."""
    material = _resolve(table.get("material", DEFAULT_MATERIAL), source)
    sensor = _resolve(table.get("sensor", DEFAULT_SENSOR), source)
    load_material(material), load_sensor(sensor)  # fail here, with the file named, not at scan time
    lo, hi = np.asarray(mesh.bounds, dtype=float)
    length_mm = _number(table, "scan_length_mm", (hi[0] - lo[0]) / _MM, where)
    step_mm = _number(table, "scan_step_mm", DEFAULT_STEP_MM, where)
    if not (length_mm > 0 and step_mm > 0):
        raise ConfigError(f"{where}: scan_length_mm and scan_step_mm must be positive")
    centre = _vector(table, "rotation_centre_mm", where)
    process = _process(table, where)
    return Part(
        name=name,
        mesh=mesh,
        material=material,
        sensor=sensor,
        motion=ScanMotion(length_mm * _MM, step_mm * _MM),
        rotation_centre=0.5 * (lo + hi) if centre is None else centre * _MM,
        source=source,
        description=str(table.get("description", "")),
        process=process,
    )


def _process(table: dict, where: str) -> str:
    """The part's manufacturing process: empty (the cell's default), ``cad`` or a preset of
    optipose/data/processes.toml (read here, not through :mod:`optipose.cell`, which builds on ``model``)."""
    process = table.get("process", "")
    if not isinstance(process, str):
        raise ConfigError(f"{where}: process must be a process's name, got {process!r}")
    presets = read_toml(resources.files("optipose.data").joinpath("processes.toml"), "process presets")[0]
    if process and process != "cad" and process not in presets:
        raise ConfigError(
            f"{where}: unknown manufacturing process '{process}' (presets: cad, {', '.join(sorted(presets))})"
        )
    return process


def _resolve(value, source: Path) -> str:
    """A preset name as is; a relative file path (has a suffix) resolved against the part file's folder."""
    text = str(value)
    if Path(text).suffix and not Path(text).is_absolute():
        candidate = source.parent / text
        if candidate.exists():
            return str(candidate)
    return text


def _number(table: dict, key: str, default: float, where: str) -> float:
    value = table.get(key, default)
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ConfigError(f"{where}: {key} must be a number, got {value!r}")
    return float(value)


def _vector(table: dict, key: str, where: str) -> np.ndarray | None:
    if key not in table:
        return None
    try:
        v = np.array(table[key], dtype=float)
    except (TypeError, ValueError):
        v = np.zeros(0)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ConfigError(f"{where}: {key} must be 3 numbers, got {table[key]!r}")
    return v


def _keepouts(entries, where: str) -> list[Keepout]:
    if not isinstance(entries, list):
        raise ConfigError(f"{where}: keep-outs must be [[keepout]] tables")
    out = []
    for i, entry in enumerate(entries):
        label = str(entry.get("name", f"keepout{i + 1}")) if isinstance(entry, dict) else f"keepout{i + 1}"
        lo = _vector(entry, "min_mm", f"{where}: keepout '{label}'") if isinstance(entry, dict) else None
        hi = _vector(entry, "max_mm", f"{where}: keepout '{label}'") if isinstance(entry, dict) else None
        if lo is None or hi is None or np.any(hi <= lo):
            raise ConfigError(f"{where}: keepout '{label}' needs min_mm and max_mm with min < max on every axis")
        out.append(Keepout(label, lo * _MM, hi * _MM))
    return out


def _layouts(tables, where: str) -> dict[str, Layout]:
    if not isinstance(tables, dict):
        raise ConfigError(f"{where}: layouts must be [layouts.NAME] tables")
    return {
        name: layout_from_table(table, name=name, where=f"{where} [layouts.{name}]") for name, table in tables.items()
    }
