"""A search's result folder: written as the search goes, so an interrupted run explains itself.

``config.toml`` (first), ``history.csv`` and ``cache.npz`` (flushed as the search goes: what was computed
is never lost, and ``--resume`` replays it), ``layouts/found_k*.toml`` (the surrogate's best first, the
finalists after the selection), ``selection.csv``, ``surrogate_scores.csv``, ``validation/`` (one
evaluation folder per evaluated layout) and ``comparison.csv`` (found vs. hand per k and axis), ``verdict/``
(the verdict's further draws, one folder each) and ``verdict.csv`` (the verdict with confidence).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from optipose.io.evaluation import write_evaluation
from optipose.files import atomic_path, reading
from optipose.io.folders import part_table, read_config, versions, write_config, write_csv
from optipose.io.tables import (
    comparison_frame,
    history_frame,
    selection_frame,
    surrogate_frame,
    verdict_frame,
)
from optipose.model.baseline import baseline_label
from optipose.model.layout import Layout, write_layout
from optipose.verdict.confidence import Verdicts

__all__ = ["SearchFolder", "save_cache", "load_cache"]

# what a search writes from its surrogate's results on, each anew (and its report: optipose.report.build's names)
_REWRITTEN = (
    "surrogate_scores.csv",
    "selection.csv",
    "validation",
    "comparison.csv",
    "verdict",
    "verdict.csv",
    "kinds.csv",
)


class SearchFolder:
    """A search's result folder as the pipeline's sink (:class:`optipose.search.pipeline.ResultSink`):
    each stage's records are written here the moment they exist."""

    def __init__(self, folder: Path):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)

    def start(self, part, objective, config, budget: str, seed: int, validation_seed: int) -> None:
        """``config.toml``; in a folder an earlier search wrote (its ``config.toml`` says so), after what that search
        wrote from its surrogate's results on is taken away (:data:`_REWRITTEN`): this search writes its own, and a
        folder must not show another run's draws, kinds or report beside this one's config. Its history, cache and
        layouts stay until this search writes its own (a resumed search starts from the cache; the layouts are the
        best so far of an interrupted one). A folder no search wrote is left as it is."""
        import shutil

        from optipose.errors import ConfigError
        from optipose.report.build import FIGURE_DIR, REPORT_HTML, REPORT_MD

        try:
            earlier = read_config(self.folder).command == "search"
        except ConfigError:  # none there, or not one of ours
            earlier = False
        for name in (*_REWRITTEN, REPORT_HTML, REPORT_MD, FIGURE_DIR) if earlier else ():
            path = self.folder / name
            if path.is_dir():
                shutil.rmtree(path)
            elif path.exists():
                path.unlink()
        _write_search_config(self.folder, part, objective, config, budget, seed, validation_seed)

    def load_cache(self, space_version: int) -> dict:
        return load_cache(self.folder, space_version)

    def flush(self, history, cache, space_version: int) -> None:
        """History and cache to disk: what was computed is never lost."""
        write_csv(history_frame(history), self.folder / "history.csv")
        save_cache(self.folder, cache, space_version)

    def layouts(self, layouts: dict[int, Layout], baseline: Layout | None) -> None:
        """``layouts/found_k*.toml`` and the baseline's: ``layouts/hand.toml`` when the part has a hand layout,
        else ``layouts/conventional.toml`` (:func:`optipose.model.baseline.baseline_label`)."""
        layout_dir = self.folder / "layouts"
        layout_dir.mkdir(exist_ok=True)
        for k, layout in layouts.items():
            write_layout(layout, layout_dir / f"found_k{k}.toml")
        if baseline is not None:
            write_layout(baseline, layout_dir / f"{baseline_label(baseline)}.toml")

    def selection(self, records) -> None:
        write_csv(selection_frame(records), self.folder / "selection.csv")

    def surrogate_scores(self, outcome) -> None:
        write_csv(surrogate_frame(outcome), self.folder / "surrogate_scores.csv")

    def evaluation(self, name: str, result) -> None:
        """``validation/<name>/``: one evaluation of the validation, as soon as it ends."""
        _write_evaluations(self.folder / "validation" / name, result)

    def validation(self, validation) -> None:
        """``comparison.csv``: found vs. hand per k and axis."""
        write_csv(comparison_frame(validation), self.folder / "comparison.csv")

    def verdict_draw(self, draw: int, name: str, result) -> None:
        """``verdict/draw-<i>/<name>/``: one evaluation of a draw of the verdict (after the validation's), as
        soon as it ends."""
        _write_evaluations(self.folder / "verdict" / f"draw-{draw}" / name, result)

    def verdict(self, verdicts: Verdicts) -> None:
        """``verdict.csv``: the verdict with confidence per k (and one found sensor against the baseline's largest
        choice), its intervals per axis; nothing without verdicts."""
        if verdicts.in_order():
            write_csv(verdict_frame(verdicts), self.folder / "verdict.csv")

    def kinds(self, kinds: dict) -> None:
        """``kinds.csv``: the BUYs raced again in each common kind of cell (``verdict.csv``'s rows with the cell's
        name first); nothing when none was raced."""
        frames = [verdict_frame(v).assign(cell=name) for name, v in kinds.items() if v.in_order()]
        if frames:
            table = pd.concat(frames, ignore_index=True)
            write_csv(table[["cell", *(c for c in table.columns if c != "cell")]], self.folder / "kinds.csv")


