"""A shipped part's surface in other triangles, written with its part file beside it (docs/cell.md, "The cell
and the tessellation").

    .venv/bin/python scripts/retessellate.py part_b /tmp/part_b-2mm --edge-mm 2
    .venv/bin/python scripts/retessellate.py part_b /tmp/part_b-centroid --split centroid
    .venv/bin/optipose evaluate /tmp/part_b-2mm/part.toml --seed 3

``--edge-mm E``: every triangle split at its edges' midpoints until no edge is longer than E mm
(``trimesh.remesh.subdivide_to_size``); ``--split centroid``: every triangle split in three at its centroid.
The mesh is written as a binary STL (float32 vertices, as a CAD export holds them: the new vertices a few nm
off the surface) or, with ``--format ply``, as a binary PLY of float64 vertices (the same surface exactly).
The part file is the shipped one with its ``mesh`` line naming the new file.
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import numpy as np
import trimesh

from optipose.model.part import PARTS_DIR


def retessellated(mesh: trimesh.Trimesh, edge: float | None, split: str | None) -> trimesh.Trimesh:
    v, f = np.asarray(mesh.vertices, float), np.asarray(mesh.faces)
    if split == "centroid":
        c = np.arange(len(v), len(v) + len(f))
        f = np.concatenate([np.stack([f[:, a], f[:, b], c], 1) for a, b in ((0, 1), (1, 2), (2, 0))])
        v = np.vstack([v, mesh.triangles.mean(axis=1)])
    if edge:
        v, f = trimesh.remesh.subdivide_to_size(v, f, edge)
    return trimesh.Trimesh(v, f, process=False)


def write_ply(path: Path, mesh: trimesh.Trimesh) -> None:
    """A binary PLY of float64 vertices (trimesh writes float32)."""
    v, f = np.asarray(mesh.vertices, "<f8"), np.asarray(mesh.faces)
    head = (
        f"ply\nformat binary_little_endian 1.0\nelement vertex {len(v)}\nproperty double x\nproperty double y\n"
        f"property double z\nelement face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    face = np.zeros(len(f), dtype=[("n", "u1"), ("i", "<i4", 3)])
    face["n"], face["i"] = 3, f
    path.write_bytes(head.encode() + v.tobytes() + face.tobytes())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("part", help="a shipped part's name")
    parser.add_argument("out", type=Path, help="the folder to write the mesh and its part file into")
    parser.add_argument("--edge-mm", type=float, default=None, help="split triangles until no edge is longer")
    parser.add_argument("--split", choices=["centroid"], default=None, help="split every triangle at its centroid")
    parser.add_argument("--format", choices=["stl", "ply"], default="stl")
    args = parser.parse_args()
    if not args.edge_mm and not args.split:
        parser.error("give --edge-mm or --split")
    folder = PARTS_DIR / args.part
    text = (folder / "part.toml").read_text()
    old = re.search(r'^mesh = "([^"]+)"', text, re.MULTILINE)
    mesh = retessellated(
        trimesh.load(folder / old.group(1), process=False), args.edge_mm and args.edge_mm * 1e-3, args.split
    )
    args.out.mkdir(parents=True, exist_ok=True)
    name = f"{args.part}.{args.format}"
    if args.format == "ply":
        write_ply(args.out / name, mesh)
    else:
        mesh.export(args.out / name)
    (args.out / "part.toml").write_text(text[: old.start()] + f'mesh = "{name}"' + text[old.end() :])
    print(f"{args.out / name}: {len(mesh.faces):,} triangles")


if __name__ == "__main__":
    main()
