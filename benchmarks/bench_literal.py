"""The paper's own registration (objectives/paper-literal.toml: point-to-point ICP against a 0.2 mm CAD
sample, stopped as Open3D stops it) in the compiled back-end and in Open3D's, on part B's hand layout, the
same seed, in one run: wall time of each, their ratio, and Table 1 of both side by side.

    .venv/bin/python benchmarks/bench_literal.py [--jobs 2] [--protocol reduced|full]

Figures, not asserts: compare the ratio, not seconds across runs (the machine may be shared).
"""

from __future__ import annotations

import argparse
import os
import time
from dataclasses import replace

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--protocol", choices=("reduced", "full"), default="reduced")
    args = ap.parse_args()

    from optipose.evaluate.evaluator import Evaluator
    from optipose.evaluate.objective import load_objective, reduced_objective
    from optipose.model.part import load_part

    part = load_part("part_b")
    layout = part.layouts["hand"]
    objective = load_objective("paper-literal")
    objective = reduced_objective(objective) if args.protocol == "reduced" else objective
    print(
        f"part_b hand layout, objective paper-literal ({args.protocol} protocol), --jobs {args.jobs}, "
        f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}"
    )
    results, walls = {}, {}
    for backend in ("fast", "open3d"):
        obj = replace(objective, registration=replace(objective.registration, backend=backend))
        # a 2-scan evaluation first, untimed: compiled kernels built (or loaded from their cache) in every worker
        warm = replace(obj, protocol=replace(obj.protocol, sequences=("R", "P"), start=obj.protocol.stop))
        t0 = time.perf_counter()
        with Evaluator(part, warm, seed=0, jobs=args.jobs) as ev:
            ev(layout)
        print(f"{backend:>7}: worker start-up and a 2-scan evaluation {time.perf_counter() - t0:.1f} s (not counted)")
        with Evaluator(part, obj, seed=0, jobs=args.jobs) as ev:
            t0 = time.perf_counter()
            results[backend] = ev(layout)
            walls[backend] = time.perf_counter() - t0
        r = results[backend]
        print(
            f"{backend:>7}: {walls[backend]:.1f} s wall, registration {r.timings['register']:.1f} CPU-s, "
            f"{r.n_failed} failed of {len(r.per_scan)}"
        )
    fast, o3d = results["fast"], results["open3d"]
    print(
        f"compiled / Open3D: {walls['open3d'] / walls['fast']:.2f}x faster wall, "
        f"{o3d.timings['register'] / fast.timings['register']:.2f}x in registration CPU-s"
    )
    errors = ["err_roll", "err_pitch", "err_yaw"]
    diff = np.rad2deg(np.abs(fast.per_scan[errors].to_numpy() - o3d.per_scan[errors].to_numpy())) * 1e3
    print(f"per-scan estimates: largest difference {diff.max():.4f} mdeg, median {np.median(diff):.6f} mdeg")
    worst = 0.0
    for a, b in zip(fast.table, o3d.table):
        for x, y in zip(a.axes, b.axes):
            m = np.rad2deg([x.median, x.p75, y.median, y.p75]) * 1e3
            rel = np.abs(m[:2] - m[2:]) / np.maximum(m[2:], 1e-12)
            worst = max(worst, rel.max())
            print(
                f"  k={a.k} {x.axis:5}: compiled {m[0]:.3f} / {m[1]:.3f} ({x.name}), Open3D {m[2]:.3f} / {m[3]:.3f} ({y.name}) mdeg"
            )
    print(f"largest difference of a Table 1 median or p75: {100 * worst:.2f} %")


if __name__ == "__main__":
    main()
