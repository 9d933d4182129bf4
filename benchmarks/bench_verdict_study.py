"""The verdict in the real cell on six parts, and a held-out check of every verdict (issue #33).

    .venv/bin/python benchmarks/bench_verdict_study.py run     [--parts part_a,part_b,part_c,bushing,angle,housing]
                                                               [--budget default] [--cell ur10e] [--seed 0] [--out results/verdict-study] [--report]
                                                               [--search-config settings.toml]
    .venv/bin/python benchmarks/bench_verdict_study.py holdout [--out results/verdict-study] [--offset 1000] [--jobs 2] [--verdict-time 0]
                                                               [--draws 30] [--file holdout.csv] [--choices kept] [--in-cell cobot,common:low]
    .venv/bin/python benchmarks/bench_verdict_study.py table   [--out results/reference,results/verdict-study] [--file holdout.csv]
                                                               [--remade-file holdout-remade.csv] [--in-cell cobot,common:low]
    .venv/bin/python benchmarks/bench_verdict_study.py draws   [--out results/reference,results/verdict-study]

``run``: ``optipose search PART --budget B --cell C --seed S --jobs 2`` per part, one after another, each into
``OUT/<part>/`` (with its report under ``--report``: ``scripts/reference.sh`` makes results/reference so); the
wall time and peak memory of each (``getrusage`` of the child) into ``OUT/runs.csv``. ``--out`` may name several
folders, separated by commas (``holdout`` and ``table``: each part in the first that holds it). The
parts are the shipped A, B, C (hand layouts) and the three of ``scripts/make_study_parts.py`` (conventional
baselines; ``studies/parts/``).
``holdout``: per search folder, its found layouts and its baseline evaluated again on a run seed the search never
used (the search's seed + ``--offset``: another held-out validation seed, other cell instances, other noise),
and the verdict raced as the search's was (:func:`optipose.search.draws.confident_verdicts`, the search's own
settings, or up to ``--draws``) — into ``OUT/<part>/holdout.csv`` (or ``--file``). ``--choices kept`` (the default)
keeps each layout's choice (its subset per axis) as the search made it: what a BUY mounts, checked on draws the
search never saw (in a real cell without a held-out validation, whose draw the race would not read). ``--in-cell``
races the kept choices in other cells instead (a preset, or ``NAME:low`` / ``NAME:high``: every range at that end),
each into ``holdout-<cell>.csv``: whether a BUY holds at the ranges' ends and in the other kinds of cell. ``--choices remade`` makes the choices again on the held-out validation's draw: whether another
search's validation would choose, and buy, the same. A BUY holds when the held-out verdict is BUY too.
``table``: one row per part and k — the search's verdict, hand / found in sum with its interval, the predicted
median per axis for found and baseline, the draws, and the held-out verdicts (with their draws; the choices remade in a
column of their own where ``--remade-file`` is present); as Markdown, for docs/results.md.
``draws``: per search folder and k, hand / found in sum on each draw the search stored — the validation's, where
the choices of subsets were made, then the verdict's — and the mean over the verdict's: how much the draw a choice
was made on flatters it.
"""

from __future__ import annotations

import argparse
import functools
import resource
import shutil
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
PARTS = {
    "part_a": "part_a",
    "part_b": "part_b",
    "part_c": "part_c",
    "bushing": "studies/parts/bushing/part.toml",
    "angle": "studies/parts/angle/part.toml",
    "housing": "studies/parts/housing/part.toml",
}


def run(args) -> None:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for name in args.parts.split(","):
        folder = out / name
        shutil.rmtree(
            folder, ignore_errors=True
        )  # a search's folder holds only what this run writes: no draws or holdouts of an earlier one
        command = [
            sys.executable,
            "-m",
            "optipose",
            "search",
            PARTS[name],
            "--budget",
            args.budget,
            "--cell",
            args.cell,
            "--seed",
            str(args.seed),
            "--jobs",
            "2",
            "--out",
            str(folder),
        ] + ([] if args.report else ["--no-report"])
        command += ["--search-config", str(Path(args.search_config).resolve())] if args.search_config else []
        t0 = time.perf_counter()
        done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
        (out / f"{name}.log").write_text(done.stdout + done.stderr)
        rows.append({"part": name, "exit": done.returncode, "wall_s": round(wall, 1), "peak_mb_so_far": round(peak)})
        print(f"{name}: exit {done.returncode}, {wall:.1f} s", flush=True)
        pd.DataFrame(rows).to_csv(out / "runs.csv", index=False)


