"""The same surface in other triangles: Table 1, moved registrations, wall time and memory of `evaluate`.

    .venv/bin/python benchmarks/bench_tessellation.py [--part part_b] [--meshes shipped centroid midpoint 0.5]
        [--jobs 2]
    .venv/bin/python benchmarks/bench_tessellation.py --reference 0.5 [--part part_b]

Each mesh of the part (``shipped``; ``centroid``: every triangle split in three at its centroid;
``midpoint``: split in four at its edges' midpoints; a number: trimesh's ``subdivide_to_size`` to that
edge in mm) is evaluated with the part's hand layout under the paper's objective in a process of its own,
while this one samples that process tree's memory every 0.5 s: the summed RSS (a page mapped by several
processes counted in each) and the summed PSS (each shared page shared out). It prints per mesh the
faces, the wall time, both peaks, Table 1 (median / p75 per axis, mdeg) and, against the first mesh, the
registrations that moved by more than 0.01 mdeg and the largest relative change of a Table 1 statistic.

``--reference MM``: only the CAD-surface reference of the part subdivided to MM edges, in this process:
its build time, the peak RSS it adds (ru_maxrss), what stays resident, and the grid's entries per face.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

CHILD = r"""
import json, pickle, sys, time
import numpy as np, trimesh
from dataclasses import replace
from optipose.model.part import load_part
from optipose.evaluate.evaluator import evaluate
name, mesh_kind, jobs, out = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4]
part = load_part(name)
m = part.mesh
if mesh_kind == "centroid":
    v, f = np.asarray(m.vertices), np.asarray(m.faces)
    c = np.arange(len(v), len(v) + len(f))
    faces = np.concatenate([np.stack([f[:, a], f[:, b], c], 1) for a, b in ((0, 1), (1, 2), (2, 0))])
    m = trimesh.Trimesh(np.vstack([v, v[f].mean(axis=1)]), faces, process=False)
elif mesh_kind == "midpoint":
    m = m.subdivide()
elif mesh_kind != "shipped":
    v, f = trimesh.remesh.subdivide_to_size(m.vertices, m.faces, max_edge=float(mesh_kind) * 1e-3)
    m = trimesh.Trimesh(v, f, process=False)
print("READY", len(m.faces), flush=True)
t = time.perf_counter()
r = evaluate(replace(part, mesh=m), None, "paper", seed=0, jobs=jobs)
wall = time.perf_counter() - t
pickle.dump({"faces": len(m.faces), "wall": wall, "per_scan": r.per_scan, "table": r.table}, open(out, "wb"))
"""


def run(part: str, mesh: str, jobs: int, out: Path) -> dict:
    """One evaluation in a child process; its tree's memory sampled from when the mesh is built."""
    import psutil

    proc = subprocess.Popen(
        [sys.executable, "-c", CHILD, part, mesh, str(jobs), str(out)], stdout=subprocess.PIPE, text=True
    )
    assert proc.stdout.readline().startswith("READY")
    root, rss, pss = psutil.Process(proc.pid), 0, 0
    while proc.poll() is None:
        try:
            tree = [root] + root.children(recursive=True)
            rss = max(rss, sum(p.memory_info().rss for p in tree))
            pss = max(pss, sum(p.memory_full_info().pss for p in tree))
        except psutil.Error:
            pass
        time.sleep(0.5)
    if proc.returncode:
        raise SystemExit(f"{mesh}: the evaluation failed ({proc.returncode})")
    import pickle

    return pickle.load(open(out, "rb")) | {"rss": rss, "pss": pss}


def reference_only(part: str, edge_mm: float) -> None:
    import psutil
    import trimesh

    from optipose.model.part import load_part
    from optipose.registration.reference import SurfaceReference

    mesh = load_part(part).mesh
    v, f = trimesh.remesh.subdivide_to_size(mesh.vertices, mesh.faces, max_edge=edge_mm * 1e-3)
    import threading

    me = psutil.Process()
    resident, peak, done = me.memory_info().rss, [0], threading.Event()

    def sample() -> None:  # the build's peak above what was resident before it, every 20 ms
        while not done.wait(0.02):
            peak[0] = max(peak[0], me.memory_info().rss - resident)

    sampler = threading.Thread(target=sample)
    sampler.start()
    t = time.perf_counter()
    reference = SurfaceReference(v, f)
    wall = time.perf_counter() - t
    done.set()
    sampler.join()
    kept = me.memory_info().rss - resident
    print(
        f"{part} at {edge_mm} mm edges, {len(f)} faces: built in {wall:.1f} s, peak +{peak[0] / 2**20:.0f} MB "
        f"({peak[0] / len(f):.0f} B a face), resident +{kept / 2**20:.0f} MB ({kept / len(f):.0f} B a face), "
        f"grid {len(reference._grid_faces) / len(f):.1f} entries a face"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reference", type=float, default=None, help="only the reference, at this edge (mm)")
    ap.add_argument("--part", default="part_b")
    ap.add_argument("--meshes", nargs="+", default=["shipped", "centroid", "midpoint"])
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()
    if args.reference is not None:
        return reference_only(args.part, args.reference)
    print(" ".join(sys.argv), "| load", " ".join(f"{x:.1f}" for x in __import__("os").getloadavg()))
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for mesh in args.meshes:
            results[mesh] = run(args.part, mesh, args.jobs, Path(tmp) / f"{mesh}.pkl")
    first = results[args.meshes[0]]
    mdeg = lambda rad: np.rad2deg(rad) * 1e3  # noqa: E731
    for mesh, r in results.items():
        print(
            f"\n{mesh}: {r['faces']} faces, wall {r['wall']:.1f} s, peak RSS {r['rss'] / 2**20:.0f} MB, PSS {r['pss'] / 2**20:.0f} MB"
        )
        worst = 0.0
        for a, b in zip(first["table"], r["table"]):
            cells = ", ".join(
                f"{x.axis} {mdeg(x.median):.4f}/{mdeg(x.p75):.4f} ({x.name})" if x.observable else f"{x.axis} {x.label}"
                for x in b.axes
            )
            print(f"  k={b.k} {b.name} score {mdeg(b.score):.4f}: {cells}")
            same = a.sensors == b.sensors and all(x.subset == y.subset for x, y in zip(a.axes, b.axes))
            if not same:
                print("    other sensors or subsets than the first mesh's")
            for x, y in zip(a.axes, b.axes):
                if x.observable and y.observable:
                    worst = max(worst, abs(y.median / x.median - 1), abs(y.p75 / x.p75 - 1))
            worst = max(worst, abs(b.score / a.score - 1))
        cols = ["err_roll", "err_pitch", "err_yaw"]
        d = mdeg(np.abs(first["per_scan"][cols].to_numpy() - r["per_scan"][cols].to_numpy())).max(axis=1)
        print(
            f"  against {args.meshes[0]}: {int((d > 0.01).sum())} of {len(d)} registrations moved by over 0.01 mdeg "
            f"(largest {d.max():.3f} mdeg); largest relative change of a Table 1 statistic {100 * worst:.3f} %"
        )


if __name__ == "__main__":
    main()
