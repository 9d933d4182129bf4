"""Does a face guess change the surrogate? (docs/method.md, "The evaluator": closest points, whatever the triangles)

The surrogate's voxel bias searches each turned voxel centroid's closest point starting from the face its first
point hit (``SurfaceReference.nearest(points, ids)``, which keeps a guess only off the face's edges). For every
sensor pose of the search histories kept in ``results/reference`` and ``results/ranges-study`` (each layout's
sensors, once each), this scores the pose in the paper's cell with the guesses and with a search from no face, and
counts the poses whose information, bias and cell maps differ in any bit. ``--loose`` keeps a guess on an edge too
(the ICP's steps' rule, ``nearest_into(exact=False)``): the check must then find poses that differ (part A's voxel
centroids on a crease's edge).

    .venv/bin/python benchmarks/bench_surrogate_guess.py [--parts part_a,part_b] [--most 100000] [--loose]
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import fields, is_dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from optipose.cell.scans import CellSetup
from optipose.evaluate.objective import load_objective
from optipose.model.part import load_part
from optipose.registration.reference import SurfaceReference
from optipose.search.space import PoseSpace
from optipose.search.surrogate import Surrogate, protocol_turns

ROOT = Path(__file__).resolve().parents[1]
PARTS = {
    "part_a": "part_a",
    "part_b": "part_b",
    "part_c": "part_c",
    "angle": "studies/parts/angle/part.toml",
    "bushing": "studies/parts/bushing/part.toml",
    "housing": "studies/parts/housing/part.toml",
}


def same(a, b) -> bool:
    """Two records of arrays equal to the last bit."""
    if is_dataclass(a):
        return type(a) is type(b) and all(same(getattr(a, f.name), getattr(b, f.name)) for f in fields(a))
    if isinstance(a, np.ndarray):
        return isinstance(b, np.ndarray) and a.shape == b.shape and np.array_equal(a, b, equal_nan=True)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    return a == b


def sensor_params(name: str) -> np.ndarray:
    """Every distinct sensor (6 parameters in [0, 1]) of the part's kept search histories."""
    out = []
    for folder in ("reference", "ranges-study"):
        path = ROOT / "results" / folder / name / "history.csv"
        if path.exists():
            out += [u for text in pd.read_csv(path)["u"] for u in np.array(json.loads(text)).reshape(-1, 6)]
    return np.unique(np.round(np.array(out), 9), axis=0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", default=",".join(PARTS))
    ap.add_argument("--most", type=int, default=100000, help="at most this many poses a part (a seeded sample)")
    ap.add_argument("--loose", action="store_true", help="keep a guess on an edge too (the check must fail)")
    args = ap.parse_args()
    objective = load_objective("paper")
    searched = SurfaceReference.nearest

    def loose(self, points, ids=None):
        points = np.ascontiguousarray(points, dtype=np.float64)
        ids = np.full(len(points), -1, np.int64) if ids is None else np.array(ids, dtype=np.int64)
        q, n, open_ = np.empty((len(points), 3)), np.empty((len(points), 3)), np.zeros(len(points), dtype=bool)
        self.nearest_into(points, ids, q, n, open_, exact=False)
        return q, n, ids

    guessed = loose if args.loose else searched
    total = 0
    for name in args.parts.split(","):
        part = load_part(PARTS[name])
        surrogate = Surrogate(
            part,
            voxel=objective.registration.voxel_size,
            turns=protocol_turns(objective),
            cell=CellSetup.of(objective.cell, part),
        )
        space = PoseSpace.around(np.asarray(part.mesh.bounds), 0.005, 60.0)
        params = sensor_params(name)
        if len(params) > args.most:
            params = params[np.random.default_rng(0).choice(len(params), args.most, replace=False)]
        poses = [space.to_pose(u) for u in params]
        SurfaceReference.nearest = guessed
        t0 = time.perf_counter()
        with_guess = [surrogate.info(T) for T in poses]
        t1 = time.perf_counter()
        SurfaceReference.nearest = lambda self, points, ids=None: searched(self, points)
        without = [surrogate.info(T) for T in poses]
        t2 = time.perf_counter()
        SurfaceReference.nearest = searched
        differ = sum(not same(g, s) for g, s in zip(with_guess, without))
        total += differ
        cells = sum(g.cell is not None for g in with_guess)
        print(
            f"{name}: {len(poses)} poses ({cells} with cell maps), {differ} differ; "
            f"with guesses {t1 - t0:.1f} s, without {t2 - t1:.1f} s",
            flush=True,
        )
    print(f"poses that differ, all parts: {total}")


if __name__ == "__main__":
    main()
