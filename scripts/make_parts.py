"""Build the three shipped parts (docs/parts.md) as watertight meshes from named parameters.

Usage: ``.venv/bin/python scripts/make_parts.py [OUT_DIR]`` (default: the repo's ``parts/``). Writes
``OUT_DIR/part_a/part_a.stl`` etc., binary STL in **metres**. The CAD models of the paper are not
published, so these are parametric re-creations with the paper's sizes and the features its text names.
Lengths below are in millimetres (the constants say so); the meshes are scaled to metres on export.

Object frame (docs/conventions.md): the part is carried along ``+x_O``; its length runs along x from 0 to L, its
width along y centred on 0, its height along z from 0 (the bottom, where the flange holds it) up.

The build is deterministic: manifold3d booleans on the same inputs give the same triangles, and the STL
header is fixed, so re-running gives byte-identical files (the tests check this).

Curved features are polygons with a fixed number of segments; the exact volumes of these polygonal
solids are in :func:`expected_volume_mm3` (hand formulas from the parameters, used by the tests).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

# --- Part A: milled aluminium block, Ra 1.6 ----------------------------------------------------------
A_LENGTH_MM = 54.0  # along x (scanning direction)
A_WIDTH_MM = 45.0  # along y
A_HEIGHT_MM = 32.0  # along z
A_REBATE_WIDTH_MM = 10.0  # step milled along the left (-y) long top edge: its floor and inner wall
A_REBATE_DEPTH_MM = 10.0
A_FILLET_RADIUS_MM = 8.0  # rounded right (+y) long top edge
A_HOLE_DIAMETER_MM = 8.0  # two blind holes in the top face, on y = A_HOLE_Y_MM
A_HOLE_DEPTH_MM = 12.0
A_HOLE_X_MM = (13.5, 40.5)
A_HOLE_Y_MM = 0.0

# --- Part B: 3D-printed black PLA block ----------------------------------------------------------------
B_LENGTH_MM = 60.0
B_WIDTH_MM = 41.0
B_HEIGHT_MM = 17.6  # the paper's S2 aims at z = 17.5 mm: 0.1 mm below this top face, well inside its range
B_POCKET_UPPER_MM = (36.0, 24.0, 4.0)  # stepped pocket centred in the top: length, width, depth
B_POCKET_LOWER_MM = (24.0, 12.0, 5.0)  # second step, below the first (depth counted from the first floor)
B_HOLE_DIAMETER_MM = 5.5  # four through holes (M5 clearance) at (x, ±y)
B_HOLE_X_MM = (7.0, 53.0)
B_HOLE_Y_MM = 14.0

# --- Part C: bent steel sheet, U bracket -------------------------------------------------------------
C_LENGTH_MM = 42.5  # base plate along x
C_WIDTH_MM = 55.0  # outside of the two bent lugs, along y
C_HEIGHT_MM = 32.5  # bottom of the base to the top of the lugs
C_SHEET_MM = 2.0
C_BEND_INNER_RADIUS_MM = 2.0
C_LUG_WIDTH_MM = 12.0  # the bent elements, centred on x = L/2; also the scanning length
C_HOLE_DIAMETER_MM = 8.0  # one through hole in the base, under the lugs' strip, at (L/2, 0)

# --- Tessellation ------------------------------------------------------------------------------------
# Chord error (sagitta) r·(1 - cos(π/n)): 2.1 µm on a Ø8 hole with 96 segments, 2.4 µm on the R8 fillet
# with 32 per 90° — about the sensor's noise (2 µm), while each part stays under 2,000 triangles.
HOLE_SEGMENTS = 96  # per full circle
ARC_SEGMENTS = 32  # per 90° of fillet or bend

PARTS = ("part_a", "part_b", "part_c")
_MM_TO_M = 1e-3
_YZ_TO_X = np.array([[0.0, 0.0, 1.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]])  # (u,v,w)->(w,u,v)


def _arc(centre: tuple[float, float], radius: float, start_deg: float, end_deg: float) -> list:
    """Points (ARC_SEGMENTS + 1) of a 90° arc in the (y, z) plane, both ends included."""
    a = np.deg2rad(np.linspace(start_deg, end_deg, ARC_SEGMENTS + 1))
    return list(zip(centre[0] + radius * np.cos(a), centre[1] + radius * np.sin(a)))


def _extrude_yz(outline: list, x0: float, length: float):
    """A prism from a CCW (y, z) outline, spanning x0..x0+length along x."""
    from manifold3d import CrossSection

    prism = CrossSection([np.asarray(outline, dtype=float)]).extrude(length)
    return prism.transform(_YZ_TO_X).translate((x0, 0.0, 0.0))


def _box(lo: tuple, hi: tuple):
    from manifold3d import Manifold

    size = tuple(h - l for l, h in zip(lo, hi))
    return Manifold.cube(size).translate(lo)


def _hole(x: float, y: float, z0: float, depth: float, diameter: float):
    """A vertical cylinder (cutter) from z0 up by depth."""
    from manifold3d import Manifold

    return Manifold.cylinder(depth, diameter / 2, diameter / 2, HOLE_SEGMENTS).translate((x, y, z0))


def build_part_a():
    w2, h, r = A_WIDTH_MM / 2, A_HEIGHT_MM, A_FILLET_RADIUS_MM
    ry, rz = -w2 + A_REBATE_WIDTH_MM, h - A_REBATE_DEPTH_MM
    outline = [(-w2, 0.0), (w2, 0.0), *_arc((w2 - r, h - r), r, 0.0, 90.0), (ry, h), (ry, rz), (-w2, rz)]
    body = _extrude_yz(outline, 0.0, A_LENGTH_MM)
    eps = 1.0  # cutters poke out of the top so no coplanar faces are left behind
    for x in A_HOLE_X_MM:
        body -= _hole(x, A_HOLE_Y_MM, h - A_HOLE_DEPTH_MM, A_HOLE_DEPTH_MM + eps, A_HOLE_DIAMETER_MM)
    return body


def build_part_b():
    L, w2, h, eps = B_LENGTH_MM, B_WIDTH_MM / 2, B_HEIGHT_MM, 1.0
    body = _box((0.0, -w2, 0.0), (L, w2, h))
    (ul, uw, ud), (ll, lw, ld) = B_POCKET_UPPER_MM, B_POCKET_LOWER_MM
    body -= _box((L / 2 - ul / 2, -uw / 2, h - ud), (L / 2 + ul / 2, uw / 2, h + eps))
    body -= _box((L / 2 - ll / 2, -lw / 2, h - ud - ld), (L / 2 + ll / 2, lw / 2, h - ud + eps))
    for x in B_HOLE_X_MM:
        for y in (-B_HOLE_Y_MM, B_HOLE_Y_MM):
            body -= _hole(x, y, -eps, h + 2 * eps, B_HOLE_DIAMETER_MM)
    return body


def _u_outline() -> list:
    """The bracket's (y, z) cross-section across the lugs: base, two 90° bends, two lugs (CCW)."""
    w2, h, t, ri = C_WIDTH_MM / 2, C_HEIGHT_MM, C_SHEET_MM, C_BEND_INNER_RADIUS_MM
    ro, c = ri + t, w2 - ri - t  # outer radius; |y| of the bend centres
    return [
        *_arc((c, ro), ro, -90.0, 0.0),
        (w2, h),
        (w2 - t, h),
        *_arc((c, ro), ri, 0.0, -90.0),
        *_arc((-c, ro), ri, -90.0, -180.0),
        (-w2 + t, h),
        (-w2, h),
        *_arc((-c, ro), ro, 180.0, 270.0),
    ]


