"""The fidelity ladder (issue #14): time per evaluation against how far the objective lands from full fidelity.

Layouts, per part (seeded, the same for every rung): the hand-placed layout (all its sensors, Table 1 at
k = all), each of its sensors alone, and ``--layouts`` random feasible SINGLE-sensor layouts drawn as
``bench_surrogate_ranking.py`` draws them (``SurrogateProblem(part, objective, SearchConfig())``, uniform
u in [0, 1]^6 kept when ``problem.score(u).feasible``). Single sensors keep an evaluation cheap (one scan
and one registration per orientation), so the ladder can afford >= 50 of them; the hand layout is the one
where the multi-sensor speed-ups (``subset_start``) act.

The reference is full fidelity: the ``paper`` objective, its full 77-scan protocol, ``column_stride = 1``
(every column cast), ``subset_start = "identity"`` and the ICP tolerance 1e-5° / 1e-5 mm; every rung runs on the same ``--seed`` and changes
ONE knob from the reference:

- ``cols<n>`` / ``cols<n>-nz``: a sensor model with n columns over the same width (3200 ... 100); the
  first keeps the per-point noise (a device with fewer pixels), the ``-nz`` one scales it by sqrt(n/3200)
  so a voxel's centroid keeps the full device's noise ("give the voxel the statistics of the columns not
  cast"). The benchmark builds these with ``dataclasses.replace`` on the part's sensor model.
- ``step<mm>``: the scan motion's step (0.5 = the reference, 1, 2, 4 mm), ``replace`` on ``part.motion``.
- ``proto<n>``: protocol size 77 (reference), 35 (step 1 deg), 21 (step 2 deg), 14 (``reduced_objective``,
  the ends of each sequence), 7 (one angle per sequence, +2 deg).
- ``vox<mm>``: the registration voxel (0.25, 0.5 = reference, 1, 2 mm).
- ``iter<n>``: ICP max_iterations (100 = reference, 20, 10, 5); ``tol<deg>``: the convergence tolerance,
  rotation (deg) and translation (mm) set to the same number (1e-5 = reference, 1e-4, 1e-3).
- ``p2plane-sample`` / ``p2point-sample``: the fast back-end against a 0.2 mm CAD sample, point-to-plane
  or point-to-point (the paper's method, ``objectives/paper-literal.toml``); ``o3d-p2plane``: Open3D's
  point-to-plane ICP (against the same sample), on the first ``--o3d-layouts`` layouts only (hand first).
- ``stride8``: the shipped column stride; ``combined``: the shipped multi-sensor start (hand layout only:
  a single sensor always starts at identity); ``shipped``: both, i.e. ``paper.toml`` as shipped (hand only).
- ``surrogate``: ``predicted_stats`` of ``problem.surrogate.info(T)`` per sensor, its time (scans + stats).

Per (rung, layout) a row goes to ``<out>/<part>_rows.csv`` as soon as it is measured (a rerun skips the
rows already there, so the ladder is resumable); the per-rung summary (``<part>_summary.csv``) and the
Pareto plot (``<part>_pareto.png``) are rebuilt from all rows. Per rung: the median wall time per
evaluation and the median over layouts of its ratio to the reference's time on that layout (the rows of
one run, so under the same load); per axis the absolute difference of Table 1's median and p75 from the
reference (mdeg, median over layouts and max); |Δ score| (mdeg); Spearman rho of the score across
layouts against the reference's, and per axis (median + p75 of the axis).

    .venv/bin/python benchmarks/bench_fidelity.py [--part part_b] [--layouts 50] [--seed 0] [--jobs 2]
        [--rungs ref,surrogate,proto7,...] [--max-layouts N] [--out benchmarks/results/fidelity] [--summary-only]

``--rungs`` runs the named rungs in the order given; ``--max-layouts`` measures only the first N layouts
(a costly rung on fewer layouts; the summary's ``layouts`` column says how many each rung has).

Figures, not asserts: the machine may be shared; compare the ratios, not seconds across runs.
"""

from __future__ import annotations

import argparse
import csv
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import numpy as np

AXES = ("roll", "pitch", "yaw")
DEG = np.pi / 180
MM = 1e-3
UNOBSERVABLE_MDEG = 1000.0  # the surrogate predicts ~3400 mdeg for an axis it cannot see; ICP reports NaN
FIELDS = [
    "part",
    "rung",
    "knob",
    "layout",
    "sensors",
    "k",
    "wall_s",
    "scans",
    "failed",
    "iterations",
    "score_mdeg",
    *[f"median_{a}_mdeg" for a in AXES],
    *[f"p75_{a}_mdeg" for a in AXES],
]


