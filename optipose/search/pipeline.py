"""``optipose search`` as a pipeline: surrogate search → full-protocol validation → result folder.

Steps, each in its own function:

1. :func:`run` sets up the result folder (or reopens one with ``resume``) and saves the config first, so
   even an interrupted run explains itself;
2. the NLopt search on the surrogate (:mod:`optipose.search.core`), with the per-sensor cache and the history
   flushed to the folder as it goes; a resumed run reloads the cache and replays its earlier evaluations
   for free (same seed, same sequence);
3. validation: the found layouts and the hand-placed one are evaluated on the objective's full protocol
   with a noise seed the search never saw (:func:`validation_seed`); those are the numbers reported.
   The ``quick`` budget validates on the reduced protocol (each sequence at its end angles, 14 of the
   paper's 77 scans) with the same held-out seed, so it answers within a minute; the table says so;
4. the comparison table (found vs. hand per axis), layouts as TOML, history, per-scan errors.
"""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from optipose.errors import ConfigError, OptiposeError
from optipose.model.layout import Layout, SensorPose, write_layout
from optipose.search.space import SPACE_VERSION
from optipose.search.core import BUDGETS, Found, SearchConfig, SearchOutcome, SurrogateProblem, run_search
from optipose.search.surrogate import SensorInfo
from optipose.seeds import validation_seed

__all__ = ["SearchReport", "run", "validation_seed", "config_from_budget", "NoFeasibleLayout"]

log = logging.getLogger(__name__)


class NoFeasibleLayout(OptiposeError):
    """The search met no layout that satisfies the constraints (e.g. the sensors cannot see the part)."""


@dataclass
class SearchReport:
    folder: Path
    outcome: SearchOutcome
    rows: list[dict] = field(default_factory=list)  # found vs. hand per k and axis (degrees)
    layouts: dict[int, Layout] = field(default_factory=dict)
    validated: bool = False
    protocol: str = "full"  # the validation's protocol: full, or reduced (the quick budget)


# --- the folder ---------------------------------------------------------------------------------------
def _config_table(part, objective, config: SearchConfig, budget: str, seed: int) -> dict:
    from optipose.io.folders import versions

    return {
        "command": "search",
        "part": {"name": part.name, "source": str(getattr(part, "source", ""))},
        "seed": seed,
        "validation_seed": validation_seed(seed),
        "budget": budget,
        "search": asdict(config),
        "objective": objective.to_dict(),
        "objective_file": objective.source_text,
        "versions": versions(),
    }


def _save_cache(folder: Path, cache: dict) -> None:
    keys = list(cache)
    infos = [cache[k] for k in keys]
    ok = np.array([isinstance(v, SensorInfo) for v in infos])
    n_phases = max((len(v.G) for v in infos if isinstance(v, SensorInfo) and v.G is not None), default=0)
    np.savez_compressed(
        folder / "cache.npz",
        u=np.array(keys, dtype=float).reshape(-1, 6),
        feasible=ok,
        H=np.array([v.H if isinstance(v, SensorInfo) else np.zeros((6, 6)) for v in infos]).reshape(-1, 6, 6),
        counts=np.array([[v.n_points, v.n_voxels] if isinstance(v, SensorInfo) else [0, 0] for v in infos]).reshape(-1, 2),
        violation=np.array([0.0 if isinstance(v, SensorInfo) else v for v in infos]),
        A=np.array([_or_zeros(v, "A", (6, 6)) for v in infos]).reshape(len(infos), 6, 6),
        G=np.array([_or_zeros(v, "G", (n_phases, 6)) for v in infos]).reshape(len(infos), n_phases, 6),
        space=SPACE_VERSION,
    )


def _or_zeros(info, name: str, shape: tuple) -> np.ndarray:
    value = getattr(info, name, None) if isinstance(info, SensorInfo) else None
    return np.zeros(shape) if value is None else value


