"""Read a result folder back: :func:`load_result` gives the typed result a command wrote.

``optipose evaluate`` folders give an :class:`~optipose.evaluate.evaluator.EvaluationResult`, ``optipose
search`` folders a :class:`~optipose.search.records.SearchResult` whose ``verdicts()`` say, per k, whether
the found layout beats the hand-placed one, ``optipose robustness`` folders a
:class:`~optipose.io.robustness.RobustnessResult`. A search's trace comes back as records too:
:func:`load_history` (``Evaluation`` per surrogate call) and :func:`load_selection` (``IcpEvaluation`` per
ICP look at a candidate). The CLI tables, ``scripts/search_table.py`` and reports read
results through here, never by parsing CSV columns of their own.
"""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from optipose.errors import ConfigError
from optipose.evaluate.assignment import FAILED, UNOBSERVABLE, AxisChoice, Choice
from optipose.evaluate.objective import AXES
from optipose.io.folders import read_config

__all__ = ["load_result", "load_search", "load_history", "load_selection", "load_surrogate_scores", "choices_from_comparison"]


def load_result(folder: str | Path):
    """The result saved in ``folder``: an EvaluationResult or a SearchResult (ConfigError for anything else)."""
    folder = Path(folder)
    config = read_config(folder)
    command = config.get("command")
    if command == "evaluate":
        from optipose.io.evaluation import read_evaluation

        return read_evaluation(folder, config)
    if command == "search":
        return load_search(folder, config)
    if command == "robustness":
        from optipose.io.robustness import read_robustness

        return read_robustness(folder, config)
    raise ConfigError(f"{folder}: a '{command}' result, which optipose cannot read back")


def load_search(folder: Path, config: dict | None = None):
    """The :class:`~optipose.search.records.SearchResult` of a search folder."""
    from optipose.model.layout import load_layout
    from optipose.search.records import SearchResult, Validation

    folder = Path(folder)
    config = config or read_config(folder)
    layouts = {int(p.stem.removeprefix("found_k")): load_layout(p) for p in sorted((folder / "layouts").glob("found_k*.toml"))}
    hand_path = folder / "layouts" / "hand.toml"
    hand = load_layout(hand_path) if hand_path.is_file() else None
    found_names = [f"F{i + 1}" for i in range(max(layouts, default=0))]

    def validation(path: Path):
        if not path.is_file():
            return None
        rows = pd.read_csv(path)
        found = choices_from_comparison(rows[rows.layout == "found"], found_names)
        hand_choices = choices_from_comparison(rows[rows.layout == "hand"], hand.names if hand else [])
        protocol = str(rows["protocol"].iloc[0]) if len(rows) else "full"
        return Validation(protocol, int(config.get("validation_seed", -1)), found, hand_choices)

    return SearchResult(folder, config["part"]["name"], int(config["seed"]), str(config.get("budget", "")), config,
                        layouts, hand, validation(folder / "comparison.csv"),
                        validation(folder / "band" / "comparison.csv") if "band" in config else None)  # fmt: skip


def choices_from_comparison(rows: pd.DataFrame, names: list[str]) -> dict[int, Choice]:
    """k → Choice from ``comparison.csv`` rows of one layout (degrees back to radians), in file order;
    under a band (a ``condition`` column) the robust choice, carrying its statistics per condition."""
    if "condition" not in rows:
        return {k: _choice(group, k, names) for k, group in rows.groupby("k", sort=False)}
    out = {}
    for k, group in rows.groupby("k", sort=False):
        labels = list(dict.fromkeys(group["condition"]))
        under = tuple((label, _choice(group[group.condition == label], k, names)) for label in labels if label != "band")
        out[int(k)] = replace(_choice(group[group.condition == "band"], k, names), under=under)
    return out


def _choice(group: pd.DataFrame, k, names: list[str]) -> Choice:
    by_axis = {r.axis: r for r in group.itertuples(index=False)}
    axes = []
    for axis in AXES:
        r = by_axis[axis]
        axes.append(_axis(axis, r.subset, r.median_deg, r.p75_deg, names))
    first = group.iloc[0]
    sensors = str(first["sensors"])
    return Choice(int(k), _indices(sensors, names), sensors, tuple(axes), float(np.deg2rad(first["score_deg"])))