@dataclass(frozen=True)
class Rung:
    """One rung: ``build(part, objective) -> (part, objective)`` changes one knob of the reference.
    ``only``: "all" layouts, "hand" (the multi-sensor layout), or "o3d" (the first --o3d-layouts)."""

    name: str
    knob: str
    build: Callable | None  # None: the surrogate
    only: str = "all"


def _reg(**kw) -> Callable:
    return lambda p, o: (p, replace(o, registration=replace(o.registration, **kw)))


def _proto(**kw) -> Callable:
    return lambda p, o: (p, replace(o, protocol=replace(o.protocol, **kw)))


def _columns(n: int, scale_noise: bool) -> Callable:
    def build(part, objective):
        from optipose.model.sensor import load_sensor

        s = load_sensor(part.sensor)
        sigma = s.noise_sigma * (np.sqrt(n / s.points_per_profile) if scale_noise else 1.0)
        return replace(part, sensor=replace(s, points_per_profile=n, noise_sigma=sigma)), objective

    return build


def _step(mm: float) -> Callable:
    return lambda p, o: (replace(p, motion=replace(p.motion, step=mm * MM)), o)


def _reduced(p, o):
    from optipose.evaluate.objective import reduced_objective

    return p, reduced_objective(o)


def _shipped(p, o):
    """The shipped objective as it is (the rung's figures in benchmarks/README.md are of the shipped settings
    of their run: stride 8 and the combined start then)."""
    from optipose.evaluate.objective import load_objective

    return p, load_objective("paper").in_cell("ideal")


def rungs() -> list[Rung]:
    """The ladder in the order it runs: the reference, then the cheap rungs and the issue's questions first,
    so a run cut short has whole rungs (the hand layout is measured first in each)."""
    cols = {n: Rung(f"cols{n}", "columns", _columns(n, False)) for n in (100, 200, 400, 800, 1600)}
    nz = {n: Rung(f"cols{n}-nz", "columns (noise scaled)", _columns(n, True)) for n in (100, 200, 400, 800, 1600)}
    step = {s: Rung(f"step{s:g}", "scan step", _step(s)) for s in (4.0, 2.0, 1.0)}
    vox = {v: Rung(f"vox{v:g}", "voxel", _reg(voxel_size=v * MM)) for v in (2.0, 1.0, 0.25)}
    it = {n: Rung(f"iter{n}", "ICP iterations", _reg(max_iterations=n)) for n in (5, 10, 20)}
    tol = {
        t: Rung(f"tol{t:g}", "ICP tolerance", _reg(tolerance_rotation=t * DEG, tolerance_translation=t * MM))
        for t in (1e-3, 1e-4)
    }
    return [
        Rung("ref", "reference", lambda p, o: (p, o)),
        Rung("surrogate", "surrogate", None),
        Rung("proto7", "protocol", _proto(start=2 * DEG, stop=2 * DEG)),
        Rung("proto14", "protocol", _reduced),
        Rung("proto21", "protocol", _proto(step=2 * DEG)),
        Rung("proto35", "protocol", _proto(step=1 * DEG)),
        Rung("combined", "speed-ups", _reg(subset_start="combined"), "hand"),
        Rung("shipped", "speed-ups", _shipped, "hand"),
        Rung("stride8", "speed-ups", lambda p, o: (p, replace(o, scan=replace(o.scan, column_stride=8)))),
        nz[100],
        nz[400],
        nz[1600],
        cols[100],
        cols[400],
        cols[1600],
        step[4.0],
        step[2.0],
        step[1.0],
        vox[2.0],
        vox[1.0],
        it[5],
        it[10],
        tol[1e-3],
        Rung("p2point-sample", "method", _reg(method="point_to_point", reference="cad-sample")),
        Rung("o3d-p2plane", "method", _reg(backend="open3d", reference="cad-sample"), "o3d"),
        nz[200],
        nz[800],
        cols[200],
        cols[800],
        vox[0.25],
        it[20],
        tol[1e-4],
        Rung("p2plane-sample", "method", _reg(reference="cad-sample")),
    ]


def reference_objective():
    from optipose.evaluate.objective import load_objective

    o = load_objective("paper").in_cell("ideal")
    return replace(
        o,
        scan=replace(o.scan, column_stride=1),
        registration=replace(
            o.registration, subset_start="identity", tolerance_rotation=1e-5 * DEG, tolerance_translation=1e-5 * MM
        ),
    )


