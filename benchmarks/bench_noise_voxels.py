"""What the sensor noise does through the voxels: one sensor's per-axis error against the noise level, with
the objective's voxel down-sampling and without it (every raw point registered).

Equal-weight voxel centroids turn noise along the ray into a bias that grows as σ² where faces cut voxels
obliquely (docs/conditions.md, 'Noise through the voxels'). Default: part B's single sensor ``F1`` of the nominal quick
search (seed 0; a grazing view of few voxels, ``tests/test_noise_bias.py``) and hand S3 beside it.

    .venv/bin/python benchmarks/bench_noise_voxels.py [--part part_b] [--scales 1,2,3,5] [--seed 1] [--jobs 2]
    .venv/bin/python benchmarks/bench_noise_voxels.py --layout results/<search>/layouts/found_k1.toml --sensor 0
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace

import numpy as np

from optipose.evaluate.evaluator import evaluate
from optipose.evaluate.objective import load_objective
from optipose.model.layout import Layout, SensorPose, load_layout
from optipose.model.part import load_part
from optipose.model.sensor import load_sensor

F1 = np.array(
    [
        [-0.383_022_221_559, 0.663_413_948_169, 0.642_787_609_687, 0.014_444_444_072],
        [0.866_025_403_784, 0.5, -0.0, 0.004_080_000_091],
        [-0.321_393_804_843, 0.556_670_399_226, -0.766_044_443_119, -0.002_792_000_008],
        [0.0, 0.0, 0.0, 1.0],
    ]
)
AXES = ("roll", "pitch", "yaw")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", default="part_b")
    ap.add_argument("--objective", default="paper")
    ap.add_argument("--layout", default=None, help="a layout TOML (default: B's F1 and hand S3)")
    ap.add_argument(
        "--sensor", type=int, action="append", help="sensor index of --layout to measure alone (repeatable)"
    )
    ap.add_argument("--scales", default="1,2,3,5")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args()

    part, objective = load_part(args.part), load_objective(args.objective)
    if args.layout:
        layout = load_layout(args.layout)
        sensors = [layout.sensors[i] for i in (args.sensor or range(len(layout.sensors)))]
    else:
        sensors = [SensorPose("F1", F1), part.layouts["hand"].sensors[2]]
    model = load_sensor(part.sensor)
    scales = [float(s) for s in args.scales.split(",")]
    print(
        f"bench_noise_voxels: {args.part}, objective {objective.name}, seed {args.seed}; mdeg over the protocol's scans"
    )
    print(
        f"{'sensor':8} {'voxels':>8} {'noise x':>7} {'points':>7}  "
        + "  ".join(f"{a + ' med / mean':>18}" for a in AXES)
    )
    for pose in sensors:
        for voxel in (objective.registration.voxel_size, 0.0):
            for scale in scales if voxel > 0 else (scales[0], scales[-1]):
                noisy = replace(part, sensor=replace(model, noise_sigma=model.noise_sigma * scale))
                obj = replace(objective, registration=replace(objective.registration, voxel_size=voxel))
                t0 = time.perf_counter()
                result = evaluate(noisy, Layout((pose,), pose.name), obj, seed=args.seed, jobs=args.jobs)
                rows = result.per_scan[result.per_scan.subset_index == 0]
                err = np.rad2deg(rows[[f"err_{a}" for a in AXES]].to_numpy()) * 1e3
                cells = "  ".join(f"{np.median(np.abs(e)):8.2f} / {e.mean():+7.2f}" for e in err.T)
                label = f"{voxel * 1e3:g} mm" if voxel > 0 else "none"
                print(
                    f"{pose.name:8} {label:>8} {scale:>7g} {rows.n_points.mean():7.0f}  {cells}   ({time.perf_counter() - t0:.0f} s)"
                )


if __name__ == "__main__":
    main()
