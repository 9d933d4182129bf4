"""Build the three mechanical parts of the verdict study (docs/results.md, "The verdict in the real cell").

Usage: ``.venv/bin/python scripts/make_study_parts.py [OUT_DIR]`` (default: ``studies/parts/``). Writes
``OUT_DIR/<name>/<name>.stl`` (binary STL in metres) and ``OUT_DIR/<name>/part.toml`` for each of:

- ``bushing``: a milled aluminium flanged bushing — a Ø50 × 10 mm flange under a Ø30 × 22 mm hub, a Ø16 bore
  through both, four Ø6.6 bolt holes (M6 clearance) on a Ø40 circle: a round part;
- ``angle``: a bent 2 mm steel sheet angle — a 60 × 50 mm base and a 35 mm upright bent at 90° (inner radius
  2 mm), two Ø8.5 holes in the base and one in the upright: a thin part with one bend;
- ``housing``: an FDM-printed PLA housing — a 70 × 45 × 24 mm block with a 50 × 29 × 14 mm pocket open at the
  top, a Ø10 boss standing in it and four Ø3.4 holes in the corners.

None has a hand-placed layout, so each is compared with the conventional placement. The object frame is the
shipped parts' (scripts/make_parts.py): carried along +x, length along x from 0, width centred on y, height
from z = 0 up, the flange that holds it below. Deterministic, as make_parts is.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import make_parts as mp  # noqa: E402  (the shipped parts' builders: extrusion, boxes, holes, arcs, export)

OUT_DIR = Path(__file__).resolve().parents[1] / "studies" / "parts"

# bushing (mm)
BUSH_FLANGE = (50.0, 10.0)  # diameter, height
BUSH_HUB = (30.0, 22.0)  # diameter, height above the flange
BUSH_BORE = 16.0
BUSH_BOLTS = (6.6, 40.0)  # diameter, bolt circle
# angle (mm)
ANGLE_LENGTH, ANGLE_BASE, ANGLE_UP, ANGLE_SHEET, ANGLE_RADIUS = 60.0, 50.0, 35.0, 2.0, 2.0
ANGLE_HOLE = 8.5
# housing (mm)
HOUSING = (70.0, 45.0, 24.0)
HOUSING_POCKET = (50.0, 29.0, 14.0)
HOUSING_BOSS = 10.0
HOUSING_HOLE = (3.4, 5.0)  # diameter, inset from the sides


def build_bushing():
    from manifold3d import Manifold

    (fd, fh), (hd, hh), r = BUSH_FLANGE, BUSH_HUB, BUSH_FLANGE[0] / 2
    body = Manifold.cylinder(fh, fd / 2, fd / 2, mp.HOLE_SEGMENTS) + Manifold.cylinder(
        fh + hh, hd / 2, hd / 2, mp.HOLE_SEGMENTS
    )
    body -= mp._hole(0.0, 0.0, -1.0, fh + hh + 2.0, BUSH_BORE)
    for a in np.deg2rad([45.0, 135.0, 225.0, 315.0]):
        body -= mp._hole(BUSH_BOLTS[1] / 2 * np.cos(a), BUSH_BOLTS[1] / 2 * np.sin(a), -1.0, fh + 2.0, BUSH_BOLTS[0])
    return body.translate((r, 0.0, 0.0))


def _angle_outline() -> list:
    """The angle's (y, z) cross-section: the base along +y from the upright's outer face at y = -w/2, one bend."""
    w2, t, ri, up = ANGLE_BASE / 2, ANGLE_SHEET, ANGLE_RADIUS, ANGLE_UP
    ro = ri + t
    c = (-w2 + ro, ro)  # the bend's centre
    return [
        (w2, 0.0),
        (w2, t),
        (c[0], t),
        *mp._arc(c, ri, 270.0, 180.0),
        (-w2 + t, up),
        (-w2, up),
        *mp._arc(c, ro, 180.0, 270.0),
    ]


def build_angle():
    from manifold3d import Manifold

    body = mp._extrude_yz(_angle_outline(), 0.0, ANGLE_LENGTH)
    for x in (15.0, 45.0):
        body -= mp._hole(x, 8.0, -1.0, ANGLE_SHEET + 2.0, ANGLE_HOLE)
    cutter = Manifold.cylinder(ANGLE_SHEET + 2.0, ANGLE_HOLE / 2, ANGLE_HOLE / 2, mp.HOLE_SEGMENTS).rotate(
        (-90.0, 0.0, 0.0)
    )
    return body - cutter.translate(
        (ANGLE_LENGTH / 2, -ANGLE_BASE / 2 - 1.0, 22.0)
    )  # its axis along y, through the upright


def build_housing():
    (L, W, H), (pl, pw, pd) = HOUSING, HOUSING_POCKET
    body = mp._box((0.0, -W / 2, 0.0), (L, W / 2, H))
    body -= mp._box((L / 2 - pl / 2, -pw / 2, H - pd), (L / 2 + pl / 2, pw / 2, H + 1.0))
    from manifold3d import Manifold

    body += Manifold.cylinder(pd - 4.0, HOUSING_BOSS / 2, HOUSING_BOSS / 2, mp.HOLE_SEGMENTS).translate(
        (L / 2 + 10.0, 0.0, H - pd)
    )
    d, inset = HOUSING_HOLE
    for x in (inset, L - inset):
        for y in (-W / 2 + inset, W / 2 - inset):
            body -= mp._hole(x, y, -1.0, H + 2.0, d)
    return body


PARTS = {
    "bushing": (
        build_bushing,
        "milled-aluminium-ra1.6",
        "milled",
        "milled aluminium flanged bushing: a D50 x 10 mm flange "
        "under a D30 x 22 mm hub, a D16 bore, four D6.6 bolt holes on a D40 circle",
    ),
    "angle": (
        build_angle,
        "smooth-steel",
        "bent-sheet",
        "bent 2 mm steel sheet angle: a 60 x 50 mm base and a 35 mm "
        "upright bent at 90 deg (inner radius 2 mm), two D8.5 holes in the base, one in the upright",
    ),
    "housing": (
        build_housing,
        "black-pla",
        "fdm",
        "FDM-printed PLA housing: a 70 x 45 x 24 mm block, a 50 x 29 x 14 mm "
        "pocket open at the top, a D10 boss standing in it, four D3.4 corner holes",
    ),
}


def part_toml(name: str, mesh) -> str:
    """The part file of a built part: its material, process, scan and flange (the shipped parts' schema)."""
    _, material, process, description = PARTS[name]
    lo, hi = np.asarray(mesh.bounds) * 1e3
    centre = (lo + hi) / 2
    return (
        f"# {name}: a part of the verdict study, built by scripts/make_study_parts.py (no hand layout: the\n"
        f'# conventional placement is the baseline).\n\n[part]\nname = "{name}"\n'
        f'description = "{description}"\nmesh = "{name}.stl"\nunits = "m"\nmaterial = "{material}"\n'
        f'process = "{process}"\nsensor = "keyence-lj-x8080"\nscan_length_mm = {hi[0] - lo[0]:.1f}\nscan_step_mm = 0.5\n'
        f"rotation_centre_mm = [{centre[0]:.2f}, {centre[1]:.2f}, {centre[2]:.2f}]\n\n"
        f'[[keepout]]\nname = "flange"\nmin_mm = [{lo[0] - 20:.1f}, -40.0, -50.0]\nmax_mm = [{hi[0] + 20:.1f}, 40.0, 0.0]\n'
    )


def main(argv: list[str]) -> None:
    out = Path(argv[0]) if argv else OUT_DIR
    for name, (build, *_rest) in PARTS.items():
        folder = out / name
        folder.mkdir(parents=True, exist_ok=True)
        mesh = mp.to_trimesh(build())
        mesh.export(folder / f"{name}.stl")
        (folder / "part.toml").write_text(part_toml(name, mesh))
        print(
            f"{folder / (name + '.stl')}: {len(mesh.faces)} faces, watertight {mesh.is_watertight}, {mesh.volume * 1e9:.1f} mm^3"
        )


if __name__ == "__main__":
    main(sys.argv[1:])