def draw_layouts(part, problem, n: int, seed: int) -> list[tuple[str, list[np.ndarray]]]:
    """(id, [T_O_S]) : the hand layout, its sensors alone, then n random feasible single-sensor layouts."""
    out = []
    if "hand" in part.layouts:
        hand = part.layouts["hand"]
        out.append(("hand", [s.T_O_S for s in hand.sensors]))
        out += [(f"hand_{s.name}", [s.T_O_S]) for s in hand.sensors]
    rng, drawn = np.random.default_rng(seed), 0
    while drawn < n:
        u = rng.random(6)
        if problem.score(u).feasible:
            out.append((f"r{drawn:02d}", list(problem.space.to_poses(u))))
            drawn += 1
    return out


def _row(part, rung, layout_id, poses, wall, score, median, p75, scans=0, failed=0, iterations=float("nan")) -> dict:
    row = dict(
        part=part,
        rung=rung.name,
        knob=rung.knob,
        layout=layout_id,
        sensors=len(poses),
        k=len(poses),
        wall_s=f"{wall:.4f}",
        scans=scans,
        failed=failed,
        iterations=f"{iterations:.3f}",
        score_mdeg=f"{score:.6g}",
    )
    row |= {f"median_{a}_mdeg": f"{m:.6g}" for a, m in zip(AXES, median)}
    return row | {f"p75_{a}_mdeg": f"{q:.6g}" for a, q in zip(AXES, p75)}


def _surrogate_table(s: dict, weights) -> tuple[float, list, list]:
    """The surrogate's score, per-axis median and p75 (mdeg) as Table 1 states them: an axis predicted at
    >= UNOBSERVABLE_MDEG (its information is ~0) is unobservable, NaN, and costs the evaluator's penalty."""
    from optipose.evaluate.assignment import UNOBSERVABLE_PENALTY

    (w, mw, pw), score, med, q = weights, 0.0, [], []
    for a, sub in enumerate(s.best_subset):
        j = s.subsets.index(sub)
        m, p = 1e3 * s.median_deg[j, a], 1e3 * s.p75_deg[j, a]
        if m >= UNOBSERVABLE_MDEG:
            m = p = np.nan
            score += w[a] * 1e3 * np.rad2deg(UNOBSERVABLE_PENALTY) * (mw + pw)
        else:
            score += w[a] * (mw * m + pw * p)
        med.append(m)
        q.append(p)
    return score, med, q


def run_rung(rung, part, objective, problem, layouts, done, args, write) -> None:
    from optipose.evaluate.evaluator import Evaluator
    from optipose.search.surrogate import predicted_stats

    todo = [(i, p) for i, p in layouts if (rung.name, i) not in done]
    if rung.only == "hand":
        todo = [(i, p) for i, p in todo if i == "hand"]
    elif rung.only == "o3d":
        keep = {i for i, _ in layouts[: args.o3d_layouts]}
        todo = [(i, p) for i, p in todo if i in keep]
    if not todo:
        return
    t0 = time.perf_counter()
    if rung.build is None:
        for i, poses in todo:
            t = time.perf_counter()
            s = predicted_stats([problem.surrogate.info(T) for T in poses], *problem.weights)
            wall = time.perf_counter() - t
            write(_row(part.name, rung, i, poses, wall, *_surrogate_table(s, problem.weights)))
    else:
        p, o = rung.build(part, objective)
        with Evaluator(p, o, seed=args.seed, jobs=args.jobs, quiet=True) as ev:
            for i, poses in todo:
                r = ev(poses)
                c = r.table[len(poses) - 1]
                med = [1e3 * np.rad2deg(a.median) for a in c.axes]
                q = [1e3 * np.rad2deg(a.p75) for a in c.axes]
                write(
                    _row(
                        part.name,
                        rung,
                        i,
                        poses,
                        r.timings["wall"],
                        1e3 * np.rad2deg(c.score),
                        med,
                        q,
                        r.n_scans,
                        r.n_failed,
                        float(r.per_scan["iterations"].mean()),
                    )
                )
    print(f"  {rung.name:15s} {len(todo):3d} layouts in {time.perf_counter() - t0:6.1f} s", flush=True)