def build_part_c():
    L, t = C_LENGTH_MM, C_SHEET_MM
    c = C_WIDTH_MM / 2 - C_BEND_INNER_RADIUS_MM - t
    base = _box((0.0, -c, 0.0), (L, c, t))  # the flat plate; outside the lugs' strip it ends at the bends
    lugs = _extrude_yz(_u_outline(), L / 2 - C_LUG_WIDTH_MM / 2, C_LUG_WIDTH_MM)
    return (base + lugs) - _hole(L / 2, 0.0, -1.0, t + 2.0, C_HOLE_DIAMETER_MM)


BUILDERS = {"part_a": build_part_a, "part_b": build_part_b, "part_c": build_part_c}


def _polygon_area(radius: float, segments: int, angle: float) -> float:
    """Area of the fan of ``segments`` chords spanning ``angle`` rad on a circle of ``radius``."""
    return 0.5 * segments * radius**2 * np.sin(angle / segments)


def expected_volume_mm3(name: str) -> float:
    """Exact volume (mm³) of the polygonal solid ``name``, from the parameters by hand formulas."""
    hole = _polygon_area(1.0, HOLE_SEGMENTS, 2 * np.pi)  # area of a unit-radius HOLE_SEGMENTS-gon
    if name == "part_a":
        r = A_FILLET_RADIUS_MM
        fillet_removed = r**2 - _polygon_area(r, ARC_SEGMENTS, np.pi / 2)
        section = A_WIDTH_MM * A_HEIGHT_MM - A_REBATE_WIDTH_MM * A_REBATE_DEPTH_MM - fillet_removed
        holes = len(A_HOLE_X_MM) * hole * (A_HOLE_DIAMETER_MM / 2) ** 2 * A_HOLE_DEPTH_MM
        return section * A_LENGTH_MM - holes
    if name == "part_b":
        pockets = np.prod(B_POCKET_UPPER_MM) + np.prod(B_POCKET_LOWER_MM)
        holes = 2 * len(B_HOLE_X_MM) * hole * (B_HOLE_DIAMETER_MM / 2) ** 2 * B_HEIGHT_MM
        return B_LENGTH_MM * B_WIDTH_MM * B_HEIGHT_MM - pockets - holes
    if name == "part_c":
        t, ri = C_SHEET_MM, C_BEND_INNER_RADIUS_MM
        ro = ri + t
        bend = _polygon_area(1.0, ARC_SEGMENTS, np.pi / 2) * (ro**2 - ri**2)  # chords at the same angles
        base = C_LENGTH_MM * (C_WIDTH_MM - 2 * ro) * t
        lugs = C_LUG_WIDTH_MM * 2 * (bend + (C_HEIGHT_MM - ro) * t)
        return base + lugs - hole * (C_HOLE_DIAMETER_MM / 2) ** 2 * t
    raise KeyError(name)


