"""What a command pays before and after its work: the compiled kernels on a fresh clone's first run, and its
end (the idle workers, the interpreter's last collections).

- ``kernels``: ``optipose search part_b --budget quick`` (``--no-report``) with numba's cache in an empty folder
  (``NUMBA_CACHE_DIR``: the kernels compiled on first use, as a fresh clone's first command did before
  ``scripts/setup.sh`` compiled them) against the same with the folder ``scripts/warm_kernels.py`` filled; both
  end their verdict by ``answer_time``, so the compile shows in the draws the verdict got, not in the wall
  alone. Also ``warm_kernels.py`` itself, cold and warm.
- ``exit``: a child process that evaluates B's hand layout in the paper's cell on 4 scans with two loky workers
  and writes the report of ``results/reference/part_b`` (in a copy), then ends: as it is, after
  :func:`optipose.parallel.executors.stop_workers`, and after that and ``gc.freeze()`` (what the ``optipose``
  command does at its end, :func:`optipose.cli.main`): the seconds from the end of its work to the end of the
  process, interleaved in ``--repeats`` rounds.

    .venv/bin/python benchmarks/bench_start.py [--repeats 5] [--skip-kernels]
"""

from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
PYTHON = ROOT / ".venv/bin/python"

CHILD = """
import gc, shutil, sys, tempfile, time
from pathlib import Path
from optipose.evaluate.evaluator import Evaluator
from optipose.parallel.executors import stop_workers
from optipose.model.baseline import baseline
from optipose.model.part import load_part
from optipose.report.build import write_report
part = load_part("part_b")
with Evaluator(part, "paper", jobs=2, scans=4, quiet=True) as evaluator:
    evaluator(baseline(part))
with tempfile.TemporaryDirectory() as folder:
    shutil.copytree("results/reference/part_b", Path(folder) / "b")
    write_report(Path(folder) / "b")
print(time.time(), flush=True)
if sys.argv[1] != "neither":
    stop_workers()
if sys.argv[1] == "both":
    gc.freeze()
"""


def timed(cmd: list[str], env: dict | None = None) -> tuple[float, str]:
    t0 = time.perf_counter()
    out = subprocess.run(cmd, cwd=ROOT, env={**os.environ, **(env or {})}, capture_output=True, text=True, check=True)
    return time.perf_counter() - t0, out.stdout


def kernels() -> None:
    with tempfile.TemporaryDirectory() as cache, tempfile.TemporaryDirectory() as out:
        env = {"NUMBA_CACHE_DIR": cache}
        search = [str(ROOT / ".venv/bin/optipose"), "search", "part_b", "--budget", "quick", "--no-report"]
        cold, _ = timed([*search, "--out", f"{out}/cold"], env)
        warm_script = [timed([str(PYTHON), "scripts/warm_kernels.py"], env)[0] for _ in range(2)]
        warm, _ = timed([*search, "--out", f"{out}/warm"], env)
        draws = {name: _draws(Path(out) / name) for name in ("cold", "warm")}
    print(f"warm_kernels.py: {warm_script[0]:.1f} s with an empty cache, {warm_script[1]:.1f} s with it filled")
    print(
        f"search part_b --budget quick --no-report: {cold:.1f} s and {draws['cold']} verdict draws with an empty cache, "
        f"{warm:.1f} s and {draws['warm']} draws with the cache warm_kernels.py filled"
    )


def _draws(folder: Path) -> int:
    with open(folder / "verdict.csv", newline="") as f:
        return max(int(row["draws"]) for row in csv.DictReader(f))


def exits(repeats: int) -> None:
    waits: dict[str, list[float]] = {"neither": [], "stop": [], "both": []}
    for _ in range(repeats):
        for mode in waits:
            proc = subprocess.run(
                [str(PYTHON), "-c", CHILD, mode], cwd=ROOT, capture_output=True, text=True, check=True
            )
            waits[mode].append(time.time() - float(proc.stdout.split()[-1]))
    neither, stop, both = (float(np.median(waits[m])) for m in waits)
    print(
        f"end of the work to the end of the process (two idle loky workers, a report written), median of {repeats}: "
        f"as it is {neither:.2f} s, stop_workers {stop:.2f} s, and gc.freeze {both:.2f} s, ratio {neither / both:.1f}x"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--skip-kernels", action="store_true")
    args = ap.parse_args()
    exits(args.repeats)
    if not args.skip_kernels:
        kernels()


if __name__ == "__main__":
    sys.exit(main())