# --- summary -------------------------------------------------------------------------------------------
def summarize(rows_path: Path, part: str):
    import pandas as pd
    from scipy.stats import spearmanr

    df = pd.read_csv(rows_path)
    df = df[df["part"] == part]
    ref = df[df["rung"] == "ref"].set_index("layout")
    order = [r.name for r in rungs() if r.name in set(df["rung"])]
    out = []
    for name in order:
        d = df[df["rung"] == name].set_index("layout")
        d = d[d.index.isin(ref.index)]
        if d.empty:
            continue
        r = ref.loc[d.index]
        row = {
            "rung": name,
            "knob": d["knob"].iloc[0],
            "layouts": len(d),
            "time_s": d["wall_s"].median(),
            "time_ratio": float(np.median(d["wall_s"] / r["wall_s"])),
            "dscore_med_mdeg": float(np.nanmedian(np.abs(d["score_mdeg"] - r["score_mdeg"]))),
            "dscore_max_mdeg": float(np.nanmax(np.abs(d["score_mdeg"] - r["score_mdeg"]))),
            "dscore_rel_med": float(np.nanmedian(np.abs(d["score_mdeg"] / r["score_mdeg"] - 1))),
        }
        for stat in ("median", "p75"):
            for a in AXES:
                diff = np.abs(d[f"{stat}_{a}_mdeg"] - r[f"{stat}_{a}_mdeg"]).to_numpy()
                diff = diff[np.isfinite(diff)]
                row[f"d{stat}_{a}_med"] = float(np.median(diff)) if len(diff) else np.nan
                row[f"d{stat}_{a}_max"] = float(np.max(diff)) if len(diff) else np.nan
        row["rho_score"] = _rho(spearmanr, d["score_mdeg"], r["score_mdeg"])
        for a in AXES:
            row[f"rho_{a}"] = _rho(
                spearmanr, d[f"median_{a}_mdeg"] + d[f"p75_{a}_mdeg"], r[f"median_{a}_mdeg"] + r[f"p75_{a}_mdeg"]
            )
        out.append(row)
    return pd.DataFrame(out)


def _rho(spearmanr, x, y) -> float:
    ok = np.isfinite(x.to_numpy()) & np.isfinite(y.to_numpy())
    return float(spearmanr(x[ok], y[ok])[0]) if ok.sum() >= 5 else np.nan


def print_summary(s) -> None:
    print(
        f"{'rung':15s} {'n':>3s} {'t/eval s':>8s} {'x ref':>7s} {'|dS| med':>9s} {'max':>8s} {'rel':>6s} "
        f"{'|dmed| worst-axis med/max':>26s} {'|dp75| worst-axis med/max':>26s} {'rho S':>6s} {'rho r/p/y':>17s}"
    )
    for _, r in s.iterrows():
        dm = max(r[f"dmedian_{a}_med"] for a in AXES), max(r[f"dmedian_{a}_max"] for a in AXES)
        dq = max(r[f"dp75_{a}_med"] for a in AXES), max(r[f"dp75_{a}_max"] for a in AXES)
        print(
            f"{r['rung']:15s} {r['layouts']:3d} {r['time_s']:8.3f} {r['time_ratio']:7.3f} {r['dscore_med_mdeg']:9.3f} "
            f"{r['dscore_max_mdeg']:8.2f} {100 * r['dscore_rel_med']:5.1f}% {dm[0]:12.3f} / {dm[1]:11.3f} "
            f"{dq[0]:12.3f} / {dq[1]:11.3f} {r['rho_score']:6.3f} {r['rho_roll']:5.2f} {r['rho_pitch']:5.2f} {r['rho_yaw']:5.2f}"
        )
    print(
        "(mdeg; |dS| = |score - reference score| over layouts; worst-axis = the largest of roll/pitch/yaw; "
        "x ref = median over layouts of time / reference time)"
    )