def _write_evaluations(sub: Path, result) -> None:
    """One evaluation into ``sub``."""
    sub.mkdir(parents=True, exist_ok=True)
    write_evaluation(result, sub)


def _write_search_config(folder: Path, part, objective, config, budget: str, seed: int, validation_seed: int) -> Path:
    from optipose.search.config import search_table

    return write_config(
        folder,
        {
            "command": "search",
            "part": part_table(part.name, str(getattr(part, "source", "")), getattr(part, "units", "auto")),
            "seed": seed,
            "validation_seed": validation_seed,
            "budget": budget,
            "search": search_table(config),
            "objective": objective.to_dict(),
            "objective_file": objective.source_text,
            "versions": versions(),
        },
    )


def save_cache(folder: Path, cache, space_version: int) -> None:
    """The per-sensor cache (u key → SensorInfo or Violation) as ``cache.npz``."""
    from optipose.search.surrogate import SensorInfo

    keys = list(cache)
    infos = [cache[k] for k in keys]
    ok = np.array([isinstance(v, SensorInfo) for v in infos])
    n_phases = max((len(v.G) for v in infos if isinstance(v, SensorInfo) and v.G is not None), default=0)
    arrays = dict(
        u=np.array(keys, dtype=float).reshape(-1, 6),
        feasible=ok,
        H=np.array([v.H if isinstance(v, SensorInfo) else np.zeros((6, 6)) for v in infos]).reshape(-1, 6, 6),
        counts=np.array([[v.n_points, v.n_voxels] if isinstance(v, SensorInfo) else [0, 0] for v in infos]).reshape(
            -1, 2
        ),
        violation=np.array([0.0 if isinstance(v, SensorInfo) else v.amount for v in infos]),
        constraint=np.array(["" if isinstance(v, SensorInfo) else v.constraint for v in infos], dtype=str),
        A=np.array([_or_zeros(v, "A", (6, 6)) for v in infos]).reshape(len(infos), 6, 6),
        G=np.array([_or_zeros(v, "G", (n_phases, 6)) for v in infos]).reshape(len(infos), n_phases, 6),
        space=space_version,
    )
    with atomic_path(folder / "cache.npz") as tmp, open(tmp, "wb") as file:  # a file: savez would add .npz to a name
        np.savez_compressed(file, **arrays)


def _or_zeros(info, name: str, shape: tuple) -> np.ndarray:
    value = getattr(info, name, None)  # a Violation has neither
    return np.zeros(shape) if value is None else value


def load_cache(folder: Path, space_version: int) -> dict:
    """The cache saved by :func:`save_cache`; empty when there is none or it was made under another pose
    map or surrogate (its keys or scores would mean something else); a damaged file is a ConfigError."""
    path = folder / "cache.npz"
    if not path.is_file():
        return {}
    with reading(path):
        return _cache_entries(np.load(path), space_version)


def _cache_entries(data, space_version: int) -> dict:
    from optipose.search.problem import Violation
    from optipose.search.surrogate import SensorInfo

    if "G" not in data:  # from before the voxel bias: start over
        return {}
    if (int(data["space"]) if "space" in data else 1) != space_version:  # its u keys name other poses: start over
        return {}
    constraint = data["constraint"] if "constraint" in data else np.full(len(data["u"]), "infeasible")
    out = {}
    rows = zip(
        data["u"],
        data["feasible"],
        data["H"],
        data["counts"],
        data["violation"],
        data["A"],
        data["G"],
        constraint,
    )
    for u, ok, H, (n_points, n_voxels), violation, A, G, why in rows:
        out[tuple(np.round(u, 9))] = (
            SensorInfo(H, int(n_points), int(n_voxels), A, G) if ok else Violation(str(why), float(violation))
        )
    return out
