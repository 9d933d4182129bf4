"""Where a search's work goes: wall and CPU seconds per stage of ``optipose search``, for one or more code trees.

Each code tree (``--code DIR``, a worktree of another commit, repeatable; this tree by default) runs ``optipose
search PART --budget BUDGET --seed SEED --no-report`` in a child process whose stage changes (the progress's
``stage`` calls: ``screen:k=1``, ``greedy:k=1``, …, then the ICP stages by name) are stamped with the wall clock and
the CPU-seconds of the whole process tree (the command, its workers and the hand layout's processes; the ones
that ended counted through their parent). A stage's row is what the tree spent from its start to the next stage's.
The trees run one after the other (``--rounds`` times, interleaved), on the same machine in the same hour.

    .venv/bin/python benchmarks/bench_search_stages.py [--code ../base] [--part part_b] [--budget default]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PYTHON = ROOT / ".venv/bin/python"

CHILD = r"""
import json, os, sys, time
import psutil
from optipose.cli import progress

me = psutil.Process()
stamps = []

def tree_cpu():
    total = sum(me.cpu_times()[:4])
    for child in me.children(recursive=True):
        try:
            total += sum(child.cpu_times()[:2])
        except psutil.Error:
            pass
    return total

def stamp(name):
    stamps.append((name, time.monotonic(), tree_cpu()))

stage = progress.StageProgress.stage
def stamped(self, name, *args, **kwargs):
    if name != self.name:
        stamp(name)
    return stage(self, name, *args, **kwargs)
progress.StageProgress.stage = stamped

stamp("start-up")
from optipose.cli.app import main
try:
    main(sys.argv[2:])
except SystemExit:
    pass
stamp("end")
with open(sys.argv[1], "w") as f:
    json.dump(stamps, f)
"""


def run(code: Path, args: list[str]) -> list[tuple[str, float, float]]:
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "stamps.json"
        env = {**os.environ, "PYTHONPATH": str(code)}
        cmd = [str(PYTHON), "-c", CHILD, str(out), *args, "--out", str(Path(folder) / "result")]
        t0 = time.monotonic()
        subprocess.run(cmd, cwd=code, env=env, check=True, stdout=subprocess.DEVNULL)
        wall = time.monotonic() - t0
        stamps = json.loads(out.read_text())
        rows = [(a[0], b[1] - a[1], b[2] - a[2]) for a, b in zip(stamps, stamps[1:])]
        print(f"{code.name}: {wall:.1f} s wall (the child process)", file=sys.stderr)
        return rows


def coarse(name: str) -> str:
    """A surrogate stage without its k (``greedy:k=2`` → ``greedy``), an ICP stage by its first words."""
    if ":k=" in name:
        return "surrogate " + name.split(":k=")[0]
    return " ".join(name.split()[:2])


def table(rows: list[tuple[str, float, float]]) -> dict[str, tuple[float, float]]:
    out: dict[str, tuple[float, float]] = {}
    for name, wall, cpu in rows:
        w, c = out.get(coarse(name), (0.0, 0.0))
        out[coarse(name)] = (w + wall, c + cpu)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--code", type=Path, action="append", help="a code tree (default: this one)")
    parser.add_argument("--part", default="part_b")
    parser.add_argument("--budget", default="default")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--rounds", type=int, default=1)
    parser.add_argument("--detail", action="store_true", help="every stage, not only the kinds")
    parser.add_argument("--search-config", type=Path, help="a TOML with a search table, passed to every tree")
    args = parser.parse_args()
    codes = [c.resolve() for c in (args.code or [ROOT])]
    command = ["search", args.part, "--budget", args.budget, "--seed", str(args.seed), "--no-report"]
    if args.search_config:
        command += ["--search-config", str(args.search_config.resolve())]
    results: dict[Path, list[dict]] = {c: [] for c in codes}
    for _ in range(args.rounds):
        for code in codes:
            rows = run(code, command)
            if args.detail:
                for name, wall, cpu in rows:
                    print(f"{code.name}\t{name}\t{wall:.1f}\t{cpu:.1f}", file=sys.stderr)
            results[code].append(table(rows))
    names = list(dict.fromkeys(n for c in codes for t in results[c] for n in t))
    print(f"`optipose {' '.join(command)}`, {args.rounds} round(s), mean wall s / CPU-s per stage\n")
    print("| stage | " + " | ".join(f"{c.name} wall | {c.name} CPU" for c in codes) + " |")
    print("| --- |" + " ---: | ---: |" * len(codes))
    for name in [*names, "total"]:
        cells = []
        for code in codes:
            runs = results[code]
            if name == "total":
                w = sum(sum(v[0] for v in t.values()) for t in runs) / len(runs)
                c = sum(sum(v[1] for v in t.values()) for t in runs) / len(runs)
            else:
                w = sum(t.get(name, (0, 0))[0] for t in runs) / len(runs)
                c = sum(t.get(name, (0, 0))[1] for t in runs) / len(runs)
            cells.append(f"{w:.1f} | {c:.1f}")
        print(f"| {name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