def _load_cache(folder: Path) -> dict:
    path = folder / "cache.npz"
    if not path.is_file():
        return {}
    data = np.load(path)
    if "G" not in data:  # a cache from before the surrogate modelled the voxel bias: scores differ, start over
        return {}
    if (int(data["space"]) if "space" in data else 1) != SPACE_VERSION:  # its u keys name other poses: start over
        return {}
    out = {}
    rows = zip(data["u"], data["feasible"], data["H"], data["counts"], data["violation"], data["A"], data["G"])
    for u, ok, H, (n_points, n_voxels), violation, A, G in rows:
        out[tuple(np.round(u, 9))] = SensorInfo(H, int(n_points), int(n_voxels), A, G) if ok else float(violation)
    return out


def _flush(folder: Path, problem: SurrogateProblem) -> None:
    """History and cache to disk: what was computed is never lost."""
    pd.DataFrame(problem.history).to_csv(folder / "history.csv", index=False)
    _save_cache(folder, problem.cache)


# --- the pipeline -------------------------------------------------------------------------------------
def run(part, objective, config: SearchConfig, seed: int, folder: Path, budget: str = "default",
        jobs: int = 1, resume: bool = False, on_eval=None, on_stage=None) -> SearchReport:  # fmt: skip
    """Search, validate and write everything to ``folder``. ``on_eval(row)`` follows the search;
    ``on_stage(text)`` is told when a stage starts."""
    from optipose.io.folders import write_config

    folder.mkdir(parents=True, exist_ok=True)
    write_config(folder, _config_table(part, objective, config, budget, seed))
    problem = SurrogateProblem(part, objective, config)
    if resume:
        problem.cache.update(_load_cache(folder))
        log.info("resuming with %d cached sensor poses", len(problem.cache))
    flushed = [0]

    def tick(row):
        if on_eval:
            on_eval(row)
        if len(problem.history) - flushed[0] >= 100:
            _flush(folder, problem)
            flushed[0] = len(problem.history)

    problem.on_eval = tick
    if on_stage:
        on_stage("searching on the surrogate")
    outcome = run_search(part, objective, config, seed, problem)
    _flush(folder, problem)
    if not outcome.found:
        raise NoFeasibleLayout(
            f"no feasible layout for '{part.name}': in {len(outcome.history)} evaluations no sensor pose returned "
            f"{config.min_points} points without its head hitting the part or a keep-out (can the sensors see "
            f"this part at all? check --units, the material and the part's size against the {config.clearance * 1e3:.0f} mm clearance)"
        )
    report = SearchReport(folder, outcome)
    _write_layouts(report, part, outcome.found)  # the surrogate's best, on disk before anything slower
    if config.select_candidates > 0 and not outcome.interrupted:
        from optipose.search.refine import select_finalists

        if on_stage:
            on_stage("selecting finalists by ICP on a reduced protocol")
        finalists, rows = select_finalists(
            part, objective, outcome, problem, seed, config.select_candidates, config.select_time, on_stage, jobs
        )
        pd.DataFrame(rows).to_csv(folder / "selection.csv", index=False)
        _write_layouts(report, part, {**outcome.found, **finalists})
    _surrogate_rows(report, outcome)
    if outcome.interrupted:
        return report
    if on_stage:
        on_stage(f"validating on the {config.validation} protocol (held-out noise seed)")
    report.protocol = config.validation
    _validate(report, part, objective, seed, jobs)
    _pictures(report, part)
    return report


def _pictures(report: SearchReport, part) -> None:
    """``layouts/found_k*.png`` beside the TOML files: each found layout drawn as ``optipose show`` does."""
    from dataclasses import replace as _replace

    from optipose.report.views import render_part

    shown = _replace(part, layouts={**part.layouts, **{f"found_k{k}": lay for k, lay in report.layouts.items()}})
    for k in report.layouts:
        try:
            render_part(shown, report.folder / "layouts" / f"found_k{k}.png", f"found_k{k}")
        except Exception as exc:  # a picture must never cost the results
            log.warning("could not draw found_k%d: %s", k, exc)


def _write_layouts(report: SearchReport, part, found: dict[int, Found]) -> None:
    report.layouts = {k: _layout(f, k) for k, f in found.items()}
    layout_dir = report.folder / "layouts"
    layout_dir.mkdir(exist_ok=True)
    for k, layout in report.layouts.items():
        write_layout(layout, layout_dir / f"found_k{k}.toml")
    if "hand" in part.layouts:
        write_layout(part.layouts["hand"], layout_dir / "hand.toml")


