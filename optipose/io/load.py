"""Read a result folder back: :func:`load_result` gives the typed result a command wrote.

``optipose evaluate`` folders give an :class:`~optipose.evaluate.evaluator.EvaluationResult`, ``optipose
search`` folders a :class:`~optipose.io.results.SearchResult` whose ``verdicts()`` say, per k, whether
the found layout beats the hand-placed one, ``optipose robustness`` folders a
:class:`~optipose.io.results.RobustnessResult` (all three in :mod:`optipose.io.results`); each reads the
folder's ``config.toml`` once, as a :class:`~optipose.io.config.RunConfig`. A search's trace comes back as
records too: :func:`load_history` (``Evaluation`` per surrogate call) and :func:`load_selection`
(``IcpEvaluation`` per ICP look at a candidate). The CLI tables, ``scripts/search_table.py`` and reports read
results through here, never by parsing CSV columns of their own.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from optipose.errors import ConfigError
from optipose.evaluate.assignment import Choice
from optipose.evaluate.objective import AXES
from optipose.files import reading
from optipose.io.choices import axis_choice, choices_from_comparison
from optipose.io.config import RunConfig, given
from optipose.io.folders import read_config
from optipose.verdict.confidence import (
    AxisError,
    AxisRatio,
    ConfidentVerdict,
    Decision,
    Interval,
    Verdicts,
)
from optipose.verdict.ruling import Ruling

__all__ = ["load_result", "load_search", "load_history", "load_selection", "load_surrogate_scores"]


def load_result(folder: str | Path):
    """The result saved in ``folder``: an EvaluationResult or a SearchResult (ConfigError for anything else)."""
    folder = Path(folder)
    config = read_config(folder)
    command = config.command
    if command == "evaluate":
        from optipose.io.evaluation import read_evaluation

        return read_evaluation(folder, config)
    if command == "search":
        return load_search(folder, config)
    if command == "robustness":
        from optipose.io.robustness import read_robustness

        return read_robustness(folder, config)
    raise ConfigError(f"{folder}: a '{command}' result, which optipose cannot read back")


def load_search(folder: Path, config: RunConfig | None = None):
    """The :class:`~optipose.io.results.SearchResult` of a search folder."""
    from optipose.io.results import SearchResult
    from optipose.model.layout import is_part_of, load_layout
    from optipose.search.records import Validation

    folder = Path(folder)
    config = config or read_config(folder)
    layouts = {
        int(p.stem.removeprefix("found_k")): load_layout(p) for p in sorted((folder / "layouts").glob("found_k*.toml"))
    }
    baselines = [p for p in (folder / "layouts" / "hand.toml", folder / "layouts" / "conventional.toml") if p.is_file()]
    baseline = load_layout(baselines[0]) if baselines else None
    found_names = [f"F{i + 1}" for i in range(max(layouts, default=0))]

    def names(
        k: int,
    ) -> list[str]:  # a found choice names the largest layout's sensors; the baseline's own, its sensors
        return layouts[k].names if k in layouts and is_part_of(layouts[k], baseline) else found_names

    def validation(path: Path):
        if not path.is_file():
            return None
        with reading(path):
            rows = pd.read_csv(path)
            found = {}
            for k, group in rows[rows.layout == "found"].groupby("k", sort=False):
                found |= choices_from_comparison(group, names(int(k)))
            baseline_choices = choices_from_comparison(rows[rows.layout == "hand"], baseline.names if baseline else [])
            protocol = str(rows["protocol"].iloc[0]) if len(rows) else "full"
        return Validation(protocol, int(given(config.validation_seed, -1)), found, baseline_choices)

    return SearchResult(
        folder,
        config.part_name,
        int(config.seed),
        str(given(config.budget, "")),
        config,
        layouts,
        baseline,
        validation(folder / "comparison.csv"),
        read_verdicts(folder / "verdict.csv"),
        read_kinds(folder / "kinds.csv"),
    )


def read_verdicts(path: Path) -> Verdicts:
    """The :class:`~optipose.verdict.confidence.Verdicts` of ``verdict.csv`` (none without one): per k, and the
    comparison of fewer found sensors with more hand ones (a row whose ``hand_k`` exceeds its ``k``)."""
    if not path.is_file():
        return Verdicts()
    with reading(path):
        return _verdicts_of(pd.read_csv(path, keep_default_na=False, na_values=[""]))


def read_kinds(path: Path) -> dict[str, Verdicts]:
    """Cell → the :class:`~optipose.verdict.confidence.Verdicts` of ``kinds.csv``: a search's BUYs raced again in the
    common kinds of cell (none without one)."""
    if not path.is_file():
        return {}
    with reading(path):
        rows = pd.read_csv(path, keep_default_na=False, na_values=[""])
        return {str(cell): _verdicts_of(group.drop(columns="cell")) for cell, group in rows.groupby("cell", sort=False)}


def _verdicts_of(rows: pd.DataFrame) -> Verdicts:
    """The verdicts of ``verdict.csv``'s rows (:func:`read_verdicts`)."""
    by_k, fewer = {}, None
    if "hand_k" not in rows:
        rows["hand_k"] = rows["k"]
    for name, value in (
        ("failed", np.nan),
        ("failed_low", np.nan),
        ("failed_high", np.nan),
        ("failures", np.nan),
        ("kept", False),
        ("ended", ""),
        ("ruling", ""),
        *((f"{side}_cell_median_deg{end}", np.nan) for side in ("found", "hand") for end in ("", "_low", "_high")),
    ):
        if name not in rows:  # a folder from before the failures' rule (NaN: not applied), the hand choice's answer,
            rows[name] = value  # the one-cell interval (NaN: not given)
    for (k, baseline_k), group in rows.groupby(["k", "hand_k"], sort=True):
        score, axes = group[group.axis == "score"].iloc[0], group[group.axis != "score"]

        def iv(row, name):
            return Interval(float(row[name]), float(row[f"{name}_low"]), float(row[f"{name}_high"]))

        more = int(score["more_draws"])
        against_more = int(baseline_k) != int(k)
        verdict = ConfidentVerdict(
            k=int(k),
            decision=Decision(str(score["decision"])),
            found_name=str(score["found"]),
            baseline_name=str(score["hand"]),
            score=iv(score, "ratio"),
            axes=tuple(
                AxisRatio(r.axis, iv(r, "ratio"), iv(r, "median_ratio"), iv(r, "p75_ratio"), iv(r, "failed"))
                for _, r in axes.iterrows()
            ),
            found=tuple(
                AxisError(r.axis, iv(r, "found_median_deg"), iv(r, "found_p75_deg"), iv(r, "found_cell_median_deg"))
                for _, r in axes.iterrows()
            ),
            baseline=tuple(
                AxisError(r.axis, iv(r, "hand_median_deg"), iv(r, "hand_p75_deg"), iv(r, "hand_cell_median_deg"))
                for _, r in axes.iterrows()
            ),
            found_score_deg=iv(score, "found_median_deg"),
            baseline_score_deg=iv(score, "hand_median_deg"),
            n_draws=int(score["draws"]),
            n_scans=int(score["scans"]),
            tolerance=float(score["tolerance"]),
            confidence=float(score["confidence"]),
            more_draws=None if more < 0 else more,
            seconds_per_draw=float(score["seconds_per_draw"]),
            reference=str(score["reference"]),
            baseline_k=int(baseline_k) if against_more else 0,
            failures=float(score["failures"]),
            kept=str(score["kept"]) == "True",
            ended=score["ended"] if isinstance(score["ended"], str) else "",  # "" reads back as NaN
            ruling=_ruling(score),
        )
        if against_more:
            fewer = verdict
        else:
            by_k[int(k)] = verdict
    return Verdicts(by_k, fewer)