def expected_size_mm(name: str) -> tuple[float, float, float]:
    """Bounding-box size (L, W, H) in mm."""
    return {
        "part_a": (A_LENGTH_MM, A_WIDTH_MM, A_HEIGHT_MM),
        "part_b": (B_LENGTH_MM, B_WIDTH_MM, B_HEIGHT_MM),
        "part_c": (C_LENGTH_MM, C_WIDTH_MM, C_HEIGHT_MM),
    }[name]


def to_trimesh(solid):
    """A manifold3d solid in mm -> a ``trimesh.Trimesh`` in metres (not re-processed: order is kept)."""
    import trimesh

    mesh_gl = solid.to_mesh()
    vertices = np.asarray(mesh_gl.vert_properties, dtype=np.float64)[:, :3] * _MM_TO_M
    return trimesh.Trimesh(vertices, np.asarray(mesh_gl.tri_verts, dtype=np.int64), process=False)


def write_part(name: str, out_dir: Path) -> Path:
    """Build part ``name`` and write ``out_dir/name/name.stl`` (binary, metres)."""
    solid = BUILDERS[name]()
    if solid.status().name != "NoError" or len(solid.decompose()) != 1:
        raise RuntimeError(f"{name}: the boolean build did not give one valid solid")
    path = out_dir / name / f"{name}.stl"
    path.parent.mkdir(parents=True, exist_ok=True)
    data = to_trimesh(solid).export(file_type="stl")  # binary; trimesh's header is a fixed string
    path.write_bytes(data)
    return path


def main(argv: list[str]) -> None:
    out_dir = Path(argv[0]) if argv else Path(__file__).resolve().parents[1] / "parts"
    for name in PARTS:
        path = write_part(name, out_dir)
        size = " x ".join(f"{v:g}" for v in expected_size_mm(name))
        print(f"{path}: {size} mm, {expected_volume_mm3(name):.3f} mm^3")


if __name__ == "__main__":
    main(sys.argv[1:])