def holdout(args) -> None:
    import tomllib

    from optipose.evaluate.objective import objective_from_table
    from optipose.io.load import load_result
    from optipose.io.tables import verdict_frame
    from optipose.model.part import load_part
    from optipose.search.config import Preset, SearchConfig, saved_table, search_preset
    from optipose.search.validate import validate
    from optipose.search.draws import choice_draw_counts, confident_verdicts
    from optipose.verdict.words import confident_line, ruling_line

    wanted = set(args.parts.split(","))
    for folder, cell in ((f, c) for f in sorted(_folders(args.out, wanted).values()) for c in _in_cells(args)):
        result = load_result(folder)
        saved = result.config
        objective = objective_from_table(tomllib.loads(saved.objective_file)).in_cell(cell or saved.cell_name)
        config = search_preset(saved_table(saved.search)).apply(
            SearchConfig()
        )  # sectioned or flat, as the folder has it
        if args.verdict_time is not None:  # 0: race on draws alone, whatever the machine's load
            config = Preset(verdict={"time": args.verdict_time}).apply(config)
        if args.draws:  # a longer race than the search's, to settle what its draws left open
            config = Preset(verdict={"draws": args.draws}).apply(config)
        part = load_part(saved.part_source or saved.part_name)
        seed = int(saved.seed) + args.offset
        first: dict = {}
        t0 = time.perf_counter()
        if args.choices == "kept" and not choice_draw_counts(
            objective
        ):  # the search's choices; the race does not read a validation's draw
            validation = result.validation
        else:
            validation = validate(
                part, objective, result.layouts, seed, args.jobs, config.validation.protocol, first.__setitem__
            )
            if args.choices == "kept":  # what the search bought, on the held-out draws (the ideal cell's first)
                validation = replace(validation, found=result.validation.found, baseline=result.validation.baseline)
        verdicts = confident_verdicts(part, objective, result.layouts, validation, first, seed, config, args.jobs)
        pd.DataFrame(verdict_frame(verdicts)).to_csv(folder / _held_file(args.file, cell), index=False)
        print(
            f"{folder.name}{f' in {cell}' if cell else ''} ({time.perf_counter() - t0:.0f} s): "
            + "; ".join(confident_line(v) for v in verdicts.by_k.values()),
            flush=True,
        )
        for line in filter(None, (ruling_line(v) for v in verdicts.by_k.values())):
            print(line, flush=True)


def _in_cells(args) -> list:
    """holdout's cells: the search's own (None), or each of ``--in-cell``."""
    return args.in_cell.split(",") if args.in_cell else [None]


def _held_file(file: str, cell: str | None) -> str:
    """The file a holdout in ``cell`` writes: ``holdout.csv`` in the search's own cell, ``holdout-cobot-low.csv`` in
    ``cobot:low``."""
    return file if cell is None else f"{Path(file).stem}-{Path(cell).stem.replace(':', '-')}{Path(file).suffix}"


def table(args) -> None:
    from optipose.io.load import load_result, read_verdicts
    from optipose.verdict.words import interval_cell, ratio_cell  # "not measured" for an axis a layout does not see

    folders = _folders(args.out, set(PARTS))
    remade = args.remade_file and any((folder / args.remade_file).is_file() for folder in folders.values())
    cells = [c for c in _in_cells(args) if c]
    print(
        "| part | k | verdict | found / baseline | baseline / found in sum | roll, found / baseline | pitch | yaw | draws | held out |"
        + (" held out, choices remade |" if remade else "")
        + "".join(f" held out in {c} |" for c in cells)
    )
    print("| --- | ---: | --- | --- | --- | --- | --- | --- | ---: | --- |" + " --- |" * (bool(remade) + len(cells)))
    for name, folder in folders.items():
        by_k = load_result(folder).confident.by_k
        files = [args.file] + ([args.remade_file] if remade else []) + [_held_file(args.file, c) for c in cells]
        held = [read_verdicts(folder / file).by_k for file in files]
        for k, v in by_k.items():
            axes = [
                f"{interval_cell(f.median_deg)} / {interval_cell(h.median_deg)}" for f, h in zip(v.found, v.baseline)
            ]
            others = [
                f"{h.decision} {ratio_cell(h.score)} ({h.n_draws})" if h else "-" for h in (by.get(k) for by in held)
            ]
            print(
                f"| {name} | {k} | {v.decision} | {v.found_name} / {v.reference} {v.baseline_name} | {ratio_cell(v.score)} | "
                + " | ".join(axes)
                + f" | {v.n_draws} | "
                + " | ".join(others)
                + " |"
            )