def _ruling(row) -> Ruling | None:
    """A verdict row's ruling range (``ruling``, ``ruling_at``, ``ruling_above``, ``ruling_share``), or None."""
    if not isinstance(row["ruling"], str) or not row["ruling"]:
        return None
    return Ruling(
        row["ruling"], float(row["ruling_at"]), str(row["ruling_above"]) == "True", float(row["ruling_share"])
    )


def load_history(folder: str | Path) -> list:
    """The search's surrogate evaluations (``history.csv``) as :class:`~optipose.search.records.Evaluation`
    records, in order; [] when there is none."""
    import ast

    from optipose.search.records import EvalState, Evaluation

    path = Path(folder) / "history.csv"
    if not path.is_file():
        return []
    with reading(path):
        rows = pd.read_csv(path, keep_default_na=False, na_values={"value": ["nan"], "best": ["nan", ""]})
        return [
            Evaluation(
                int(r.eval),
                str(r.stage),
                int(r.k),
                tuple(ast.literal_eval(r.u)),
                EvalState(r.state),
                float(r.value),
                float(r.best),
                str(r.constraint),
            )
            for r in rows.itertuples(index=False)
        ]


def load_selection(folder: str | Path, names: list[str] | None = None) -> list:
    """The ICP evaluations of the selection, polish and confirmation (``selection.csv``) as
    :class:`~optipose.search.records.IcpEvaluation` records (degrees back to radians); [] when there is none.

    names : the sensor names subsets are spelled with (default F1 … F9 and S1 … S9)."""
    from optipose.search.records import IcpEvaluation

    path = Path(folder) / "selection.csv"
    if not path.is_file():
        return []
    names = names or [f"F{i}" for i in range(1, 10)] + [f"S{i}" for i in range(1, 10)]
    out = []
    with reading(path):
        rows = pd.read_csv(path, keep_default_na=False, na_values={"surrogate_deg": ["nan", ""]})
        for r in rows.to_dict("records"):
            axes = tuple(
                axis_choice(axis, r[f"{axis}_subset"], r[f"{axis}_median_deg"], r[f"{axis}_p75_deg"], names)
                for axis in AXES
            )
            choice = Choice(int(r["k"]), (), "", axes, float(np.deg2rad(r["score_deg"])))
            dominates = str(r["dominates_hand"]).strip().lower() == "true"
            out.append(
                IcpEvaluation(
                    int(r["k"]), str(r["origin"]), float(r["surrogate_deg"]), str(r["protocol"]), choice, dominates
                )
            )
    return out


def load_surrogate_scores(folder: str | Path) -> dict[tuple[str, int], float]:
    """(layout label, k) → the surrogate's predicted score (deg) from ``surrogate_scores.csv`` (found,
    greedy, joint, hand); {} when there is none."""
    path = Path(folder) / "surrogate_scores.csv"
    if not path.is_file():
        return {}
    with reading(path):
        rows = pd.read_csv(path)
        return {(str(r.layout), int(r.k)): float(r.score_deg) for r in rows.itertuples(index=False)}
