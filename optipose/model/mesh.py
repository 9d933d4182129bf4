"""Loading and checking part meshes; everything downstream is in metres (docs/conventions.md, "Units")."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from optipose.errors import MeshError
from optipose.model.grouping import bodies, closed_and_wound, unique_rows

__all__ = ["load_mesh", "check_mesh", "UNIT_SCALE"]

log = logging.getLogger(__name__)

UNIT_SCALE = {"m": 1.0, "mm": 1e-3, "in": 0.0254}
_AUTO_MM_DIAGONAL = 2.0  # a part with a bounding-box diagonal over 2 "units" is taken to be in mm
# ... but 2-20 "units" is a 2-20 mm part or a 2-20 inch one (51-508 mm, the likelier for a 35 mm laser line):
# auto refuses to guess there
_AUTO_AMBIGUOUS_DIAGONAL = 20.0


def load_mesh(path: str | Path, units: str = "auto"):
    """Load a triangle mesh and return it in metres as a ``trimesh.Trimesh``.

    units : ``auto`` | ``m`` | ``mm`` | ``in``. ``auto`` takes a mesh whose bounding-box diagonal is over
    2 as millimetres and logs that choice, except for a diagonal of 2 to 20, which might as well be
    inches: that needs the units given.
    """
    import trimesh

    path = Path(path)
    if units not in (*UNIT_SCALE, "auto"):
        raise MeshError(f"unknown units '{units}' (use auto, m, mm or in)")
    if not path.is_file():
        raise MeshError(f"mesh file not found: {path}")
    if path.stat().st_size == 0:
        raise MeshError(f"mesh file is empty: {path}")
    try:
        mesh = _read(path)
    except Exception as exc:  # trimesh raises many types for unreadable files
        raise MeshError(f"cannot read mesh {path}: {type(exc).__name__}: {exc}".splitlines()[0]) from None
    if not isinstance(mesh, trimesh.Trimesh):
        raise MeshError(f"cannot read mesh {path}: no triangles found")
    check_mesh(mesh, path.name, watertight=False)
    _merge_vertices(mesh)  # only after the raw data were checked
    if units == "auto":
        diagonal = float(np.linalg.norm(mesh.extents))
        if _AUTO_MM_DIAGONAL < diagonal <= _AUTO_AMBIGUOUS_DIAGONAL:
            raise MeshError(
                f"{path.name}: bounding-box diagonal {diagonal:.3g} could be mm or inches "
                f"({diagonal:.3g} or {diagonal * 25.4:.3g} mm across); give --units mm or --units in"
            )
        units = "mm" if diagonal > _AUTO_MM_DIAGONAL else "m"
        if units == "mm":
            log.info("%s: bounding-box diagonal %.4g > 2, taking units as millimetres", path.name, diagonal)
    scale = UNIT_SCALE[units]
    if scale != 1.0:
        mesh.apply_scale(scale)
    diagonal_m = float(np.linalg.norm(mesh.extents))
    if not (1e-4 < diagonal_m < 20.0):
        raise MeshError(f"{path.name}: part is {diagonal_m:.3g} m across in '{units}' units; wrong --units?")
    check_mesh(mesh, path.name)  # after the scaling, which would clear what it finds from trimesh's cache
    return mesh


def _read(path: Path):
    """The file's triangles, unprocessed. An STL is read by trimesh's STL reader straight into one mesh (a
    CAD export of millions of triangles: its scene, copied and concatenated, took longer than reading it),
    its face normals computed from the triangles as ``trimesh.load`` computes them; any other format by
    ``trimesh.load``."""
    import trimesh

    if path.suffix.lower() == ".stl":
        with path.open("rb") as fh:
            read = trimesh.exchange.stl.load_stl(fh)
        if "vertices" not in read or "faces" not in read:  # text that is no STL: no triangles (the caller says so)
            return None
        return trimesh.Trimesh(vertices=read["vertices"], faces=read["faces"], process=False)
    return trimesh.load(path, force="mesh", process=False)


def _merge_vertices(mesh) -> None:
    """Merge the vertices at one position, as ``mesh.process(validate=False)`` does (trimesh's rounding to
    ``tol.merge``, the first of each kept, the face normals kept), with the equal rows found by hashing
    (:func:`optipose.model.grouping.unique_rows`, the same answer in linear time). A mesh whose vertices
    carry normals or texture coordinates, which trimesh merges only where those agree too, is trimesh's."""
    from trimesh import util
    from trimesh.constants import tol

    if mesh.visual.kind == "texture" or "vertex_normals" in mesh._cache:
        mesh.process(validate=False)
        return
    vertices = mesh.vertices
    referenced = np.zeros(len(vertices), dtype=bool)
    referenced[mesh.faces] = True
    keys = (np.asarray(vertices) * 10 ** util.decimal_to_digits(tol.merge)).round().astype(np.int64)
    first, inverse_referenced = unique_rows(keys[referenced])
    inverse = np.zeros(len(vertices), dtype=np.int64)
    inverse[referenced] = inverse_referenced
    with mesh._cache:  # as trimesh's process: the face normals survive the merge
        mesh.update_vertices(mask=np.flatnonzero(referenced)[first], inverse=inverse)
        mesh._cache.clear(exclude={"face_normals", "vertex_normals"})
    mesh.metadata["processed"] = True


def check_mesh(mesh, name: str = "mesh", watertight: bool = True) -> None:
    """Raise :class:`MeshError` for a mesh the scanner cannot use: no faces, NaN/inf vertices, zero area; warn
    about one that is not a closed solid. ``watertight=False``: the raw file's check before its vertices are
    merged (faces and finite vertices only)."""
    if len(mesh.faces) == 0 or len(mesh.vertices) == 0:
        raise MeshError(f"{name}: mesh has no triangles")
    bad = ~np.all(np.isfinite(mesh.vertices), axis=1)
    if bad.any():
        raise MeshError(f"{name}: mesh has {int(bad.sum())} vertices with NaN or infinite coordinates")
    if not watertight:  # the raw file's check, before the merge: the area is the merged mesh's
        return
    if not float(mesh.area) > 0:
        raise MeshError(f"{name}: mesh has zero surface area")
    known = closed_and_wound(mesh.faces, len(mesh.vertices))  # trimesh's answers, found in linear time
    if known is not None:
        mesh._cache["is_watertight"], mesh._cache["is_winding_consistent"] = known
    # warned, not refused: an open surface (a sheet, a scanned face) is scanned and registered as any other;
    # a soup of loose triangles is too, but its registrations may fail, and every verdict then says so
    # (verdict.compare.Verdict.failed_line)
    problems = [
        w
        for w, bad in (
            ("open: some edges have one face", not mesh.is_watertight),
            ("faces not consistently oriented", not mesh.is_winding_consistent),
        )
        if bad
    ]
    if problems:
        log.warning(
            "%s: mesh is not a closed solid (%s); shadows and inside/outside tests may be wrong and registrations "
            "may fail: export the part as a closed solid",
            name,
            "; ".join(problems),
        )
    count = bodies(mesh.faces, len(mesh.vertices))  # trimesh's body_count (vertices joined by edges), by union-find
    if count > 1:  # legal (a part and its fixture move as one), but often an assembly exported by mistake
        log.warning("%s: mesh has %d separate bodies; they are scanned and registered as one rigid part", name, count)
