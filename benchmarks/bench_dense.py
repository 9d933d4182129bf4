"""How `scan`, `evaluate`, `search --budget quick` and `report` grow with the triangle count of the part.

Two parts, each in meshes of the same surface in more and more triangles:

- round: a sphere of radius 25 mm (trimesh's icosphere, subdivisions 3-9: 1.3 k to 5.2 M faces), a bare
  STL, so it is compared with the conventional placement (optipose.model.baseline); every vertex is on its
  convex hull, the case that made the collision test quadratic;
- flat: part B, shipped (1.6 k faces) and subdivided (trimesh's subdivide_to_size, edges of 4 to 0.25 mm:
  about 50 k to 5.3 M faces), with its part file and hand layout.

Each row is one command of the CLI in a process of its own, started by a process of its own that reads its
peak resident memory (``getrusage(RUSAGE_CHILDREN)``, so the row's peak is its own) and its wall time. The
`report` row draws the `evaluate` row's folder (its 3D views of the dense part).

    .venv/bin/python benchmarks/bench_dense.py [--max-faces N] [--rows PATTERNS] [--timeout S] [--work DIR]

``--rows`` keeps the rows whose name (``kind/faces/command``, e.g. ``round/81920/search``) contains one of
the comma-separated patterns: ``--rows /scan,/evaluate`` or ``--rows flat/``. ``--max-faces`` (default
5,300,000) drops the larger meshes. Prints one line per row and a table; nothing is asserted.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RADIUS = 0.025  # m
SUBDIVISIONS = (3, 4, 5, 6, 7, 8, 9)  # 20 · 4^s faces
EDGES_MM = (None, 4.0, 2.0, 1.0, 0.5, 0.25)  # None: part B as shipped
COMMANDS = ("scan", "evaluate", "report", "search")


def round_faces(s: int) -> int:
    return 20 * 4**s


def make_round(work: Path, s: int) -> Path:
    import trimesh

    path = work / f"sphere_{s}.stl"
    if not path.is_file():
        mesh = trimesh.creation.icosphere(subdivisions=s, radius=RADIUS)
        mesh.apply_translation([0.0, 0.0, RADIUS])  # resting on z = 0, as a part on the flange
        mesh.export(path)
    return path


def make_flat(work: Path, edge_mm: float | None) -> tuple[Path, int]:
    """Part B's part file beside its mesh subdivided to ``edge_mm`` (the shipped mesh when None)."""
    import trimesh

    src = ROOT / "parts" / "part_b"
    name = "part_b_shipped" if edge_mm is None else f"part_b_{edge_mm:g}mm"
    folder = work / name
    folder.mkdir(parents=True, exist_ok=True)
    mesh_path = folder / f"{name}.stl"
    if not mesh_path.is_file():
        mesh = trimesh.load(src / "part_b.stl", force="mesh")
        if edge_mm is not None:
            v, f = trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, max_edge=edge_mm * 1e-3)
            mesh = trimesh.Trimesh(v, f, process=False)
        mesh.export(mesh_path)
    toml = (src / "part.toml").read_text()
    (folder / "part.toml").write_text(
        re.sub(r'(?m)^mesh = ".*"$', f'mesh = "{mesh_path.name}"', toml).replace(
            'name = "part_b"', f'name = "{name}"', 1
        )
    )
    faces = len(trimesh.load(mesh_path, force="mesh").faces)
    return folder / "part.toml", faces


def row_command(command: str, part: Path, out: Path) -> list[str]:
    py = [sys.executable, "-m", "optipose"]
    if command == "scan":
        return [*py, "scan", str(part)]
    if command == "evaluate":
        return [*py, "evaluate", str(part), "--out", str(out / "evaluate"), "--no-report"]
    if command == "report":
        return [*py, "report", str(out / "evaluate")]
    return [*py, "search", str(part), "--budget", "quick", "--out", str(out / "search"), "--no-report"]


def measure(argv: list[str], timeout: float) -> None:
    """In a process of its own: run ``argv`` and print its wall time, peak memory and exit code as JSON."""
    import resource

    t0 = time.perf_counter()
    try:
        proc = subprocess.run(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, timeout=timeout)
        code, tail = proc.returncode, proc.stderr.strip().splitlines()[-1:] if proc.returncode else []
    except subprocess.TimeoutExpired:
        code, tail = "timeout", []
    wall = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    print(json.dumps({"wall_s": wall, "peak_mb": peak, "exit": code, "error": tail[0][:200] if tail else ""}))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--max-faces", type=int, default=5_300_000)
    ap.add_argument("--rows", default="", help="comma-separated patterns of row names kind/faces/command")
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per row")
    ap.add_argument("--work", type=Path, default=Path("/tmp/optipose_bench_dense"))
    ap.add_argument("--measure", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.measure:
        return measure(args.measure, args.timeout)
    args.work.mkdir(parents=True, exist_ok=True)
    patterns = [
        p.replace("_", "") for p in args.rows.split(",") if p
    ]  # digits may be grouped with _, as the docs write them
    parts = [("round", round_faces(s), s) for s in SUBDIVISIONS] + [("flat", None, e) for e in EDGES_MM]
    print(f"$ {' '.join(sys.argv)}  (cores: {os.cpu_count()}, load: {os.getloadavg()[0]:.1f})")
    table = []
    for kind, faces, param in parts:
        if kind == "round":
            if faces > args.max_faces:
                continue
            part = make_round(args.work, param)
        else:
            if param is not None and param < 0.5 and args.max_faces < 5_000_000:
                continue  # about 5.3 M faces: not built unless asked for
            part, faces = make_flat(args.work, param)
            if faces > args.max_faces:
                continue
        for command in COMMANDS:
            name = f"{kind}/{faces}/{command}"
            if patterns and not any(p in name for p in patterns):
                continue
            out = args.work / "runs" / f"{kind}_{faces}"
            argv = [
                sys.executable,
                __file__,
                "--timeout",
                str(args.timeout),
                "--measure",
                *row_command(command, part, out),
            ]
            env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
            res = json.loads(
                subprocess.run(argv, capture_output=True, text=True, env=env).stdout.strip().splitlines()[-1]
            )
            table.append((name, res))
            print(
                f"{name:28s} {res['wall_s']:8.1f} s {res['peak_mb']:8.0f} MB  exit {res['exit']} {res['error']}",
                flush=True,
            )
    print("\n| row | wall s | peak MB | exit |\n| --- | --- | --- | --- |")
    for name, res in table:
        print(f"| {name} | {res['wall_s']:.1f} | {res['peak_mb']:.0f} | {res['exit']} |")


if __name__ == "__main__":
    main()
