"""Rays cast and time of one scan against the column stride (the anchors of ``[scan] column_stride``),
on part B's hand layout (its three sensors in one ``scan_many``), single-threaded, strides interleaved.

    .venv/bin/python benchmarks/bench_columns.py [--repeats 7] [--strides 1,8,16,32]

Per stride: primary rays cast (``first_triangle``), shadow rays (``occluded``), the median time of a
scan, and whether the points are those of casting every column (stride 1). Figures, not asserts.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--strides", default="1,8,16,32")
    args = ap.parse_args()

    from optipose.model.part import load_part
    from optipose.scan.scanner import PartPose, part_scanner

    part = load_part("part_b")
    poses = list(part.layouts["hand"].poses)
    rpy = np.deg2rad([1.2, -0.8, 0.4])
    strides = [int(s) for s in args.strides.split(",")]
    scanners, counts = {}, {}
    for stride in strides:
        scanner = part_scanner(part, threads=1, column_stride=stride)
        count = counts[stride] = {"primary": 0, "shadow": 0}
        first, occluded = scanner.caster.first_triangle, scanner.caster.occluded

        def cast(o, d, t, _f=first, _c=count):
            _c["primary"] += len(o)
            return _f(o, d, t)

        def shade(o, d, t, _f=occluded, _c=count):
            _c["shadow"] += len(o)
            return _f(o, d, t)

        scanner.caster.first_triangle, scanner.caster.occluded = cast, shade
        scanners[stride] = scanner
    scan = lambda s: s.scan_many(poses, part.motion, PartPose(rpy, part.rotation_centre), rng=5)  # noqa: E731
    clouds = {s: scan(scanners[s]) for s in strides}  # also compiles and warms
    rays = {s: dict(counts[s]) for s in strides}
    times = {s: [] for s in strides}
    for r in range(args.repeats):
        for s in strides[r % len(strides) :] + strides[: r % len(strides)]:
            t0 = time.perf_counter()
            scan(scanners[s])
            times[s].append(time.perf_counter() - t0)
    total = len(poses) * part.motion.n_profiles * scanners[strides[0]].sensor.points_per_profile
    ref = clouds[min(strides)]
    print(
        f"part_b hand layout, 3 sensors, rpy (1.2, -0.8, 0.4) deg, {total:,} primary rays in all, 1 thread, "
        f"load {os.getloadavg()[0]:.1f}, {args.repeats} interleaved rounds"
    )
    print(
        f"{'stride':>6} {'primary cast':>13} {'share':>6} {'shadow rays':>12} {'median ms':>10} {'x stride 1':>10}  same points as stride {min(strides)}"
    )
    for s in strides:
        same = all(np.array_equal(a.points, b.points) for a, b in zip(clouds[s], ref))
        print(
            f"{s:>6} {rays[s]['primary']:>13,} {rays[s]['primary'] / total:>6.1%} {rays[s]['shadow']:>12,} "
            f"{1e3 * np.median(times[s]):>10.1f} {np.median(times[s]) / np.median(times[min(strides)]):>10.2f}  {same}"
        )


if __name__ == "__main__":
    main()