def draws(args) -> None:
    import tomllib

    import numpy as np

    from optipose.verdict.confidence import compare_draws, paired_draw
    from optipose.verdict.rules import Rules
    from optipose.evaluate.objective import objective_from_table
    from optipose.io.load import load_result
    from optipose.search.draws import sides

    print("| part | k | validation's draw | verdict's draws (mean, range) | draws |")
    print("| --- | ---: | ---: | --- | ---: |")
    for name, folder in _folders(args.out, set(PARTS)).items():
        result = load_result(folder)
        rules = Rules(
            replicates=1, statistic=objective_from_table(tomllib.loads(result.config.objective_file)).statistic
        )
        stored = [folder / "validation"] + sorted((folder / "verdict").glob("draw-*"), key=lambda d: int(d.name[5:]))
        v = result.validation
        loaded = functools.cache(load_result)  # a nested group's evaluation serves each of its k
        for k, side in sides(result.layouts, v, result.baseline).items():
            ratios = []
            for d in stored:
                if (d / side.evaluation).is_dir():
                    pair = paired_draw(loaded(d / side.evaluation), side.choice, loaded(d / "hand"), v.baseline[k])
                    ratios.append(compare_draws([pair], rules).score.estimate)
            rest = np.array(ratios[1:])
            spread = f"{rest.mean():.2f}x ({rest.min():.2f}-{rest.max():.2f})" if len(rest) else "-"
            print(f"| {name} | {k} | {ratios[0]:.2f}x | {spread} | {len(rest)} |")


def _folders(outs: str, wanted: set) -> dict[str, Path]:
    """Part name → its search folder: the first of the comma-separated ``outs`` that holds one, in PARTS' order."""
    held = {
        name: [Path(out) / name for out in outs.split(",") if (Path(out) / name / "verdict.csv").is_file()]
        for name in PARTS
        if name in wanted
    }
    return {name: folders[0] for name, folders in held.items() if folders}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=("run", "holdout", "table", "draws"))
    ap.add_argument("--parts", default=",".join(PARTS))
    ap.add_argument("--budget", default="default")
    ap.add_argument("--cell", default="ur10e")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--offset", type=int, default=1000)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--report", action="store_true", help="run: write each search's report")
    ap.add_argument(
        "--search-config",
        default=None,
        help="run: a TOML of [search] settings over the budget's (optipose search --search-config)",
    )
    ap.add_argument(
        "--verdict-time",
        type=float,
        default=None,
        help="holdout: the race's seconds (default: the search's; 0: draws alone)",
    )
    ap.add_argument(
        "--in-cell",
        default="",
        help="holdout, table: race (read) the held-out verdicts in these cells instead of the search's own, comma-separated "
        "(a preset, NAME:low / NAME:high for every range at that end), each into holdout-<cell>.csv",
    )
    ap.add_argument("--draws", type=int, default=0, help="holdout: the race's draws at most (default: the search's)")
    ap.add_argument(
        "--choices",
        choices=("kept", "remade"),
        default="kept",
        help="holdout: each layout's subset per axis as the search chose it, or chosen again on the held-out validation",
    )
    ap.add_argument(
        "--remade-file",
        default="holdout-remade.csv",
        help="table: the held-out verdicts with choices remade, a column where present",
    )
    ap.add_argument(
        "--file", default="holdout.csv", help="holdout: the file each folder's verdicts go to; table: the file read"
    )
    ap.add_argument("--out", default=str(ROOT / "results" / "verdict-study"))
    args = ap.parse_args()
    {"run": run, "holdout": holdout, "table": table, "draws": draws}[args.what](args)


if __name__ == "__main__":
    main()