def _indices(name: str, names: list[str]) -> tuple[int, ...]:
    """Sensor indices of a subset name such as ``S1S3`` (the layout's names, longest first)."""
    if not name:
        return ()
    pattern = "|".join(re.escape(n) for n in sorted(names, key=len, reverse=True))
    tokens = re.findall(pattern, name) if pattern else []
    if "".join(tokens) != name:
        raise ConfigError(f"subset '{name}' does not name sensors of the layout ({', '.join(names)})")
    return tuple(sorted(names.index(t) for t in tokens))


def load_history(folder: str | Path) -> list:
    """The search's surrogate evaluations (``history.csv``) as :class:`~optipose.search.records.Evaluation`
    records, in order; [] when there is none."""
    import ast

    from optipose.search.records import EvalState, Evaluation

    path = Path(folder) / "history.csv"
    if not path.is_file():
        return []
    rows = pd.read_csv(path, keep_default_na=False, na_values={"value": ["nan"], "best": ["nan", ""]})
    return [
        Evaluation(int(r.eval), str(r.stage), int(r.k), tuple(ast.literal_eval(r.u)), EvalState(r.state), float(r.value),
                   float(r.best), str(r.constraint))
        for r in rows.itertuples(index=False)
    ]  # fmt: skip


def load_selection(folder: str | Path, names: list[str] | None = None) -> list:
    """The ICP evaluations of the selection, polish and confirmation (``selection.csv``) as
    :class:`~optipose.search.records.IcpEvaluation` records (degrees back to radians); [] when there is none.

    names : the sensor names subsets are spelled with (default F1 … F9 and S1 … S9)."""
    from optipose.search.records import IcpEvaluation

    path = Path(folder) / "selection.csv"
    if not path.is_file():
        return []
    rows = pd.read_csv(path, keep_default_na=False, na_values={"surrogate_deg": ["nan", ""]})
    names = names or [f"F{i}" for i in range(1, 10)] + [f"S{i}" for i in range(1, 10)]
    out = []
    for r in rows.to_dict("records"):
        axes = tuple(_axis(axis, r[f"{axis}_subset"], r[f"{axis}_median_deg"], r[f"{axis}_p75_deg"], names) for axis in AXES)
        choice = Choice(int(r["k"]), (), "", axes, float(np.deg2rad(r["score_deg"])))
        dominates = str(r["dominates_hand"]).strip().lower() == "true"
        out.append(IcpEvaluation(int(r["k"]), str(r["origin"]), float(r["surrogate_deg"]), str(r["protocol"]), choice, dominates))
    return out


def _axis(axis: str, subset, median_deg: float, p75_deg: float, names: list[str]) -> AxisChoice:
    """An axis of a choice from a table's cells: its subset's name or, where there is none, the reason
    written instead (``unobservable``, ``registrations failed``; an empty cell: unobservable)."""
    text = str(subset)
    median, p75 = np.deg2rad(_number(median_deg)), np.deg2rad(_number(p75_deg))
    if text in ("", "nan", UNOBSERVABLE, FAILED):
        return AxisChoice(axis, (), "", median, p75, FAILED if text == FAILED else UNOBSERVABLE)
    return AxisChoice(axis, _indices(text, names), text, median, p75)


def _number(cell) -> float:
    """A table's numeric cell as a float: an empty one (an axis with no subset, read without NA
    conversion) is NaN."""
    return np.nan if str(cell).strip() in ("", "nan") else float(cell)


def load_surrogate_scores(folder: str | Path) -> dict[tuple[str, int], float]:
    """(layout label, k) → the surrogate's predicted score (deg) from ``surrogate_scores.csv`` (found,
    greedy, joint, hand); {} when there is none."""
    path = Path(folder) / "surrogate_scores.csv"
    if not path.is_file():
        return {}
    rows = pd.read_csv(path)
    return {(str(r.layout), int(r.k)): float(r.score_deg) for r in rows.itertuples(index=False)}