def _layout(found: Found, k: int) -> Layout:
    names = [f"F{i + 1}" for i in range(k)]
    sensors = tuple(SensorPose(n, T) for n, T in zip(names, found.poses))
    return Layout(sensors, name=f"found_k{k}", description=f"found by the {found.strategy} search, surrogate score {found.score:.5f} deg")


def _surrogate_rows(report: SearchReport, outcome: SearchOutcome) -> None:
    rows = []
    for k, f in sorted(outcome.found.items()):
        for label, g in (("found", f), ("greedy", outcome.greedy.get(k)), ("joint", outcome.joint.get(k)), ("hand", outcome.hand.get(k))):
            if g is not None and g.stats:
                rows.append({"k": k, "layout": label, "fidelity": "surrogate", "score_deg": g.stats["score"],
                             "penalised_deg": g.score})  # fmt: skip
    pd.DataFrame(rows).to_csv(report.folder / "surrogate_scores.csv", index=False)


def _groups(layouts: dict[int, Layout]) -> list[list[int]]:
    """Which found layouts can share one evaluation: a layout whose poses all belong to a larger one."""
    groups: list[tuple[list[np.ndarray], list[int]]] = []
    for k in sorted(layouts, reverse=True):
        poses = layouts[k].poses
        for pool, members in groups:
            if all(any(np.allclose(T, P) for P in pool) for T in poses):
                members.append(k)
                break
        else:
            groups.append((list(poses), [k]))
    return [members for _, members in groups]


def _validate(report: SearchReport, part, objective, seed: int, jobs: int) -> None:
    from optipose.evaluate.assignment import _choose
    from optipose.evaluate.evaluator import Evaluator
    from optipose.io.folders import write_evaluation

    vseed = validation_seed(seed)
    if report.protocol == "reduced":
        from optipose.search.refine import reduced_objective

        objective = reduced_objective(objective)
    out_dir = report.folder / "validation"
    out_dir.mkdir(exist_ok=True)
    rows = []
    with Evaluator(part, objective, seed=vseed, jobs=jobs) as evaluator:
        for members in _groups(report.layouts):
            big = report.layouts[max(members)]
            result = evaluator(big)
            write_evaluation(result, _sub(out_dir, f"found_k{max(members)}"))
            by_key = {(r.subset, r.axis): r for r in result.stats.itertuples(index=False)}
            n_scans = result.per_scan["scan"].nunique()
            for k in members:
                idx = tuple(big.names.index(n) for n in _names_in(report.layouts[k], big))
                rows += _choice_rows("found", k, _choose(idx, big.names, by_key, objective.statistic, n_scans))
        if "hand" in part.layouts:
            hand = evaluator(part.layouts["hand"])
            write_evaluation(hand, _sub(out_dir, "hand"))
            for choice in hand.table:
                if choice.k in report.layouts:
                    rows += _choice_rows("hand", choice.k, choice)
    for row in rows:
        row["protocol"] = report.protocol
    report.rows = rows
    report.validated = True
    pd.DataFrame(rows).to_csv(report.folder / "comparison.csv", index=False)


def _names_in(layout: Layout, big: Layout) -> list[str]:
    """Names in ``big`` of the poses of ``layout``."""
    return [next(n for n, P in zip(big.names, big.poses) if np.allclose(T, P)) for T in layout.poses]


def _sub(folder: Path, name: str) -> Path:
    path = folder / name
    path.mkdir(parents=True, exist_ok=True)
    return path


def _choice_rows(label: str, k: int, choice) -> list[dict]:
    return [
        {"k": k, "layout": label, "sensors": choice.sensors, "axis": a.axis, "subset": a.subset or "unobservable",
         "median_deg": float(np.rad2deg(a.median)), "p75_deg": float(np.rad2deg(a.p75)), "score_deg": float(np.rad2deg(choice.score))}
        for a in choice.axes
    ]  # fmt: skip


def config_from_budget(budget: str, sensors: tuple[int, ...], overrides: dict | None = None) -> SearchConfig:
    if budget not in BUDGETS:
        raise ConfigError(f"unknown budget '{budget}' (use {', '.join(BUDGETS)})")
    return SearchConfig(sensors=sensors, **{**BUDGETS[budget], **(overrides or {})})
