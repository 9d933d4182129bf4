"""How the evaluation's time and memory grow with the scene: mesh size, scanning length, number of sensors.

Each rung changes one thing from part B with its hand-placed sensors and runs in a fresh process (so its
peak resident memory, ``ru_maxrss``, is its own): it builds the evaluator's scanner and reference, then
evaluates the reduced protocol (14 orientations, every sensor subset) in one process. Printed per rung:
the set-up time (Embree scene, convex hull, the reference's face grid), the time per orientation, points
per orientation, and the peak memory; and the growth against the first rung of the same axis.

- mesh size: B's mesh subdivided (each step splits every triangle in four: the same surface, 4x the faces),
  1.6 k to 1.6 M triangles;
- scanning length: 12 to 300 mm of travel at B's 0.5 mm step (past 60 mm the part has left the line);
- sensors: 1 to 6: the hand layout's S1, S2, S3, then the same three moved 8 mm along the motion
  (every subset is registered: 2^k - 1 of them, as Table 1's assignment needs).

    .venv/bin/python benchmarks/bench_scaling.py [--axes mesh,length,sensors] [--max-faces N]   # N: default two million
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np


def rung(axis: str, value: float) -> dict:
    """One rung, in this process: set-up and per-orientation time, points, peak memory."""
    import resource
    from dataclasses import replace

    import trimesh

    from optipose.evaluate.evaluator import Evaluator
    from optipose.evaluate.objective import load_objective, reduced_objective
    from optipose.model.layout import Layout, SensorPose
    from optipose.model.motion import ScanMotion
    from optipose.model.part import load_part

    part = load_part("part_b")
    layout = part.layouts["hand"]
    if axis == "mesh":
        mesh = part.mesh
        while len(mesh.faces) < value:
            v, f = trimesh.remesh.subdivide(mesh.vertices, mesh.faces)
            mesh = trimesh.Trimesh(v, f, process=False)
        part = replace(part, mesh=mesh)
    elif axis == "length":
        part = replace(part, motion=ScanMotion(value * 1e-3, part.motion.step))
    elif axis == "sensors":
        sensors = list(layout.sensors)
        for s in layout.sensors:
            T = s.T_O_S.copy()
            T[0, 3] += 0.008
            sensors.append(SensorPose(name=f"{s.name}'", T_O_S=T))
        layout = Layout(tuple(sensors[: int(value)]), name=f"{int(value)} sensors")
    objective = reduced_objective(load_objective("paper").in_cell("ideal"))
    t0 = time.perf_counter()
    with Evaluator(part, objective, seed=0, jobs=1, quiet=True) as ev:
        from optipose.evaluate.worker import run_chunk

        tasks = ev.tasks()
        run_chunk(ev.setup, layout, tasks[:1])  # builds the scanner and the reference
        setup = time.perf_counter() - t0
        t1 = time.perf_counter()
        rows, points, timing, _ = run_chunk(ev.setup, layout, tasks)
        per = (time.perf_counter() - t1) / len(tasks)
    n_points = sum(r["n_points"] for r in points) / len(tasks)
    return {
        "axis": axis,
        "value": value,
        "faces": len(part.mesh.faces),
        "setup_s": setup,
        "per_orientation_s": per,
        "scan_s": timing["scan"] / len(tasks),
        "register_s": timing["register"] / len(tasks),
        "points": n_points,
        "registrations": len(rows) / len(tasks),
        "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--axes", default="mesh,length,sensors")
    ap.add_argument("--max-faces", type=int, default=2_000_000)
    ap.add_argument("--rung", nargs=2, help=argparse.SUPPRESS)  # internal: run one rung, print JSON
    args = ap.parse_args()
    if args.rung:
        print(json.dumps(rung(args.rung[0], float(args.rung[1]))))
        return
    values = {
        "mesh": [f for f in (1_596, 6_384, 25_536, 102_144, 408_576, 1_634_304) if f <= args.max_faces],
        "length": [12, 30, 60, 120, 300],
        "sensors": [1, 2, 3, 4, 5, 6],
    }
    print(
        f"bench_scaling: part B, reduced protocol (14 orientations), one process, {os.cpu_count()} cores, "
        f"load {os.getloadavg()[0]:.1f}"
    )
    for axis in args.axes.split(","):
        print(
            f"\n{axis:>8} {'faces':>9} {'set-up s':>9} {'s/orient.':>10} {'scan':>7} {'register':>9} {'points':>9} "
            f"{'regs':>5} {'peak MB':>8}  growth vs first (time, memory)"
        )
        first = None
        for value in values[axis]:
            out = subprocess.run([sys.executable, __file__, "--rung", axis, str(value)], capture_output=True, text=True)
            if out.returncode:
                print(f"{value:>8} failed: {out.stderr.strip().splitlines()[-1]}")
                continue
            r = json.loads(out.stdout.strip().splitlines()[-1])
            first = first or r
            print(
                f"{value:>8g} {r['faces']:>9} {r['setup_s']:>9.2f} {r['per_orientation_s']:>10.3f} {r['scan_s']:>7.3f} "
                f"{r['register_s']:>9.3f} {r['points']:>9.0f} {r['registrations']:>5.0f} {r['peak_mb']:>8.0f}  "
                f"{r['per_orientation_s'] / first['per_orientation_s']:.2f}x, {r['peak_mb'] / first['peak_mb']:.2f}x",
                flush=True,
            )
    print(f"\nload at the end {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
