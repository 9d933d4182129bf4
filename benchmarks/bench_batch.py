"""Trials per hour of ``optipose batch`` with 1 and 2 workers, for joblib's process pool and for a local
Dask cluster, and the 2-worker speed-up over the 1-worker baseline of the same back-end, in the same run.

    .venv/bin/python benchmarks/bench_batch.py [--trials 12] [--part part_b]

The study: ``--trials`` evaluations of the part's hand-placed layout on a 9-scan protocol (the R, P and Y
sequences at -1, 0, +1 deg), one seed each, so every trial is the same amount of work. Every trial runs
with one process and one thread (``trial_jobs=1``), so the figures measure the back-ends, not a trial's own
parallelism. Each configuration starts its workers and warms them with one trial per worker (imports,
compiled kernels) before the timed study; the warm-up is printed, not counted.

Besides trials per hour it prints each trial's mean wall and CPU time in its worker and how busy the workers were
(trials x that time / (workers x wall time)). Busy near 100 % says the back-end keeps its workers fed; a
trial that takes longer with 2 workers than with 1 says the workers did not get a core each (other load
on the machine), which caps the speed-up whatever the back-end. Figures, not asserts: on a shared
machine look at the load printed before, during and after.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

PROTOCOL = """name = "bench-batch"
[protocol]
sequences = ["R", "P", "Y"]
start_deg = -1.0
stop_deg = 1.0
step_deg = 1.0
"""


def study(folder: Path, part: str, seeds: range, name: str):
    from optipose.batch.spec import study_from_table

    table = {
        "name": name,
        "grid": {
            "parts": [part],
            "tasks": ["evaluate"],
            "objectives": [str(folder / "bench.toml")],
            "sensors": [1],
            "seeds": list(seeds),
        },
    }
    return study_from_table(table, where=name, base=folder)


def measure(backend: str, workers: int, folder: Path, part: str, trials: int) -> tuple[float, float, float, float]:
    """(warm-up seconds, timed seconds, mean wall and CPU seconds of a trial in its worker) of ``trials``
    trials on ``workers`` workers of ``backend``."""
    from optipose.batch.pools import DaskPool, LokyPool
    from optipose.batch.records import TrialState
    from optipose.batch.study import run_study

    t0 = time.perf_counter()
    pool = DaskPool(workers, trial_jobs=1) if backend == "dask" else LokyPool(workers, trial_jobs=1)
    try:
        run_study(study(folder, part, range(1000, 1000 + workers), "warm"), folder / f"{backend}{workers}-warm", pool)
        t1 = time.perf_counter()
        index = run_study(study(folder, part, range(trials), "timed"), folder / f"{backend}{workers}", pool)
        t2 = time.perf_counter()
    finally:
        pool.close()
    assert index.count(TrialState.COMPLETE) == trials, "a trial failed; see the index"
    frame = index.frame()
    return t1 - t0, t2 - t1, float(frame["seconds"].mean()), float(frame["cpu_seconds"].mean())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=12)
    ap.add_argument("--part", default="part_b")
    ap.add_argument("--backends", default="joblib,dask")
    args = ap.parse_args()

    print(
        f"bench_batch: {args.trials} trials of {args.part} (evaluate, 9 scans, k=1, trial_jobs=1), "
        f"{os.cpu_count()} cores; load before: {os.getloadavg()[0]:.2f}"
    )
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        (folder / "bench.toml").write_text(PROTOCOL)
        for backend in args.backends.split(","):
            rates, per_trial = {}, {}
            for workers in (1, 2):
                warm, seconds, per_trial[workers], cpu = measure(backend, workers, folder, args.part, args.trials)
                rates[workers] = args.trials / seconds * 3600
                busy = args.trials * per_trial[workers] / (workers * seconds)
                print(
                    f"  {backend:6s} {workers} worker(s) {seconds:7.1f} s  {rates[workers]:7.0f} trials/h  "
                    f"trial {per_trial[workers]:5.2f} s in its worker ({cpu:5.2f} s CPU), workers busy {busy:.0%}  (start + warm-up {warm:.1f} s; "
                    f"load {os.getloadavg()[0]:.2f})"
                )
            print(
                f"  {backend:6s} 2 workers / 1 worker: {rates[2] / rates[1]:.2f}x trials per hour; a trial took "
                f"{per_trial[2] / per_trial[1]:.2f}x as long with 2 workers (1.0 on 2 free cores)"
            )
    print(f"load after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