def plot(s, path: Path, part: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    colors = {k: f"C{i}" for i, k in enumerate(dict.fromkeys(s["knob"]))}
    fig, axes = plt.subplots(1, 2, figsize=(15, 6.5))
    floor = {"dscore_med_mdeg": 1e-3, "one_minus_rho": 1e-4}
    s = s.assign(one_minus_rho=1 - s["rho_score"])
    for ax, col, label in (
        (axes[0], "dscore_med_mdeg", "median |Δ score| over layouts [mdeg]"),
        (axes[1], "one_minus_rho", "1 − Spearman ρ of the score vs the reference"),
    ):
        d = s[(s["rung"] != "ref") & np.isfinite(s[col]) & (s["layouts"] >= 5)]
        x, y = d["time_ratio"].to_numpy(), np.maximum(d[col].to_numpy(), floor[col])
        for knob in colors:
            m = (d["knob"] == knob).to_numpy()
            if m.any():
                ax.scatter(x[m], y[m], color=colors[knob], label=knob, s=36, zorder=3)
        for xi, yi, name in zip(x, y, d["rung"]):
            ax.annotate(name, (xi, yi), textcoords="offset points", xytext=(4, 3), fontsize=7.5)
        x, y = np.append(x, 1.0), np.append(y, floor[col])
        front = _pareto(x, y)
        ax.step(x[front], y[front], where="post", color="k", lw=1, alpha=0.6, label="Pareto front", zorder=2)
        ax.scatter([1.0], [floor[col]], marker="*", s=120, color="k", zorder=4, label="reference (0 by definition)")
        ax.axhline(floor[col], color="grey", ls=":", lw=1)
        ax.set(xscale="log", yscale="log", xlabel="time per evaluation / reference (full fidelity) time", ylabel=label)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_title(f"{part}: the fidelity ladder (floor {floor['dscore_med_mdeg']:g} mdeg)")
    axes[1].set_title(f"{part}: rank agreement across layouts (floor {floor['one_minus_rho']:g})")
    axes[1].legend(fontsize=8, loc="lower left")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _pareto(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Indices of the points no other is both faster and closer than, by increasing time."""
    idx, best = [], np.inf
    for i in np.lexsort((y, x)):
        if y[i] < best:
            idx.append(i)
            best = y[i]
    return np.array(idx, dtype=int)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", default="part_b")
    ap.add_argument("--layouts", type=int, default=50, help="random feasible single-sensor layouts")
    ap.add_argument("--seed", type=int, default=0, help="the layouts' draw and every evaluation's noise seed")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--rungs", default="", help="comma-separated rung names (default: all, in ladder order)")
    ap.add_argument(
        "--max-layouts", type=int, default=0, help="measure only the first N layouts (hand ones first); 0: all"
    )
    ap.add_argument("--o3d-layouts", type=int, default=8, help="layouts (hand ones first) the Open3D rung runs on")
    ap.add_argument("--out", type=Path, default=Path("benchmarks/results/fidelity"))
    ap.add_argument("--summary-only", action="store_true")
    args = ap.parse_args()

    args.out.mkdir(parents=True, exist_ok=True)
    rows_path = args.out / f"{args.part}_rows.csv"
    if not args.summary_only:
        measure(args, rows_path)
    s = summarize(rows_path, args.part)
    s.to_csv(args.out / f"{args.part}_summary.csv", index=False, float_format="%.6g")
    print_summary(s)
    plot(s, args.out / f"{args.part}_pareto.png", args.part)
    print(f"wrote {rows_path}, {args.out / f'{args.part}_summary.csv'}, {args.out / f'{args.part}_pareto.png'}")


def measure(args, rows_path: Path) -> None:
    import os

    from optipose.model.part import load_part
    from optipose.search.config import SearchConfig
    from optipose.search.problem import SurrogateProblem

    part, objective = load_part(args.part), reference_objective()
    problem = SurrogateProblem(part, objective, SearchConfig())
    layouts = draw_layouts(part, problem, args.layouts, args.seed)
    by_name = {r.name: r for r in rungs()}
    wanted = [by_name[n] for n in args.rungs.split(",")] if args.rungs else list(by_name.values())
    layouts = layouts[: args.max_layouts] if args.max_layouts else layouts
    done = set()
    if rows_path.is_file():
        with rows_path.open() as f:
            done = {(r["rung"], r["layout"]) for r in csv.DictReader(f) if r["part"] == args.part}
    print(
        f"bench_fidelity: {args.part}, {len(layouts)} layouts ({args.layouts} random single-sensor + hand), seed {args.seed}, "
        f"--jobs {args.jobs}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}; {len(done)} rows already measured",
        flush=True,
    )
    new = not rows_path.is_file()
    with rows_path.open("a", newline="") as f:
        w = csv.DictWriter(f, FIELDS)
        if new:
            w.writeheader()

        def write(row):
            w.writerow(row)
            f.flush()

        t0 = time.perf_counter()
        for rung in wanted:
            run_rung(rung, part, objective, problem, layouts, done, args, write)
        print(f"measured in {time.perf_counter() - t0:.0f} s, load {os.getloadavg()[0]:.1f}", flush=True)


if __name__ == "__main__":
    main()
